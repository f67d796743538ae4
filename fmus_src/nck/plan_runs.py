"""Compiled run detection of a member's piecewise-constant samples (:meth:`.batch_plan.BatchPlanBuilder.add`).

The batch plan stores feed, spindle reference and speed, line and tool as runs: a run starts at every sample
where any of the five changes its bits (floats compared as their 64-bit patterns, so -0.0 and NaN stay
distinct), plus sample 0. :func:`run_starts` finds them in one pass, with the member's sentinel sample K (feed
0.0, the rest held) appended, and gathers the values at the starts: the same integers and bit patterns as the
numpy steps of :meth:`.batch_plan.BatchPlanBuilder.add` (which stay the reference).
"""
from __future__ import annotations

import numpy as np

from ..jit import njit


@njit
def run_starts(feed_bits: np.ndarray, ref_bits: np.ndarray, speed_bits: np.ndarray, line: np.ndarray,
               tool: np.ndarray):
    """Run starts and run values of one member (K samples + the sentinel).

    Parameters
    ----------
    feed_bits, ref_bits, speed_bits : ndarray (K,) of int64
        Feed (m/s), spindle reference and actual speed (rad/s) viewed as int64 bit patterns.
    line, tool : ndarray (K,) of int64
        Executing line, tool in the spindle.

    Returns
    -------
    starts : ndarray (R,) of int64
        Samples (0 .. K) at which a run starts.
    feed, ref, speed : ndarray (R,) of int64
        Bit patterns at the starts (view them as float64); the sentinel's feed is 0.0.
    line_v, tool_v : ndarray (R,) of int64
        Line and tool at the starts.
    """
    K = feed_bits.shape[0]
    changed = np.zeros(K + 1, dtype=np.bool_)
    changed[0] = True
    count = 1
    for k in range(1, K):
        if (feed_bits[k] != feed_bits[k - 1] or ref_bits[k] != ref_bits[k - 1] or speed_bits[k] != speed_bits[k - 1]
                or line[k] != line[k - 1] or tool[k] != tool[k - 1]):
            changed[k] = True
            count += 1
    if feed_bits[K - 1] != 0:  # the sentinel: feed 0.0 (bits 0), the rest held
        changed[K] = True
        count += 1
    starts = np.empty(count, dtype=np.int64)
    feed = np.empty(count, dtype=np.int64)
    ref = np.empty(count, dtype=np.int64)
    speed = np.empty(count, dtype=np.int64)
    line_v = np.empty(count, dtype=np.int64)
    tool_v = np.empty(count, dtype=np.int64)
    i = 0
    for k in range(K + 1):
        if changed[k]:
            j = min(k, K - 1)
            starts[i] = k
            feed[i] = feed_bits[k] if k < K else 0
            ref[i] = ref_bits[j]
            speed[i] = speed_bits[j]
            line_v[i] = line[j]
            tool_v[i] = tool[j]
            i += 1
    return starts, feed, ref, speed, line_v, tool_v
