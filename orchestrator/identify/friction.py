"""Friction identification: Stribeck parameters per axis and direction from reciprocating runs.

The recording is searched for constant-velocity windows
(:mod:`.segments`); each window gives one Stribeck point ``(|v|, |F|)`` with
``F = Atc kt 2 pi / Lb`` (at constant velocity the drive force equals the
friction, Sim & Lee 2023 Section 2.2). The points of every case are pooled
per axis and direction and fitted with :func:`.stribeck.fit_stribeck`.
"""
from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..case import Case
from ..machine import Machine
from .common import fitted_machine, provenance, write_outputs
from .data import CaseData, axes_in, check_columns, force_per_amp, load_inputs, measured_rows
from .errors import IdentificationError
from .fit_quality import stribeck_misfit
from .journal import Journal
from .segments import Segment, SegmentSettings, find_segments, require_segments
from .stribeck import StribeckFit, fit_stribeck

_log = logging.getLogger(__name__)

DIRECTIONS = {1: "positive", -1: "negative"}


@dataclass
class FrictionFit:
    """Result of :func:`identify_friction` (attributes ending in ``_``).

    Attributes
    ----------
    params_ : dict
        ``params_[axis][direction]`` -> :class:`StribeckFit` (direction
        ``"positive"`` / ``"negative"``).
    segments_ : list of Segment
        All constant-velocity windows used.
    machine_ : Machine
        The case's machine with the fitted friction.
    provenance_ : dict
        Dotted key -> source text of the fitted values.
    method : str
    wall_time_ : float
        Seconds for the whole identification.
    cases : list of str
    notes_ : list of str
        Rows left out because a needed cell was empty (not measured), per case and axis, and fits whose
        residual the plateaus' own scatter does not explain (:func:`.fit_quality.stribeck_misfit`: the
        friction does not follow the Stribeck law at the speeds named) (``report.json`` -> ``notes``).
    """

    params_: dict[str, dict[str, StribeckFit]]
    segments_: list[Segment]
    machine_: Machine
    provenance_: dict[str, str]
    method: str
    wall_time_: float
    cases: list[str] = field(default_factory=list)
    notes_: list[str] = field(default_factory=list)

    def points(self, axis: str, direction: str) -> tuple[np.ndarray, np.ndarray]:
        """Stribeck points ``(speed [m/s], force [N])`` (magnitudes) of one axis and direction."""
        sign = 1 if direction == "positive" else -1
        segs = [s for s in self.segments_ if s.axis == axis and s.direction == sign]
        return (np.array([abs(s.velocity) for s in segs]), np.array([sign * s.force for s in segs]))

    def report(self) -> dict:
        """JSON-ready report: parameters, fitness, residual RMS, iterations, wall time, points."""
        return {
            "kind": "friction",
            "method": self.method,
            "cases": self.cases,
            "wall_time_s": self.wall_time_,
            "notes": self.notes_,
            "axes": {
                a: {d: {
                    "coulomb_N": f.coulomb, "static_N": f.static, "stribeck_velocity_m_per_s": f.stribeck_velocity,
                    "viscous_Ns_per_m": f.viscous, "fitness_J_N2": f.fitness, "residual_rms_N": f.rms,
                    "iterations": f.iterations, "evaluations": f.evaluations, "wall_time_s": f.wall_time,
                    "points": f.points,
                } for d, f in dirs.items()} for a, dirs in self.params_.items()
            },
            "segments": [s.to_dict() for s in self.segments_],
        }

    def write(self, out: str | Path, plots: bool = True) -> dict[str, Path]:
        """Write ``machine.toml``, ``report.json`` and ``stribeck_<axis>.png`` into ``out``."""
        files = write_outputs(out, self.machine_, self.provenance_, self.report())
        if plots:
            from .plots import stribeck_png

            for a in self.params_:
                files[f"stribeck_{a}"] = stribeck_png(self, a, Path(out) / f"stribeck_{a}.png")
        return files


def collect_segments(data: Sequence[CaseData], axes: Sequence[str] | None, settings: SegmentSettings,
                     notes: list[str] | None = None) -> tuple[list[str], list[Segment]]:
    """Constant-velocity windows of the requested (or all recorded) axes of every case.

    Rows without a needed cell (not measured) are left out, each case and axis adding a line to ``notes``
    (:func:`.data.measured_rows`).
    """
    notes = [] if notes is None else notes
    segments: list[Segment] = []
    wanted: list[str] = []
    for d in data:
        rec = d.recording
        present = axes_in(rec, ("_mm", "_tcmd_A"))
        use = list(axes) if axes else present
        if not use:
            raise IdentificationError(
                f"{d.source}: friction identification needs a position column '<axis>_mm' and the current command "
                f"'<axis>_tcmd_A' of at least one axis; the recording has {rec.channels}"
            )
        for a in use:
            cols = ["t_s", f"{a}_mm", f"{a}_tcmd_A"]
            purpose = f"friction identification of axis {a}"
            rows, note = measured_rows(rec, cols, purpose)
            if note is not None:
                _log.warning("%s", note)
                notes.append(note)
            check_columns(rows, cols, purpose)
            found = find_segments(rows, a, force_per_amp(d.case, a), settings)
            if axes or found:
                segments += found
                if a not in wanted:
                    wanted.append(a)
    if not wanted:
        raise IdentificationError(
            f"{', '.join(d.source for d in data)}: no axis moves at constant velocity; expected reciprocating runs "
            "(`cnctwin experiment friction`)"
        )
    for a in wanted:
        require_segments([s for s in segments if s.axis == a], a, ", ".join(d.source for d in data), settings)
    return wanted, segments


def identify_friction(
    cases: Iterable[str | Path | Case],
    method: str = "default",
    seed: int = 0,
    axes: Sequence[str] | None = None,
    settings: SegmentSettings | None = None,
    journal: Journal | None = None,
) -> FrictionFit:
    """Identify Stribeck friction (Fc, Fs, vs, mu_v) per axis and direction.

    Parameters
    ----------
    cases : iterable of case folders / ``case.toml`` paths / Case
        Reciprocating runs (``cnctwin experiment friction``) with their
        recordings (``t_s``, ``{a}_mm``, ``{a}_tcmd_A``; ``{a}_ref_mm``
        helps detection).
    method : {"default", "paper-ga"}
        Optimiser of ``J = sum e^2 + max |e|`` (see :mod:`.stribeck`).
    seed : int
        GA seed.
    axes : sequence of str, optional
        Axes to identify (default: every axis that moves at constant velocity).
    settings : SegmentSettings, optional
        Segment detection tuning.
    journal : Journal, optional
        Records each Stribeck fit (one per axis and direction) for checkpoints and resume
        (see :func:`orchestrator.identify.identify`).

    Returns
    -------
    FrictionFit

    Examples
    --------
    >>> fit = identify_friction(["runs/friction_x"])            # doctest: +SKIP
    >>> fit.params_["x"]["positive"].coulomb                   # doctest: +SKIP
    """
    start = time.perf_counter()
    settings = settings or SegmentSettings()
    data = load_inputs(cases)
    journal = journal or Journal()
    notes: list[str] = []
    wanted, segments = collect_segments(data, axes, settings, notes)
    params: dict[str, dict[str, StribeckFit]] = {}
    for a in wanted:
        params[a] = {}
        for sign, name in DIRECTIONS.items():
            segs = [s for s in segments if s.axis == a and s.direction == sign]
            speed = np.array([abs(s.velocity) for s in segs])
            force = np.array([sign * s.force for s in segs])
            label = f"{data[0].source}: axis {a} {name}"
            params[a][name] = journal.memo("friction.stribeck", (speed, force, method, seed, label),
                                           lambda: fit_stribeck(speed, force, method, seed, label=label))
            # the law is tested with the best Stribeck curve (the default fit): the paper's GA stops at its fitness
            # limit (100 N^2), about 3 N rms from Stribeck data, which is its tolerance, not a misfit of the law
            best = params[a][name] if method == "default" else fit_stribeck(speed, force, "default", label=label)
            misfit = stribeck_misfit(segs, best, label)
            if misfit is not None:
                _log.warning("%s", misfit)
                notes.append(misfit)
    names = [d.name for d in data]
    source = provenance(f"friction {method} (Stribeck fit of constant-velocity segments, J = sum e^2 + max|e|)", names)
    updates = {
        f"axis.{a}.friction.{d}": {
            "coulomb_N": f.coulomb, "static_N": f.static,
            "stribeck_velocity_m_per_s": f.stribeck_velocity, "viscous_Ns_per_m": f.viscous,
        } for a, dirs in params.items() for d, f in dirs.items()
    }
    machine, extra = fitted_machine(data[0].case.machine, updates, source, "friction")
    return FrictionFit(params, segments, machine, extra, method, time.perf_counter() - start, names, notes)


class FrictionIdentifier:
    """Estimator-style wrapper of :func:`identify_friction` (``fit`` returns self).

    Parameters
    ----------
    method : {"default", "paper-ga"}
    seed : int
    axes : sequence of str, optional
    settings : SegmentSettings, optional
    """

    def __init__(self, method: str = "default", seed: int = 0, axes: Sequence[str] | None = None,
                 settings: SegmentSettings | None = None) -> None:
        self.method = method
        self.seed = seed
        self.axes = axes
        self.settings = settings

    def fit(self, cases: Iterable[str | Path | Case]) -> "FrictionIdentifier":
        """Identify from ``cases``; sets ``result_``, ``params_``, ``machine_``."""
        self.result_ = identify_friction(cases, self.method, self.seed, self.axes, self.settings)
        self.params_ = self.result_.params_
        self.machine_ = self.result_.machine_
        return self
