"""Compiled (numba) drive step: the stick/slip integrator of :mod:`.stick_slip`, member by member.

:func:`advance_kernel` performs one whole ``DriveAxis.do_step`` for every
batch member in one compiled call: net force ``u - Fd``, all substeps, RK4
on the sliding branch, the zero-velocity crossing search, the stick /
break-away checks and the final friction force, written in place into the
output arrays. It is the scalar transcription of the numpy reference
:func:`fmus_src.servo.stick_slip.advance`: the same state machine, the same
Runge-Kutta stages, the same Illinois iteration with the same tolerances,
with every floating-point operation in the same order (no fastmath, no
reassociation), so the two agree to rounding of ``exp`` (tested to 1e-12
relative, usually bit for bit).

The reference stays the specification; :func:`advance` here has its exact
signature and is what the equivalence tests call.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit, njit_inline
from .errors import ServoError
from .friction import StribeckParameters
from .stick_slip import (BACKWARD_BREAK_AWAY, CROSSING_MAX_ITER, CROSSING_NOT_CONVERGED, CROSSING_TIME_RTOL,
                         CROSSING_VELOCITY_TOL, OK, SlipState)
from .stick_slip import advance as reference_advance

#: Rows of the packed parameter array (shape ``(N_PARAMETERS, B)``) taken by :func:`advance_kernel`.
PARAMETER_ROWS = (
    "force_constant", "inv_mass",
    "coulomb_pos", "delta_pos", "inv_stribeck_velocity_pos", "viscous_pos", "static_pos",
    "coulomb_neg", "delta_neg", "inv_stribeck_velocity_neg", "viscous_neg", "static_neg",
)
N_PARAMETERS = len(PARAMETER_ROWS)

#: Status codes of :func:`advance_kernel` (those of the reference, :mod:`.stick_slip`).
STATUS_CODES = (OK, BACKWARD_BREAK_AWAY, CROSSING_NOT_CONVERGED)


def pack_parameters(friction: StribeckParameters, mass: np.ndarray, force_constant: np.ndarray) -> np.ndarray:
    """Parameter block of :func:`advance_kernel`, computed exactly as the reference computes them.

    Parameters
    ----------
    friction : StribeckParameters
        Both Stribeck branches, shape (B,).
    mass : ndarray, shape (B,)
        Moving mass ``Ms`` [kg].
    force_constant : ndarray, shape (B,)
        ``kt 2 pi / Lb`` [N/A] (1 when the kernel is fed forces directly).

    Returns
    -------
    ndarray, shape (12, B), C-contiguous
        Rows in the order of :data:`PARAMETER_ROWS`; ``delta = Fs - Fc`` [N], ``inv_*`` reciprocals.
    """
    f = friction
    rows = (
        force_constant, 1.0 / mass,
        f.coulomb_pos, f.static_pos - f.coulomb_pos, 1.0 / f.stribeck_velocity_pos, f.viscous_pos, f.static_pos,
        f.coulomb_neg, f.static_neg - f.coulomb_neg, 1.0 / f.stribeck_velocity_neg, f.viscous_neg, f.static_neg,
    )
    batch = np.broadcast(*rows).shape
    return np.ascontiguousarray(np.stack([np.broadcast_to(np.asarray(r, dtype=float), batch) for r in rows]))


# ------------------------------------------------------------------------------------------ scalar physics
@njit
def _branch_force(v: float, d: float, fc: float, delta: float, inv_vs: float, mu: float) -> float:
    """``DirectedFriction.force`` for one member (continued branch for ``d v < 0``)."""
    s_v = max(d * v, 0.0)
    return mu * v + d * (fc + delta * math.exp(-s_v * inv_vs))


@njit
def _rk4(x: float, v: float, dt: float, force: float, inv_mass: float, d: float,
         fc: float, delta: float, inv_vs: float, mu: float) -> tuple[float, float]:
    """``stick_slip._rk4`` for one member, same operation order."""
    a1 = (force - _branch_force(v, d, fc, delta, inv_vs, mu)) * inv_mass
    v2 = v + 0.5 * dt * a1
    a2 = (force - _branch_force(v2, d, fc, delta, inv_vs, mu)) * inv_mass
    v3 = v + 0.5 * dt * a2
    a3 = (force - _branch_force(v3, d, fc, delta, inv_vs, mu)) * inv_mass
    v4 = v + dt * a3
    a4 = (force - _branch_force(v4, d, fc, delta, inv_vs, mu)) * inv_mass
    x_new = x + dt * v + (dt * dt / 6.0) * (a1 + a2 + a3)
    v_new = v + (dt / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    return x_new, v_new


@njit
def _break_away(force: float, static_pos: float, static_neg: float) -> float:
    """+1, -1, or 0 (stay in stick) for a table at rest under ``force``."""
    if force > static_pos:
        return 1.0
    if force < -static_neg:
        return -1.0
    return 0.0


@njit
def _locate_crossing(x0: float, v0: float, dt: float, v1: float, force: float, inv_mass: float, d: float,
                     fc: float, delta: float, inv_vs: float, mu: float) -> tuple[float, float, bool]:
    """``stick_slip._locate_crossing`` for one member: (tau, x_c, converged)."""
    lo = 0.0
    f_lo = d * v0
    hi = dt
    f_hi = d * v1
    tau = hi
    done = f_hi == 0.0
    side = 0
    t_tol = CROSSING_TIME_RTOL * dt
    for _ in range(CROSSING_MAX_ITER):
        if done:
            break
        c = hi - f_hi * (hi - lo) / (f_hi - f_lo)
        c = min(max(c, lo), hi)
        vc = _rk4(x0, v0, c, force, inv_mass, d, fc, delta, inv_vs, mu)[1]
        fcv = d * vc
        tau = c
        new_done = (abs(fcv) <= CROSSING_VELOCITY_TOL) or ((hi - lo) <= t_tol)
        if not new_done:
            if fcv > 0.0:  # root in [c, hi]
                if side == 1:
                    f_hi = 0.5 * f_hi
                lo = c
                f_lo = fcv
                side = 1
            else:
                if side == -1:
                    f_lo = 0.5 * f_lo
                hi = c
                f_hi = fcv
                side = -1
        done = new_done
    x_c = _rk4(x0, v0, tau, force, inv_mass, d, fc, delta, inv_vs, mu)[0]
    return tau, x_c, done


# ------------------------------------------------------------------------------------------ kernel
@njit_inline
def commit_state(position: np.ndarray, velocity: np.ndarray, direction: np.ndarray, position_out: np.ndarray,
                 velocity_out: np.ndarray, new_direction: np.ndarray) -> None:
    """Copy the step's results into the drive state, in place, after every member is done (outputs may alias).

    Parameters
    ----------
    position, velocity : ndarray, shape (B,)
        State [m], [m/s], overwritten.
    direction : ndarray of int8, shape (B,)
        Stick/slip state, overwritten.
    position_out, velocity_out, new_direction : ndarray, shape (B,)
        The values at ``t + h``.
    """
    for b in range(position.shape[0]):
        position[b] = position_out[b]
        velocity[b] = velocity_out[b]
        direction[b] = new_direction[b]


@njit
def advance_kernel(
    current_cmd: np.ndarray, disturbance: np.ndarray, params: np.ndarray,
    position: np.ndarray, velocity: np.ndarray, direction: np.ndarray,
    h: float, max_step: np.ndarray,
    motor_force_out: np.ndarray, position_out: np.ndarray, velocity_out: np.ndarray, friction_out: np.ndarray,
    status_out: np.ndarray,
) -> int:
    """One drive step of every batch member (compiled).

    Parameters
    ----------
    current_cmd, disturbance : ndarray, shape (B,)
        ``Atc`` [A] and ``Fd`` [N], held over the step.
    params : ndarray, shape (12, B)
        :func:`pack_parameters`.
    position, velocity : ndarray of float64, shape (B,)
        State [m], [m/s]; updated in place, except for members that fail.
        A member whose position is NaN (failed earlier) is frozen: not
        integrated, outputs NaN.
    direction : ndarray of int8, shape (B,)
        Stick/slip state (0, +1, -1); updated likewise.
    h : float
        Step [s], > 0.
    max_step : ndarray, shape (B,)
        Largest internal substep of each member [s]; member ``b`` takes
        ``ceil(h / max_step[b])`` equal substeps, as the reference.
    motor_force_out, position_out, velocity_out, friction_out : ndarray, shape (B,)
        Written in place: ``u`` [N], ``x`` [m], ``v`` [m/s], ``Ff`` [N] at ``t + h``
        (a failed member: its unchanged state). May be the state arrays themselves.
    status_out : ndarray of int8, shape (B,)
        Written in place: :data:`OK`, :data:`BACKWARD_BREAK_AWAY` or
        :data:`CROSSING_NOT_CONVERGED` per member.

    Returns
    -------
    int
        :data:`OK` when every member succeeded, else the status of the first failed member.
    """
    n = position.shape[0]
    new_dir = np.empty(n, dtype=np.int8)
    first = OK
    for b in range(n):
        u = current_cmd[b] * params[0, b]
        motor_force_out[b] = u
        status_out[b] = OK
        x = position[b]
        v = velocity[b]
        d = float(direction[b])
        if math.isnan(x):  # frozen (failed) member
            position_out[b] = x
            velocity_out[b] = math.nan
            friction_out[b] = math.nan
            new_dir[b] = direction[b]
            continue
        force = u - disturbance[b]
        inv_mass = params[1, b]
        fs_pos = params[6, b]
        fs_neg = params[11, b]
        n_sub = max(1, int(math.ceil(h / max_step[b] * (1.0 - 1e-12))))
        dt = h / n_sub
        code = OK
        for _ in range(n_sub):
            if v == 0.0:
                d = _break_away(force, fs_pos, fs_neg)
            if d == 0.0:
                continue
            r = 2 if d > 0.0 else 7
            x1, v1 = _rk4(x, v, dt, force, inv_mass, d, params[r, b], params[r + 1, b], params[r + 2, b],
                          params[r + 3, b])
            if d * v1 <= 0.0:  # crossed (or reached) zero velocity within the substep
                if d * v <= 0.0:
                    code = BACKWARD_BREAK_AWAY
                    break
                tau, x_c, ok = _locate_crossing(x, v, dt, v1, force, inv_mass, d, params[r, b], params[r + 1, b],
                                                params[r + 2, b], params[r + 3, b])
                if not ok:
                    code = CROSSING_NOT_CONVERGED
                    break
                d_new = _break_away(force, fs_pos, fs_neg)
                rest = dt - tau
                x = x_c
                v = 0.0
                if d_new != 0.0 and rest > 0.0:
                    r2 = 2 if d_new > 0.0 else 7
                    x, v = _rk4(x_c, 0.0, rest, force, inv_mass, d_new, params[r2, b], params[r2 + 1, b],
                                params[r2 + 2, b], params[r2 + 3, b])
                d = d_new
            else:
                x = x1
                v = v1
        if code != OK:  # this member keeps its state; the others carry on
            status_out[b] = code
            if first == OK:
                first = code
            x = position[b]
            v = velocity[b]
            d = float(direction[b])
        if d == 0.0:
            ff = min(max(force, -fs_neg), fs_pos)
        else:
            r = 2 if d > 0.0 else 7
            ff = _branch_force(v, d, params[r, b], params[r + 1, b], params[r + 2, b], params[r + 3, b])
        position_out[b] = x
        velocity_out[b] = v
        friction_out[b] = ff
        new_dir[b] = np.int8(d)
    commit_state(position, velocity, direction, position_out, velocity_out, new_dir)
    return first


def raise_reference_error(state: SlipState, force: np.ndarray, mass: np.ndarray, friction: StribeckParameters,
                          h: float, max_step: np.ndarray | float, status: int, owner: str) -> None:
    """Raise the reference's :class:`ServoError`, prefixed with ``owner``, for a failed kernel step.

    Re-running the reference on a copy gives the detailed message (all
    failing members, the substep).
    """
    probe = SlipState(state.position.copy(), state.velocity.copy(), state.direction.copy())
    try:
        reference_advance(probe, force, mass, friction, h, max_step)
    except ServoError as err:
        raise ServoError(f"{owner}: {err}") from err
    what = "backward break-away" if status == BACKWARD_BREAK_AWAY else "crossing search did not converge"
    raise ServoError(f"{owner}: compiled stick/slip step failed ({what}, status {status}) but the numpy "
                     f"reference did not; expected both to agree")


def advance(
    state: SlipState, force: np.ndarray, mass: np.ndarray, friction: StribeckParameters,
    h: float, max_step: np.ndarray | float,
) -> np.ndarray:
    """Compiled twin of :func:`fmus_src.servo.stick_slip.advance` (same signature and semantics).

    ``state`` arrays are updated in place (float64 position / velocity,
    int8 direction, C-contiguous). Raises the reference's
    :class:`~fmus_src.servo.errors.ServoError` on failure (state unchanged).
    """
    force = np.ascontiguousarray(force, dtype=float)
    params = pack_parameters(friction, np.asarray(mass, dtype=float), np.ones_like(force))
    step = np.ascontiguousarray(np.broadcast_to(np.asarray(max_step, dtype=float), force.shape))
    before = SlipState(state.position.copy(), state.velocity.copy(), state.direction.copy())
    ff = np.empty_like(force)
    xo, vo, uo = np.empty_like(force), np.empty_like(force), np.empty_like(force)
    codes = np.zeros(force.shape, dtype=np.int8)
    status = advance_kernel(force, np.zeros_like(force), params, state.position, state.velocity, state.direction,
                            float(h), step, uo, xo, vo, ff, codes)
    if status != OK:
        state.position[...], state.velocity[...], state.direction[...] = \
            before.position, before.velocity, before.direction
        raise_reference_error(before, force, mass, friction, h, step, status, "stick_slip_numba.advance")
    return ff
