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

Excess following-error alarm (FANUC SV0411 / SV0410, parameters No. 1828 /
No. 1829), :func:`excess_error_alarm`: after each step the following error
``|r - x|`` (the held inputs) is compared with the *in-motion* limit, or with
the *at-stop* limit once the reference has not changed for
``settle_ticks`` position ticks (the time the position loop needs to take
up the lag of the last move, :func:`settle_ticks`). A limit of 0 is off.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def stack_fields(obj: object, fields: tuple[str, ...]) -> np.ndarray:
    """The array attributes ``fields`` of ``obj`` broadcast together and stacked, shape ``(len(fields), *shape)``.

    Returns
    -------
    ndarray of float64
        C-contiguous (the block layout the compiled kernels take).
    """
    arrays = [np.asarray(getattr(obj, f), dtype=float) for f in fields]
    shape = np.broadcast(*arrays).shape
    return np.ascontiguousarray(np.stack([np.broadcast_to(a, shape) for a in arrays]))


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

    def block(self) -> np.ndarray:
        """The six gains stacked in the order :data:`GAIN_FIELDS`, shape ``(6, *shape)``, C-contiguous."""
        return stack_fields(self, GAIN_FIELDS)


#: Rows of the state block of :class:`CascadeState` (and of the compiled MCU kernel).
STATE_FIELDS = ("integrator", "velocity_cmd", "current_ff", "ref_prev", "ref_prev2", "current_cmd", "still_ticks")

#: Rows of the excess-error limit block (:meth:`ExcessErrorLimits.block`).
LIMIT_FIELDS = ("in_motion", "at_stop", "settle_ticks")

#: The reference counts as stopped after this many position-loop time constants ``1 / (Pp Spp)`` without
#: change: an ideal P loop has then taken up all but e^-8 = 3.4e-4 of the lag of the move (12 mm of lag at
#: 36 m/min rapid with Pp = 50/s -> 4 um); the margin over ln(12 mm / 0.5 mm) = 3.2 covers the velocity
#: loop's own lag and friction at the end of the move.
SETTLE_TIME_CONSTANTS = 8.0

#: Alarm codes of :func:`excess_error_alarm`: 0 = none, else ``1 + 2 axis + at_stop``.
NO_ALARM = 0

#: Rows of the packed gain block taken by the compiled MCU kernel (:func:`CascadeGains.block`).
GAIN_FIELDS = ("position", "velocity_p", "velocity_i", "velocity_ff", "accel_ff_current", "peak_current")


def _state_field(index: int, doc: str) -> property:
    def get(self: "CascadeState") -> np.ndarray:
        return self.block[index]

    def put(self: "CascadeState", value: np.ndarray) -> None:
        self.block[index][...] = value  # in place: the block is shared with the compiled kernel

    return property(get, put, doc=doc)


@dataclass
class ExcessErrorLimits:
    """Excess following-error limits of each axis, arrays of shape (3, B).

    Attributes
    ----------
    in_motion : ndarray
        Limit while the reference moves (FANUC No. 1828) [m]; 0 = off.
    at_stop : ndarray
        Limit once the reference has stopped (FANUC No. 1829) [m]; 0 = off.
    settle_ticks : ndarray
        Position ticks without a reference change after which the axis is "at
        stop" (:func:`settle_ticks`); a float holding an integer, or ``inf``.
    """

    in_motion: np.ndarray
    at_stop: np.ndarray
    settle_ticks: np.ndarray

    def block(self) -> np.ndarray:
        """The three rows stacked in the order :data:`LIMIT_FIELDS`, shape ``(3, *shape)``, C-contiguous."""
        return stack_fields(self, LIMIT_FIELDS)


def settle_ticks(position_gain: np.ndarray, period: float) -> np.ndarray:
    """Position ticks after which a stopped reference counts as "at stop": ``ceil(8 / (Pp Spp Tp))``.

    Parameters
    ----------
    position_gain : ndarray
        Effective position gain ``Pp Spp`` [1/s]; ``<= 0`` or NaN gives ``inf`` (never at stop).
    period : float
        Position-loop period ``Tp`` [s].
    """
    kp = np.asarray(position_gain, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        ticks = np.ceil(SETTLE_TIME_CONSTANTS / (kp * period))
    return np.where(np.isfinite(ticks) & (kp > 0.0), ticks, np.inf)


def excess_error_alarm(state: "CascadeState", limits: ExcessErrorLimits, ref: np.ndarray,
                       position: np.ndarray) -> np.ndarray:
    """Alarm code of each member (the first axis in x, y, z order that exceeds its limit), shape (B,).

    Parameters
    ----------
    state : CascadeState
        After the step (``still_ticks``).
    limits : ExcessErrorLimits
        Shape (3, B).
    ref, position : ndarray, shape (3, B)
        Reference and actual position held over the step [m].

    Returns
    -------
    ndarray of int8, shape (B,)
        :data:`NO_ALARM`, or ``1 + 2 axis + at_stop`` (SV0411 in motion: even offset, SV0410 at stop: odd).
    """
    err = np.abs(ref - position)
    stopped = state.still_ticks >= limits.settle_ticks
    limit = np.where(stopped, limits.at_stop, limits.in_motion)
    over = (limit > 0.0) & (err > limit)
    codes = np.zeros(ref.shape[1:], dtype=np.int8)
    for i in range(ref.shape[0] - 1, -1, -1):  # x wins: written last
        codes = np.where(over[i], 1 + 2 * i + stopped[i].astype(np.int8), codes).astype(np.int8)
    return codes


class CascadeState:
    """Internal state of the cascade, one float block of shape ``(7, *shape)``.

    The seven quantities are views of rows of :attr:`block` (order
    :data:`STATE_FIELDS`); assigning to one copies **into** the block, so the
    numpy reference (:func:`position_loop`, :func:`velocity_loop`) and the
    compiled MCU kernel (which updates :attr:`block` in place) share one state.

    Parameters
    ----------
    block : ndarray, shape (6, ...)
        Float64, C-contiguous; used (not copied).

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
    still_ticks : ndarray
        Position ticks since the reference last changed (an integer count, as float).
    """

    __slots__ = ("block",)

    integrator = _state_field(0, "Velocity-loop integral term I [A].")
    velocity_cmd = _state_field(1, "Held velocity command [m/s].")
    current_ff = _state_field(2, "Held acceleration feed-forward current [A].")
    ref_prev = _state_field(3, "Reference sample of the previous position tick [m].")
    ref_prev2 = _state_field(4, "Reference sample of the position tick before that [m].")
    current_cmd = _state_field(5, "Last current command [A].")
    still_ticks = _state_field(6, "Position ticks since the reference last changed (integer count).")

    def __init__(self, block: np.ndarray) -> None:
        if block.shape[:1] != (len(STATE_FIELDS),) or block.dtype != np.float64 or not block.flags.c_contiguous:
            raise ValueError(f"CascadeState block must be C-contiguous float64 of shape (7, ...), got "
                             f"{block.dtype} {block.shape}")
        self.block = block

    @classmethod
    def initial(cls, ref0: np.ndarray) -> "CascadeState":
        """State at rest with the reference history filled with ``ref0`` (zero feed-forward)."""
        ref0 = np.asarray(ref0, dtype=float)
        block = np.zeros((len(STATE_FIELDS),) + ref0.shape)
        block[3] = ref0
        block[4] = ref0
        return cls(block)


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
    state.still_ticks = np.where(ref == state.ref_prev, state.still_ticks + 1.0, 0.0)
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
