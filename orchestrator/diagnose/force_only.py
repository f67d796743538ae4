"""A dynamometer-only recording: its clock from the cutting load, its tool path from the twin.

A dynamometer on its own DAQ (the paper's Kistler and NI card) records ``t_s``, ``fx_N``, ``fy_N`` (maybe
``fc_N``) and nothing of the controller: no ``line``, no positions. Its clock is found by lining up the
recorded cutting load with the twin's predicted one (:func:`.align.time_offset_from_forces`), refined by the
twin's forces replayed at the recorded instants (:func:`.force_phase.phase_matched_offset`), and the
cutting diagnosis then drives the cutting model with the tool path, spindle speed and lines of the twin's
run (with cutting) at ``t - offset``: the recording is augmented with them (:func:`force_only_recording`).
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from ..case import Case
from ..machine import Machine
from ..recording import Recording
from ..simulate import simulate as simulate_twin
from .align import ENVELOPE_REVOLUTIONS, force_clock
from .errors import DiagnosisError
from .force_phase import phase_matched_offset
from .prepare import MIN_STROKE_M

#: Twin channels taken at ``t - offset`` into the augmented recording.
TWIN_CHANNELS = ("x_mm", "y_mm", "z_mm", "spindle_ref_rpm")
#: Recorded channels that the augmented recording drops (they did not move, or are not measured).
CNC_CHANNELS = ("line", "x_mm", "y_mm", "z_mm", "x_ref_mm", "y_ref_mm", "z_ref_mm", "x_tcmd_A", "y_tcmd_A",
                "z_tcmd_A")


@dataclass
class ForceOnly:
    """A force recording aligned by its cutting load and completed with the twin's path.

    Attributes
    ----------
    recording : Recording
        Recorded ``t_s`` and forces (and ``spindle_rpm`` when measured) plus the twin's ``x_mm``,
        ``y_mm``, ``z_mm``, ``spindle_ref_rpm`` (the twin's ramped spindle speed when ``spindle_rpm`` is not
        measured) and ``line`` at ``t - offset``.
    offset : float
        Recording clock minus program clock, s.
    method : str
        How the offset was found.
    twin : Recording or None
        The twin's run with cutting (program clock) whose path was added.
    window_s : float
        Envelope window of the clock fit [s] (:data:`.align.ENVELOPE_REVOLUTIONS` spindle revolutions).
    """

    recording: Recording
    offset: float
    method: str
    twin: Recording | None = field(default=None, repr=False)
    window_s: float = 0.0


def _moves(recording: Recording, name: str) -> bool:
    if name not in recording:
        return False
    v = np.asarray(recording[name], float)
    ok = np.isfinite(v)
    return bool(ok.mean() > 0.5 and np.ptp(v[ok]) > MIN_STROKE_M * 1e3)


def needs_force_clock(recording: Recording) -> bool:
    """True when nothing but the forces can align the recording: no ``line`` and no moving position or command."""
    if "line" in recording and np.isfinite(recording["line"]).any():
        return False
    return not any(_moves(recording, f"{a}{s}") for a in "xyz" for s in ("_mm", "_ref_mm"))


def measures_positions(recording: Recording) -> bool:
    """True when an axis's actual position (``x_mm``, ``y_mm`` or ``z_mm``) is mostly measured and moves.

    Without one the feed drives cannot be diagnosed (the following error is commanded minus actual position),
    and a recording with forces is aligned by its cutting load like a dynamometer's, even when it has ``line``.
    """
    return any(_moves(recording, f"{a}_mm") for a in "xyz")


def twin_loads_for_clock(twin: Recording, case: Case) -> dict[str, np.ndarray]:
    """The twin's cutting loads offered to the clock alignment [N]; the better fit of the recording is taken.

    ``"step-mean torque"``: the step-mean spindle torque over the tool radius, which does not depend on
    where samples fall. ``"1 ms |F|"``: ``hypot(fx_N, fy_N)`` of the twin's instantaneous 1 ms samples. At a
    whole number of samples per tooth period (a 2-flute tool at 6000 rpm: 5) those fall at the same few
    angles of every tooth, so a narrow pulse (a 1 mm side pass: 0.7 ms of the 5 ms) is caught or missed for
    whole cuts: the twin's samples missed the first 90 ms of such a pass of :mod:`.scorecard_part` that the
    truth's dynamometer caught, and its clock came out 14 ms off. Its own recording, though, is sampled at
    the same angles, and the 1 ms ``|F|`` fits it exactly.
    """
    out = {}
    if "spindle_torque_Nm" in twin and case.tool is not None and case.tool.diameter_mm > 0.0:
        torque = np.nan_to_num(np.abs(np.asarray(twin["spindle_torque_Nm"], float)))
        out["step-mean torque"] = torque / (0.5e-3 * case.tool.diameter_mm)
    out["1 ms |F|"] = np.hypot(np.asarray(twin["fx_N"], float), np.asarray(twin["fy_N"], float))
    if "step-mean torque" not in out:
        out["step-mean torque"] = out["1 ms |F|"]
    return out


def force_only_recording(case: Case, recording: Recording, machine: Machine) -> ForceOnly:
    """Align a force-only recording by its cutting load and add the twin's tool path, spindle speed and lines.

    Parameters
    ----------
    case : Case
        With a ``[stock]``: the twin's run with cutting predicts the load.
    recording : Recording
        ``t_s``, ``fx_N``, ``fy_N`` (at least).
    machine : Machine
        Parameter set of the twin's run.

    Raises
    ------
    DiagnosisError
        The twin's run does not cut the stock, or the recording has no force samples.
    """
    src = recording.source
    twin = simulate_twin(case=replace(case, machine=machine), plot=False).recording
    t_twin = np.asarray(twin.t, float)
    loads = twin_loads_for_clock(twin, case)
    load_twin = loads["step-mean torque"]
    cutting = load_twin > 0.0
    if len(twin) < 3 or not cutting.any():
        raise DiagnosisError(f"{src}: the recording has forces only (no 'line', no moving position): its clock is "
                             f"found from the twin's predicted cutting load, but the twin's run of {case.program} "
                             f"does not cut the stock of {case.source or case.folder}")
    t = np.asarray(recording.t, float)
    fx, fy = np.asarray(recording["fx_N"], float), np.asarray(recording["fy_N"], float)
    ok = np.isfinite(fx) & np.isfinite(fy)
    if ok.sum() < 100:
        raise DiagnosisError(f"{src}: fewer than 100 rows with both fx_N and fy_N; a force-only recording is "
                             "aligned by its cutting load")
    rpm = float(np.median(np.asarray(twin["spindle_rpm"], float)[cutting]))
    window = ENVELOPE_REVOLUTIONS * 60.0 / max(rpm, 1.0)
    fits = {name: force_clock(t[ok], np.hypot(fx[ok], fy[ok]), t_twin, load, window) for name, load in loads.items()}
    chosen = min(fits, key=lambda name: fits[name][1])
    coarse = fits[chosen][0]
    method = (f"cutting load |F| = hypot(fx_N, fy_N) against the twin's prediction ({chosen}, the better fit of "
              f"{' and '.join(loads)}): where each cuts, cross-correlated, then {1e3 * window:.3g} ms moving means "
              f"({ENVELOPE_REVOLUTIONS} spindle revolutions) refined by least squares, an affine map per cut")
    try:
        offset, _ = phase_matched_offset(case, machine, twin, t[ok], fx[ok], fy[ok], coarse, window)
        method += (f" ({1e3 * coarse:.4g} ms); then the twin's fx, fy replayed at the recorded instants, offset and "
                   f"spindle angle by least squares sample by sample ({1e3 * (offset - coarse):+.3g} ms)")
    except DiagnosisError as exc:  # the replay cannot follow the twin's path: keep the envelope's clock
        offset = coarse
        method += f"; not refined sample by sample ({exc})"
    return ForceOnly(_augmented(recording, twin, offset), float(offset), method, twin, window)


def _augmented(recording: Recording, twin: Recording, offset: float) -> Recording:
    """``recording`` without its CNC channels, plus the twin's path, spindle speed and line at ``t - offset``."""
    t_twin = np.asarray(twin.t, float)
    t_prog = np.asarray(recording.t, float) - offset
    channels = {c: np.asarray(recording[c], float) for c in recording.channels if c not in CNC_CHANNELS}
    for c in TWIN_CHANNELS:
        channels[c] = np.interp(t_prog, t_twin, np.asarray(twin[c], float))
    measured_rpm = "spindle_rpm" in recording and np.isfinite(recording["spindle_rpm"]).mean() > 0.5
    if not measured_rpm:
        # the twin's ramped spindle speed is a command, not a measurement: as `spindle_rpm` it was taken for a
        # measured speed with no noise (droop rows whose noise floor came out 1e-12 rpm, a column of 5e13 that
        # broke the selection of every cutting effect on some clocks), so it is the speed command here
        channels.pop("spindle_rpm", None)
        channels["spindle_ref_rpm"] = np.interp(t_prog, t_twin, np.asarray(twin["spindle_rpm"], float))
    idx = np.clip(np.searchsorted(t_twin, t_prog, side="right") - 1, 0, t_twin.size - 1)
    channels["line"] = np.asarray(twin["line"], float)[idx]
    return Recording.from_channels(channels, source=recording.source, file_lines=recording.file_lines)


def refine_with_effects(case: Case, recording: Recording, machine: Machine, only: ForceOnly,
                        effects: Mapping[str, float], names: str) -> ForceOnly:
    """The force clock refined once more on a replay with the effects the cutting diagnosis fitted.

    :func:`force_only_recording` refines the clock on a replay of the twin *without* the effects found later;
    a runout gives a 2-flute tool's teeth chips of ``h +- 2e`` (about 4 N/um on the test part), which that
    replay fits with a biased offset (1.85 ms on the 10 um runout of ``tests/test_diagnose_force_only.py``).
    Here :func:`.force_phase.phase_matched_offset` runs again from ``only.offset`` with ``effects`` in every
    replayed member, and the twin's path is added at the new clock.

    Parameters
    ----------
    case : Case
    recording : Recording
        The recording as read (``t_s``, ``fx_N``, ``fy_N``, ...).
    machine : Machine
        Parameter set of the twin's run.
    only : ForceOnly
        The first clock (from :func:`force_only_recording`, with its twin's run).
    effects : mapping
        Cutting-component parameter values (SI, :func:`.cutting_library.component_values`).
    names : str
        The fitted effects, for ``method``.

    Raises
    ------
    DiagnosisError
        ``only`` has no twin's run, or the replay cannot follow the twin's path.
    """
    if only.twin is None:
        raise DiagnosisError(f"{recording.source}: the force clock has no twin's run to refine it with the effects")
    t = np.asarray(recording.t, float)
    fx, fy = np.asarray(recording["fx_N"], float), np.asarray(recording["fy_N"], float)
    ok = np.isfinite(fx) & np.isfinite(fy)
    offset, _ = phase_matched_offset(case, machine, only.twin, t[ok], fx[ok], fy[ok], only.offset, only.window_s,
                                     effects)
    method = (f"{only.method}; then, with the fitted {names} in the replay, refined again the same way "
              f"({1e3 * (offset - only.offset):+.3g} ms) and the cutting effects refitted at that clock")
    return ForceOnly(_augmented(recording, only.twin, offset), float(offset), method, only.twin, only.window_s)
