"""Measurement imperfections for synthetic recordings (robustness studies and tests).

:func:`degrade` turns a clean simulated recording into what a logger would
deliver: Gaussian sensor noise, encoder quantisation, current-command
quantisation, dynamometer noise and a clock offset between logger and
program. All random draws come from one seeded generator.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..recording import Recording


@dataclass(frozen=True)
class Imperfections:
    """Noise levels of a logged recording.

    Attributes
    ----------
    position_noise_um : float
        Standard deviation of actual-position noise, µm (before quantisation).
    position_quantum_um : float
        Encoder resolution, µm (0 = none).
    current_noise_A : float
        Standard deviation of current-command noise, A.
    current_quantum_A : float
        Current-command resolution, A (0 = none).
    force_noise_N : float
        Standard deviation of dynamometer noise on fx, fy, fz, N.
    time_offset_s : float
        Logger clock minus program clock, s.
    """

    position_noise_um: float = 0.3
    position_quantum_um: float = 1.0
    current_noise_A: float = 0.02
    current_quantum_A: float = 0.01
    force_noise_N: float = 1.0
    time_offset_s: float = 1.2345

    def scaled(self, factor: float) -> "Imperfections":
        """Noise levels (not resolutions, not the offset) multiplied by ``factor``."""
        return replace(self, position_noise_um=self.position_noise_um * factor,
                       current_noise_A=self.current_noise_A * factor, force_noise_N=self.force_noise_N * factor)


def _quantise(x: np.ndarray, q: float) -> np.ndarray:
    return np.round(x / q) * q if q > 0.0 else x


def degrade(recording: Recording, imperfections: Imperfections | None = None, seed: int = 0) -> Recording:
    """A copy of a single-member recording with measurement imperfections.

    Actual positions ``{a}_mm`` get noise and encoder quantisation; the
    reference ``{a}_ref_mm`` (a controller variable) stays exact; current
    commands get noise and quantisation; forces get noise and ``fc_N`` is
    recomputed from the noisy ``fx_N``, ``fy_N`` when both exist.
    """
    imp = imperfections or Imperfections()
    rng = np.random.default_rng(seed)
    channels = {name: np.array(recording[name], dtype=float) for name in recording.channels}
    n = len(recording)
    channels["t_s"] = channels["t_s"] + imp.time_offset_s
    for a in "xyz":
        if f"{a}_mm" in channels:
            noisy = channels[f"{a}_mm"] + rng.normal(0.0, imp.position_noise_um * 1e-3, n)
            channels[f"{a}_mm"] = _quantise(noisy, imp.position_quantum_um * 1e-3)
        if f"{a}_tcmd_A" in channels:
            noisy = channels[f"{a}_tcmd_A"] + rng.normal(0.0, imp.current_noise_A, n)
            channels[f"{a}_tcmd_A"] = _quantise(noisy, imp.current_quantum_A)
        if f"f{a}_N" in channels:
            channels[f"f{a}_N"] = channels[f"f{a}_N"] + rng.normal(0.0, imp.force_noise_N, n)
    if "fc_N" in channels:
        if "fx_N" in channels and "fy_N" in channels:
            channels["fc_N"] = np.hypot(channels["fx_N"], channels["fy_N"])
        else:
            channels["fc_N"] = np.abs(channels["fc_N"] + rng.normal(0.0, imp.force_noise_N, n))
    return Recording.from_channels(channels, recording.units, recording.success, recording.message,
                                   f"{recording.source} (degraded, seed {seed})")


def synthetic_case(
    case_dir,
    machine,
    imperfections: Imperfections | None = None,
    seed: int = 0,
    time_limit_s: float = 600.0,
) -> tuple[Recording, Recording]:
    """Run a case's program on the twin with a known machine and write a degraded ``recording.csv``.

    A self-check of an identification: generate the experiment
    (:func:`orchestrator.experiments.write_experiment`), simulate it here with
    parameters you chose, identify them back.

    Parameters
    ----------
    case_dir : str or Path
        Case folder (``case.toml`` naming ``recording = "recording.csv"``).
    machine : str, Path or Machine
        The "true" machine parameter set.
    imperfections : Imperfections, optional
        Default :class:`Imperfections` (pass ``Imperfections(0, 0, 0, 0, 0, 0)`` for a clean file).
    seed : int
        Noise seed.
    time_limit_s : float
        Simulated-time limit, s.

    Returns
    -------
    clean, degraded : Recording
        The simulated recording and the one written to the case's recording file.
    """
    from pathlib import Path

    from ..case import load_case
    from ..machine import Machine
    from ..simulate import simulate
    from .errors import IdentificationError

    case = load_case(case_dir)
    if isinstance(machine, Machine):
        case.machine = machine
    else:
        case = load_case(case_dir, machine_override=machine)
    result = simulate(case=case, plot=False, time_limit_s=time_limit_s)
    if not result.success:
        raise IdentificationError(f"{case_dir}: simulation of the experiment failed: {result.message}")
    degraded = degrade(result.recording, imperfections, seed)
    target = case.recording or Path(case.folder) / "recording.csv"
    degraded.write_csv(target)
    return result.recording, degraded
