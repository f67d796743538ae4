"""The MCU step of the compiled master loop with the batch members innermost (vectorisable).

:func:`mcu_rows` does what the compiled loop's member-by-member MCU branch does
(:func:`fmus_src.servo.control_numba.axis_member` for each axis and member, then the
in-position flag and :func:`~fmus_src.servo.control_numba.axis_alarm`), with the loops
turned round: for each axis and velocity tick, one loop over all members. The
position-loop decision (``tick % ratio``) is the same for every member, so it is
taken outside that loop, and the anti-windup and saturation branches become
selects that LLVM can turn into SIMD. Every member sees the same floating-point
operations in the same order as in :func:`~fmus_src.servo.control_numba.axis_ticks`,
so the results are bit-identical (tested in ``tests/test_compiled_rows.py``).
"""
from __future__ import annotations

import numpy as np

from ..jit import njit_rows
from ..jit_cache import guard_cache
from . import control_numba
from .control_numba import axis_alarm


@njit_rows
def _axis_rows(k0: int, n_ticks: int, ratio: int, tp: float, tv: float, tp2: float, gains: np.ndarray,
               state: np.ndarray, i: int, ref: np.ndarray, pos: np.ndarray, vel: np.ndarray) -> None:
    """Ticks ``k0 .. k0 + n_ticks - 1`` of axis ``i`` for every member (state block updated in place).

    Parameters as :func:`fmus_src.servo.control_numba.axis_ticks`; ``gains`` (6, 3, B) and ``state``
    (7, 3, B) are the MCU's blocks; ``ref``, ``pos`` (m) and ``vel`` (m/s) are rows of shape (B,).
    """
    B = ref.shape[0]
    kp, kv, ki, kvff, kaff, i_max = gains[0, i], gains[1, i], gains[2, i], gains[3, i], gains[4, i], gains[5, i]
    s_int, s_vcmd, s_iff, s_r1, s_r2, s_cmd, s_still = (state[0, i], state[1, i], state[2, i], state[3, i],
                                                         state[4, i], state[5, i], state[6, i])
    for k in range(k0, k0 + n_ticks):
        if k % ratio == 0:  # position loop
            for b in range(B):
                r = ref[b]
                r1 = s_r1[b]
                v_ref = (r - r1) / tp
                a_ref = (r - 2.0 * r1 + s_r2[b]) / tp2
                s_still[b] = s_still[b] + 1.0 if r == r1 else 0.0
                s_r2[b] = r1
                s_r1[b] = r
                s_vcmd[b] = kp[b] * (r - pos[b]) + kvff[b] * v_ref
                s_iff[b] = kaff[b] * a_ref
        for b in range(B):  # velocity loop (PI, conditional-integration anti-windup, saturation)
            im = i_max[b]
            integ = s_int[b]
            err = s_vcmd[b] - vel[b]
            p_term = kv[b] * err + s_iff[b]
            candidate = min(max(integ + ki[b] * tv * err, -im), im)
            unsat = p_term + candidate
            sgn = 1.0 if unsat > 0.0 else (-1.0 if unsat < 0.0 else 0.0)
            sgn_err = 1.0 if err > 0.0 else (-1.0 if err < 0.0 else 0.0)
            headroom = im - sgn * p_term
            windup = sgn * max(sgn * integ, min(sgn * candidate, headroom))
            integ = windup if (abs(unsat) > im) & (sgn == sgn_err) else candidate
            s_int[b] = integ
            s_cmd[b] = min(max(p_term + integ, -im), im)


@njit_rows
def mcu_rows(k0: int, n_ticks: int, ratio: int, tp: float, tv: float, tp2: float, gains: np.ndarray,
             state: np.ndarray, V: np.ndarray, base: int, width: np.ndarray, limits: np.ndarray,
             alarm: np.ndarray) -> int:
    """One MCU step of every member on the compiled loop's value rows.

    Parameters
    ----------
    k0, n_ticks, ratio : int
        First absolute velocity tick, ticks in this step, ``Tp / Tv``.
    tp, tv, tp2 : float
        Position- and velocity-loop periods (s) and ``tp * tp`` (s^2); ``tp`` > 0.
    gains, state : ndarray, shapes (6, 3, B), (7, 3, B)
        The MCU's gain and state blocks (state updated in place).
    V : ndarray, shape (n_rows, B)
        The loop's values; rows ``base + 0 ..`` are :data:`orchestrator.compiled.loop.MCU_ROWS`: references,
        positions (m), velocities (m/s) read; current commands (A), velocity commands (m/s) and the
        in-position flag (1.0 / 0.0) written.
    width : ndarray, shape (B,)
        In-position width, m.
    limits : ndarray, shape (3, 3, B)
        Excess-error limits (in motion, at stop: m; settle ticks).
    alarm : ndarray of int8, shape (B,)
        Written: each member's alarm code (0: none).

    Returns
    -------
    int
        Number of members with an alarm.
    """
    B = V.shape[1]
    for i in range(3):
        _axis_rows(k0, n_ticks, ratio, tp, tv, tp2, gains, state, i, V[base + i], V[base + 3 + i],
                   V[base + 6 + i])
        cmd_row = V[base + 9 + i]
        vcmd_row = V[base + 12 + i]
        for b in range(B):
            cmd_row[b] = state[5, i, b]
            vcmd_row[b] = state[1, i, b]
    n_alarm = 0
    for b in range(B):
        in_pos = True
        code = 0
        for i in range(3):
            err = abs(V[base + i, b] - V[base + 3 + i, b])
            if not err <= width[b]:
                in_pos = False
            if code == 0:
                code = axis_alarm(i, err, state[6, i, b], limits[0, i, b], limits[1, i, b], limits[2, i, b])
        V[base + 15, b] = 1.0 if in_pos else 0.0
        alarm[b] = code
        if code != 0:
            n_alarm += 1
    return n_alarm


for _fn in (_axis_rows, mcu_rows):
    guard_cache(_fn, control_numba)
