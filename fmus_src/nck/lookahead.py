"""Look-ahead feed planning of a chain of feed blocks (FANUC AI contour control style).

Speed limits per block: programmed feed, ``max_cutting_feed`` (FANUC No. 1430)
and, on arcs, ``sqrt(arc_accel R)`` (No. 1735). Junction limits: the corner
speed at which no axis changes its velocity by more than
``corner_velocity_difference`` (No. 1783),
``v_c = dV / max_axis |t_out - t_in|``, and the lower of the two block feeds.
The tool must always be able to stop at the end of the look-ahead window of
``lookahead_blocks`` blocks (including the executing block); a backward pass
from the window end and a forward pass from the chain start give the
junction speeds. The chain starts and ends at rest.

The window may differ from block to block (Haas ``G103 P<n>``:
:func:`block_windows`, :mod:`.block_buffering`): each block's own window W_i
bounds the speed at its end (stop at the end of block i + W_i - 1). When the
windows differ, a last backward pass keeps every junction speed within reach
of the next one, so that the stop constraints of the later blocks (e.g. the
first block read after ``G103 P1``) are kept too. With one window for all
blocks that pass changes nothing and is skipped, so the result is the same as
without per-block windows, bit for bit.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .geometry import ChainGeometry
from .profiles import SpeedChange


@dataclass(frozen=True)
class ChainSpeeds:
    """Planned speeds of a chain.

    Attributes
    ----------
    junction : ndarray (n + 1,)
        Speed at block boundaries (m/s); ``junction[0] = junction[n] = 0``.
    vmax : ndarray (n,)
        Speed limit of each block (m/s).
    corner : ndarray (n - 1,)
        Corner speed limit at each inner junction from the velocity-difference rule (m/s, inf when tangent).
    """

    junction: np.ndarray
    vmax: np.ndarray
    corner: np.ndarray


def block_speed_limits(geo: ChainGeometry, feed: np.ndarray, max_cutting_feed: float, arc_accel: float) -> np.ndarray:
    """Speed limit of each block (m/s): feed, maximum cutting feed and arc centripetal clamp."""
    vmax = np.minimum(np.asarray(feed, dtype=float), max_cutting_feed)
    if geo.is_arc.any():
        vmax = np.where(geo.is_arc, np.minimum(vmax, np.sqrt(arc_accel * geo.radius)), vmax)
    return vmax


def corner_limits(geo: ChainGeometry, velocity_difference: float) -> np.ndarray:
    """Corner speed limit at each inner junction (m/s), from the allowable per-axis velocity difference."""
    if len(geo.length) < 2:
        return np.zeros(0)
    dt = np.abs(geo.t_in[1:] - geo.t_out[:-1]).max(axis=1)
    with np.errstate(divide="ignore"):
        return np.where(dt > 1e-12, velocity_difference / np.maximum(dt, 1e-300), np.inf)


def block_windows(limits: Sequence[int], lookahead_blocks: int) -> list[int]:
    """Look-ahead window of each block (blocks, including the executing one) under Haas ``G103 P<n>`` limits.

    Parameters
    ----------
    limits : sequence of int
        ``G103 P<n>`` of each block (:attr:`.blocks.Linear.lookahead_limit`): n blocks may be read beyond it;
        0 means no limit.
    lookahead_blocks : int
        The machine's window W (>= 1, FANUC-style: including the executing block).

    Returns
    -------
    list of int
        ``min(W, n + 1)`` for a limited block, ``W`` otherwise.
    """
    w = max(int(lookahead_blocks), 1)
    return [min(w, int(n) + 1) if n > 0 else w for n in limits]


def plan_chain_speeds(geo: ChainGeometry, feed: np.ndarray, sc: SpeedChange, *, max_cutting_feed: float,
                      arc_accel: float, corner_velocity_difference: float,
                      lookahead_blocks: int | Sequence[int]) -> ChainSpeeds:
    """Junction speeds of a chain with a look-ahead window.

    Parameters
    ----------
    geo : ChainGeometry
        Geometry of the n blocks (no zero-length blocks).
    feed : ndarray (n,)
        Programmed feed of each block (m/s).
    sc : SpeedChange
        Tangential acc/dec law.
    max_cutting_feed, arc_accel, corner_velocity_difference : float
        NC parameters (m/s, m/s2, m/s).
    lookahead_blocks : int or sequence of int (n,)
        Window length W (>= 1), one for all blocks or one per block (:func:`block_windows`).

    Returns
    -------
    ChainSpeeds
    """
    n = len(geo.length)
    L = geo.length.tolist()
    vmax = block_speed_limits(geo, feed, max_cutting_feed, arc_accel)
    corner = corner_limits(geo, corner_velocity_difference)
    jl = np.zeros(n)
    if n > 1:
        jl[:-1] = np.minimum(np.minimum(vmax[:-1], vmax[1:]), corner)
    J = jl.tolist()
    # unwindowed backward pass: b[i] = speed limit at the end of block i
    b = [0.0] * n
    for i in range(n - 2, -1, -1):
        b[i] = min(J[i], sc.reach(b[i + 1], L[i + 1]))
    if isinstance(lookahead_blocks, (int, np.integer)):
        windows = [max(int(lookahead_blocks), 1)] * n
    else:
        windows = [max(int(w), 1) for w in lookahead_blocks]
        if len(windows) != n:
            raise ValueError(f"plan_chain_speeds: {len(windows)} look-ahead windows for {n} blocks")
    bw = list(b)
    for i in range(n - 1):
        last = i + windows[i] - 1
        if last >= n - 1:
            continue  # the window reaches the chain end: the unwindowed limit b[i]
        x = 0.0  # must be able to stop at the end of block `last`
        for k in range(last - 1, i - 1, -1):
            x = min(J[k], sc.reach(x, L[k + 1]))
            if x >= b[k]:
                x = b[i]  # joined the unwindowed solution: identical from here back to i
                break
        bw[i] = min(x, b[i])
    if len(set(windows)) > 1:  # a shorter window later in the chain also bounds the junctions before it
        for i in range(n - 3, -1, -1):
            bw[i] = min(bw[i], sc.reach(bw[i + 1], L[i + 1]))
    v = [0.0] * (n + 1)
    for i in range(n):
        v[i + 1] = min(bw[i], sc.reach(v[i], L[i]))
    v[n] = 0.0
    return ChainSpeeds(np.array(v), vmax, corner)
