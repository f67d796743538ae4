"""Compiled (numba) scalar transcriptions of the effect terms of :mod:`fmus_src.servo.effects`.

One member at a time, every floating-point operation in the numpy
reference's order (no fastmath), so the results equal the reference's up to
the rounding of ``sin`` and ``exp`` (numpy's vector routines against the C
library's; tested to 1e-12 relative). Used by the compiled servo replay
(:mod:`fmus_src.servo.replay_numba`).
"""
from __future__ import annotations

import math

from ..jit import njit_inline

TWO_PI = 2.0 * math.pi


@njit_inline
def axis_load(position: float, gravity_force: float, gravity_spring: float, ripple_amplitude: float,
              ripple_period: float) -> float:
    """``Fg + k_g x_m - A_r sin(2 pi x_m / P_r)`` [N] (:func:`fmus_src.servo.effects.axis_load`, one member)."""
    load = gravity_force + gravity_spring * position
    if ripple_period > 0.0 and ripple_amplitude != 0.0:
        load = load - ripple_amplitude * math.sin(TWO_PI * position / ripple_period)
    return load


@njit_inline
def reversal_friction(travel: float, peak: float, decay: float) -> float:
    """``F_r exp(-s / d)`` [N], 0 when off (:func:`fmus_src.servo.effects.reversal_friction`, one member)."""
    if decay > 0.0 and peak != 0.0:
        return peak * math.exp(-travel / decay)
    return 0.0


@njit_inline
def travel_after_step(travel: float, last_direction: float, old_position: float, new_position: float,
                      velocity: float) -> tuple[float, float]:
    """Travel since reversal [m] and last motion direction after a step (:func:`~fmus_src.servo.effects.update_travel`)."""
    if velocity > 0.0:
        sign = 1.0
    elif velocity < 0.0:
        sign = -1.0
    elif velocity == 0.0:
        sign = 0.0
    else:  # NaN, as np.sign
        sign = velocity
    moved = abs(new_position - old_position)
    if sign != 0.0 and sign != last_direction:
        travel = 0.0
    else:
        travel = travel + moved
    if sign != 0.0:
        last_direction = sign
    return travel, last_direction


@njit_inline
def table_position(table: float, motor_position: float, motor_force: float, elapsed: float, slope: float,
                   amplitude: float, period: float, stiffness: float, backlash: float,
                   drift_rate: float) -> tuple[float, float]:
    """New play state and table position ``x_t`` [m] (:func:`fmus_src.servo.effects.table_position`, one member).

    Returns
    -------
    table, position : float
        The play operator's output (the state) and ``table + drift_rate * elapsed``.
    """
    err = slope * motor_position
    if period > 0.0 and amplitude != 0.0:
        err = err + amplitude * math.sin(TWO_PI * motor_position / period)
    nut = motor_position + err
    if stiffness <= 0.0:
        nut = nut - 0.0
    else:
        nut = nut - motor_force / stiffness
    half = 0.5 * backlash
    table = min(max(table, nut - half), nut + half)
    return table, table + drift_rate * elapsed
