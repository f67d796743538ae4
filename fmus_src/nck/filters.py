"""Acc/dec after interpolation: FIR moving-average filters on the interpolated increments.

A moving average of length ``T`` applied to the piecewise-linear interpolation
of the sampled path is, sampled again, a box of ``N = round(T / Ts)`` samples
followed by a two-tap average. It delays a move by ``T / 2`` and lengthens it
by exactly ``T``; the sum of the increments (the end point) is preserved.

* ``"linear"``: one box of length ``T`` (linear acc/dec, acceleration time ``T``).
* ``"bell"``: two cascaded boxes of ``T / 2`` each (bell-shaped acc/dec,
  acceleration time ``T``, jerk-limited).
"""
from __future__ import annotations

import numpy as np

from .errors import NCParameterError


def box_lengths(time_constant: float, kind: str, period: float) -> list[int]:
    """Box lengths (samples) of the filter; empty for ``time_constant < period / 2``."""
    n = int(round(time_constant / period))
    if n <= 0:
        return []
    if kind == "linear":
        return [n]
    if kind == "bell":
        if n == 1:
            return [1]
        return [n // 2, n - n // 2]
    raise NCParameterError(f"filter kind must be 'linear' or 'bell', got {kind!r}")


def filter_extension(boxes: list[int]) -> int:
    """Number of samples by which the filter lengthens a move (= T / Ts)."""
    return sum(boxes)


def apply_fir(increments: np.ndarray, boxes: list[int]) -> np.ndarray:
    """Filter position increments along axis 0.

    Parameters
    ----------
    increments : ndarray (K, ...)
        Increments per sample period; the array must end with at least
        ``filter_extension(boxes)`` zero rows so that nothing is cut off.
    boxes : list of int
        From :func:`box_lengths`.

    Returns
    -------
    ndarray (K, ...)
        Filtered increments (same sum).
    """
    y = np.asarray(increments, dtype=float)
    for n in boxes:
        c = np.cumsum(y, axis=0)
        z = c.copy()
        if n < len(c):
            z[n:] -= c[:-n]
        z /= n
        two = z.copy()
        two[1:] += z[:-1]
        two *= 0.5
        y = two
    return y
