"""Batched replay of the twin's servo loop and drives on commanded positions, with effect terms.

Like :func:`orchestrator.identify.closed_loop.replay` (same timing: servo
ticks at ``Tv`` from the first command sample, MCU first, then the drives
with this tick's command, the position loop sampling the command at the
tick), but it returns what diagnosis compares: the **table** position (the
drive's ``table_position``, which carries the motor-to-table effects), the
motor position and force (for the kinematic effect columns) and the current
command, and it accepts per-member effect parameters of the MCU and the
drives.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np
from scipy.interpolate import PchipInterpolator

from fmus_src.servo import MCU, DriveAxis

from ..identify.closed_loop import run_servo_samples
from ..identify.start_state import AxisStart, apply_start, initial_positions
from ..machine import Machine
from ..twin import drive_parameters, mcu_parameters
from .errors import DiagnosisError


@dataclass
class Replay:
    """Replay outputs at the requested times, arrays of shape (n, B) per axis.

    Attributes
    ----------
    t : ndarray, shape (n,)
    table : dict
        Table position [m].
    motor : dict
        Motor-side position [m].
    force : dict
        Motor force ``u`` [N].
    current : dict
        Current command [A].
    """

    t: np.ndarray
    table: dict[str, np.ndarray]
    motor: dict[str, np.ndarray]
    force: dict[str, np.ndarray]
    current: dict[str, np.ndarray]


def interpolate_command(t: np.ndarray, x: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Commanded position at ``query`` from samples: shape-preserving cubic (PCHIP), held outside.

    A logger samples the command more coarsely than the servo tick; linear
    interpolation would cut the corners of every acceleration by
    ``a dt^2 / 8`` (0.7 µm at 2 m/s2 and 1.7 ms), which the loop turns into a
    delay-like residual. PCHIP is exact for the command's piecewise cubic
    shape to third order and never overshoots at the ends of a move.
    """
    q = np.clip(query, t[0], t[-1])
    if t.size < 3:
        return np.interp(q, t, x) if x.ndim == 1 else np.column_stack([np.interp(q, t, c) for c in x.T])
    return PchipInterpolator(t, x, axis=0, extrapolate=False)(q)


def command_before(t: np.ndarray, x: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    """``f(q)``: the command at ``q`` (:func:`interpolate_command`), extrapolated linearly before ``t[0]``.

    The reference history of a replay that starts in motion: the position loop's feed-forward differences
    at the first tick look one and two position-loop periods back, before the recording's first sample,
    where the command moved on at its start velocity rather than stood still.
    """
    x = x if x.ndim == 1 else x[:, 0]
    slope = (x[1] - x[0]) / (t[1] - t[0]) if t.size > 1 else 0.0

    def f(q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        return np.where(q < t[0], x[0] + slope * (q - t[0]), interpolate_command(t, x, q))
    return f


def run_replay(
    machine: Machine,
    t_cmd: np.ndarray,
    commands: Mapping[str, np.ndarray],
    t_out: np.ndarray,
    batch: int = 1,
    mcu_values: Mapping[str, np.ndarray | float] | None = None,
    drive_values: Mapping[str, Mapping[str, np.ndarray | float]] | None = None,
    t_start: float | None = None,
    disturbance: Mapping[str, Callable[[np.ndarray], np.ndarray]] | None = None,
    start: Mapping[str, AxisStart] | None = None,
) -> Replay:
    """Simulate MCU + drives of the axes in ``commands`` for ``B`` parameter sets.

    Parameters
    ----------
    machine : Machine
        Nominal parameters.
    t_cmd : ndarray, shape (m,)
        Times of the commanded positions (program clock), s, increasing.
    commands : mapping axis -> ndarray, shape (m,) or (m, B), or callable
        Commanded positions [m] at ``t_cmd`` (per member when 2-D), interpolated to the servo ticks; or
        ``f(q)`` giving them at the tick times ``q`` directly (shape (len(q),) or (len(q), B)).
    t_out : ndarray, shape (n,)
        Output times within ``[t_cmd[0], t_cmd[-1]]``.
    batch : int
    mcu_values, drive_values : mapping, optional
        Per-member parameter overrides (arrays of shape (B,) or scalars).
    t_start : float, optional
        First servo tick (default ``t_cmd[0]``): put it on the controller's own
        tick grid when known, so that the position loop samples the command
        in the controller's phase. Outputs before it hold the initial state.
    disturbance : mapping axis -> callable, optional
        ``f(t)`` -> disturbance force on the axis [N] (the recorded cutting force on the workpiece,
        ``Fd = +F``), evaluated at the middle of each servo tick.
    start : mapping axis -> AxisStart, optional
        The state the recording implies at its first sample (:func:`.identify.start_state.estimate_start`):
        an axis that moves there starts at that position and velocity at the first tick, with the velocity
        loop's integrator holding the current of each member's force balance (its friction, load and mass;
        :func:`.identify.start_state.apply_start`), instead of at rest on the command. Default: at rest.

    Returns
    -------
    Replay
    """
    t_cmd = np.asarray(t_cmd, dtype=float)
    t_out = np.asarray(t_out, dtype=float)
    axes = [a for a in "xyz" if a in commands]
    if not axes:
        raise DiagnosisError("replay needs the commanded positions of at least one axis")
    tv = float(machine.si("servo")["velocity_loop_period"])
    t0 = float(t_cmd[0]) if t_start is None else float(t_start)
    n_ticks = int(np.floor((float(t_out[-1]) - t0) / tv + 1e-9)) + 1
    tick_t = t0 + tv * np.arange(n_ticks + 1)
    ref = {a: (np.asarray(commands[a](tick_t), dtype=float) if callable(commands[a])
              else interpolate_command(t_cmd, np.asarray(commands[a], dtype=float), tick_t)) for a in axes}

    params = mcu_parameters(machine)
    params.update(dict(mcu_values or {}))
    mcu = MCU("mcu", batch=batch, **params)
    drives: dict[str, DriveAxis] = {}
    moving = initial_positions(start, t0)
    for a in axes:
        dp = drive_parameters(machine, a)
        dp.update(dict((drive_values or {}).get(a, {})))
        x0 = moving[a] if a in moving else ref[a][0]
        drives[a] = DriveAxis(f"{a}_drive", batch=batch, initial_position=x0, **dp)
        mcu.set(f"{a}_ref", ref[a][0])
        mcu.set(f"{a}_position", drives[a].values["position"])
    mcu.setup(t0)
    for d in drives.values():
        d.setup(t0)
    dist = ({a: np.asarray(f(tick_t[:-1] + 0.5 * tv), dtype=float) for a, f in disturbance.items() if a in drives}
            if disturbance else None)
    if start:
        before = {a: (commands[a] if callable(commands[a])
                      else command_before(t_cmd, np.asarray(commands[a], dtype=float))) for a in axes}
        apply_start(mcu, drives, {a: s for a, s in start.items() if a in drives}, t0, before,
                    {a: f[0] for a, f in dist.items()} if dist else None)
    j = np.clip(np.searchsorted(tick_t, t_out, side="right"), 1, n_ticks)
    f = np.clip((t_out - tick_t[j - 1]) / tv, 0.0, 1.0)
    out = run_servo_samples(mcu, drives, ref, t0, tv, n_ticks, j, f, ("table_position", "position", "motor_force"),
                            dist)
    return Replay(t_out, out["table_position"], out["position"], out["motor_force"], out["current_cmd"])
