"""Compiled servo replay: one axis of the MCU and its drive, every member, every velocity-loop tick, one call.

The identification and diagnosis replays (:func:`fmus_src.servo.replay.replay_ticks`) step an MCU and its
drives tick by tick against a given reference. Axes are independent (each
axis has its own position and velocity loop, its own drive and effect
terms), and so are members; :func:`replay_axis` therefore runs one axis of
all members through all ticks with the state in registers:

per tick ``k`` (``t = t0 + k Tv``), as ``MCU.do_step`` then ``DriveAxis.do_step``:

1. the position loop when ``k`` is a multiple of ``Tp / Tv``, the velocity loop
   (:func:`~fmus_src.servo.control_numba.axis_ticks`), the excess-error check
   (:func:`~fmus_src.servo.control_numba.axis_alarm`) on the held inputs;
2. the servo delay: the current command of ``t + Tv - delay``, linear between
   the step-end commands (:class:`fmus_src.servo.effects.DelayLine`);
3. the drive: disturbance plus the load terms at the start position, friction
   raised by the reversal term, one exponential drive step
   (:func:`~fmus_src.servo.exponential_numba.exponential_member`), then the
   travel since reversal and the table position (:mod:`.effects_numba`).

The operations are those of the components' compiled kernels, in their
order, so a replay equals the tick-by-tick run up to the rounding of ``sin``
and ``exp`` in the effect terms (numpy's vector routines against the C
library's). A drive failure or an excess-error alarm stops the call and is
reported; the caller then re-runs the components tick by tick, which fail
the member with the components' own message.
"""
from __future__ import annotations

import numpy as np

from ..jit import njit, njit_nogil
from ..jit_cache import guard_cache
from . import control_numba, effects_numba, exponential_numba, stick_slip, stick_slip_numba
from .control_numba import axis_alarm, axis_ticks
from .effects_numba import axis_load, reversal_friction, table_position, travel_after_step
from .exponential_numba import exponential_member
from .stick_slip import OK

#: Rows of the per-axis drive block of :func:`replay_axis`, shape ``(N_DRIVE_ROWS, B)``: the packed
#: parameters of :data:`fmus_src.servo.stick_slip_numba.PARAMETER_ROWS` (rows 0-11), then these.
DRIVE_EXTRA_ROWS = (
    "max_step",
    "gravity_force", "gravity_spring", "ripple_amplitude", "ripple_period",
    "reversal_friction_peak", "reversal_friction_decay",
    "pitch_slope", "pitch_amplitude", "pitch_period", "screw_stiffness", "backlash_width", "thermal_drift_rate",
)
N_DRIVE_ROWS = 12 + len(DRIVE_EXTRA_ROWS)

#: Rows of the state block of :func:`replay_axis`, shape ``(N_STATE_ROWS, B)``, updated in place.
STATE_ROWS = ("position", "velocity", "direction", "table", "travel", "last_direction")
N_STATE_ROWS = len(STATE_ROWS)

#: Rows of the output block, shape ``(N_OUTPUT_ROWS, n_out, B)``.
OUTPUT_ROWS = ("table_position", "position", "motor_force", "current_cmd")
N_OUTPUT_ROWS = len(OUTPUT_ROWS)

#: Status of :func:`replay_axis`.
REPLAY_OK, REPLAY_DRIVE_FAILED, REPLAY_ALARM = 0, 1, 2


@njit
def _delayed(ring: np.ndarray, count: int, t0: float, tv: float, query: float, initial: float) -> float:
    """Command at ``query`` from the last ``min(count, len(ring))`` step-end commands (sample ``s`` at ``t0 + s Tv``).

    :meth:`fmus_src.servo.effects.DelayLine.read` for one member: linear between samples, the newest
    after it, ``initial`` before the oldest kept sample.
    """
    cap = ring.shape[0]
    n = min(count, cap)
    first = count - n
    s = count - 1
    while s >= first and t0 + s * tv > query:
        s -= 1
    j = s - first + 1
    if j == 0:
        return initial
    lo = min(max(j - 1, 0), n - 1) + first
    hi = min(max(j, 0), n - 1) + first
    t_lo = t0 + lo * tv
    t_hi = t0 + hi * tv
    w = 0.0
    if t_hi > t_lo:
        w = min(max((query - t_lo) / (t_hi - t_lo), 0.0), 1.0)
    return ring[lo % cap] * (1.0 - w) + ring[hi % cap] * w


@njit_nogil
def replay_axis(
    b0: int, b1: int, n_ticks: int, ratio: int, tp: float, tv: float, t0: float, axis_index: int,
    gains: np.ndarray, mcu_state: np.ndarray, limits: np.ndarray, delay: np.ndarray, delay_capacity: int,
    ref: np.ndarray, disturbance: np.ndarray, drive: np.ndarray, switches: np.ndarray,
    state: np.ndarray, sample_tick: np.ndarray, sample_weight: np.ndarray, out: np.ndarray,
) -> tuple[int, int, int]:
    """Ticks ``0 .. n_ticks - 1`` of one axis of members ``b0 .. b1 - 1`` (see the module docstring).

    Releases the GIL: threads may run other axes or other members of the same arrays side by side.

    Parameters
    ----------
    b0, b1 : int
        Members to run (the others' columns are neither read nor written).
    n_ticks, ratio : int
        Ticks to run; ``Tp / Tv``.
    tp, tv, t0 : float
        Position- and velocity-loop periods, start time [s] (tick ``k`` at ``t0 + k tv``).
    axis_index : int
        0, 1, 2 for x, y, z (the alarm code).
    gains : ndarray, shape (6, B)
        This axis's rows of :meth:`fmus_src.servo.control.CascadeGains.block`.
    mcu_state : ndarray, shape (7, B)
        This axis's rows of the MCU state block, updated in place.
    limits : ndarray, shape (3, B)
        This axis's excess-error limits (in motion [m], at stop [m], settle ticks).
    delay : ndarray, shape (B,)
        Servo delay [s] (0: none).
    delay_capacity : int
        Step-end commands kept for the delay (the MCU's delay line capacity).
    ref : ndarray, shape (n_ticks + 1, 1) or (n_ticks + 1, B)
        Reference position at each tick [m].
    disturbance : ndarray, shape (n_ticks, 1), (n_ticks, B) or (1, B)
        Disturbance force during each tick [N] (one row: held for every tick).
    drive : ndarray, shape (N_DRIVE_ROWS, B)
        Packed friction parameters, the internal step cap and the effect parameters (:data:`DRIVE_EXTRA_ROWS`).
    switches : ndarray of int64, shape (3,)
        Load terms, reversal friction, table terms on (1) or off (0), as the drive decided at set-up.
    state : ndarray, shape (N_STATE_ROWS, B)
        Drive and table state (:data:`STATE_ROWS`), updated in place.
    sample_tick, sample_weight : ndarray, shape (n_out,)
        Output sample ``i`` is ``y[j - 1] (1 - w) + y[j] w`` with ``j = sample_tick[i]`` (non-decreasing,
        ``1 <= j <= n_ticks``), ``w = sample_weight[i]`` and ``y[k]`` the output after tick ``k`` (``y[0]``: the
        set-up values, see ``out``); ``j = k``, ``w = 1`` gives ``y[k]`` itself.
    out : ndarray, shape (N_OUTPUT_ROWS, n_out, B)
        On entry, column ``b`` of ``out[:, 0]`` holds the set-up outputs ``y[0]`` of member ``b``; on return,
        the output samples (:data:`OUTPUT_ROWS`). Only the samples are stored, never the ticks: a
        10-minute log at 250 µs ticks would otherwise hold 2.4 million rows per output and member.

    Returns
    -------
    status, member, tick : int
        :data:`REPLAY_OK`, or the first failure (:data:`REPLAY_DRIVE_FAILED`, :data:`REPLAY_ALARM`) with its
        member and tick; the state is then partly advanced and must be discarded.
    """
    tp2 = tp * tp
    load_on = switches[0] != 0
    reversal_on = switches[1] != 0
    table_on = switches[2] != 0
    per_member_ref = ref.shape[1] > 1
    per_member_dist = disturbance.shape[1] > 1
    held_dist = disturbance.shape[0] == 1
    n_out = sample_tick.shape[0]
    ring = np.empty(max(delay_capacity, 2))
    prev = np.empty(4)
    for b in range(b0, b1):
        for r in range(4):
            prev[r] = out[r, 0, b]
        p = 0
        integ = mcu_state[0, b]
        v_cmd = mcu_state[1, b]
        i_ff = mcu_state[2, b]
        r1 = mcu_state[3, b]
        r2 = mcu_state[4, b]
        cmd = mcu_state[5, b]
        still = mcu_state[6, b]
        kp, kv, ki, kvff, kaff, i_max = gains[0, b], gains[1, b], gains[2, b], gains[3, b], gains[4, b], gains[5, b]
        x, v, d = state[0, b], state[1, b], state[2, b]
        table, travel, last = state[3, b], state[4, b], state[5, b]
        lag = delay[b]
        delayed = lag > 0.0
        initial_cmd = cmd
        if delayed:
            ring[0] = cmd
        rb = b if per_member_ref else 0
        db = b if per_member_dist else 0
        for k in range(n_ticks):
            r = ref[k, rb]
            integ, v_cmd, i_ff, r1, r2, cmd, still = axis_ticks(
                k, 1, ratio, tp, tv, tp2, kp, kv, ki, kvff, kaff, i_max, integ, v_cmd, i_ff, r1, r2, cmd, still,
                r, x, v)
            if axis_alarm(axis_index, abs(r - x), still, limits[0, b], limits[1, b], limits[2, b]) != 0:
                return REPLAY_ALARM, b, k
            current = cmd
            if delayed:
                ring[(k + 1) % ring.shape[0]] = cmd
                t_end = t0 + (k + 1) * tv
                current = _delayed(ring, k + 2, t0, tv, t_end - lag, initial_cmd)
            fd = disturbance[0 if held_dist else k, db]
            if load_on:
                fd = fd + axis_load(x, drive[13, b], drive[14, b], drive[15, b], drive[16, b])
            fc_p, fs_p, fc_n, fs_n = drive[2, b], drive[6, b], drive[7, b], drive[11, b]
            if reversal_on:
                extra = reversal_friction(travel, drive[17, b], drive[18, b])
                fc_p, fs_p, fc_n, fs_n = fc_p + extra, fs_p + extra, fc_n + extra, fs_n + extra
            old = x
            u, x, v, d, ff, code = exponential_member(
                current, fd, drive[0, b], drive[1, b], fc_p, drive[3, b], drive[4, b], drive[5, b], fs_p,
                fc_n, drive[8, b], drive[9, b], drive[10, b], fs_n, x, v, d, tv, drive[12, b])
            if code != OK:
                return REPLAY_DRIVE_FAILED, b, k
            if reversal_on:
                travel, last = travel_after_step(travel, last, old, x, v)
            position_out = x
            if table_on:
                elapsed = ((t0 + k * tv) + tv) - t0
                table, position_out = table_position(table, x, u, elapsed, drive[19, b], drive[20, b],
                                                     drive[21, b], drive[22, b], drive[23, b], drive[24, b])
            while p < n_out and sample_tick[p] == k + 1:
                w = sample_weight[p]
                out[0, p, b] = prev[0] * (1.0 - w) + position_out * w
                out[1, p, b] = prev[1] * (1.0 - w) + x * w
                out[2, p, b] = prev[2] * (1.0 - w) + u * w
                out[3, p, b] = prev[3] * (1.0 - w) + current * w
                p += 1
            prev[0] = position_out
            prev[1] = x
            prev[2] = u
            prev[3] = current
        mcu_state[0, b] = integ
        mcu_state[1, b] = v_cmd
        mcu_state[2, b] = i_ff
        mcu_state[3, b] = r1
        mcu_state[4, b] = r2
        mcu_state[5, b] = cmd
        mcu_state[6, b] = still
        state[0, b], state[1, b], state[2, b] = x, v, d
        state[3, b], state[4, b], state[5, b] = table, travel, last
    return REPLAY_OK, -1, -1


# the compiled code links the callees' code: recompile when their modules change
for _fn in (_delayed, replay_axis):
    guard_cache(_fn, control_numba, effects_numba, exponential_numba, stick_slip, stick_slip_numba)
