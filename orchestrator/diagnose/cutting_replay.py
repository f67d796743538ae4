"""Cutting-only replay: the twin's cutting component driven by the recorded motion and spindle speed.

The spec's "commanded versus actual" rule, for the cutting load: the force
model is fed with what the machine actually did, so that servo differences
are not mistaken for cutting physics.

* **Tool path**: the recorded actual positions. When the commands
  (``{a}_ref_mm``) are recorded too, the path is the command (exact,
  shape-preserving cubic between samples) minus the recorded following error
  smoothed over :data:`SMOOTH_S` (which removes the encoder quantisation
  that would otherwise enter the chip thickness through the feed per
  tooth); without commands, the actual positions themselves, smoothed.
* **Spindle**: the recorded actual ``spindle_rpm`` (else ``spindle_ref_rpm``).
  The spindle angle at the first force sample is not logged: it is an
  alignment quantity (:mod:`.cutting_align`).
* **Component**: :class:`fmus_src.cutting.PathCuttingLoad` on the engagement
  table of the case's program, stepped from force sample to force sample,
  one batch member per parameter set (baseline, effect columns, refit
  Jacobians) in one run.
* **Chip over one tooth period**: a tooth cuts what the previous tooth left,
  so the feed per tooth at the instant ``t`` is the tool-centre displacement
  ``c(t) - c(t - T)`` over the last tooth period ``T`` (Altintas ch. 2; the
  independent truth's definition). The component takes it so from its own
  record of the steps (:func:`fmus_src.cutting.kernel.chord_feed`), also
  where the feed changes within ``T`` (a cut that stops in the material);
  against a surface left ``m`` teeth back (runout, chatter) the displacement
  over ``m`` periods (:func:`fmus_src.cutting.kernel.chords_back`).
* **Speed**: all steps of all members in one compiled call
  (:func:`fmus_src.cutting.path_replay.compiled_path_steps`, bit-identical to
  stepping the component), the step-by-step loop as the fallback.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
from scipy.signal import savgol_filter

from fmus_src.cutting.component import CuttingError
from fmus_src.cutting.path_component import PathCuttingLoad
from fmus_src.cutting.path_replay import compiled_path_steps
from fmus_src.cutting.table import EngagementTable

from ..case import Case
from ..recording import Recording
from ..twin import cutting_parameters
from .align import fill_gaps
from .errors import DiagnosisError
from .replay import interpolate_command

#: Savitzky-Golay window of the following error (or position) smoothing, s.
SMOOTH_S = 0.02
#: Grid of the smoothing, s.
SMOOTH_GRID_S = 1e-3
#: Largest distance of the recorded tool path from the program's path where it cuts, m (the replay
#: follows the recorded motion; a vibrating tool may leave the nominal path by more than the twin's default).
PATH_TOLERANCE = 2e-3


def _smooth(t: np.ndarray, y: np.ndarray, query: np.ndarray, window_s: float = SMOOTH_S) -> np.ndarray:
    """Quadratic Savitzky-Golay smoothing of unevenly sampled ``y`` (via a uniform grid), evaluated at ``query``."""
    ok = np.isfinite(y)
    ts, ys = t[ok], y[ok]
    if ts.size < 8:
        return np.interp(query, ts, ys) if ts.size else np.zeros_like(query)
    grid = np.arange(ts[0], ts[-1] + SMOOTH_GRID_S, SMOOTH_GRID_S)
    g = np.interp(grid, ts, ys)
    n = int(round(window_s / SMOOTH_GRID_S)) | 1
    if grid.size > n >= 5:
        g = savgol_filter(g, n, 2, mode="interp")
    return np.interp(query, grid, g)


@dataclass
class ForceInputs:
    """What the cutting replay is driven with, at the force sample times.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Force sample times (logger clock), s.
    position : ndarray, shape (n, 3)
        Tool-tip position, work coordinates, m.
    omega : ndarray, shape (n,)
        Actual spindle speed, rad/s.
    omega_source : str
        The channel it comes from.
    """

    t: np.ndarray
    position: np.ndarray
    omega: np.ndarray
    omega_source: str


def force_inputs(recording: Recording, rows: np.ndarray) -> ForceInputs:
    """Tool path and spindle speed at the force rows ``rows`` of ``recording`` (see module docstring).

    Raises
    ------
    DiagnosisError
        No actual position of an axis, or no spindle speed.
    """
    t_all = np.asarray(recording.t, float)
    t = t_all[rows]
    pos = np.zeros((t.size, 3))
    for i, a in enumerate("xyz"):
        if f"{a}_mm" not in recording or not np.isfinite(recording[f"{a}_mm"]).any():
            raise DiagnosisError(f"{recording.source}: the cutting diagnosis needs the actual position '{a}_mm' "
                                 f"(work coordinates) besides the forces; the recording has {recording.channels}")
        actual = np.asarray(recording[f"{a}_mm"], float)
        ref_name = f"{a}_ref_mm"
        if ref_name in recording and np.mean(np.isfinite(recording[ref_name][np.isfinite(actual)])) > 0.9:
            ref = np.asarray(recording[ref_name], float)
            ok = np.isfinite(ref)
            cmd = interpolate_command(t_all[ok], ref[ok], t)
            both = ok & np.isfinite(actual)
            fe = _smooth(t_all[both], ref[both] - actual[both], t)
            pos[:, i] = (cmd - fe) * 1e-3
        else:
            pos[:, i] = _smooth(t_all, actual, t) * 1e-3
    source = next((c for c in ("spindle_rpm", "spindle_ref_rpm") if c in recording
                   and np.isfinite(recording[c]).any()), None)
    if source is None:
        raise DiagnosisError(f"{recording.source}: the cutting diagnosis needs the spindle speed ('spindle_rpm' or "
                             f"'spindle_ref_rpm'); the recording has {recording.channels}")
    rpm = fill_gaps(t_all, np.asarray(recording[source], float))[rows]
    return ForceInputs(t, pos, np.maximum(rpm, 0.0) * 2.0 * math.pi / 60.0, source)


@dataclass
class ForceReplay:
    """Replay outputs at the force sample times, shape (n, B).

    Attributes
    ----------
    fx, fy : ndarray
        Force on the workpiece, N.
    torque : ndarray
        Cutting torque (step mean), N.m.
    omega : ndarray
        Spindle speed after the component's droop term, rad/s (the input where the component has none).
    engaged : ndarray of int
        Teeth in material with a positive chip.
    depth : ndarray
        Largest axial depth of the engaged teeth, m.
    """

    fx: np.ndarray
    fy: np.ndarray
    torque: np.ndarray
    omega: np.ndarray
    engaged: np.ndarray
    depth: np.ndarray

    def member(self, j: int) -> "ForceReplay":
        """Member ``j`` alone (arrays of shape (n, 1))."""
        return ForceReplay(self.fx[:, [j]], self.fy[:, [j]], self.torque[:, [j]], self.omega[:, [j]],
                           self.engaged[:, [j]], self.depth[:, [j]])


def step_speeds(inputs: ForceInputs) -> np.ndarray:
    """Spindle speed input of each step ``k -> k + 1`` [rad/s]: the mean of its ends (trapezoidal angle)."""
    om = inputs.omega
    return 0.5 * (om[:-1] + om[1:])


def run_force_replay(case: Case, table: EngagementTable, inputs: ForceInputs,
                     members: Sequence[Mapping[str, float]], theta0: float | np.ndarray,
                     step_omega: np.ndarray | None = None) -> ForceReplay:
    """Step the twin's path-mode cutting load along the recorded motion, one member per parameter set.

    Parameters
    ----------
    case : Case
        Tool, stock and material (the baseline parameters).
    table : EngagementTable
        Engagement of the case's program.
    inputs : ForceInputs
    members : sequence of mapping
        Component parameter overrides per member (SI, e.g. ``{"kt": 1.3e9, "edge_force_tangential": 2e4}``).
    theta0 : float or ndarray (B,)
        Spindle angle of tooth 0 at the first force sample, rad.
    step_omega : ndarray, shape (n - 1,), optional
        Spindle speed input of each step (default :func:`step_speeds`); the component turns the
        spindle by ``step_omega[k] (t[k+1] - t[k])`` over step ``k``.

    Notes
    -----
    All steps run in one compiled call (:func:`fmus_src.cutting.path_replay.compiled_path_steps`, the
    same outputs bit for bit) when it covers the case; otherwise, or when a member fails on the way, the
    component is stepped here one force sample at a time, which raises the errors below.

    Raises
    ------
    DiagnosisError
        A parameter the component does not have, or every member failed (the component's reason and the
        logger time of the step).
    """
    batch = len(members)
    params = cutting_parameters(case)
    declared = {v.name for v in PathCuttingLoad.variables if v.causality == "parameter"}
    names = sorted({k for m in members for k in m})
    unknown = [k for k in names if k not in declared]
    if unknown:
        raise DiagnosisError(f"cutting replay: the twin's cutting component has no parameter(s) {unknown}; "
                             "expected names of PathCuttingLoad's parameters")
    for name in names:
        base = params.get(name, next(v.start for v in PathCuttingLoad.variables if v.name == name))
        params[name] = np.array([float(m.get(name, base)) for m in members])
    params["initial_spindle_angle"] = np.broadcast_to(np.asarray(theta0, float), (batch,)).copy()
    params["path_tolerance"] = PATH_TOLERANCE
    comp = PathCuttingLoad("cutting", batch=batch, **params)
    comp.attach_table(table)
    p, t = inputs.position, inputs.t
    om = step_speeds(inputs) if step_omega is None else np.asarray(step_omega, float)
    for i, a in enumerate("xyz"):
        comp.set(f"{a}_position", p[0, i])
    comp.setup(float(t[0]))
    n = t.size
    fast = compiled_path_steps(comp, t, p, om)
    if fast is not None:
        omega = fast["spindle_speed_actual"]
        omega[0] = inputs.omega[0]
        for name in ("fx", "fy", "spindle_torque", "engaged_teeth", "axial_depth"):
            fast[name][0] = 0  # no step yet: no force, as the loop below
        return ForceReplay(fast["fx"], fast["fy"], fast["spindle_torque"], omega, fast["engaged_teeth"].astype(int),
                           fast["axial_depth"])
    out = {k: np.zeros((n, batch)) for k in ("fx", "fy", "spindle_torque", "omega", "engaged_teeth",
                                                "axial_depth")}
    v = comp.values
    has_actual = "spindle_speed_actual" in v
    out["omega"][0] = inputs.omega[0]
    for k in range(n - 1):
        for i, a in enumerate("xyz"):
            v[f"{a}_position"][...] = p[k + 1, i]
        v["spindle_speed"][...] = om[k]
        try:
            comp.do_step(float(t[k]), float(t[k + 1] - t[k]))
        except CuttingError as exc:
            raise DiagnosisError(f"cutting replay at t = {t[k + 1]:.4f} s (logger clock): {exc}") from None
        out["fx"][k + 1] = v["fx"]
        out["fy"][k + 1] = v["fy"]
        out["spindle_torque"][k + 1] = v["spindle_torque"]
        out["engaged_teeth"][k + 1] = v["engaged_teeth"]
        out["axial_depth"][k + 1] = v["axial_depth"]
        out["omega"][k + 1] = v["spindle_speed_actual"] if has_actual else om[k]
    return ForceReplay(out["fx"], out["fy"], out["spindle_torque"], out["omega"], out["engaged_teeth"].astype(int),
                       out["axial_depth"])
