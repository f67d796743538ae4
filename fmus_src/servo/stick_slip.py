"""Stick/slip integration of a feed-drive table with Stribeck friction.

Equation of motion (Sim & Lee 2023, Eq. 1)::

    M x'' = F - Ff(x'),      F = u - Fd   (held constant over one call)

Friction is handled as a per-member state machine, vectorised with masks:

* **stick** (``direction == 0``, ``v == 0``): the table stays put and the
  static friction balances ``F`` while ``-Fs_neg <= F <= Fs_pos`` (the
  break-away force of the direction the table would move). When ``F``
  exceeds it, the member breaks away in that direction.
* **slip** (``direction = +1 / -1``): the smooth Stribeck branch of that
  direction is integrated with the classical 4th-order Runge-Kutta method on
  ``(x, v)``. With ``F`` constant the velocity equation is a scalar
  autonomous ODE, so ``v`` is monotone inside a call and crosses zero at most
  once. When a substep ends with ``direction * v <= 0`` the crossing time is
  located on the Runge-Kutta solution itself (Illinois regula falsi on the
  step length), the table is stopped there, the stick condition is checked
  again, and the rest of the substep is either spent at rest (stick) or
  integrated on the opposite branch (direct reversal).

Because friction is never evaluated across ``v = 0`` with a sign function,
there is no chattering around zero velocity and no step-size-dependent
friction: halving the substep changes results only by the Runge-Kutta
truncation error (see the tests).

This numpy module is the reference implementation; the components run its
compiled, member-by-member transcription
:func:`fmus_src.servo.stick_slip_numba.advance_kernel` by default.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import ServoError
from .friction import DirectedFriction, StribeckParameters

#: Root search on the zero-velocity crossing: stop when |v| <= this [m/s] ...
CROSSING_VELOCITY_TOL = 1e-13
#: ... or when the bracket on the crossing time is narrower than this fraction of the substep.
CROSSING_TIME_RTOL = 1e-12
#: Iteration cap of the crossing search (Illinois converges in ~10); exceeding it is an error.
CROSSING_MAX_ITER = 200

#: Per-member status codes of a step (also returned by the compiled kernel).
OK, BACKWARD_BREAK_AWAY, CROSSING_NOT_CONVERGED = 0, 1, 2


def substeps(h: float, max_step: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Number and length of the equal internal substeps of an interval ``h``, per member.

    Parameters
    ----------
    h : float
        Interval [s], > 0.
    max_step : float or ndarray, shape (B,)
        Largest substep of each member [s].

    Returns
    -------
    n_sub : ndarray of int, shape (B,) (or scalar shape for a scalar ``max_step``)
        ``max(1, ceil(h / max_step))`` (with a 1e-12 relative allowance, so ``h = k max_step`` gives ``k``).
    dt : ndarray, same shape
        ``h / n_sub`` [s].
    """
    n_sub = np.maximum(1, np.ceil(h / np.asarray(max_step, dtype=float) * (1.0 - 1e-12))).astype(np.int64)
    return n_sub, h / n_sub


def failure_reason(status: int, dt: float) -> str:
    """Text of a failed member's step (status :data:`BACKWARD_BREAK_AWAY` or :data:`CROSSING_NOT_CONVERGED`)."""
    if status == BACKWARD_BREAK_AWAY:
        return (f"stick/slip integrator: a table breaking away from rest moved backwards within one substep "
                f"of {dt!r} s; expected integration_step small against the Stribeck time scale")
    if status == CROSSING_NOT_CONVERGED:
        return (f"zero-velocity crossing search did not converge in {CROSSING_MAX_ITER} iterations "
                f"(substep {dt!r} s); expected |v| <= {CROSSING_VELOCITY_TOL} m/s")
    return f"stick/slip integrator: unknown status {status}"


@dataclass
class SlipState:
    """Mechanical state of ``B`` tables.

    Attributes
    ----------
    position : ndarray, shape (B,)
        Table position [m].
    velocity : ndarray, shape (B,)
        Table velocity [m/s]; exactly 0 in stick.
    direction : ndarray of int8, shape (B,)
        0 = stick, +1 / -1 = sliding on the positive / negative branch.
    """

    position: np.ndarray
    velocity: np.ndarray
    direction: np.ndarray


def _rk4(
    x: np.ndarray, v: np.ndarray, dt: np.ndarray | float, force: np.ndarray,
    inv_mass: np.ndarray, branch: DirectedFriction, d: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """One RK4 step of ``x' = v, M v' = F - Ff_d(v)`` of length ``dt`` (scalar or per member)."""
    a1 = (force - branch.force(v, d)) * inv_mass
    v2 = v + 0.5 * dt * a1
    a2 = (force - branch.force(v2, d)) * inv_mass
    v3 = v + 0.5 * dt * a2
    a3 = (force - branch.force(v3, d)) * inv_mass
    v4 = v + dt * a3
    a4 = (force - branch.force(v4, d)) * inv_mass
    x_new = x + dt * v + (dt * dt / 6.0) * (a1 + a2 + a3)
    v_new = v + (dt / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    return x_new, v_new


def _break_away(force: np.ndarray, static_pos: np.ndarray, static_neg: np.ndarray) -> np.ndarray:
    """Direction (+1, -1, or 0 = stay in stick) of a table at rest under ``force``."""
    return np.where(force > static_pos, 1, np.where(force < -static_neg, -1, 0)).astype(np.int8)


def _locate_crossing(
    x0: np.ndarray, v0: np.ndarray, dt: np.ndarray, v1: np.ndarray, force: np.ndarray,
    inv_mass: np.ndarray, branch: DirectedFriction, d: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Time ``tau`` in (0, dt] where the RK4 solution from ``(x0, v0)`` reaches ``v = 0``.

    Illinois (modified regula falsi) on ``phi(tau) = d * v_rk4(tau)``, with
    ``phi(0) > 0 >= phi(dt)``; all arrays are the crossing subset, shape (n,),
    ``dt`` included (each member's own substep).

    Returns
    -------
    tau : ndarray, shape (n,)
        Crossing time after the substep start [s].
    x_c : ndarray, shape (n,)
        Position at the crossing [m].
    converged : ndarray of bool, shape (n,)
        False for members whose search did not converge within ``CROSSING_MAX_ITER`` iterations.
    """
    lo = np.zeros_like(v0)
    f_lo = d * v0
    hi = np.array(dt, dtype=float, copy=True)
    f_hi = d * v1
    tau = hi.copy()
    done = f_hi == 0.0
    side = np.zeros(v0.shape, dtype=np.int8)
    t_tol = CROSSING_TIME_RTOL * dt
    for _ in range(CROSSING_MAX_ITER):
        if done.all():
            break
        c = hi - f_hi * (hi - lo) / (f_hi - f_lo)
        c = np.where(done, tau, np.clip(c, lo, hi))
        _, vc = _rk4(x0, v0, c, force, inv_mass, branch, d)
        fc = d * vc
        tau = c
        new_done = done | (np.abs(fc) <= CROSSING_VELOCITY_TOL) | ((hi - lo) <= t_tol)
        upd = ~new_done
        # root in [c, hi] when fc > 0 (fc has the sign of f_lo)
        go_right = upd & (fc > 0.0)
        go_left = upd & (fc <= 0.0)
        # Illinois: halve the retained end's function value when the same end is kept twice
        f_hi = np.where(go_right & (side == 1), 0.5 * f_hi, f_hi)
        f_lo = np.where(go_left & (side == -1), 0.5 * f_lo, f_lo)
        lo = np.where(go_right, c, lo)
        f_lo = np.where(go_right, fc, f_lo)
        hi = np.where(go_left, c, hi)
        f_hi = np.where(go_left, fc, f_hi)
        side = np.where(go_right, 1, np.where(go_left, -1, side)).astype(np.int8)
        done = new_done
    x_c, _ = _rk4(x0, v0, tau, force, inv_mass, branch, d)
    return tau, x_c, done


def advance(
    state: SlipState, force: np.ndarray, mass: np.ndarray, friction: StribeckParameters,
    h: float, max_step: np.ndarray | float, status: np.ndarray | None = None,
) -> np.ndarray:
    """Advance ``state`` in place by ``h`` under the constant net force ``force``.

    Parameters
    ----------
    state : SlipState
        Positions, velocities and stick/slip directions, shape (B,); updated in place.
        A member whose position is NaN (a failed member, see ``status``) is frozen:
        it is not integrated; its velocity and friction force are NaN.
    force : ndarray, shape (B,)
        Net applied force ``u - Fd`` [N], held over the interval.
    mass : ndarray, shape (B,)
        Equivalent moving mass ``Ms`` [kg].
    friction : StribeckParameters
        Both Stribeck branches, arrays of shape (B,).
    h : float
        Interval length [s], > 0.
    max_step : float or ndarray, shape (B,)
        Largest internal substep of each member [s]; member ``b`` cuts the
        interval into ``ceil(h / max_step[b])`` equal substeps
        (:func:`substeps`), so a member's result does not depend on the
        other members of the batch.
    status : ndarray of int8, shape (B,), optional
        When given, a member whose step fails gets its status code
        (:data:`BACKWARD_BREAK_AWAY`, :data:`CROSSING_NOT_CONVERGED`; :data:`OK`
        otherwise), keeps its state unchanged, and the others carry on: no
        exception. Without it, any failure raises :class:`ServoError`.

    Returns
    -------
    ndarray, shape (B,)
        Friction force at the end of the interval [N]: the Stribeck force when
        sliding, the static reaction ``F`` when stuck.

    Raises
    ------
    ServoError
        Without ``status``: if a member at rest that breaks away ends its first
        substep moving backwards (the substep is too long for its friction
        parameters), or if a zero-velocity crossing search does not converge.
    """
    n_sub, dt = substeps(h, np.broadcast_to(np.asarray(max_step, dtype=float), np.shape(force)))
    inv_mass = 1.0 / mass
    x0, v0, d0 = state.position, state.velocity, state.direction
    x, v, d = x0, v0, d0
    frozen = np.isnan(x0)
    failed = np.zeros(x0.shape, dtype=bool)
    codes = np.zeros(x0.shape, dtype=np.int8)
    for j in range(int(np.max(n_sub, initial=1))):
        live = (j < n_sub) & ~frozen & ~failed
        at_rest = live & (v == 0.0)
        if at_rest.any():
            d = np.where(at_rest, _break_away(force, friction.static_pos, friction.static_neg), d).astype(np.int8)
        slip = live & (d != 0)
        if not slip.any():
            continue
        branch = friction.select(d)
        x1, v1 = _rk4(x, v, dt, force, inv_mass, branch, d)
        dv0 = d * v
        crossed = slip & (d * v1 <= 0.0)
        bad = crossed & (dv0 <= 0.0)
        if bad.any():
            if status is None:
                first = int(np.flatnonzero(bad)[0])
                raise ServoError(f"{failure_reason(BACKWARD_BREAK_AWAY, float(dt[first]))} "
                                 f"(members {np.nonzero(bad)[0].tolist()})")
            codes[bad] = BACKWARD_BREAK_AWAY
            failed |= bad
            slip &= ~bad
            crossed &= ~bad
        x_new = np.where(slip, x1, x)
        v_new = np.where(slip, v1, v)
        if crossed.any():
            idx = np.nonzero(crossed)[0]
            sub = branch.take(idx)
            f_i, im_i, d_i = force[idx], inv_mass[idx], d[idx]
            tau, x_c, converged = _locate_crossing(x[idx], v[idx], dt[idx], v1[idx], f_i, im_i, sub, d_i)
            if not converged.all():
                lost = idx[~converged]
                if status is None:
                    raise ServoError(failure_reason(CROSSING_NOT_CONVERGED, float(dt[lost[0]])))
                codes[lost] = CROSSING_NOT_CONVERGED
                failed[lost] = True
            d_new = _break_away(f_i, friction.static_pos[idx], friction.static_neg[idx])
            rest = dt[idx] - tau
            x_out = x_c.copy()
            v_out = np.zeros_like(x_c)
            rev = (d_new != 0) & (rest > 0.0)
            if rev.any():
                j_rev = np.nonzero(rev)[0]
                gidx = idx[j_rev]
                br2 = friction.take(gidx).select(d_new[j_rev])
                d2 = d_new[j_rev]
                xr, vr = _rk4(x_c[j_rev], np.zeros(j_rev.size), rest[j_rev], force[gidx], inv_mass[gidx], br2, d2)
                x_out[j_rev] = xr
                v_out[j_rev] = vr
            x_new[idx] = x_out
            v_new[idx] = v_out
            d = d.copy()
            d[idx] = d_new
        x, v = x_new, v_new
    if failed.any():  # failed members keep the state they had before the call
        x = np.where(failed, x0, x)
        v = np.where(failed, v0, v)
        d = np.where(failed, d0, d).astype(np.int8)
    if status is not None:
        status[...] = codes
    if frozen.any():
        v = np.where(frozen, np.nan, v)
    state.position, state.velocity, state.direction = x, v, d
    ff = friction_force(state, force, friction)
    if frozen.any():
        ff = np.where(frozen, np.nan, ff)
    return ff


def friction_force(state: SlipState, force: np.ndarray, friction: StribeckParameters) -> np.ndarray:
    """Friction force [N] of ``state``: Stribeck force when sliding, static reaction when stuck.

    Parameters
    ----------
    state : SlipState
        Current state, shape (B,).
    force : ndarray, shape (B,)
        Net applied force ``u - Fd`` [N].
    friction : StribeckParameters
        Both branches.

    Returns
    -------
    ndarray, shape (B,)
    """
    d = state.direction
    sliding = friction.select(d).force(state.velocity, d)
    static = np.clip(force, -friction.static_neg, friction.static_pos)
    return np.where(d == 0, static, sliding)
