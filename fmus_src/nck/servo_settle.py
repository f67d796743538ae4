"""In-position check on the servo's following error, before a rapid that follows cutting feed.

A FANUC control (and Haas, Mazak, Siemens in their defaults) starts a positioning (G00) block only after the
previous block is in position: every axis's position deviation (the servo's error counter) within the
in-position width (No. 1826). After cutting feed the axes lag their command by the following error (v/Kv at
speed), so without the check a drilling cycle's rapid retract would start while Z is still short of the hole
bottom.

The NC kernel plans offline, so it predicts that deviation with the position loop it commands: a P loop of gain
Kv (1/s) per axis, ``y' = Kv (r - y)``, with the reference ``r`` held over each interpolation period Ts (the loop
samples the command of the current period)::

    y[0] = r[0],    y[k + 1] = a y[k] + (1 - a) r[k],    a = exp(-Kv Ts).

Once the reference is at rest on its end point ``p`` the deviation decays geometrically,
``p - y[k + j] = (p - y[k]) a**j``, so the count beyond the move's samples is found without sampling the tail.
The velocity loop and the friction are left out: the check is the loop the controller closes, not the drive.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from ..jit import njit
from .errors import NCParameterError


@njit
def position_loop_response(reference: np.ndarray, a: float) -> np.ndarray:
    """The P loop's position over the samples, ``y[0] = 0``, ``y[k + 1] = a y[k] + (1 - a) r[k]`` (m).

    The operations of ``scipy.signal.lfilter([0, 1 - a], [1, -a], r)`` (its transposed direct form II: ``y[k] =
    z + 0 r[k]``, ``z = (1 - a) r[k] - (-a) y[k]``) in their order, so the result is lfilter's bit for bit
    (tested), without importing ``scipy.signal`` (about 1 s) in every process that plans a program.

    Parameters
    ----------
    reference : ndarray, shape (m,)
        The reference ``r`` relative to the move's start, m.
    a : float
        ``exp(-Kv Ts)``.

    Returns
    -------
    ndarray, shape (m,)
    """
    b1 = 1.0 - a
    a1 = -a
    y = np.empty_like(reference)
    z = 0.0
    for k in range(reference.shape[0]):
        x = reference[k]
        yk = z + 0.0 * x
        z = b1 * x - a1 * yk
        y[k] = yk
    return y


def _decay_periods(error: float, width: float, a: float, rate: float) -> int:
    """Fewest periods ``j >= 0`` with ``error * a**j <= width`` (``rate = Kv Ts = -ln a``)."""
    if error <= width:
        return 0
    j = max(int(math.ceil(math.log(error / width) / rate)), 0)
    while error * a ** j > width:
        j += 1
    while j > 0 and error * a ** (j - 1) <= width:
        j -= 1
    return j


def servo_in_position(path: np.ndarray, target: np.ndarray, gains: Sequence[float], width: float,
                      period: float) -> int:
    """Samples after a move's start until the modelled servo is within ``width`` of the end on every axis.

    Parameters
    ----------
    path : ndarray (m, 3)
        The move's own reference after acc/dec after interpolation (m), row k at k periods after the move's
        start, the last row at rest on the end point.
    target : ndarray (3,)
        The move's end point (m).
    gains : sequence of 3 float
        Position loop gain Kv of X, Y, Z (1/s): the machine file's ``position_gain_per_s`` x ``position_scale``.
    width : float
        In-position width (m), per axis (FANUC No. 1826).
    period : float
        Interpolation period Ts (s).

    Returns
    -------
    int
        First row index k at which every axis's deviation ``|p - y[k]|`` is within ``width`` and stays so (it may
        lie beyond the last row).

    Raises
    ------
    NCParameterError
        When ``exp(-Kv Ts)`` rounds to 1 on an axis (the deviation would never decay).
    """
    m = path.shape[0]
    if m == 0:
        return 0
    rel = path - path[0]
    end = np.asarray(target, dtype=float) - path[0]
    count = 0
    for ax in range(3):
        rate = float(gains[ax]) * period
        a = math.exp(-rate)
        if not (math.isfinite(rate) and a < 1.0):  # a = 1: the deviation would never decay (endless count)
            raise NCParameterError(f"in-position model: position loop gain {gains[ax]!r} 1/s x period {period!r} s "
                                   f"of axis {'XYZ'[ax]} gives no decay; expected Kv x Ts > 1.2e-16 "
                                   "(exp(-Kv Ts) < 1 in floating point)")
        y = position_loop_response(np.ascontiguousarray(rel[:, ax]), a)  # y[0] = 0: at rest on the move's start
        err = np.abs(end[ax] - y)
        out = np.nonzero(err > width)[0]
        if len(out) == 0:
            continue
        if out[-1] == m - 1:
            count = max(count, m - 1 + _decay_periods(float(err[-1]), width, a, rate))
        else:
            count = max(count, int(out[-1]) + 1)
    return count
