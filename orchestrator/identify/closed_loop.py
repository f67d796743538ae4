"""Closed-loop replay: MCU + drive axes driven by a recorded reference position.

Used by servo identification (and by the synthetic recordings of the tests):
the components are the twin's own (:class:`fmus_src.servo.MCU`,
:class:`fmus_src.servo.DriveAxis`), batched over ``B`` parameter sets.

Timing follows the twin (:mod:`orchestrator.twin`, Gauss-Seidel master):

* the servo ticks at the velocity-loop period ``Tv`` on the grid
  ``t0 + k Tv`` with ``t0`` the first sample of the recording (or a given
  ``t_start``, the controller's own tick grid); the MCU steps
  first (feedback from the drive at ``t_k``), then the drives (current
  command of this tick);
* the position loop at ``t`` samples the NC command of the current
  interpolation period, i.e. the reference recorded at ``t`` (the twin steps
  MCU and drives before the NC kernel, as a real controller does); a
  different convention of a foreign logger is absorbed by ``ref_lead``
  (linear interpolation of the recorded reference between samples); a
  reference may instead be a callable ``f(tick_times)`` that gives the
  command at the ticks directly (the twin's own interpolation, for logs
  without commands, :meth:`orchestrator.diagnose.prepare.Prepared.twin_commands`);
* outputs are sampled after each tick and interpolated linearly to the
  requested times (the recording's).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from fmus_src.servo import MCU, DriveAxis
from fmus_src.servo.replay import COMPILED_OUTPUTS, compiled_samples

from ..machine import Machine
from ..twin import drive_parameters, mcu_parameters
from .errors import IdentificationError
from .start_state import AxisStart, apply_start, initial_positions


@dataclass
class ReplayResult:
    """Outputs of :func:`replay` at the requested times.

    Attributes
    ----------
    t : ndarray, shape (n,)
        Times, s.
    position : dict[str, ndarray]
        Axis -> actual position [m], shape (n, B).
    current : dict[str, ndarray]
        Axis -> current command [A], shape (n, B).
    ticks : int
        Velocity-loop ticks simulated.
    """

    t: np.ndarray
    position: dict[str, np.ndarray]
    current: dict[str, np.ndarray]
    ticks: int


def _column(values: np.ndarray, batch: int) -> np.ndarray:
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.shape[1] not in (1, batch):
        raise IdentificationError(f"reference has {arr.shape[1]} columns, expected 1 or {batch}")
    return np.broadcast_to(arr, (arr.shape[0], batch))


def replay(
    machine: Machine,
    t_ref: np.ndarray,
    refs: Mapping[str, np.ndarray | Callable[[np.ndarray], np.ndarray]],
    batch: int = 1,
    mcu_values: Mapping[str, np.ndarray | float] | None = None,
    drive_values: Mapping[str, Mapping[str, np.ndarray | float]] | None = None,
    initial_position: Mapping[str, np.ndarray | float] | None = None,
    t_out: np.ndarray | None = None,
    ref_lead: float = 0.0,
    t_start: float | None = None,
    disturbance: Mapping[str, Callable[[np.ndarray], np.ndarray]] | None = None,
    start: Mapping[str, AxisStart] | None = None,
    start_at: float | np.ndarray | None = None,
) -> ReplayResult:
    """Simulate the servo loops of some axes driven by recorded reference positions.

    Parameters
    ----------
    machine : Machine
        Gains, masses, friction (overridable per member below).
    t_ref : ndarray, shape (n,)
        Sample times of the reference, s (strictly increasing, any spacing).
    refs : mapping axis -> ndarray, shape (n,) or (n, B), or callable
        Reference positions [m] of the axes to simulate at ``t_ref``; or
        ``f(q)`` giving them at the servo tick times ``q`` directly (shape
        ``(len(q),)`` or ``(len(q), B)``; ``ref_lead`` is then not applied).
        Other axes stay at rest and are not simulated.
    batch : int
        ``B``.
    mcu_values : mapping, optional
        MCU parameters per member (e.g. ``{"x_position_scale": (B,) array}``).
    drive_values : mapping axis -> mapping, optional
        DriveAxis parameters per member (e.g. friction of a fitted set).
    initial_position : mapping axis -> float or (B,), optional
        Table position at the first tick [m]; default the reference there.
    t_out : ndarray, optional
        Output times (default ``t_ref``), within ``[t_ref[0], t_ref[-1]]``;
        outputs before the first tick hold the initial state.
    ref_lead : float
        The position loop at ``t`` uses the reference recorded at
        ``t + ref_lead``, s (default 0, the twin's convention).
    t_start : float, optional
        First servo tick, s (default ``t_ref[0]``): the controller's own tick
        grid when known, so that the position loop samples the command in
        the controller's phase.
    disturbance : mapping axis -> callable, optional
        ``f(t)`` -> disturbance force on the axis [N] (cutting force on the
        workpiece, ``Fd = +F``), evaluated at the middle of each servo tick.
    start : mapping axis -> AxisStart, optional
        The state the recording implies at its start (:func:`.start_state.estimate_start`): an axis that
        moves there starts at that position, velocity and integrator current (:func:`.start_state.apply_start`)
        instead of at rest; it overrides ``initial_position``.
    start_at : float or ndarray, shape (B,), optional
        Recording time whose ``start`` state the first tick takes, per member (default the first tick).

    Returns
    -------
    ReplayResult
    """
    t_ref = np.asarray(t_ref, dtype=float)
    t_out = t_ref if t_out is None else np.asarray(t_out, dtype=float)
    servo = machine.si("servo")
    tv = float(servo["velocity_loop_period"])
    lead = float(ref_lead)
    axes = [a for a in "xyz" if a in refs]
    if not axes:
        raise IdentificationError("replay needs the reference of at least one axis")
    t0 = float(t_ref[0]) if t_start is None else float(t_start)
    n_ticks = int(np.floor((float(t_out[-1]) - t0) / tv + 1e-9)) + 1
    tick_t = t0 + tv * np.arange(n_ticks + 1)
    query = np.clip(tick_t + lead, t_ref[0], t_ref[-1])
    idx = np.clip(np.searchsorted(t_ref, query, side="right"), 1, t_ref.size - 1)
    w = ((query - t_ref[idx - 1]) / (t_ref[idx] - t_ref[idx - 1]))[:, None]
    ref_ticks = {a: (_column(refs[a](tick_t), batch) if callable(refs[a]) else
                     _column(refs[a], batch)[idx - 1] * (1.0 - w) + _column(refs[a], batch)[idx] * w) for a in axes}

    params = mcu_parameters(machine)
    params.update(dict(mcu_values or {}))
    mcu = MCU("mcu", batch=batch, **params)
    drives: dict[str, DriveAxis] = {}
    moving = initial_positions(start, t0 if start_at is None else start_at)
    for a in axes:
        dp = drive_parameters(machine, a)
        dp.update(dict((drive_values or {}).get(a, {})))
        x0 = moving[a] if a in moving else (initial_position or {}).get(a, ref_ticks[a][0])
        drives[a] = DriveAxis(f"{a}_drive", batch=batch, initial_position=x0, **dp)
        mcu.set(f"{a}_ref", ref_ticks[a][0])
        mcu.set(f"{a}_position", drives[a].values["position"])
    mcu.setup(t0)
    for d in drives.values():
        d.setup(t0)
    dist = ({a: np.asarray(fd(tick_t[:-1] + 0.5 * tv), dtype=float) for a, fd in disturbance.items() if a in drives}
            if disturbance else None)
    if start:
        before = {a: (refs[a] if callable(refs[a]) else _extrapolated(t_ref, _column(refs[a], 1)[:, 0])) for a in axes}
        apply_start(mcu, drives, {a: s for a, s in start.items() if a in drives}, t0, before,
                    {a: f[0] for a, f in dist.items()} if dist else None, start_at)
    # outputs interpolated linearly between the ticks to the requested times (held before the first tick)
    j = np.clip(np.searchsorted(tick_t, t_out, side="right"), 1, n_ticks)
    f = np.maximum((t_out - tick_t[j - 1]) / tv, 0.0)
    out = run_servo_samples(mcu, drives, ref_ticks, t0, tv, n_ticks, j, f, ("position",), dist)
    return ReplayResult(t_out, out["position"], out["current_cmd"], n_ticks)


def _extrapolated(t: np.ndarray, x: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """``f(q)``: samples ``x`` at ``t``, linear inside and extrapolated linearly from the first two before them."""
    slope = (x[1] - x[0]) / (t[1] - t[0]) if t.size > 1 else 0.0
    return lambda q: np.where(np.asarray(q) < t[0], x[0] + slope * (np.asarray(q) - t[0]), np.interp(q, t, x))


def run_servo_ticks(
    mcu: MCU,
    drives: dict[str, DriveAxis],
    ref: dict[str, np.ndarray],
    t0: float,
    tv: float,
    n_ticks: int,
    outputs: tuple[str, ...] = ("position",),
    disturbance: dict[str, np.ndarray] | None = None,
) -> dict[str, dict[str, np.ndarray]]:
    """Step a set-up MCU and its drives tick by tick against given reference positions.

    Parameters
    ----------
    mcu, drives : MCU and DriveAxis (one per axis in ``ref``), already set up at ``t0``.
    ref : dict axis -> ndarray, shape (n_ticks + 1,) or (n_ticks + 1, B)
        Reference position at each velocity-loop tick, m.
    t0, tv : float
        Start time and velocity-loop period, s.
    n_ticks : int
        Ticks to run.
    outputs : tuple of str
        Drive outputs to record besides the MCU current command.
    disturbance : dict axis -> ndarray, shape (n_ticks,), optional
        Disturbance force of the axis during each tick, N (e.g. a recorded cutting force).

    Returns
    -------
    dict
        ``{output: {axis: ndarray (n_ticks + 1, B)}}`` with ``"current_cmd"`` (A) included.

    The components are stepped here one tick at a time (:func:`run_servo_samples` runs them compiled
    when it can, and keeps only the samples it is asked for).
    """
    axes = list(ref)
    batch = mcu.batch
    traces = {name: {a: np.empty((n_ticks + 1, batch)) for a in axes} for name in (*outputs, "current_cmd")}
    mv = mcu.values

    def record(k: int) -> None:
        for a in axes:
            dv = drives[a].values
            for name in outputs:
                traces[name][a][k] = dv[name]
            traces["current_cmd"][a][k] = mv[f"{a}_current_cmd"]

    record(0)
    for k in range(n_ticks):
        t = t0 + k * tv
        for a in axes:
            dv = drives[a].values
            mv[f"{a}_ref"][...] = ref[a][k]
            mv[f"{a}_position"][...] = dv["position"]
            mv[f"{a}_velocity"][...] = dv["velocity"]
        mcu.do_step(t, tv)
        for a in axes:
            drives[a].values["current_cmd"][...] = mv[f"{a}_current_cmd"]
            if disturbance is not None and a in disturbance:
                drives[a].values["disturbance_force"][...] = disturbance[a][k]
            drives[a].do_step(t, tv)
        record(k + 1)
    return traces


def run_servo_samples(
    mcu: MCU,
    drives: dict[str, DriveAxis],
    ref: dict[str, np.ndarray],
    t0: float,
    tv: float,
    n_ticks: int,
    sample_tick: np.ndarray,
    sample_weight: np.ndarray,
    outputs: tuple[str, ...] = ("position",),
    disturbance: dict[str, np.ndarray] | None = None,
) -> dict[str, dict[str, np.ndarray]]:
    """Outputs of a set-up MCU and its drives at given instants between their ticks.

    Output sample ``i`` is ``y[j - 1] (1 - w) + y[j] w`` with ``j = sample_tick[i]`` and
    ``w = sample_weight[i]``, ``y[k]`` the output after tick ``k`` of :func:`run_servo_ticks` (``y[0]``:
    the set-up values). All ticks run in one compiled call per axis and block of members
    (:func:`fmus_src.servo.replay.compiled_samples`: the same numbers, only the samples kept in memory)
    whenever the components allow it (compiled kernels, exponential drives, outputs among
    ``table_position``, ``position``, ``motor_force``); otherwise, or when a member fails on the way
    (the components then fail it with their own message), by :func:`run_servo_ticks`. The components
    are consumed: their state afterwards is not defined.

    Parameters
    ----------
    mcu, drives, ref, t0, tv, n_ticks, outputs, disturbance
        As :func:`run_servo_ticks`.
    sample_tick : ndarray of int, shape (n_out,)
        ``1 <= j <= n_ticks``.
    sample_weight : ndarray, shape (n_out,)
        ``w``.

    Returns
    -------
    dict
        ``{output: {axis: ndarray (n_out, B)}}`` with ``"current_cmd"`` (A) included.
    """
    names = (*outputs, "current_cmd")
    if set(outputs) <= set(COMPILED_OUTPUTS):
        compiled = compiled_samples(mcu, drives, ref, t0, tv, n_ticks, sample_tick, sample_weight, disturbance)
        if compiled is not None:
            return {name: compiled[name] for name in names}
    traces = run_servo_ticks(mcu, drives, ref, t0, tv, n_ticks, outputs, disturbance)
    j = np.asarray(sample_tick, dtype=np.int64)
    w = np.asarray(sample_weight, dtype=float)[:, None]
    return {name: {a: arr[j - 1] * (1.0 - w) + arr[j] * w for a, arr in traces[name].items()} for name in names}

