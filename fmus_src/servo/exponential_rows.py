"""The exponential drive step of the compiled master loop with the batch members innermost (vectorisable).

:func:`exponential_rows` gives every member the result of
:func:`fmus_src.servo.exponential_numba.exponential_member`, bit for bit, but
steps the common cases over all members of one axis in a few member loops
without calls or branches, which LLVM turns into SIMD:

* a member **sliding** smoothly (``d v > 0``, ``|J h| <= 0.2``, the velocity
  stays on its branch and the correction is within
  :data:`~fmus_src.servo.exponential_numba.EXPONENTIAL_VELOCITY_TOL`): the
  exponential Rosenbrock-Euler substep with its correction, the same operations
  in the same order (Horner sums of ``phi1``, ``phi2``);
* a member **in stick** (``v = 0``) whose force does not break it away.

The three ``exp`` of a sliding member (start, end, friction output) are libm
calls, each in a loop of its own over the members (numba vectorises ``exp`` only
through Intel's SVML, which this llvmlite lacks); the arithmetic between them is
vectorised. The friction output's ``exp`` is kept per member (``memo``) and is
the next step's first one when its argument is the same (a member still
sliding), so a sliding member costs two ``exp`` calls per step, not three; a
member at rest (argument 0: ``exp(+-0) = 1`` exactly, C99 Annex F) calls none.

Every other member (break-away, reversal, large correction, failed member,
``|J h| > 0.2``, a step longer than one substep) is stepped afterwards by
``exponential_member`` itself, from its unchanged state.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit_inline, njit_rows
from ..jit_cache import guard_cache
from . import exponential_numba, stick_slip, stick_slip_numba
from .exponential_numba import (EXPONENTIAL_MAX_STEP, EXPONENTIAL_VELOCITY_TOL, PHI_SERIES_LIMIT, _horner,
                                exponential_member)
from .stick_slip_numba import OK

#: Rows of :func:`exponential_rows`'s work space.
ROWS_WORK = 7


@njit_rows
def _exp_row(a: np.ndarray, e: np.ndarray, n: int) -> None:
    """``e[:n] = exp(a[:n])`` by libm's ``exp``, as the scalar kernels call it (``exp(+-0) = 1``: not called)."""
    for b in range(n):
        x = a[b]
        e[b] = 1.0 if x == 0.0 else math.exp(x)


@njit_rows
def _exp_row_memo(a: np.ndarray, e: np.ndarray, n: int, memo: np.ndarray) -> None:
    """``e[:n] = exp(a[:n])``, taking ``memo[1, b]`` where ``a[b] == memo[0, b]`` (``memo[1] = exp(memo[0])``)."""
    for b in range(n):
        x = a[b]
        if x == memo[0, b]:
            e[b] = memo[1, b]
        else:
            e[b] = 1.0 if x == 0.0 else math.exp(x)


@njit_inline
def _branch_friction(params: np.ndarray, b: int, positive: bool) -> tuple[float, float, float, float]:
    """Member ``b``'s friction on its sliding branch: Coulomb force (N), Stribeck excess (N), 1/vs (s/m), viscous
    coefficient (N.s/m); the positive-velocity columns of ``params`` when ``positive``, else the negative ones.

    Both columns are loaded and one is selected (no branch), so the member loops stay vectorisable; inlined.
    """
    fc_p = params[2, b]
    fc_n = params[7, b]
    delta_p = params[3, b]
    delta_n = params[8, b]
    inv_vs_p = params[4, b]
    inv_vs_n = params[9, b]
    mu_p = params[5, b]
    mu_n = params[10, b]
    return (fc_p if positive else fc_n, delta_p if positive else delta_n, inv_vs_p if positive else inv_vs_n,
            mu_p if positive else mu_n)


@njit_rows
def exponential_rows(V: np.ndarray, base: int, params: np.ndarray, position: np.ndarray, velocity: np.ndarray,
                     direction: np.ndarray, h: float, max_step: np.ndarray, status: np.ndarray,
                     work: np.ndarray, memo: np.ndarray) -> int:
    """One drive step of every member on the compiled loop's value rows; ``exponential_member``'s results.

    Parameters
    ----------
    V : ndarray, shape (n_rows, B)
        The loop's values; rows ``base + 0 ..`` are :data:`orchestrator.compiled.loop.DRIVE_ROWS`: current
        command (A) and disturbance force (N) read; position (m), velocity (m/s), motor force (N) and friction
        force (N) written (the table position is left to the caller).
    params : ndarray, shape (12, B)
        The drive's packed parameters (:data:`~fmus_src.servo.stick_slip_numba.PARAMETER_ROWS`).
    position, velocity : ndarray, shape (B,)
        State, m and m/s; updated (a member whose step fails keeps its state).
    direction : ndarray of int8, shape (B,)
        Sliding direction (+1, -1, 0); updated.
    h : float
        Step, s.
    max_step : ndarray, shape (B,)
        Each member's internal RK4 step on guarded substeps, s.
    status : ndarray of int8, shape (B,)
        Written: each member's status (``OK`` = 0).
    work : ndarray, shape (>= ROWS_WORK, >= B)
        Work space.
    memo : ndarray, shape (2, >= B)
        Per member, an argument of ``exp`` and its value (NaN, NaN before the first call), kept from call to
        call: the friction output's ``exp`` of a sliding member is the next step's first ``exp`` (same
        velocity, direction and branch), so it is taken from here when the argument is the same.

    Returns
    -------
    int
        The first member's non-OK status, or ``OK``.
    """
    B = V.shape[1]
    cur = V[base]
    dist = V[base + 1]
    x_out = V[base + 2]
    v_out = V[base + 3]
    u_out = V[base + 4]
    ff_out = V[base + 5]
    n_sub = max(1, int(math.ceil(h / EXPONENTIAL_MAX_STEP * (1.0 - 1e-12))))
    first = OK
    if n_sub == 1:
        dt = h / n_sub
        arg = work[0]
        ex = work[1]
        x1s = work[2]
        v1s = work[3]
        f0s = work[4]
        jacs = work[5]
        fast = work[6]  # 1.0: sliding, 2.0: in stick, 0.0: the scalar step
        for b in range(B):
            d = float(direction[b])
            ivp = params[4, b]
            ivn = params[9, b]
            inv_vs = ivp if d > 0.0 else ivn
            arg[b] = -(d * velocity[b]) * inv_vs
        _exp_row_memo(arg, ex, B, memo)
        for b in range(B):  # the substep up to the end velocity
            force = cur[b] * params[0, b] - dist[b]
            inv_mass = params[1, b]
            x = position[b]
            v = velocity[b]
            d = float(direction[b])
            pos_branch = d > 0.0
            fc, delta, inv_vs, mu = _branch_friction(params, b, pos_branch)
            e0 = delta * ex[b]
            f0 = (force - (mu * v + d * (fc + e0))) * inv_mass
            jac = (e0 * inv_vs - mu) * inv_mass
            z = jac * dt
            p1 = _horner(z, 1, 13)
            p2 = _horner(z, 0, 12)
            v1 = v + dt * p1 * f0
            x1 = x + dt * v + dt * dt * p2 * f0
            x1s[b] = x1
            v1s[b] = v1
            f0s[b] = f0
            jacs[b] = jac
            arg[b] = -(d * v1) * inv_vs
            sliding = (d * v > 0.0) & (abs(z) <= PHI_SERIES_LIMIT) & (d * v1 > 0.0) & (x == x)
            fs_p = params[6, b]
            fs_n = params[11, b]
            stick = (v == 0.0) & (not force > fs_p) & (not force < -fs_n) & (x == x)
            fast[b] = 1.0 if sliding else (2.0 if stick else 0.0)
        _exp_row(arg, ex, B)
        for b in range(B):  # the correction, the guard, the new state
            force = cur[b] * params[0, b] - dist[b]
            inv_mass = params[1, b]
            x = position[b]
            v = velocity[b]
            d = float(direction[b])
            pos_branch = d > 0.0
            fc, delta, inv_vs, mu = _branch_friction(params, b, pos_branch)
            v1 = v1s[b]
            e1 = delta * ex[b]
            rem = (force - (mu * v1 + d * (fc + e1))) * inv_mass - f0s[b] - jacs[b] * (v1 - v)
            dv = rem * dt / 3.0
            kind = fast[b]
            sliding = (kind == 1.0) & (abs(dv) <= EXPONENTIAL_VELOCITY_TOL) & (d * (v1 + dv) > 0.0)
            stick = kind == 2.0
            x_new = x1s[b] + rem * dt * dt / 12.0 if sliding else x
            v_new = v1 + dv if sliding else v
            d_new = 0.0 if stick else d
            x1s[b] = x_new
            v1s[b] = v_new
            f0s[b] = force
            fast[b] = 1.0 if sliding else (2.0 if stick else 0.0)
            arg[b] = -max(d_new * v_new, 0.0) * inv_vs
        _exp_row(arg, ex, B)
        for b in range(B):  # outputs of the members stepped here (friction force as _branch_force)
            kind = fast[b]
            if kind != 0.0:
                force = f0s[b]
                v = v1s[b]
                d = 0.0 if kind == 2.0 else float(direction[b])
                pos_branch = d > 0.0
                fc, delta, _, mu = _branch_friction(params, b, pos_branch)
                slide = mu * v + d * (fc + delta * ex[b])
                memo[0, b] = arg[b]
                memo[1, b] = ex[b]
                stuck = min(max(force, -params[11, b]), params[6, b])
                ff_out[b] = stuck if kind == 2.0 else slide
                u_out[b] = cur[b] * params[0, b]
                x_out[b] = x1s[b]
                v_out[b] = v
                position[b] = x1s[b]
                velocity[b] = v
                direction[b] = np.int8(d)
                status[b] = OK
    for b in range(B):  # everything else: the scalar step itself, from the unchanged state
        if n_sub == 1 and work[6, b] != 0.0:
            continue
        u, x, v, dd, ff, code = exponential_member(
            cur[b], dist[b], params[0, b], params[1, b], params[2, b], params[3, b], params[4, b], params[5, b],
            params[6, b], params[7, b], params[8, b], params[9, b], params[10, b], params[11, b], position[b],
            velocity[b], float(direction[b]), h, max_step[b])
        u_out[b] = u
        x_out[b] = x
        v_out[b] = v
        ff_out[b] = ff
        position[b] = x
        velocity[b] = v
        direction[b] = np.int8(dd)
        status[b] = code
        if code != OK and first == OK:
            first = code
    return first


for _fn in (_exp_row, _exp_row_memo, _branch_friction, exponential_rows):
    guard_cache(_fn, exponential_numba, stick_slip, stick_slip_numba)
