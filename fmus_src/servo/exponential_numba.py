"""Compiled drive step with an exponential integrator: one substep per velocity-loop tick.

Sliding dynamics of a feed-drive table on the Stribeck branch of direction
``d`` (Sim & Lee 2023, Eq. 1 and 3), net force ``F = u - Fd`` held over the
step::

    Ms v' = F - mu_v v - d (Fc + (Fs - Fc) exp(-d v / vs)),      x' = v

:func:`exponential_kernel` replaces the four-stage Runge-Kutta substeps of
:func:`fmus_src.servo.stick_slip_numba.advance_kernel` (two substeps of
125 us per 250 us tick, four ``exp`` each) by **one exponential
Rosenbrock-Euler substep** of up to :data:`EXPONENTIAL_MAX_STEP` per member:

1. Linearise the acceleration ``f(v)`` at the start velocity ``v0``:
   ``f(v) ~ f0 + J (v - v0)`` with ``J = ((Fs - Fc) e^{-d v0/vs} / vs - mu_v) / Ms``
   (the viscous term and the local Stribeck slope, integrated **exactly**)::

       v1 = v0 + dt phi1(J dt) f0,     x1 = x0 + dt v0 + dt^2 phi2(J dt) f0

   with ``phi1(z) = (e^z - 1) / z``, ``phi2(z) = (e^z - 1 - z) / z^2``.
2. The nonlinear remainder of the Stribeck exponential at the end,
   ``r = f(v1) - f0 - J (v1 - v0)``, grows like ``t^2`` over the substep; its
   effect is ``r dt / 3`` on the velocity and ``r dt^2 / 12`` on the position,
   which are added (third-order correction).
3. **Accuracy guard**: when that velocity correction exceeds
   :data:`EXPONENTIAL_VELOCITY_TOL`, or the velocity would reach zero within
   the substep (a stop or reversal), or the member is at rest, the substep is
   handed to the reference kernel instead: RK4 at the member's own internal
   step with the exact zero-velocity crossing (Illinois on the RK4 solution)
   and the stick / break-away logic. Stick-slip transitions are therefore
   exactly those of the reference; the exponential substep only runs where
   the table slides smoothly, where it needs two ``exp`` per tick instead of
   eight.

The state, parameters, inputs and outputs are those of ``advance_kernel``
(same packed parameter block, same in-place contract: the state is updated
only when the whole step succeeds), so :class:`~fmus_src.servo.drive.DriveAxis`
selects either with its ``integrator`` parameter (:func:`select_kernel`).
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit, njit_inline
from ..jit_cache import guard_cache
from . import stick_slip, stick_slip_numba
from .errors import ServoError
from .stick_slip import OK
from .stick_slip_numba import _branch_force, _break_away, advance_kernel, commit_state

#: Longest exponential substep [s]: one velocity-loop tick of the default servo (250 us).
EXPONENTIAL_MAX_STEP = 250e-6
#: Largest velocity correction ``|r| dt / 3`` [m/s] accepted from an exponential substep; above it the
#: substep is integrated by the reference RK4 kernel. 1e-7 m/s over 250 us is 2.5e-11 m of position.
EXPONENTIAL_VELOCITY_TOL = 1e-7
#: ``|J dt|`` below which ``phi1``, ``phi2`` are evaluated from their Taylor series (12 terms, error < 1e-17).
PHI_SERIES_LIMIT = 0.2

#: Integrators selectable with ``DriveAxis.integrator``.
INTEGRATORS = ("rk4", "exponential")

#: ``1 / k!`` for ``k = 13, 12, ..., 1`` (the Taylor coefficients of ``phi1``, ``phi2``, highest order first).
INV_FACTORIALS = tuple(1.0 / math.factorial(k) for k in range(13, 0, -1))


@njit_inline
def _horner(z: float, first: int, stop: int) -> float:
    """Horner sum of ``INV_FACTORIALS[first:stop]`` (highest order first) at ``z``."""
    p = INV_FACTORIALS[first]
    for k in range(first + 1, stop):
        p = p * z + INV_FACTORIALS[k]
    return p


@njit
def phi12(z: float) -> tuple[float, float]:
    """``phi1(z) = (e^z - 1) / z`` and ``phi2(z) = (e^z - 1 - z) / z^2`` (1 and 1/2 at ``z = 0``).

    Taylor series to ``z^11`` (Horner; coefficients ``1/(k+1)!`` and ``1/(k+2)!``) for
    ``|z| <= PHI_SERIES_LIMIT``, else from ``expm1``.
    """
    if abs(z) <= PHI_SERIES_LIMIT:
        return _horner(z, 1, 13), _horner(z, 0, 12)
    e = math.expm1(z)
    return e / z, (e - z) / (z * z)


@njit
def _reference_substep(
    force: float, x: float, v: float, d: float, dt: float, max_step: float, inv_mass: float,
    fc_p: float, delta_p: float, inv_vs_p: float, mu_p: float, fs_p: float,
    fc_n: float, delta_n: float, inv_vs_n: float, mu_n: float, fs_n: float,
) -> tuple[int, float, float, float]:
    """One substep by the reference kernel, on one-member copies (force fed as ``u`` with ``kt 2 pi / Lb = 1``).

    Returns
    -------
    status, x, v, d
    """
    params = np.empty((12, 1))
    params[0, 0] = 1.0
    params[1, 0] = inv_mass
    params[2, 0] = fc_p
    params[3, 0] = delta_p
    params[4, 0] = inv_vs_p
    params[5, 0] = mu_p
    params[6, 0] = fs_p
    params[7, 0] = fc_n
    params[8, 0] = delta_n
    params[9, 0] = inv_vs_n
    params[10, 0] = mu_n
    params[11, 0] = fs_n
    pos = np.full(1, x)
    vel = np.full(1, v)
    dirn = np.full(1, np.int8(d))
    out = np.empty((4, 1))
    status = np.zeros(1, dtype=np.int8)
    advance_kernel(np.full(1, force), np.zeros(1), params, pos, vel, dirn, dt, np.full(1, max_step),
                   out[0], out[1], out[2], out[3], status)
    return int(status[0]), pos[0], vel[0], float(dirn[0])


@njit
def exponential_member(
    current: float, disturbance: float, force_constant: float, inv_mass: float,
    fc_p: float, delta_p: float, inv_vs_p: float, mu_p: float, fs_p: float,
    fc_n: float, delta_n: float, inv_vs_n: float, mu_n: float, fs_n: float,
    x0: float, v0: float, d0: float, h: float, max_step: float,
) -> tuple[float, float, float, float, float, int]:
    """One drive step of one member (scalars in and out; see the module docstring).

    Parameters
    ----------
    current, disturbance : float
        ``Atc`` [A] and ``Fd`` [N], held over the step.
    force_constant, inv_mass, fc_p ... fs_n : float
        One column of the packed parameter block (:data:`~fmus_src.servo.stick_slip_numba.PARAMETER_ROWS`).
    x0, v0, d0 : float
        State [m], [m/s], direction (0, +1, -1); a NaN position is a frozen (failed) member.
    h : float
        Step [s], cut into ``ceil(h / EXPONENTIAL_MAX_STEP)`` equal substeps.
    max_step : float
        The member's internal RK4 step on guarded substeps [s].

    Returns
    -------
    u, x, v, d, ff : float
        Motor force [N] and state, friction force [N] at ``t + h`` (the start state when the step failed;
        ``v``, ``ff`` NaN for a frozen member).
    status : int
        The reference kernel's status (``OK`` = 0).
    """
    u = current * force_constant
    if math.isnan(x0):  # frozen (failed) member, as the reference kernel
        return u, x0, math.nan, d0, math.nan, OK
    force = u - disturbance
    n_sub = max(1, int(math.ceil(h / EXPONENTIAL_MAX_STEP * (1.0 - 1e-12))))
    dt = h / n_sub
    x = x0
    v = v0
    d = d0
    code = OK
    for _ in range(n_sub):
        if v == 0.0:  # at rest: stay in stick (as the reference) unless the force breaks it away
            d = _break_away(force, fs_p, fs_n)
            if d == 0.0:
                continue
        guarded = d * v <= 0.0  # break-away from rest: the reference integrates it
        if not guarded:
            if d > 0.0:
                fc, delta, inv_vs, mu = fc_p, delta_p, inv_vs_p, mu_p
            else:
                fc, delta, inv_vs, mu = fc_n, delta_n, inv_vs_n, mu_n
            e0 = delta * math.exp(-(d * v) * inv_vs)
            f0 = (force - (mu * v + d * (fc + e0))) * inv_mass
            jac = (e0 * inv_vs - mu) * inv_mass
            p1, p2 = phi12(jac * dt)
            v1 = v + dt * p1 * f0
            x1 = x + dt * v + dt * dt * p2 * f0
            if d * v1 > 0.0:
                e1 = delta * math.exp(-(d * v1) * inv_vs)
                rem = (force - (mu * v1 + d * (fc + e1))) * inv_mass - f0 - jac * (v1 - v)
                dv = rem * dt / 3.0
                if abs(dv) <= EXPONENTIAL_VELOCITY_TOL and d * (v1 + dv) > 0.0:
                    x = x1 + rem * dt * dt / 12.0
                    v = v1 + dv
                else:
                    guarded = True
            else:
                guarded = True
        if guarded:
            code, x, v, d = _reference_substep(force, x, v, d, dt, max_step, inv_mass, fc_p, delta_p, inv_vs_p,
                                               mu_p, fs_p, fc_n, delta_n, inv_vs_n, mu_n, fs_n)
            if code != OK:
                break
    if code != OK:  # this member keeps its state
        x = x0
        v = v0
        d = d0
    if d == 0.0:
        ff = min(max(force, -fs_n), fs_p)
    elif d > 0.0:
        ff = _branch_force(v, d, fc_p, delta_p, inv_vs_p, mu_p)
    else:
        ff = _branch_force(v, d, fc_n, delta_n, inv_vs_n, mu_n)
    return u, x, v, d, ff, code


@njit
def exponential_kernel(
    current_cmd: np.ndarray, disturbance: np.ndarray, params: np.ndarray,
    position: np.ndarray, velocity: np.ndarray, direction: np.ndarray,
    h: float, max_step: np.ndarray,
    motor_force_out: np.ndarray, position_out: np.ndarray, velocity_out: np.ndarray, friction_out: np.ndarray,
    status_out: np.ndarray,
) -> int:
    """One drive step of every batch member by :func:`exponential_member` (compiled).

    Same contract, parameters and return value as :func:`fmus_src.servo.stick_slip_numba.advance_kernel`
    (``max_step``: the internal RK4 step on guarded substeps; ``status_out``: the reference kernel's status).
    """
    n = position.shape[0]
    new_dir = np.empty(n, dtype=np.int8)
    first = OK
    for b in range(n):
        u, x, v, d, ff, code = exponential_member(
            current_cmd[b], disturbance[b], params[0, b], params[1, b], params[2, b], params[3, b], params[4, b],
            params[5, b], params[6, b], params[7, b], params[8, b], params[9, b], params[10, b], params[11, b],
            position[b], velocity[b], float(direction[b]), h, max_step[b])
        motor_force_out[b] = u
        position_out[b] = x
        velocity_out[b] = v
        friction_out[b] = ff
        new_dir[b] = np.int8(d)
        status_out[b] = code
        if code != OK and first == OK:
            first = code
    commit_state(position, velocity, direction, position_out, velocity_out, new_dir)
    return first


# the compiled code links the reference kernel's code: recompile when stick_slip_numba changes
for _fn in (_reference_substep, exponential_member, exponential_kernel):
    guard_cache(_fn, stick_slip, stick_slip_numba)


def select_kernel(name: str, owner: str):
    """The compiled drive kernel of integrator ``name`` (``"rk4"`` or ``"exponential"``).

    Raises
    ------
    ServoError
        Unknown name (the message names ``owner`` and the choices).
    """
    if name == "rk4":
        return advance_kernel
    if name == "exponential":
        return exponential_kernel
    raise ServoError(f"{owner}.integrator: {name!r}; expected one of {list(INTEGRATORS)}")
