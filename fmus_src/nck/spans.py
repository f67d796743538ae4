"""Acc/dec spans of a chain: runs of feed blocks one speed change may cross without a stop in between.

A speed change of bell-shaped acc/dec before interpolation starts and ends at zero acceleration. Planned block
by block, every change would have to fit in one block: over 0.1 mm blocks (a CAM surface path) the tool could
gain only a little speed per block, and a 3000 mm/min path would run at about 1600 mm/min. FANUC plans the
acc/dec along the path, across block ends. So the look-ahead plans *spans*: maximal runs of blocks inside
which nothing limits the speed below the feed of the run. A span ends at a block junction where

* the speed limit of the blocks changes (another F, an arc's ``sqrt(a R)`` clamp, :mod:`.lookahead`),
* the corner speed (allowable velocity difference, No. 1783) is below that limit, or
* the look-ahead window binds: from the feed of the run the tool could not stop by the end of the window
  (``lookahead_blocks`` blocks including the executing one; shorter under Haas ``G103``), given the span
  ends inside the window.

Inside a span the speed never exceeds the common limit, which no corner inside it restricts, so one speed
change may run across its inner junctions. With trapezoidal acc/dec, spans give exactly the block-by-block
plan (speed changes then compose), and a chain of blocks that all have a binding window is planned block by
block as before.
"""
from __future__ import annotations

import bisect
import math
from typing import Sequence

import numpy as np

from .profiles import SpeedChange


def static_breaks(vmax: np.ndarray, junction_limit: np.ndarray) -> np.ndarray:
    """Inner junctions (n - 1,) where a span must end whatever the window: the limit changes or a corner binds.

    Parameters
    ----------
    vmax : ndarray (n,)
        Speed limit of each block (m/s).
    junction_limit : ndarray (n - 1,)
        Speed limit at each inner junction (m/s): the lower block limit and the corner speed.
    """
    if len(vmax) < 2:
        return np.zeros(0, dtype=bool)
    return (vmax[1:] != vmax[:-1]) | (junction_limit < vmax[:-1])


def window_caps(length: np.ndarray, cum: np.ndarray, vmax: np.ndarray, junction_limit: np.ndarray,
                breaks: np.ndarray, windows: Sequence[int], sc: SpeedChange) -> np.ndarray:
    """Speed at each inner junction from which the tool can still stop by the end of that block's window (m/s).

    Parameters
    ----------
    length, cum : ndarray
        Block lengths (n,) and cumulative lengths (n + 1,) (m).
    vmax : ndarray (n,)
        Speed limit of each block (m/s).
    junction_limit : ndarray (n - 1,)
        Speed limit at each inner junction (m/s).
    breaks : ndarray (n - 1,) of bool
        :func:`static_breaks`: a stop profile restarts there, at most at the junction limit.
    windows : sequence of int (n,)
        Look-ahead window of each block (blocks, including the executing one, >= 1).
    sc : SpeedChange
        Acc/dec law.

    Returns
    -------
    ndarray (n - 1,)
        ``inf`` where the window reaches the chain end (the chain's own stop bounds the speed there) or where
        the stop from ``vmax`` fits in the window without crossing a static break.
    """
    n = len(length)
    caps = np.full(max(n - 1, 0), math.inf)
    points = np.nonzero(breaks)[0].tolist()  # inner junctions where a stop profile restarts
    for k in range(n - 1):
        last = k + max(int(windows[k]), 1) - 1  # stop at the end of block `last`
        if last >= n - 1:
            continue
        lo, hi = bisect.bisect_right(points, k), bisect.bisect_left(points, last)
        distance = float(cum[last + 1] - cum[k + 1])
        if lo == hi and sc.distance(float(vmax[k]), 0.0) <= distance:
            continue  # full speed can stop inside the window: not binding
        x, end = 0.0, last + 1  # speed and position (junction index) the stop profile ends at
        for m in reversed(points[lo:hi]):  # static breaks between junction k and the window end
            x = min(float(junction_limit[m]), sc.reach(x, float(cum[end] - cum[m + 1])))
            end = m + 1
        caps[k] = sc.reach(x, float(cum[end] - cum[k + 1]))
    return caps


def span_starts(breaks: np.ndarray, caps: np.ndarray, vmax: np.ndarray) -> np.ndarray:
    """First block of each span and the chain length: ``[0, ..., n]`` (m + 1,) for m spans.

    A span ends after block k when junction k is a static break or its window cap is below the block limit.
    """
    n = len(vmax)
    ends = np.nonzero(breaks | (caps < vmax[:-1]))[0] + 1 if n > 1 else np.zeros(0, dtype=int)
    return np.concatenate(([0], ends, [n])).astype(np.int64)
