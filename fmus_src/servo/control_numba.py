"""Compiled (numba) MCU step: every velocity and position tick of the three axes, member by member.

:func:`mcu_kernel` is the scalar transcription of the numpy reference
:func:`fmus_src.servo.control.position_loop` / :func:`~fmus_src.servo.control.velocity_loop`
as scheduled by ``MCU._do_step`` (position tick when the absolute tick index
is a multiple of ``Tp / Tv``), plus the output publication of ``MCU._publish``
(commands and the in-position flag), all written in place. Every
floating-point operation is done in the reference's order, without fastmath;
the control law contains no transcendental function, so compiled and
reference results are bit-identical (tested).
"""
from __future__ import annotations

import numpy as np

from ..jit import njit


@njit
def _sign(a: float) -> float:
    """``np.sign`` of a non-NaN float."""
    if a > 0.0:
        return 1.0
    if a < 0.0:
        return -1.0
    return 0.0


@njit
def mcu_kernel(
    k0: int, n_ticks: int, ratio: int, tp: float, tv: float, gains: np.ndarray, state: np.ndarray,
    x_ref: np.ndarray, y_ref: np.ndarray, z_ref: np.ndarray,
    x_pos: np.ndarray, y_pos: np.ndarray, z_pos: np.ndarray,
    x_vel: np.ndarray, y_vel: np.ndarray, z_vel: np.ndarray, in_position_width: np.ndarray,
    x_cur: np.ndarray, y_cur: np.ndarray, z_cur: np.ndarray,
    x_vcmd: np.ndarray, y_vcmd: np.ndarray, z_vcmd: np.ndarray, in_position: np.ndarray,
) -> None:
    """Run velocity ticks ``k0 .. k0 + n_ticks - 1`` of all axes and members, then publish.

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
    state : ndarray, shape (6, 3, B)
        :attr:`fmus_src.servo.control.CascadeState.block`, updated in place.
    x_ref ... z_vel : ndarray, shape (B,)
        Inputs held over the call: reference and actual position [m], actual velocity [m/s].
    in_position_width : ndarray, shape (B,)
        [m].
    x_cur ... z_vcmd : ndarray, shape (B,)
        Outputs written in place: current command [A], velocity command [m/s].
    in_position : ndarray of bool, shape (B,)
        Written in place: ``|ref - position| <= width`` on all three axes.
    """
    refs = (x_ref, y_ref, z_ref)
    poss = (x_pos, y_pos, z_pos)
    vels = (x_vel, y_vel, z_vel)
    curs = (x_cur, y_cur, z_cur)
    vcmds = (x_vcmd, y_vcmd, z_vcmd)
    n = x_ref.shape[0]
    tp2 = tp * tp
    for b in range(n):
        in_pos = True
        for i in range(3):
            ref = refs[i][b]
            pos = poss[i][b]
            vel = vels[i][b]
            kp = gains[0, i, b]
            kv = gains[1, i, b]
            ki = gains[2, i, b]
            kvff = gains[3, i, b]
            kaff = gains[4, i, b]
            i_max = gains[5, i, b]
            integ = state[0, i, b]
            v_cmd = state[1, i, b]
            i_ff = state[2, i, b]
            r1 = state[3, i, b]
            r2 = state[4, i, b]
            cmd = state[5, i, b]
            for k in range(k0, k0 + n_ticks):
                if k % ratio == 0:  # position loop
                    v_ref = (ref - r1) / tp
                    a_ref = (ref - 2.0 * r1 + r2) / tp2
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
            state[0, i, b] = integ
            state[1, i, b] = v_cmd
            state[2, i, b] = i_ff
            state[3, i, b] = r1
            state[4, i, b] = r2
            state[5, i, b] = cmd
            curs[i][b] = cmd
            vcmds[i][b] = v_cmd
            if not abs(ref - pos) <= in_position_width[b]:
                in_pos = False
        in_position[b] = in_pos
