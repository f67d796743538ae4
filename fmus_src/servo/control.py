"""Cascade servo control law of the MCU (Sim & Lee 2023, Section 2.3, Fig. 4).

Per axis: a proportional position loop (gain ``Pp Spp``) every position-loop
period ``Tp`` and a proportional-integral velocity loop (``Vp Svp``,
``Vi Svi``) every velocity-loop period ``Tv``, producing the current (torque)
command ``Atc`` in amperes, saturated at the amplifier peak current.

Everything here is pure numpy on arrays of any common shape (the MCU uses
``(3, B)``: axes x batch).

Discrete-time law (``k`` = velocity tick index, ``N = Tp / Tv``)::

    on position ticks (k mod N == 0), with the reference sampled at that tick:
        v_ref   = (r_k - r_{k-N}) / Tp                      backward difference
        a_ref   = (r_k - 2 r_{k-N} + r_{k-2N}) / Tp^2       second backward difference
        v_cmd   = Pp Spp (r_k - x_k) + Kvff v_ref           held until the next position tick
        i_ff    = Kaff a_ref Ms Lb / (2 pi kt)             held likewise
    on every tick:
        e_k     = v_cmd - v_k
        I_k     = I_{k-1} + Vi Svi Tv e_k                   (backward-Euler integrator, A)
        i_k     = sat(Vp Svp e_k + I_k + i_ff, +-Ipeak)

Anti-windup: **integrator clamping (conditional integration)**. When the
unsaturated command exceeds the peak current *and* the velocity error has
the same sign as that command (integrating would push further into
saturation), the integrator may only grow up to the value that puts the
command exactly at the limit, ``s I <= Ipeak - s (Vp Svp e + i_ff)`` with
``s`` the sign of the command, and is never pulled back by this clamp; in
addition ``|I| <= Ipeak``. The integrator therefore stops winding up the
tick saturation is reached, and the loop leaves saturation as soon as the
velocity error changes sign.

The feed-forward derivatives lag by half a position period (backward
differences); with both gains 0 (the default, as the paper's controller) the
law is the pure P / PI cascade of the paper.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class CascadeGains:
    """Effective gains of the cascade, arrays broadcastable to the state shape.

    Attributes
    ----------
    position : ndarray
        ``Pp Spp`` [1/s].
    velocity_p : ndarray
        ``Vp Svp`` [A/(m/s)].
    velocity_i : ndarray
        ``Vi Svi`` [A/m].
    velocity_ff : ndarray
        Velocity feed-forward gain [1].
    accel_ff_current : ndarray
        Acceleration feed-forward gain times ``Ms Lb / (2 pi kt)`` [A/(m/s2)].
    peak_current : ndarray
        Saturation limit ``Ipeak`` [A], > 0.
    """

    position: np.ndarray
    velocity_p: np.ndarray
    velocity_i: np.ndarray
    velocity_ff: np.ndarray
    accel_ff_current: np.ndarray
    peak_current: np.ndarray


@dataclass
class CascadeState:
    """Internal state of the cascade, arrays of one common shape.

    Attributes
    ----------
    integrator : ndarray
        Velocity-loop integral term ``I`` [A].
    velocity_cmd : ndarray
        Held velocity command [m/s].
    current_ff : ndarray
        Held acceleration feed-forward current [A].
    ref_prev, ref_prev2 : ndarray
        Reference samples of the two previous position ticks [m].
    current_cmd : ndarray
        Last current command [A].
    """

    integrator: np.ndarray
    velocity_cmd: np.ndarray
    current_ff: np.ndarray
    ref_prev: np.ndarray
    ref_prev2: np.ndarray
    current_cmd: np.ndarray

    @classmethod
    def initial(cls, ref0: np.ndarray) -> "CascadeState":
        """State at rest with the reference history filled with ``ref0`` (zero feed-forward)."""
        zero = np.zeros_like(ref0, dtype=float)
        return cls(zero.copy(), zero.copy(), zero.copy(), ref0.astype(float).copy(),
                   ref0.astype(float).copy(), zero.copy())


def position_loop(
    state: CascadeState, gains: CascadeGains, ref: np.ndarray, position: np.ndarray, period: float
) -> None:
    """Position-loop tick: update ``velocity_cmd``, ``current_ff`` and the reference history in place.

    Parameters
    ----------
    state : CascadeState
    gains : CascadeGains
    ref, position : ndarray
        Reference and actual position [m] sampled at this tick.
    period : float
        Position-loop period ``Tp`` [s].
    """
    v_ref = (ref - state.ref_prev) / period
    a_ref = (ref - 2.0 * state.ref_prev + state.ref_prev2) / (period * period)
    state.ref_prev2 = state.ref_prev
    state.ref_prev = ref.astype(float).copy()
    state.velocity_cmd = gains.position * (ref - position) + gains.velocity_ff * v_ref
    state.current_ff = gains.accel_ff_current * a_ref


def velocity_loop(state: CascadeState, gains: CascadeGains, velocity: np.ndarray, period: float) -> np.ndarray:
    """Velocity-loop tick: PI with conditional-integration anti-windup and saturation.

    Parameters
    ----------
    state : CascadeState
        Updated in place (``integrator``, ``current_cmd``).
    gains : CascadeGains
    velocity : ndarray
        Actual velocity [m/s] sampled at this tick.
    period : float
        Velocity-loop period ``Tv`` [s].

    Returns
    -------
    ndarray
        Current command [A], ``|i| <= peak_current``.
    """
    err = state.velocity_cmd - velocity
    i_max = gains.peak_current
    p_term = gains.velocity_p * err + state.current_ff
    candidate = np.clip(state.integrator + gains.velocity_i * period * err, -i_max, i_max)
    unsat = p_term + candidate
    sgn = np.sign(unsat)
    winding = (np.abs(unsat) > i_max) & (sgn == np.sign(err))
    # integrator may grow (in the saturating direction) only up to the value that puts the
    # command exactly at the limit, and is never pulled back by the clamp
    headroom = i_max - sgn * p_term
    clamped = sgn * np.maximum(sgn * state.integrator, np.minimum(sgn * candidate, headroom))
    state.integrator = np.where(winding, clamped, candidate)
    cmd = np.clip(p_term + state.integrator, -i_max, i_max)
    state.current_cmd = cmd
    return cmd
