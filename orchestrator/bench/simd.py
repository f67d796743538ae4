"""A member-vectorised servo step (bench prototype): the fused reference with the batch members innermost.

The fused reference (:mod:`.fused`) and the twin step each member on its own: :func:`axis_member` and
:func:`~fmus_src.servo.exponential_numba.exponential_member` take scalars and branch per member. Here the
same equations run over *all* members of one axis in one loop body, structure of arrays, without calls or
branches that LLVM cannot turn into selects, so it can emit SIMD (AVX-512: 8 members per instruction):

* MCU: the position-loop decision (``tick % ratio``) is the same for every member and is taken outside the
  member loop; the anti-windup and saturation are selects.
* Drives: one exponential Rosenbrock-Euler substep per tick (the twin's: ``h_tick`` = 250 us =
  :data:`~fmus_src.servo.exponential_numba.EXPONENTIAL_MAX_STEP`) with the accuracy guard of
  ``exponential_member`` evaluated for every member. ``math.exp`` and ``math.expm1`` are libm calls, which
  numba vectorises only through Intel's SVML (absent here: this llvmlite is built without it,
  ``llvmlite.binding.targets.has_svml()`` is False), so :func:`exp_poly` replaces them: range reduction to
  ``|r| <= ln 2 / 2``, Taylor polynomial of degree 13 (truncation below 1e-17 relative; Estrin's scheme, so the
  loop is not bound by a chain of dependent multiply-adds) and ``2^n`` from the
  exponent bits (:func:`_bits_to_float`).
* A member at rest whose force stays within the static friction stays in stick in the vector loop too. Members
  the guard refuses (break-away, a reversal, a correction above the tolerance, ``|J h| > 0.2``, a failed
  member) are flagged and stepped afterwards by the scalar ``exponential_member`` itself, from their
  unchanged state.

The results differ from the scalar reference only by rounding (``exp_poly`` against libm's ``exp``, ``sqrt``
for ``hypot`` in the simple cutting load); ``tests/test_bench_simd.py`` bounds the difference. It is not
wired into the twin: see the README, "Speed", for what that would take.
"""
from __future__ import annotations

import math
import time

import numba
import numpy as np
from llvmlite import ir
from numba import float64, int64
from numba.extending import intrinsic

from fmus_src.jit_cache import guard_cache
from fmus_src.servo import control_numba, exponential_numba, stick_slip, stick_slip_numba
from fmus_src.servo.exponential_numba import (EXPONENTIAL_MAX_STEP, EXPONENTIAL_VELOCITY_TOL, PHI_SERIES_LIMIT,
                                              exponential_member)
from fmus_src.servo.stick_slip_numba import OK

from ..errors import CncTwinError
from .fused import MIN_MOVE, FusedProblem

_LOG2E = 1.4426950408889634
_LN2_HI = 6.93147180369123816490e-01  # ln 2 split so that n * _LN2_HI is exact for |n| < 2^11
_LN2_LO = 1.90821492927058770002e-10
_ROUND = 6755399441055744.0  # 1.5 * 2^52: (t + _ROUND) - _ROUND rounds t to the nearest integer
#: 1 / k! for k = 0 .. 11 and k = 12, 13 (lowest order first).
_EXP_LOW = tuple(1.0 / math.factorial(k) for k in range(12))
_EXP_HIGH = (1.0 / math.factorial(12), 1.0 / math.factorial(13))
#: Taylor coefficients of phi1 (1 / (m + 1)!) and phi2 (1 / (m + 2)!), m = 0 .. 11, lowest order first.
_PHI1 = tuple(1.0 / math.factorial(m + 1) for m in range(12))
_PHI2 = tuple(1.0 / math.factorial(m + 2) for m in range(12))


def _vector_jit(**options: object):
    """``numba.njit(cache=True, error_model="numpy")``: no division checks (they would block vectorisation)."""
    def wrap(fn):
        return numba.njit(cache=True, error_model="numpy", **options)(fn)
    return wrap


@intrinsic
def _bits_to_float(typingctx, bits):  # noqa: ARG001 - numba's intrinsic signature
    """The float64 whose bit pattern is the int64 ``bits`` (a register bitcast; vectorisable)."""
    sig = float64(int64)

    def codegen(context, builder, signature, args):  # noqa: ARG001
        return builder.bitcast(args[0], ir.DoubleType())

    return sig, codegen


@_vector_jit(inline="always")
def _estrin12(c: tuple, x: float) -> float:
    """``sum(c[m] x^m, m = 0..11)`` by Estrin's scheme (``c`` lowest order first, 12 coefficients).

    Four dependent multiply-add levels instead of Horner's eleven: the member loop is bound by that latency.
    """
    x2 = x * x
    x4 = x2 * x2
    x8 = x4 * x4
    s0 = (c[0] + c[1] * x) + (c[2] + c[3] * x) * x2
    s1 = (c[4] + c[5] * x) + (c[6] + c[7] * x) * x2
    s2 = (c[8] + c[9] * x) + (c[10] + c[11] * x) * x2
    return (s0 + s1 * x4) + s2 * x8


@_vector_jit(inline="always")
def exp_poly(x: float) -> float:
    """``exp(x)`` for ``-708 <= x <= 709`` (clamped outside) without a libm call, so loops over it vectorise.

    ``x = n ln 2 + r`` with ``|r| <= ln 2 / 2``; ``exp(r)`` by its Taylor polynomial to ``r^13`` (Estrin's
    scheme); ``2^n`` from the exponent bits. Within a few ulp of the exact value (tested against ``math.exp``).
    """
    x = min(max(x, -708.0), 709.0)
    n = (x * _LOG2E + _ROUND) - _ROUND
    r = (x - n * _LN2_HI) - n * _LN2_LO
    r2 = r * r
    p = _estrin12(_EXP_LOW, r) + (_EXP_HIGH[0] + _EXP_HIGH[1] * r) * (r2 * r2) * (r2 * r2) * (r2 * r2)
    return p * _bits_to_float((int64(n) + 1023) << 52)


@_vector_jit(inline="always")
def _phi12_series(z: float) -> tuple[float, float]:
    """``phi1``, ``phi2`` of :func:`fmus_src.servo.exponential_numba.phi12` by its series (``|z| <= 0.2``).

    The same twelve terms as ``phi12``'s series, summed by Estrin's scheme (rounding differs from its Horner
    sums); a member with a larger ``|z|`` is refused to the scalar step (``expm1`` there), so no third
    exponential is computed for every member.
    """
    return _estrin12(_PHI1, z), _estrin12(_PHI2, z)


@_vector_jit()
def _mcu_tick(pos_tick: bool, tp: float, tv: float, tp2: float, gains: np.ndarray, state: np.ndarray,
              ref: np.ndarray, position: np.ndarray, velocity: np.ndarray, current: np.ndarray) -> None:
    """One velocity tick (and the position tick when ``pos_tick``) of one axis for all members.

    :func:`fmus_src.servo.control_numba.axis_ticks` with ``n_ticks = 1``, the member loop innermost.

    Parameters
    ----------
    pos_tick : bool
        Run the position loop first (the tick index is a multiple of ``Tp / Tv``; the same for every member).
    tp, tv, tp2 : float
        Position- and velocity-loop periods (s) and ``tp * tp`` (s^2).
    gains, state : ndarray, shapes (6, B), (7, B)
        The axis' rows of the MCU's gain and state blocks (state updated in place).
    ref, position, velocity : ndarray, shape (B,)
        Reference and actual position (m), actual velocity (m/s).
    current : ndarray, shape (B,)
        Receives the current command (A).
    """
    B = position.shape[0]
    kp, kv, ki, kvff, kaff, imax = gains[0], gains[1], gains[2], gains[3], gains[4], gains[5]
    s_int, s_vcmd, s_iff, s_r1, s_r2, s_cmd, s_still = state[0], state[1], state[2], state[3], state[4], \
        state[5], state[6]
    if pos_tick:
        for b in range(B):
            rr = ref[b]
            r1 = s_r1[b]
            v_ref = (rr - r1) / tp
            a_ref = (rr - 2.0 * r1 + s_r2[b]) / tp2
            s_still[b] = s_still[b] + 1.0 if rr == r1 else 0.0
            s_r2[b] = r1
            s_r1[b] = rr
            s_vcmd[b] = kp[b] * (rr - position[b]) + kvff[b] * v_ref
            s_iff[b] = kaff[b] * a_ref
    for b in range(B):
        err = s_vcmd[b] - velocity[b]
        p_term = kv[b] * err + s_iff[b]
        im = imax[b]
        integ = s_int[b]
        candidate = min(max(integ + ki[b] * tv * err, -im), im)
        unsat = p_term + candidate
        sgn = 1.0 if unsat > 0.0 else (-1.0 if unsat < 0.0 else 0.0)
        sgn_err = 1.0 if err > 0.0 else (-1.0 if err < 0.0 else 0.0)
        headroom = im - sgn * p_term
        windup = sgn * max(sgn * integ, min(sgn * candidate, headroom))
        integ = windup if ((abs(unsat) > im) & (sgn == sgn_err)) else candidate
        s_int[b] = integ
        cmd = min(max(p_term + integ, -im), im)
        s_cmd[b] = cmd
        current[b] = cmd


@_vector_jit()
def _drive_substep(h: float, kt: np.ndarray, inv_mass: np.ndarray, fs_p: np.ndarray, fs_n: np.ndarray,
                   fc: np.ndarray, delta: np.ndarray, inv_vs: np.ndarray, mu: np.ndarray, direction: np.ndarray,
                   disturbance: np.ndarray, current: np.ndarray, position: np.ndarray, velocity: np.ndarray,
                   refused: np.ndarray) -> None:
    """One exponential substep of ``h`` of one axis for all members; members the guard refuses keep their state.

    The substep and guard of :func:`fmus_src.servo.exponential_numba.exponential_member` for a sliding member,
    and its stick test for a member at rest (it stays, direction 0, when the force does not exceed the static
    friction ``fs_p`` / ``fs_n``); ``fc`` ... ``mu`` are the parameters of each member's current branch,
    ``direction`` its direction as a float (updated). ``refused[b]`` is set where the scalar step must run
    instead (break-away, reversal, large correction, ``|J h| > 0.2``, NaN state).

    Parameters
    ----------
    h : float
        Substep, s.
    kt, inv_mass : ndarray, shape (B,)
        Force per ampere (N/A, ``kt 2 pi / Lb``) and 1 / table mass (1/kg): rows 0 and 1 of the drive's packed
        parameters.
    fs_p, fs_n : ndarray, shape (B,)
        Static friction in the positive and negative direction, N.
    fc, delta, inv_vs, mu : ndarray, shape (B,)
        Coulomb friction (N), Stribeck excess (N), 1 / Stribeck velocity (s/m), viscous coefficient (N s/m).
    direction : ndarray, shape (B,)
        +1, -1 or 0 (stick), as floats; updated.
    disturbance, current : ndarray, shape (B,)
        Disturbance force (N) and current command (A), held over the substep.
    position, velocity : ndarray, shape (B,)
        State, m and m/s; updated where the member is not refused.
    refused : ndarray of bool, shape (B,)
        Written: members the scalar step must take.
    """
    B = position.shape[0]
    for b in range(B):
        force = current[b] * kt[b] - disturbance[b]
        v = velocity[b]
        x = position[b]
        d = direction[b]
        dl = delta[b]
        ivs = inv_vs[b]
        m = mu[b]
        f_c = fc[b]
        im = inv_mass[b]
        e0 = dl * exp_poly(-(d * v) * ivs)
        f0 = (force - (m * v + d * (f_c + e0))) * im
        jac = (e0 * ivs - m) * im
        z = jac * h
        p1, p2 = _phi12_series(z)
        v1 = v + h * p1 * f0
        x1 = x + h * v + h * h * p2 * f0
        e1 = dl * exp_poly(-(d * v1) * ivs)
        rem = (force - (m * v1 + d * (f_c + e1))) * im - f0 - jac * (v1 - v)
        dv = rem * h / 3.0
        ok = (d * v > 0.0) & (d * v1 > 0.0) & (abs(dv) <= EXPONENTIAL_VELOCITY_TOL) & (d * (v1 + dv) > 0.0) \
            & (x == x) & (abs(z) <= PHI_SERIES_LIMIT)
        stick = (v == 0.0) & (force <= fs_p[b]) & (force >= -fs_n[b]) & (x == x)
        refused[b] = not (ok | stick)
        position[b] = x1 + rem * h * h / 12.0 if ok else x
        velocity[b] = v1 + dv if ok else v
        direction[b] = 0.0 if stick else d


@_vector_jit()
def _branch(params: np.ndarray, direction: np.ndarray, active: np.ndarray, b: int) -> None:
    """Member ``b``'s parameters of its current branch (``d > 0``: positive, else negative) into ``active``."""
    off = 2 if direction[b] > 0 else 7
    for r in range(4):
        active[r, b] = params[off + r, b]


@_vector_jit()
def simd_servo_loop(
    n_steps: int, n_ticks: int, ratio: int, tp: float, tv: float, h_tick: float,
    gains: np.ndarray, mcu_state: np.ndarray, drive_params: np.ndarray, max_steps: np.ndarray,
    position: np.ndarray, velocity: np.ndarray, direction: np.ndarray,
    ref: np.ndarray, force_ref: np.ndarray, move_ref: np.ndarray, force0: np.ndarray,
    out_position: np.ndarray, out_current: np.ndarray,
) -> tuple[int, int]:
    """:func:`.fused.fused_servo_loop` (exponential drives) with the members innermost (see the module docstring).

    Parameters as :func:`.fused.fused_servo_loop`, except ``gains`` (3, 6, B) and ``mcu_state`` (3, 7, B):
    axis first, so each axis' rows are contiguous. ``h_tick`` must be at most one exponential substep.

    Returns
    -------
    status, scalar : int
        0 or the first drive failure's status; drive ticks of members stepped by the scalar fallback.
    """
    B = position.shape[1]
    cur = np.empty((3, B))
    dist = np.zeros((3, B))
    refs = np.empty((3, B))
    refused = np.zeros(B, dtype=np.bool_)
    dir_f = np.empty((3, B))
    active = np.empty((3, 4, B))  # fc, delta, inv_vs, mu of each member's current branch
    tp2 = tp * tp
    n_scalar = 0
    for i in range(3):
        for b in range(B):
            cur[i, b] = out_current[0, i, b]
            dir_f[i, b] = float(direction[i, b])
            _branch(drive_params[i], dir_f[i], active[i], b)
    for b in range(B):
        dist[0, b] = force0[0, b]
        dist[1, b] = force0[1, b]
    for k in range(n_steps):
        for i in range(3):
            r = ref[k, i]
            for b in range(B):
                refs[i, b] = r
        for j in range(n_ticks):
            pos_tick = (k * n_ticks + j) % ratio == 0
            for i in range(3):
                _mcu_tick(pos_tick, tp, tv, tp2, gains[i], mcu_state[i], refs[i], position[i], velocity[i], cur[i])
                p = drive_params[i]
                a = active[i]
                _drive_substep(h_tick, p[0], p[1], p[6], p[11], a[0], a[1], a[2], a[3], dir_f[i], dist[i], cur[i],
                               position[i], velocity[i], refused)
                for b in range(B):  # the refused members: the scalar step itself, from their unchanged state
                    if refused[b]:
                        n_scalar += 1
                        u, x, v, dd, ff, status = exponential_member(
                            cur[i, b], dist[i, b], p[0, b], p[1, b], p[2, b], p[3, b], p[4, b], p[5, b], p[6, b],
                            p[7, b], p[8, b], p[9, b], p[10, b], p[11, b], position[i, b], velocity[i, b],
                            dir_f[i, b], h_tick, max_steps[i, b])
                        if status != OK:
                            return status, n_scalar
                        position[i, b] = x
                        velocity[i, b] = v
                        direction[i, b] = np.int8(dd)
                        if dd != dir_f[i, b]:
                            dir_f[i, b] = dd
                            _branch(p, dir_f[i], a, b)
        # simple cutting load from the precomputed engagement, applied in the next step (as the fused loop)
        mv = move_ref[k + 1]
        fx, fy = force_ref[k + 1, 0], force_ref[k + 1, 1]
        for b in range(B):
            dx = position[0, b] - out_position[k, 0, b]
            dy = position[1, b] - out_position[k, 1, b]
            scale = math.sqrt(dx * dx + dy * dy) / mv if mv > MIN_MOVE else 1.0
            dist[0, b] = fx * scale
            dist[1, b] = fy * scale
        for i in range(3):
            for b in range(B):
                out_position[k + 1, i, b] = position[i, b]
                out_current[k + 1, i, b] = cur[i, b]
    for i in range(3):
        for b in range(B):
            direction[i, b] = np.int8(dir_f[i, b])
    for b in range(B):
        force0[0, b] = dist[0, b]
        force0[1, b] = dist[1, b]
    return 0, n_scalar


for _fn in (_drive_substep, simd_servo_loop):
    guard_cache(_fn, control_numba, stick_slip, stick_slip_numba, exponential_numba)


def run_simd(problem: FusedProblem) -> tuple[np.ndarray, np.ndarray, int]:
    """:meth:`.fused.FusedProblem.run` by :func:`simd_servo_loop`.

    Returns
    -------
    position, current : ndarray, shape (n_steps + 1, 3, B)
        Drive positions (m) and current commands (A) at ``t0 + k h``.
    scalar : int
        Drive ticks stepped by the scalar fallback (out of ``n_steps * n_ticks * 3 * B``).

    Raises
    ------
    CncTwinError
        The problem's drives are not exponential, or ``h_tick`` needs more than one substep, or a drive failed.
    """
    mcu_state, _width, _limits, params, max_steps, pos, vel, dirn, cur0 = (
        np.array(a, copy=True) for a in problem._state0)  # noqa: SLF001
    n_ticks, ratio, tp, tv, h_tick, exponential = problem._scalars  # noqa: SLF001
    if not exponential or h_tick > EXPONENTIAL_MAX_STEP * (1.0 + 1e-12):
        raise CncTwinError(f"simd servo loop: needs exponential drives with one substep per tick "
                           f"(h_tick {h_tick:.3g} s, exponential={exponential})")
    out_pos = np.empty((problem.n_steps + 1, 3, problem.batch))
    out_cur = np.empty((problem.n_steps + 1, 3, problem.batch))
    out_pos[0] = pos
    out_cur[0] = cur0
    force0 = np.zeros((2, problem.batch))
    gains = np.ascontiguousarray(problem._gains.transpose(1, 0, 2))  # noqa: SLF001 - (3, 6, B)
    state = np.ascontiguousarray(mcu_state.transpose(1, 0, 2))  # (3, 7, B)
    status, scalar = simd_servo_loop(problem.n_steps, n_ticks, ratio, tp, tv, h_tick, gains, state,
                                     np.ascontiguousarray(params), np.ascontiguousarray(max_steps), pos, vel, dirn,
                                     problem.ref, problem.force_ref, problem.move_ref, force0, out_pos, out_cur)
    if status != 0:
        raise CncTwinError(f"simd servo loop: drive kernel failed with status {status}")
    return out_pos, out_cur, int(scalar)


def time_simd(problem: FusedProblem, repeats: int = 3) -> dict:
    """CPU time (``time.process_time``, best of ``repeats``) of the scalar fused loop and of the vectorised one.

    The two alternate, so both see the same machine load. Returns ``fused_s``, ``simd_s``, their ratio
    ``simd_speedup``, ``scalar_fraction`` (share of drive ticks on the scalar fallback) and the largest
    differences ``max_position_diff_m``, ``max_current_diff_a`` and relative to each trace's range.
    """
    ref_pos, ref_cur = problem.run()
    pos, cur, scalar = run_simd(problem)
    fused_s = simd_s = np.inf
    for _ in range(max(1, repeats)):
        t0 = time.process_time()
        problem.run()
        fused_s = min(fused_s, time.process_time() - t0)
        t0 = time.process_time()
        run_simd(problem)
        simd_s = min(simd_s, time.process_time() - t0)
    dpos = float(np.max(np.abs(pos - ref_pos)))
    dcur = float(np.max(np.abs(cur - ref_cur)))
    n_ticks = problem._scalars[0]  # noqa: SLF001
    return {
        "batch": problem.batch, "steps": problem.n_steps, "fused_s": fused_s, "simd_s": simd_s,
        "simd_speedup": fused_s / simd_s, "scalar_fraction": scalar / (problem.n_steps * n_ticks * 3 * problem.batch),
        "max_position_diff_m": dpos, "max_current_diff_a": dcur,
        "position_diff_rel": dpos / max(float(np.ptp(ref_pos)), 1e-300),
        "current_diff_rel": dcur / max(float(np.ptp(ref_cur)), 1e-300),
    }
