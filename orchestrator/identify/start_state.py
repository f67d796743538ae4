"""The servo state a recording implies at its first sample, for replays of logs that start while an axis moves.

A logger started while the axis was already moving (the usual case with FANUC Servo Guide) catches the loop in
motion: the table lags the command by ``v / (Pp Spp)`` (tens of µm), it moves at the commanded speed, and the
velocity loop's integrator holds the current that the friction (and the inertia, while accelerating) needs. A
replay that starts at rest on the first sample spends several position-loop time constants catching up, and
the fit reads that start-up transient as a misfit of the scale factors (a log cut into a 500 mm/min plateau
gave Svp 0.94 and Svi 0.68 for 0.8 and 1.0, residual 3.5 µm and 0.20 A against 0.29 µm and 0.020 A).

:func:`estimate_start` takes that state from the first samples: a quadratic least-squares fit of the actual
positions over one position-loop time constant gives the position, velocity and acceleration at the first
servo tick (the command is not needed; the closed loop makes the actual position smooth).
:func:`apply_start` puts it into set-up components: the drive slides at that velocity on the branch of its
sign, and the velocity loop's integrator holds the current of the force balance of each member at that
velocity and acceleration (its friction, load and inertia; the velocity loop has no steady velocity error,
even while accelerating). An axis at rest is left as the components set it up (stuck, integrator 0), unless
the recorded current at the start is significantly not 0 (a holding current, or one already ramping up to a
break-away): the integrator then makes the first tick's current that one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping

import numpy as np

from fmus_src.servo import MCU, DriveAxis
from fmus_src.servo.effects import DelayLine, axis_load, pitch_error
from fmus_src.servo.mcu import AXES

from ..machine import Machine

#: A fitted velocity or holding current counts only beyond this many standard errors of the fit.
SIGNIFICANCE = 3.0
#: Least number of samples of the start fit (a quadratic needs 3; 2 more give its standard errors).
MIN_SAMPLES = 5
#: Least position noise of a start fit [m]: the quantisation noise q / sqrt(12) of the finest position step of a
#: production log, q = 0.1 um (FANUC detection unit IS-C; the diagnosis's ``columns.POSITION_QUANTUM_UM``).
#: Without it a noise-free file (the twin's own run, 12 digits) made nm of curvature a significant velocity.
LOG_POSITION_NOISE_M = 0.1e-6 / math.sqrt(12.0)


@dataclass(frozen=True)
class AxisStart:
    """The motion of one axis around the start of a recording: ``x(t) = x + v (t - t) + a (t - t)^2 / 2``.

    Attributes
    ----------
    t : float
        Reference time of the fit (the first sample), s.
    position : float
        Actual (table) position at ``t`` [m].
    velocity : float
        Velocity [m/s]; exactly 0 for an axis at rest (not significantly moving).
    acceleration : float
        Acceleration [m/s^2]; 0 at rest.
    holding_current : float
        At rest: the current the recording holds (0 unless significant) [A]; unused while moving.
    window : float
        Length of the fitted interval, s.
    """

    t: float
    position: float
    velocity: float
    acceleration: float
    holding_current: float = 0.0
    window: float = 0.0

    @property
    def moving(self) -> bool:
        """True when the axis moves at the start of the recording."""
        return self.velocity != 0.0

    def at(self, t0: float | np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Position [m], velocity [m/s] and acceleration [m/s^2] at recording time(s) ``t0`` (scalar or (B,))."""
        dt = np.asarray(t0, dtype=float) - self.t
        return (self.position + self.velocity * dt + 0.5 * self.acceleration * dt * dt,
                self.velocity + self.acceleration * dt, self.acceleration)


def start_window(machine: Machine, axis: str) -> float:
    """Length of the start fit: the position loop's time constant ``1 / (Pp Spp)`` of the machine file [s].

    Within it a following error that settles with that time constant changes little, so a quadratic holds
    the motion; longer, the quadratic would bend the start of an acceleration.
    """
    sec = machine.si(f"axis.{axis}")
    return 1.0 / (float(sec["position_gain"]) * float(sec["position_scale"]))


def _noise(x: np.ndarray) -> float:
    """Standard deviation of the white noise on a sampled signal: robust spread of its second differences."""
    d2 = np.diff(x[np.isfinite(x)], 2)
    if d2.size == 0:
        return 0.0
    steps = np.abs(np.diff(x[np.isfinite(x)]))
    quantum = float(np.min(steps[steps > 0.0])) if np.any(steps > 0.0) else 0.0
    # var(second difference) = 6 sigma^2; a quantised signal has at least the quantum / sqrt(12)
    return max(1.4826 * float(np.median(np.abs(d2))) / math.sqrt(6.0), quantum / math.sqrt(12.0))


def _quadratic(dt: np.ndarray, y: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, bool]:
    """Least-squares quadratic in ``dt`` (value, slope, curvature at 0), their standard errors, and whether it fits.

    It fits when the residual is consistent with noise ``sigma``: ``RSS / sigma^2`` within the 0.1 % tail
    of its chi-square distribution (a stick-slip transition or a kink inside the window is not a quadratic).
    """
    from scipy.stats import chi2

    span = max(float(dt[-1]), 1e-12)
    basis = np.column_stack([np.ones(dt.size), dt / span, (dt / span) ** 2])   # scaled: well conditioned
    coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
    rss = float(np.sum((y - basis @ coef) ** 2))
    dof = max(dt.size - 3, 1)
    scale = np.array([1.0, 1.0 / span, 2.0 / span ** 2])
    err = max(math.sqrt(rss / dof), sigma) * np.sqrt(np.diag(np.linalg.pinv(basis.T @ basis))) * scale
    fits = sigma > 0.0 and rss / sigma ** 2 <= float(chi2.ppf(0.999, dof)) or rss == 0.0
    return coef * scale, err, fits


def estimate_start(t: np.ndarray, actual: np.ndarray, current: np.ndarray | None, window: float,
                   min_noise: float = 0.0) -> AxisStart:
    """The motion of an axis at the first sample of a recording, from its first samples.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times, s, increasing.
    actual : ndarray, shape (n,)
        Actual (table) positions [m] (NaN where not measured).
    current : ndarray, shape (n,), optional
        Recorded current command [A] (NaN where not measured): at rest, its value at the first sample
        (fitted alike) is the current the loop holds there when it is significant.
    window : float
        Longest fitted interval from the first sample, s (:func:`start_window`). It is halved, down to
        :data:`MIN_SAMPLES` samples, while a quadratic does not fit the positions or the current within their
        noise (estimated from the whole recording): a window that holds a break-away is not one motion.
    min_noise : float
        Least position noise [m] taken for the fit (default 0): a file without noise (the twin's own run, 12
        digits) otherwise makes a nanometre of curvature at the start of a move a significant velocity.

    Returns
    -------
    AxisStart
        Velocity and acceleration are 0 when the fitted velocity is within :data:`SIGNIFICANCE` standard
        errors of 0 (an axis at rest: then ``position`` is the first sample).
    """
    t = np.asarray(t, dtype=float)
    x = np.asarray(actual, dtype=float)
    c_all = np.full(t.shape, np.nan) if current is None else np.asarray(current, dtype=float)
    ok = np.isfinite(t) & np.isfinite(x)
    tt, xx, cc = t[ok], x[ok], c_all[ok]
    if tt.size < MIN_SAMPLES:
        return AxisStart(float(t[0]), float(xx[0]) if xx.size else float("nan"), 0.0, 0.0)
    t_ref = float(tt[0])
    sx, sc = max(_noise(xx), float(min_noise)), _noise(cc)
    n = max(int(np.searchsorted(tt, t_ref + window, side="right")), MIN_SAMPLES)
    while True:
        dt = tt[:n] - t_ref
        px, ex, fx = _quadratic(dt, xx[:n], sx)
        fine = np.isfinite(cc[:n])
        pc, ec, fc = (_quadratic(dt[fine], cc[:n][fine], sc) if fine.sum() > 3
                      else (np.zeros(3), np.full(3, np.inf), True))
        if (fx and fc) or n <= MIN_SAMPLES:
            break
        n = max(n // 2, MIN_SAMPLES)
    span = float(dt[-1])
    if abs(px[1]) <= SIGNIFICANCE * ex[1]:
        holding = float(pc[0]) if abs(pc[0]) > SIGNIFICANCE * ec[0] else 0.0
        return AxisStart(t_ref, float(xx[0]), 0.0, 0.0, holding, span)
    return AxisStart(t_ref, float(px[0]), float(px[1]), float(px[2]), 0.0, span)


def initial_positions(starts: Mapping[str, AxisStart] | None, t0: float | np.ndarray) -> dict[str, np.ndarray]:
    """Axis -> position [m] at recording time(s) ``t0`` (the first servo tick) of the axes that move at the start."""
    return {a: s.at(t0)[0] for a, s in (starts or {}).items() if s.moving}


def held_within_static_friction(d: DriveAxis, current: float, disturbance: np.ndarray | None = None) -> np.ndarray:
    """A holding current of an axis at rest, limited per member to what static friction can hold, A.

    The axis stood in the recording, so the force it held, ``kf I - load``, lay within the break-away band
    ``[-Fs_neg, Fs_pos]`` of the machine. An axis stopped by a move against its friction holds the current at
    that band's edge (its integrator winds up to it), and the current estimated from noisy samples (0.02 A
    noise, 0.01 A steps) can lie beyond it: a replay started there broke away at once, slipped and never
    matched again (Z of an XY contour's Servo Guide log cut into an X move: 0.69 A rms of current residual,
    named a reversal friction and a ripple; the same log cut 4 ms later, its estimate 6 mA lower, had none).

    Parameters
    ----------
    d : DriveAxis
        Set up, not yet stepped (its members' friction, including a reversal friction at the start's travel,
        and its load terms).
    current : float
        Estimated holding current, A.
    disturbance : ndarray, optional
        Disturbance force of the first tick [N] (shape (1,) or (B,)); default the drive's own input.

    Returns
    -------
    ndarray, shape (B,)
        The current of each member, clipped to ``[(load - Fs_neg) / kf, (load + Fs_pos) / kf]``.
    """
    friction, _ = d._step_friction()
    load = np.asarray(disturbance, dtype=float) if disturbance is not None else \
        np.asarray(d.values["disturbance_force"], dtype=float)
    if d._load_on:
        v = d.values
        load = load + axis_load(d._state.position, v["gravity_force"], v["gravity_spring"], v["ripple_amplitude"],
                                v["ripple_period"])
    inside = 1.0 - 1e-9   # strictly inside: the drive breaks away when the force exceeds Fs by a rounding
    lo = (load - inside * friction.static_neg) / d._kf
    hi = (load + inside * friction.static_pos) / d._kf
    return np.clip(np.full(d.batch, float(current)), lo, hi)


def apply_start(mcu: MCU, drives: Mapping[str, DriveAxis], starts: Mapping[str, AxisStart] | None, t0: float,
                ref_before: Mapping[str, Callable[[np.ndarray], np.ndarray]] | None = None,
                disturbance: Mapping[str, np.ndarray] | None = None,
                state_at: float | np.ndarray | None = None) -> None:
    """Put the state of ``starts`` into set-up components (before the first tick at ``t0``), in place.

    Parameters
    ----------
    mcu, drives : MCU and DriveAxis, set up at ``t0`` (drives with ``initial_position`` at the start position)
        and not yet stepped.
    starts : mapping axis -> AxisStart, optional
        Axes absent, or at rest without a holding current, are left as set up.
    t0 : float
        First servo tick, s.
    ref_before : mapping axis -> callable, optional
        ``f(q)``: the command [m] at times ``q`` before ``t0`` (the reference history of the position loop's
        feed-forward differences); default: the command extrapolated at the start velocity.
    disturbance : mapping axis -> ndarray, optional
        Disturbance force of the first tick [N] (shape (1,) or (B,)).
    state_at : float or ndarray, shape (B,), optional
        Recording time whose state the first tick takes, per member (default ``t0``): a replay compared with
        the recording ``s`` seconds later on its clock (a fitted clock shift) starts from the state at ``t0 + s``.
    """
    if not starts:
        return
    state = mcu._state
    tp = float(mcu._tp)
    for a, s in starts.items():
        if a not in drives:
            continue
        d = drives[a]
        i = AXES.index(a)
        x0, v0, a0 = s.at(t0 if state_at is None else state_at)
        x0, v0 = np.broadcast_to(x0, (d.batch,)), np.broadcast_to(v0, (d.batch,))
        if not s.moving:
            if s.holding_current == 0.0:
                continue
            # the first tick's current is the recorded one: the integrator holds it less the P term of the
            # following error at the start (the position loop's velocity command, the axis being at rest)
            g = mcu._gains
            ref0 = float(np.asarray(ref_before[a](np.array([t0])), dtype=float).ravel()[0]) \
                if ref_before is not None and a in ref_before else float(x0[0])
            err = g.position[i] * (ref0 - d._state.position)
            limit = g.peak_current[i]
            holding = held_within_static_friction(d, s.holding_current, disturbance[a] if disturbance is not None
                                                  and a in disturbance else None)
            state.integrator[i] = np.clip(holding - (g.velocity_p[i] + g.velocity_i[i] * mcu._tv) * err,
                                          -limit, limit)
            state.current_cmd[i] = holding
            _publish(mcu, d, a, i)
            continue
        sign = math.copysign(1.0, s.velocity)
        st = d._state
        st.position[...] = x0
        st.velocity[...] = v0
        st.direction[...] = int(sign)
        # the current of the force balance of each member: friction on the branch of the motion, the load
        # (cutting force, gravity, spring, ripple) and the inertia; the velocity loop has no steady error
        direction = np.full(d.batch, sign)
        friction = d._friction.select(direction).force(st.velocity, direction)
        fd = np.asarray(disturbance[a], dtype=float) if disturbance is not None and a in disturbance else \
            np.asarray(d.values["disturbance_force"], dtype=float)
        if d._load_on:
            v = d.values
            fd = fd + axis_load(st.position, v["gravity_force"], v["gravity_spring"], v["ripple_amplitude"],
                                v["ripple_period"])
        current = (friction + fd + d._mass * a0) / d._kf
        # reference history of the feed-forward differences (zero gains: no effect)
        q = np.array([t0, t0 - tp, t0 - 2.0 * tp])
        if ref_before is not None and a in ref_before:
            hist = np.asarray(ref_before[a](q), dtype=float)
            hist = hist[:, 0] if hist.ndim > 1 else hist
        else:
            hist = x0[0] + s.velocity * (q - t0)
        r_now = hist[0]
        state.ref_prev[i], state.ref_prev2[i] = hist[1], hist[2]
        state.still_ticks[i] = 0.0
        a_ref = (r_now - 2.0 * hist[1] + hist[2]) / (tp * tp)
        state.current_ff[i] = mcu._gains.accel_ff_current[i] * a_ref
        limit = mcu._gains.peak_current[i]
        state.integrator[i] = np.clip(current - state.current_ff[i], -limit, limit)
        state.current_cmd[i] = np.clip(current, -limit, limit)
        if d._reversal_on:   # the last reversal lies before the recording: its extra friction has decayed
            d._table.travel[...] = np.inf
            d._table.last_direction[...] = sign
        d.values["motor_force"][...] = state.current_cmd[i] * d._kf
        if d._table_on:      # the play taken up on the side of the motion, the table at the recorded position
            v = d.values
            nut = st.position + pitch_error(st.position, v["pitch_slope"], v["pitch_amplitude"], v["pitch_period"])
            stiff = v["screw_stiffness"]
            nut = nut - np.where(stiff > 0.0, v["motor_force"] / np.where(stiff > 0.0, stiff, 1.0), 0.0)
            d._table.table[...] = nut - sign * 0.5 * v["backlash_width"]
            shift = x0 - d._table.table
            st.position[...] = st.position + shift
            d._table.table[...] = x0
            v["table_position"][...] = d._table.table
        else:
            d.values["table_position"][...] = st.position
        d.values["position"][...] = st.position
        d.values["velocity"][...] = st.velocity
        d.values["friction_force"][...] = friction
        _publish(mcu, d, a, i)


def _publish(mcu: MCU, drive: DriveAxis, axis: str, i: int) -> None:
    """Outputs of the MCU and the drive's input after the state of axis ``i`` was set; the delay line restarted."""
    cmd = mcu._state.current_cmd[i]
    mcu.values[f"{axis}_current_cmd"][...] = cmd
    drive.values["current_cmd"][...] = cmd
    drive.values["motor_force"][...] = cmd * drive._kf
    if mcu._delay_line is not None:
        line = DelayLine(mcu._state.current_cmd.shape, mcu._delay_line.capacity, mcu._state.current_cmd)
        line.push(mcu.t0, mcu._state.current_cmd)
        mcu._delay_line = line
