"""Scalar forms of numpy's float64 ``maximum``, ``minimum``, ``clip`` and ``sign``, for compiled planning kernels.

The compiled planning kernels (:mod:`.chain_sampling`, :mod:`.plan_assembly`) must give the numpy
specification's results bit for bit, signed zeros and NaN included. Python's ``max``/``min`` do not: numpy's
``maximum(a, b)`` returns ``b`` when ``a == b`` (so ``maximum(-0.0, 0.0)`` is ``+0.0`` and
``maximum(0.0, -0.0)`` is ``-0.0``) and propagates a NaN of either operand; ``clip(x, lo, hi)`` keeps ``x`` when
it equals a bound (``clip(-0.0, 0.0, 1.0)`` is ``-0.0``); ``sign(-0.0)`` is ``+0.0``. These functions reproduce
numpy 2's behaviour (tested against numpy on signed zeros, NaN and infinities in ``tests/test_nck_plan_speed.py``).
"""
from __future__ import annotations

import math

from ..jit import njit_inline


@njit_inline
def np_maximum(a: float, b: float) -> float:
    """``numpy.maximum(a, b)`` for float64 scalars (``b`` on equality, NaN propagated)."""
    return a if (a > b or math.isnan(a)) else b


@njit_inline
def np_minimum(a: float, b: float) -> float:
    """``numpy.minimum(a, b)`` for float64 scalars (``b`` on equality, NaN propagated)."""
    return a if (a < b or math.isnan(a)) else b


@njit_inline
def np_clip(x: float, lo: float, hi: float) -> float:
    """``numpy.clip(x, lo, hi)`` for float64 scalars with finite ``lo <= hi`` (``x`` kept on equality, NaN kept)."""
    v = lo if lo > x else x
    return hi if hi < v else v


@njit_inline
def np_sign(x: float) -> float:
    """``numpy.sign(x)`` for a float64 scalar: -1, +0.0 (for both zeros), 1, or NaN."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    if x == 0.0:
        return 0.0
    return x
