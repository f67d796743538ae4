"""Compiled (numba) MCU step: every velocity and position tick of the three axes, member by member.

:func:`mcu_kernel` is the scalar transcription of the numpy reference
:func:`fmus_src.servo.control.position_loop` / :func:`~fmus_src.servo.control.velocity_loop`
as scheduled by ``MCU._do_step`` (position tick when the absolute tick index
is a multiple of ``Tp / Tv``), plus the output publication of ``MCU._publish``
(commands and the in-position flag) and the excess-error check of
:func:`~fmus_src.servo.control.excess_error_alarm`, all written in place. Every
floating-point operation is done in the reference's order, without fastmath;
the control law contains no transcendental function, so compiled and
reference results are bit-identical (tested).
"""
from __future__ import annotations

import numpy as np

from ..jit import njit, njit_inline


@njit
def _sign(a: float) -> float:
    """``np.sign`` of a non-NaN float."""
    if a > 0.0:
        return 1.0
    if a < 0.0:
        return -1.0
    return 0.0


@njit
def axis_ticks(
    k0: int, n_ticks: int, ratio: int, tp: float, tv: float, tp2: float,
    kp: float, kv: float, ki: float, kvff: float, kaff: float, i_max: float,
    integ: float, v_cmd: float, i_ff: float, r1: float, r2: float, cmd: float, still: float,
    ref: float, pos: float, vel: float,
) -> tuple[float, float, float, float, float, float, float]:
    """Ticks ``k0 .. k0 + n_ticks - 1`` of one axis of one member (scalars in and out, no arrays).

    Gains (``kp`` ... ``i_max``) and state (``integ`` ... ``still``) as in the rows of the gain and
    state blocks; ``ref``, ``pos``, ``vel`` held over the ticks; ``tp2 = tp * tp``.

    Returns
    -------
    integ, v_cmd, i_ff, r1, r2, cmd, still : float
        The state after the ticks.
    """
    for k in range(k0, k0 + n_ticks):
        if k % ratio == 0:  # position loop
            v_ref = (ref - r1) / tp
            a_ref = (ref - 2.0 * r1 + r2) / tp2
            still = still + 1.0 if ref == r1 else 0.0
            r2 = r1
            r1 = ref
            v_cmd = kp * (ref - pos) + kvff * v_ref
            i_ff = kaff * a_ref
        # velocity loop (PI, conditional-integration anti-windup, saturation)
        err = v_cmd - vel
        p_term = kv * err + i_ff
        candidate = min(max(integ + ki * tv * err, -i_max), i_max)
        unsat = p_term + candidate
        sgn = _sign(unsat)
        if abs(unsat) > i_max and sgn == _sign(err):
            headroom = i_max - sgn * p_term
            integ = sgn * max(sgn * integ, min(sgn * candidate, headroom))
        else:
            integ = candidate
        cmd = min(max(p_term + integ, -i_max), i_max)
    return integ, v_cmd, i_ff, r1, r2, cmd, still


@njit_inline
def axis_member(
    k0: int, n_ticks: int, ratio: int, tp: float, tv: float, tp2: float, gains: np.ndarray, state: np.ndarray,
    i: int, b: int, ref: float, pos: float, vel: float,
) -> tuple[float, float, float]:
    """:func:`axis_ticks` of axis ``i`` of member ``b`` on the gain and state blocks (state updated in place).

    Parameters
    ----------
    gains : ndarray, shape (6, 3, B)
        :meth:`fmus_src.servo.control.CascadeGains.block`.
    state : ndarray, shape (7, 3, B)
        :attr:`fmus_src.servo.control.CascadeState.block`; column ``(i, b)`` is advanced.
    ref, pos, vel : float
        Reference and actual position [m], actual velocity [m/s], held over the ticks.

    Returns
    -------
    cmd, v_cmd, still : float
        Current command [A], velocity command [m/s] and still ticks after the ticks.
    """
    integ, v_cmd, i_ff, r1, r2, cmd, still = axis_ticks(
        k0, n_ticks, ratio, tp, tv, tp2, gains[0, i, b], gains[1, i, b], gains[2, i, b], gains[3, i, b],
        gains[4, i, b], gains[5, i, b], state[0, i, b], state[1, i, b], state[2, i, b], state[3, i, b],
        state[4, i, b], state[5, i, b], state[6, i, b], ref, pos, vel)
    state[0, i, b] = integ
    state[1, i, b] = v_cmd
    state[2, i, b] = i_ff
    state[3, i, b] = r1
    state[4, i, b] = r2
    state[5, i, b] = cmd
    state[6, i, b] = still
    return cmd, v_cmd, still


@njit
def axis_alarm(i: int, err: float, still: float, in_motion: float, at_stop: float, settle: float) -> int:
    """Alarm code of axis ``i`` (0, or ``1 + 2 i + at_stop``) for following error ``err`` [m] after a step."""
    stopped = still >= settle
    limit = at_stop if stopped else in_motion
    if limit > 0.0 and err > limit:
        return 1 + 2 * i + (1 if stopped else 0)
    return 0


@njit
def mcu_kernel(
    k0: int, n_ticks: int, ratio: int, tp: float, tv: float, gains: np.ndarray, state: np.ndarray,
    x_ref: np.ndarray, y_ref: np.ndarray, z_ref: np.ndarray,
    x_pos: np.ndarray, y_pos: np.ndarray, z_pos: np.ndarray,
    x_vel: np.ndarray, y_vel: np.ndarray, z_vel: np.ndarray, in_position_width: np.ndarray,
    x_cur: np.ndarray, y_cur: np.ndarray, z_cur: np.ndarray,
    x_vcmd: np.ndarray, y_vcmd: np.ndarray, z_vcmd: np.ndarray, in_position: np.ndarray,
    limits: np.ndarray, alarm: np.ndarray,
) -> int:
    """Run velocity ticks ``k0 .. k0 + n_ticks - 1`` of all axes and members, publish, check the error.

    Parameters
    ----------
    k0, n_ticks : int
        First absolute tick index and number of ticks (0: publish only).
    ratio : int
        ``Tp / Tv``; a position tick runs before the velocity tick when ``k % ratio == 0``.
    tp, tv : float
        Position- and velocity-loop periods [s].
    gains : ndarray, shape (6, 3, B)
        :meth:`fmus_src.servo.control.CascadeGains.block`.
    state : ndarray, shape (7, 3, B)
        :attr:`fmus_src.servo.control.CascadeState.block`, updated in place.
    x_ref ... z_vel : ndarray, shape (B,)
        Inputs held over the call: reference and actual position [m], actual velocity [m/s].
    in_position_width : ndarray, shape (B,)
        [m].
    x_cur ... z_vcmd : ndarray, shape (B,)
        Outputs written in place: current command [A], velocity command [m/s].
    in_position : ndarray of bool, shape (B,)
        Written in place: ``|ref - position| <= width`` on all three axes.
    limits : ndarray, shape (3, 3, B)
        :meth:`fmus_src.servo.control.ExcessErrorLimits.block` (in motion [m], at stop [m], settle ticks).
    alarm : ndarray of int8, shape (B,)
        Written in place: the alarm code of :func:`fmus_src.servo.control.excess_error_alarm`.

    Returns
    -------
    int
        Number of members with an alarm.
    """
    refs = (x_ref, y_ref, z_ref)
    poss = (x_pos, y_pos, z_pos)
    vels = (x_vel, y_vel, z_vel)
    curs = (x_cur, y_cur, z_cur)
    vcmds = (x_vcmd, y_vcmd, z_vcmd)
    n = x_ref.shape[0]
    tp2 = tp * tp
    n_alarm = 0
    for b in range(n):
        in_pos = True
        code = 0
        for i in range(3):
            ref = refs[i][b]
            pos = poss[i][b]
            cmd, v_cmd, still = axis_member(k0, n_ticks, ratio, tp, tv, tp2, gains, state, i, b, ref, pos,
                                            vels[i][b])
            curs[i][b] = cmd
            vcmds[i][b] = v_cmd
            err = abs(ref - pos)
            if not err <= in_position_width[b]:
                in_pos = False
            if code == 0:
                code = axis_alarm(i, err, still, limits[0, i, b], limits[1, i, b], limits[2, i, b])
        in_position[b] = in_pos
        alarm[b] = code
        if code != 0:
            n_alarm += 1
    return n_alarm
