"""Acc/dec spans of a chain: runs of feed blocks one speed change may cross without a stop in between.

A speed change of bell-shaped acc/dec before interpolation starts and ends at zero acceleration. Planned block
by block, every change would have to fit in one block: over 0.1 mm blocks (a CAM surface path) the tool could
gain only a little speed per block, and a 3000 mm/min path would run at about 1600 mm/min. FANUC plans the
acc/dec along the path, across block ends. So the look-ahead plans *spans*: runs of blocks with one speed
ceiling, inside which one speed change may cross the block ends. A span ends at a block junction where

* the speed limit of the blocks changes (another F, an arc's ``sqrt(a R)`` clamp, :mod:`.lookahead`),
* the corner speed (allowable velocity difference, No. 1783) is below that limit,
* the look-ahead window binds and holds a static break (a corner or limit change less than a window ahead:
  the stop profile must pass it, and the junction is capped as before), or
* a run of *window-limited* junctions begins or ends (below).

Window-limited speed
--------------------
While block k executes, the control has read the blocks up to k + W_k - 1 (``lookahead_blocks`` W, including
the executing one; shorter under Haas ``G103``) and must be able to stop at the end of the last of them. At
the end of block k the remaining window is ``D_k = cum[k + W_k] - cum[k + 1]`` (the blocks read beyond k),
so the speed there is at most the stop speed ``v_k = reach(0, D_k)``: the largest v whose stop distance
``sc.distance(v, 0)`` fits in ``D_k`` — for bell-shaped acc/dec ``v/2 (v/a + tc) = D`` when ``v >= a tc``
(``v = (sqrt((a tc)^2 + 8 a D) - a tc) / 2``), ``v^(3/2) sqrt(tc/a) = D`` below; ``sqrt(2 a D)`` for the
trapezoid. Inside block k the remaining window is longer (it shrinks to ``D_k`` at the block end), so ``v_k``
bounds the whole block. Where ``v_k`` is below the block limit and the window holds no static break, the
junction is *window-limited*. A run of consecutive window-limited junctions k0..k1 forms one span of the
blocks k0+1..k1 whose *ceiling* is the lowest ``v_k`` at its inner junctions (:func:`plan_spans`): the
control caps the feed at the speed from which it can stop within the window and changes speed across the
block ends. For equal blocks ``D_k = (W - 1) l`` and the ceiling is the same ``v_w`` all along the run
(50 mm of 0.1 mm blocks at F6000, W = 40, a = 2 m/s2, tc = 32 ms: D = 3.9 mm, ``v_w`` = 96.9 mm/s). The block
k0 before the run joins it when it starts at rest or at a span boundary and cannot exceed the ceiling within
its own length (``reach(v_entry, l_k0)`` at most the ceiling): joining then costs it nothing and spares the
ramp a restart. The blocks whose window reaches the chain end have no cap (the chain's own stop bounds them).

Where the window lengths vary (a cluster of tinier blocks), one ceiling for the whole run would hold the path
at the cluster's speed all along. Two rules, both exact, keep the ceiling local:

* :func:`split_at_dips`: a span ends at its lowest cap ``c_j`` when its speed profile can reach ``c_j`` there
  from both span ends; the path then slows to ``c_j`` and speeds up again with zero acceleration at j, which
  is what a bell-shaped profile does at a speed minimum anyway. Each part is split again by the same rule.
* :func:`relax_ceilings`: a junction k so near a span end that no ramp of the law from the boundary speed
  reaches ``v_k`` before it (:meth:`.profiles.SpeedChange.earliest_distance`) is safe at any cruise speed,
  so it does not lower the ceiling. The boundary speeds are then planned again with the relaxed ceilings
  until no span starts or ends above its ceiling (:func:`.lookahead._settle_ceilings`).

Inside a span the speed never exceeds its ceiling, which no corner or window inside it restricts further,
so one speed change may run across its inner junctions. A chain without window-limited junctions is planned
exactly as without this rule (the ceiling is then the block limit).
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
                breaks: np.ndarray, windows: Sequence[int], sc: SpeedChange) -> tuple[np.ndarray, np.ndarray]:
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
    caps : ndarray (n - 1,)
        ``inf`` where the window reaches the chain end (the chain's own stop bounds the speed there) or where
        the stop from ``vmax`` fits in the window without crossing a static break.
    pure : ndarray (n - 1,) of bool
        The window ends before the chain end and holds no static break after the junction: the cap is the
        stop from the window end alone, ``reach(0, cum[k + W_k] - cum[k + 1])``.
    """
    n = len(length)
    caps = np.full(max(n - 1, 0), math.inf)
    pure = np.zeros(max(n - 1, 0), dtype=bool)
    points = np.nonzero(breaks)[0].tolist()  # inner junctions where a stop profile restarts
    for k in range(n - 1):
        last = k + max(int(windows[k]), 1) - 1  # stop at the end of block `last`
        if last >= n - 1:
            continue
        lo, hi = bisect.bisect_right(points, k), bisect.bisect_left(points, last)
        distance = float(cum[last + 1] - cum[k + 1])
        pure[k] = lo == hi
        if lo == hi and sc.distance(float(vmax[k]), 0.0) <= distance:
            continue  # full speed can stop inside the window: not binding
        x, end = 0.0, last + 1  # speed and position (junction index) the stop profile ends at
        for m in reversed(points[lo:hi]):  # static breaks between junction k and the window end
            x = min(float(junction_limit[m]), sc.reach(x, float(cum[end] - cum[m + 1])))
            end = m + 1
        caps[k] = sc.reach(x, float(cum[end] - cum[k + 1]))
    return caps, pure


def plan_spans(length: np.ndarray, vmax: np.ndarray, junction_limit: np.ndarray, breaks: np.ndarray,
               caps: np.ndarray, pure: np.ndarray, sc: SpeedChange) -> tuple[np.ndarray, np.ndarray]:
    """Acc/dec spans of a chain and the speed ceiling of each (see the module docstring).

    Parameters
    ----------
    length : ndarray (n,)
        Block lengths (m).
    vmax : ndarray (n,)
        Speed limit of each block (m/s).
    junction_limit : ndarray (n - 1,)
        Speed limit at each inner junction (m/s).
    breaks : ndarray (n - 1,) of bool
        :func:`static_breaks`.
    caps, pure : ndarray (n - 1,)
        From :func:`window_caps`.
    sc : SpeedChange
        Acc/dec law.

    Returns
    -------
    starts : ndarray (m + 1,) of int
        First block of each of the m spans, then n.
    ceiling : ndarray (m,)
        Speed limit of each span (m/s): ``vmax`` of its blocks, lowered to the lowest window cap at its inner
        junctions (the window-limited speed) for a span of window-bound blocks.
    """
    n = len(vmax)
    if n < 2:
        return np.array([0, n], dtype=np.int64), np.asarray(vmax[:1], dtype=float).copy()
    bound = caps < vmax[:-1]
    windowed = bound & pure & ~breaks  # the window alone limits the speed: a ceiling, not a break
    cut = breaks | (bound & ~windowed)
    k, m = 0, n - 1
    while k < m:  # runs k0..k1 of consecutive window-limited junctions
        if not windowed[k]:
            k += 1
            continue
        k0 = k
        while k + 1 < m and windowed[k + 1]:
            k += 1
        k1 = k
        cut[k1] = True  # the block after the run has a higher (or no) window limit
        cut[k0] = not _joins_run(k0, k1, length, junction_limit, caps, cut, sc)
        k += 1
    ends = np.nonzero(cut)[0] + 1
    starts = np.concatenate(([0], ends, [n])).astype(np.int64)
    ceiling = vmax[starts[:-1]].astype(float)
    for i in range(len(starts) - 1):
        a, e = int(starts[i]), int(starts[i + 1])
        if e - a > 1:
            ceiling[i] = min(float(ceiling[i]), float(caps[a:e - 1].min()))
    return starts, ceiling


def _joins_run(k0: int, k1: int, length: np.ndarray, junction_limit: np.ndarray, caps: np.ndarray,
               cut: np.ndarray, sc: SpeedChange) -> bool:
    """Whether block k0, which ends at the first junction k0 of a window-limited run k0..k1, joins the run's span.

    It does when it starts at rest (chain start) or at a span boundary and cannot exceed the run's ceiling on
    its own: joining then costs it nothing and spares the speed change a boundary.
    """
    if k0 == k1:
        return False  # no block lies between two window-limited junctions: nothing to join
    if k0 == 0:
        entry = 0.0
    elif cut[k0 - 1]:
        entry = min(float(junction_limit[k0 - 1]), float(caps[k0 - 1]))
    else:
        return False  # block k0 continues a span with a higher ceiling
    return sc.reach(entry, float(length[k0])) <= float(caps[k0:k1].min())


def split_at_dips(starts: np.ndarray, ceiling: np.ndarray, vmax: np.ndarray, caps: np.ndarray, cum: np.ndarray,
                  speeds: Sequence[float], sc: SpeedChange) -> tuple[np.ndarray, np.ndarray] | None:
    """Split window-limited spans at their lowest cap where the path reaches that cap from both sides.

    A span capped at its lowest window cap ``c_j`` (junction j) holds the path below ``c_j`` everywhere, also
    where the window is longer. Ending the span at j costs nothing when the speed profile of the span reaches
    ``c_j`` there from both span ends: the path then runs at ``c_j`` with zero acceleration at j, as a
    bell-shaped slow-down and speed-up meet at their common speed, and each part takes the lowest cap of its
    own inner junctions as its ceiling. The parts are split again by the same rule (their ends run at the
    split caps).

    Parameters
    ----------
    starts : ndarray (m + 1,) of int
        Span boundaries; ceiling : ndarray (m,) their ceilings (m/s) (:func:`plan_spans`).
    vmax : ndarray (n,)
        Speed limit of each block (m/s).
    caps : ndarray (n - 1,)
        Window cap of each inner junction (m/s) (:func:`window_caps`).
    cum : ndarray (n + 1,)
        Cumulative block lengths (m).
    speeds : sequence of float (m + 1,)
        Planned speed at each span boundary (m/s): the lower bounds of the entry and exit speeds.
    sc : SpeedChange
        Acc/dec law.

    Returns
    -------
    (starts, ceiling) or None
        The refined spans, or None when no span is split.
    """
    out_starts: list[int] = []
    out_ceiling: list[float] = []
    split = False
    for i in range(len(starts) - 1):
        a, e = int(starts[i]), int(starts[i + 1])
        if e - a < 2 or not ceiling[i] < vmax[a]:
            out_starts.append(a)
            out_ceiling.append(float(ceiling[i]))
            continue
        pending = [(a, e, float(speeds[i]), float(speeds[i + 1]))]
        parts: list[tuple[int, float]] = []
        while pending:
            lo, hi, v_in, v_out = pending.pop()
            if hi - lo >= 2:
                j = lo + int(np.argmin(caps[lo:hi - 1]))  # lowest cap among the inner junctions lo .. hi-2
                c = float(caps[j])
                if (sc.reach(v_in, float(cum[j + 1] - cum[lo])) >= c
                        and sc.reach(v_out, float(cum[hi] - cum[j + 1])) >= c):
                    pending.append((j + 1, hi, c, v_out))
                    pending.append((lo, j + 1, v_in, c))
                    split = True
                    continue
                parts.append((lo, min(float(vmax[a]), c)))
            else:  # one block: capped at its end, where its window is shortest
                parts.append((lo, min(float(vmax[a]), float(caps[lo])) if lo < len(caps) else float(vmax[a])))
        for lo, top in parts:
            out_starts.append(lo)
            out_ceiling.append(top)
    if not split:
        return None
    out_starts.append(int(starts[-1]))
    return np.asarray(out_starts, dtype=np.int64), np.asarray(out_ceiling, dtype=float)


def relax_ceilings(starts: np.ndarray, ceiling: np.ndarray, vmax: np.ndarray, caps: np.ndarray, cum: np.ndarray,
                   speeds: Sequence[float], sc: SpeedChange) -> np.ndarray:
    """Raise each window-limited span's ceiling to the lowest cap its speed ramps could exceed (m/s).

    With its boundary speeds fixed, the path in a span passes an inner junction k on the speed-up from the
    span start, at cruise, or on the slow-down to the span end. No ramp of the law starting at ``v_start`` is
    faster than ``caps[k]`` before :meth:`~.profiles.SpeedChange.earliest_distance` ``(v_start, caps[k])``,
    and likewise backwards from the end; a junction nearer to a span end than that is safe at any cruise
    speed, so the ceiling need only be the lowest cap of the other inner junctions (and at most the block
    limit). The boundary speeds stay those planned with the lower ceilings, which are feasible under the
    higher ones.

    Parameters
    ----------
    starts : ndarray (m + 1,) of int
        Span boundaries; ceiling : ndarray (m,) their ceilings (m/s).
    vmax : ndarray (n,)
        Speed limit of each block (m/s).
    caps : ndarray (n - 1,)
        Window cap of each inner junction (m/s).
    cum : ndarray (n + 1,)
        Cumulative block lengths (m).
    speeds : sequence of float (m + 1,)
        Speed at each span boundary (m/s).
    sc : SpeedChange
        Acc/dec law.

    Returns
    -------
    ndarray (m,)
        The ceilings; unchanged for spans whose ceiling is their block limit.
    """
    out = ceiling.astype(float).copy()
    for i in range(len(starts) - 1):
        a, e = int(starts[i]), int(starts[i + 1])
        if e - a < 2 or not ceiling[i] < vmax[a]:
            continue
        top = float(vmax[a])
        for k in range(a, e - 1):  # inner junction k lies at cum[k + 1]
            c = float(caps[k])
            if c < top and float(cum[k + 1] - cum[a]) > sc.earliest_distance(float(speeds[i]), c) \
                    and float(cum[e] - cum[k + 1]) > sc.earliest_distance(float(speeds[i + 1]), c):
                top = c
        out[i] = top
    return out
