"""Switchable effect terms of the feed drive and of the controller (diagnosis, issue 8).

Every term defaults to 0 = off, which is exactly the paper's baseline model
(Sim & Lee 2023, Section 2.2-2.3). Pure numpy functions on arrays of shape
``(B,)``; :class:`~fmus_src.servo.drive.DriveAxis` and
:class:`~fmus_src.servo.mcu.MCU` are thin adapters around them.

Mechanical picture (semi-closed loop, as a FANUC machine without linear
scales): the servo loop is closed on the **motor** encoder, ``x_m`` (motor
angle x lead / 2 pi, the drive's ``position`` output). The **table** (the
drive's ``table_position`` output, what an external measurement or a
recording's ``x_mm`` sees) differs from it by the effects between motor and
table::

    x_t = play_b( x_m + p(x_m) - u / k ) + r (t - t0)

with ``p(x) = s x + A sin(2 pi x / P)`` the screw lead (pitch) error,
``u / k`` the elastic deflection of screw, nut and bearings under the motor
force ``u``, ``play_b`` the backlash play operator of width ``b`` (the table
does not move while the nut crosses the gap) and ``r`` a thermal drift rate.
These terms are quasi-static (no extra degree of freedom): the table has no
dynamics of its own relative to the motor, an assumption valid below the
first axial mode (typically > 100 Hz for a ball-screw axis).

Force terms act on the equation of motion of the lumped axis::

    Ms x_m'' = u + A_r sin(2 pi x_m / P_r) - Ff(x_m') - Fd - (Fg + k_g x_m)

with the torque ripple (cogging) ``A_r`` of period ``P_r`` in motor travel,
and the unbalanced weight ``Fg`` of a vertical axis plus a counterbalance
spring ``k_g`` (``Fg > 0`` pulls towards negative positions, i.e. down on Z).
They are evaluated at the start of every drive step and held over it, like
the cutting disturbance (at 250 µs the position changes by < 0.13 mm even at
30 m/min, against ripple periods of millimetres).

Reversal friction (presliding / quadrant glitch beyond the Stribeck curve):
the Coulomb and static forces of both branches are raised by
``F_r exp(-s / d)``, ``s`` the travel since the last change of the motion
direction (the first motion counts as a reversal).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * math.pi


def axis_load(position: np.ndarray, gravity_force: np.ndarray, gravity_spring: np.ndarray,
              ripple_amplitude: np.ndarray, ripple_period: np.ndarray) -> np.ndarray:
    """Extra force resisting positive motion (added to ``Fd``) [N], shape (B,).

    Parameters
    ----------
    position : ndarray, shape (B,)
        Motor-side position ``x_m`` [m].
    gravity_force : ndarray, shape (B,)
        Unbalanced weight ``Fg`` [N], > 0 pulls towards negative positions.
    gravity_spring : ndarray, shape (B,)
        Counterbalance spring rate ``k_g`` [N/m]; the load is ``Fg + k_g x_m``.
    ripple_amplitude : ndarray, shape (B,)
        Torque-ripple amplitude ``A_r`` as a force [N] (adds to the motor force).
    ripple_period : ndarray, shape (B,)
        Ripple period in motor travel ``P_r`` [m]; <= 0 switches the ripple off.

    Returns
    -------
    ndarray, shape (B,)
        ``Fg + k_g x_m - A_r sin(2 pi x_m / P_r)``.
    """
    load = gravity_force + gravity_spring * position
    on = ripple_period > 0.0
    if np.any(on & (ripple_amplitude != 0.0)):
        safe = np.where(on, ripple_period, 1.0)
        load = load - np.where(on, ripple_amplitude * np.sin(TWO_PI * position / safe), 0.0)
    return load


def reversal_friction(travel: np.ndarray, peak: np.ndarray, decay: np.ndarray) -> np.ndarray:
    """Extra Coulomb/static friction after a reversal, ``F_r exp(-s / d)`` [N], shape (B,).

    Parameters
    ----------
    travel : ndarray, shape (B,)
        Travel since the last reversal ``s`` [m], >= 0.
    peak : ndarray, shape (B,)
        ``F_r`` [N].
    decay : ndarray, shape (B,)
        Decay distance ``d`` [m]; <= 0 switches the term off.
    """
    on = (decay > 0.0) & (peak != 0.0)
    safe = np.where(on, decay, 1.0)
    return np.where(on, peak * np.exp(-travel / safe), 0.0)


def pitch_error(position: np.ndarray, slope: np.ndarray, amplitude: np.ndarray, period: np.ndarray) -> np.ndarray:
    """Lead error ``p(x) = s x + A sin(2 pi x / P)`` [m] at motor-side position ``x`` [m], shape (B,).

    ``slope`` is dimensionless (µm/m x 1e-6); ``period`` <= 0 switches the periodic part off.
    """
    err = slope * position
    on = period > 0.0
    if np.any(on & (amplitude != 0.0)):
        safe = np.where(on, period, 1.0)
        err = err + np.where(on, amplitude * np.sin(TWO_PI * position / safe), 0.0)
    return err


def play(previous: np.ndarray, drive: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Backlash play operator: the output stays while ``|drive - output| <= width / 2``.

    Parameters
    ----------
    previous : ndarray, shape (B,)
        Output of the previous step (table side) [m].
    drive : ndarray, shape (B,)
        Input (nut side) [m].
    width : ndarray, shape (B,)
        Backlash ``b`` [m], >= 0 (0: output = input).
    """
    half = 0.5 * width
    return np.clip(previous, drive - half, drive + half)


@dataclass
class TableState:
    """State of the motor-to-table effects of ``B`` axes.

    Attributes
    ----------
    table : ndarray, shape (B,)
        Play-operator output (table position before the thermal drift) [m].
    travel : ndarray, shape (B,)
        Travel since the last reversal [m].
    last_direction : ndarray, shape (B,)
        Sign of the last non-zero velocity (0 before the first motion).
    """

    table: np.ndarray
    travel: np.ndarray
    last_direction: np.ndarray


def update_travel(state: TableState, old_position: np.ndarray, new_position: np.ndarray,
                  velocity: np.ndarray) -> None:
    """Advance the travel-since-reversal counter in place over one step.

    A change of the sign of the (non-zero) velocity restarts the travel at
    the distance covered in the new direction within the step (approximated
    by ``|dx|``, the step is far shorter than any decay distance).
    """
    sign = np.sign(velocity)
    moved = np.abs(new_position - old_position)
    reversed_ = (sign != 0.0) & (sign != state.last_direction)
    state.travel[...] = np.where(reversed_, 0.0, state.travel + moved)
    state.last_direction[...] = np.where(sign != 0.0, sign, state.last_direction)


def table_position(state: TableState, motor_position: np.ndarray, motor_force: np.ndarray,
                   elapsed: float, slope: np.ndarray, amplitude: np.ndarray, period: np.ndarray,
                   stiffness: np.ndarray, backlash: np.ndarray, drift_rate: np.ndarray) -> np.ndarray:
    """Table position ``x_t`` [m] (updates the play state in place), shape (B,).

    Parameters
    ----------
    state : TableState
    motor_position : ndarray
        ``x_m`` [m].
    motor_force : ndarray
        ``u`` [N] transmitted by the screw.
    elapsed : float
        ``t - t0`` [s].
    slope, amplitude, period : ndarray
        Pitch error (:func:`pitch_error`).
    stiffness : ndarray
        Axial stiffness ``k`` [N/m]; <= 0 means rigid.
    backlash : ndarray
        ``b`` [m].
    drift_rate : ndarray
        ``r`` [m/s].
    """
    nut = motor_position + pitch_error(motor_position, slope, amplitude, period)
    rigid = stiffness <= 0.0
    nut = nut - np.where(rigid, 0.0, motor_force / np.where(rigid, 1.0, stiffness))
    state.table[...] = play(state.table, nut, backlash)
    return state.table + drift_rate * elapsed


class DelayLine:
    """Pure time delay of a signal sampled at irregular instants, linear interpolation, per member.

    Parameters
    ----------
    shape : tuple of int
        Shape of one sample (e.g. ``(3, B)``).
    capacity : int
        Number of samples kept (>= 2); must cover the longest delay.
    initial : ndarray
        Value before the first pushed sample.
    """

    def __init__(self, shape: tuple[int, ...], capacity: int, initial: np.ndarray) -> None:
        self.capacity = max(2, int(capacity))
        self.times = np.full(self.capacity, -np.inf)
        self.samples = np.empty((self.capacity,) + tuple(shape))
        self.samples[...] = initial
        self.count = 0
        self.initial = np.array(initial, dtype=float, copy=True)

    def push(self, t: float, value: np.ndarray) -> None:
        """Append the sample ``value`` taken at time ``t`` (increasing)."""
        i = self.count % self.capacity
        self.times[i] = t
        self.samples[i] = value
        self.count += 1

    def read(self, t: float, delay: np.ndarray) -> np.ndarray:
        """Value at ``t - delay`` (``delay`` broadcast to the sample shape), linear between samples.

        Before the oldest kept sample the initial value is returned.
        """
        n = min(self.count, self.capacity)
        order = (np.arange(self.count - n, self.count) % self.capacity)
        times = self.times[order]
        samples = self.samples[order]
        query = t - np.broadcast_to(delay, samples.shape[1:])
        j = np.searchsorted(times, query.ravel(), side="right").reshape(query.shape)
        flat = samples.reshape(n, -1)
        cols = np.arange(flat.shape[1]).reshape(query.shape)
        lo = np.clip(j - 1, 0, n - 1)
        hi = np.clip(j, 0, n - 1)
        t_lo, t_hi = times[lo], times[hi]
        span = np.where(t_hi > t_lo, t_hi - t_lo, 1.0)
        w = np.where(t_hi > t_lo, np.clip((query - t_lo) / span, 0.0, 1.0), 0.0)
        value = flat[lo, cols] * (1.0 - w) + flat[hi, cols] * w
        before = j == 0
        return np.where(before, self.initial, value)
