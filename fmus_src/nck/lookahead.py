"""Look-ahead feed planning of a chain of feed blocks (FANUC AI contour control style).

Speed limits per block: programmed feed, ``max_cutting_feed`` (FANUC No. 1430)
and, on arcs, ``sqrt(arc_accel R)`` (No. 1735). Junction limits: the corner
speed at which no axis changes its velocity by more than
``corner_velocity_difference`` (No. 1783),
``v_c = dV / max_axis |t_out - t_in|``, and the lower of the two block feeds.
The tool must always be able to stop at the end of the look-ahead window of
``lookahead_blocks`` blocks (including the executing block): that speed caps
the junction after each block (:func:`.spans.window_caps`).

The chain is planned over acc/dec spans (:mod:`.spans`): runs of blocks with
one speed ceiling and no binding corner inside (the block limit, or for a run
of short blocks the window-limited speed from which the tool can stop within
the window), so that one speed change of bell-shaped acc/dec may cross block
ends as on the control. A
backward pass from the chain end and a forward pass from its start give the
speeds at the span boundaries; the chain starts and ends at rest.

The window may differ from block to block (Haas ``G103 P<n>``:
:func:`block_windows`, :mod:`.block_buffering`): each block's own window W_i
caps the speed at its end (stop at the end of block i + W_i - 1), and the
backward pass carries a cap back to the junctions before it. A per-block
window list equal to one window for all blocks gives the same plan, bit for
bit.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .geometry import ChainGeometry
from .profiles import SpeedChange
from .spans import plan_spans, relax_ceilings, split_at_dips, static_breaks, window_caps


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
    span_start : ndarray (m + 1,) of int
        First block of each of the m acc/dec spans (:mod:`.spans`), then n: one speed change may cross the
        inner junctions of a span. ``junction`` at a span boundary is planned; inside a span it is the speed
        reachable from both span ends (the speed of trapezoidal acc/dec there).
    ceiling : ndarray (m,)
        Speed limit of each span (m/s): the limit of its blocks, or for a span of window-bound blocks the
        window-limited speed (:func:`.spans.plan_spans`).
    """

    junction: np.ndarray
    vmax: np.ndarray
    corner: np.ndarray
    span_start: np.ndarray
    ceiling: np.ndarray


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
    """Junction speeds of a chain with a look-ahead window, planned over acc/dec spans (:mod:`.spans`).

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
    vmax = block_speed_limits(geo, feed, max_cutting_feed, arc_accel)
    corner = corner_limits(geo, corner_velocity_difference)
    jl = np.zeros(max(n - 1, 0))
    if n > 1:
        jl = np.minimum(np.minimum(vmax[:-1], vmax[1:]), corner)
    if isinstance(lookahead_blocks, (int, np.integer)):
        windows = [max(int(lookahead_blocks), 1)] * n
    else:
        windows = [max(int(w), 1) for w in lookahead_blocks]
        if len(windows) != n:
            raise ValueError(f"plan_chain_speeds: {len(windows)} look-ahead windows for {n} blocks")
    breaks = static_breaks(vmax, jl)
    caps, pure = window_caps(geo.length, geo.cum, vmax, jl, breaks, windows, sc)
    starts, ceiling = plan_spans(geo.length, vmax, jl, breaks, caps, pure, sc)
    cum = geo.cum
    vs = boundary_speeds(starts, ceiling, jl, caps, cum, sc)
    refined = split_at_dips(starts, ceiling, vmax, caps, cum, vs, sc)
    if refined is not None:
        starts, ceiling = refined
        vs = boundary_speeds(starts, ceiling, jl, caps, cum, sc)
    if np.any(ceiling < vmax[starts[:-1]]):  # window-limited spans: ceilings from the speeds they run at
        starts, ceiling, vs = _settle_ceilings(starts, ceiling, vmax, jl, caps, cum, sc)
    top = ceiling.tolist()
    v = np.zeros(n + 1)
    v[starts] = vs
    for i in range(len(starts) - 1):  # inner junctions of a span: the speed reachable from both span ends, capped
        a, e = int(starts[i]), int(starts[i + 1])
        for k in range(a + 1, e):
            up, down = sc.reach(vs[i], float(cum[k] - cum[a])), sc.reach(vs[i + 1], float(cum[e] - cum[k]))
            v[k] = min(top[i], up, down)
    return ChainSpeeds(v, vmax, corner, starts, ceiling)


def boundary_speeds(starts: np.ndarray, ceiling: np.ndarray, junction_limit: np.ndarray, caps: np.ndarray,
                    cum: np.ndarray, sc: SpeedChange) -> list[float]:
    """Speed at each span boundary (m/s, m + 1 values, 0 at both chain ends): backward then forward pass.

    Parameters
    ----------
    starts : ndarray (m + 1,) of int
        Span boundaries (:func:`.spans.plan_spans`).
    ceiling : ndarray (m,)
        Speed ceiling of each span (m/s).
    junction_limit, caps : ndarray (n - 1,)
        Junction limit and window cap of each inner junction (m/s).
    cum : ndarray (n + 1,)
        Cumulative block lengths (m).
    sc : SpeedChange
        Acc/dec law.
    """
    m = len(starts) - 1
    Ls = (cum[starts[1:]] - cum[starts[:-1]]).tolist()
    top = ceiling.tolist()
    # limit at each inner span boundary (the junction after the span's last block): window cap and the
    # ceilings of the spans on both sides included
    inner = (starts[1:-1] - 1).tolist()
    J = [min(float(junction_limit[k]), float(caps[k]), top[i], top[i + 1]) for i, k in enumerate(inner)]
    b = [0.0] * m  # backward pass: b[i] = speed limit at the end of span i
    for i in range(m - 2, -1, -1):
        b[i] = min(J[i], sc.reach(b[i + 1], Ls[i + 1]))
    vs = [0.0] * (m + 1)  # forward pass: speed at span boundaries
    for i in range(m):
        vs[i + 1] = min(b[i], sc.reach(vs[i], Ls[i]))
    vs[m] = 0.0
    return vs


def _settle_ceilings(starts: np.ndarray, ceiling: np.ndarray, vmax: np.ndarray, jl: np.ndarray, caps: np.ndarray,
                     cum: np.ndarray, sc: SpeedChange) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """Boundary speeds and relaxed ceilings (:func:`.spans.relax_ceilings`) that agree: no span starts or ends
    above its ceiling.

    The boundary speeds are planned with the block limits as span ceilings first; a span whose relaxed ceiling
    is below a boundary speed then caps its boundaries at that ceiling. Lower boundary speeds only widen the
    ramps' reach below each cap, so relaxed ceilings never fall and a second plan settles it.

    Parameters
    ----------
    starts : ndarray (m + 1,) of int
        Span boundaries.
    ceiling : ndarray (m,)
        Ceilings from :func:`.spans.plan_spans` / :func:`.spans.split_at_dips` (m/s): the lowest inner caps.
    vmax : ndarray (n,)
        Speed limit of each block (m/s).
    jl, caps : ndarray (n - 1,)
        Junction limits and window caps (m/s).
    cum : ndarray (n + 1,)
        Cumulative block lengths (m).
    sc : SpeedChange
        Acc/dec law.

    Returns
    -------
    starts, ceiling, speeds
        Span boundaries (unchanged), relaxed ceilings (m/s) and the speed at each span boundary (m/s).
    """
    bound_top = vmax[starts[:-1]].astype(float)  # the ceilings that bound the boundary speeds
    while True:
        vs = boundary_speeds(starts, bound_top, jl, caps, cum, sc)
        relaxed = relax_ceilings(starts, ceiling, vmax, caps, cum, vs, sc)
        v = np.asarray(vs)
        over = (v[:-1] > relaxed) | (v[1:] > relaxed)
        if not over.any():
            return starts, relaxed, vs
        bound_top = np.where(over, np.minimum(bound_top, relaxed), bound_top)
