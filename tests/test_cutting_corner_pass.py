"""A pass below an earlier one reads only its own depth at a slot corner (Z-map mode).

Regression: the near-field ring buffer (:class:`fmus_src.cutting.engagement.SweptPath`) stored a point only every
``spacing`` = 0.1 R of XY travel. Across a corner of the tool's path (a sharp one, or the small rounding of the
drives' lagging actual path) the chord between two stored points ran up to ``spacing / 2`` inside the corner, so
the Z-map kept a wall of cells at full height outside the chord's sweep, inside the tool's real sweep. The next
pass below read those cells as uncut material of the full depth: on ``tests/fixtures/unseen_parts/sub_depths``
the third pass peaked at 41.7 and 45.4 N at the slot's corners against 26.25 N by hand; here the second pass peaked
at up to 1.90x the hand value. Now the previous tool position is stored where the path turns
(:func:`fmus_src.cutting.engagement.turn_point`).

Hand value: a 2-flute end mill in a full slot has one tooth in the cut; its force is Kt a h (1, Ke) with
h = fz sin(phi), so the largest load is Fc = Kt a fz sqrt(1 + Ke^2), reached at phi = 90 deg from the feed. Around an
inside corner (a sharp one or a fillet of radius r < R at constant speed) the engagement stays at most the
half-disc ahead of the tool and the chip over one tooth period at most fz, so no instant exceeds that value.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np
import pytest

from fmus_src.cutting import CuttingLoad
from fmus_src.cutting.engagement import TURN_TOL, SweptPath, turn_point
from fmus_src.cutting.zmap_numba import commit_rows

KT, KE = 1.23e9, 0.5  # CuttingLoad defaults (A6061), N/m2, 1
R = 3e-3  # tool radius, m
DEPTH = 0.5e-3  # depth of each pass, m
SPEED = 0.005  # feed, m/s (300 mm/min)
RPM = 6000.0
FZ = SPEED / (2 * RPM / 60.0)  # 25 um per tooth
HAND = KT * DEPTH * FZ * math.sqrt(1.0 + KE * KE)  # 17.19 N
H = 1e-3  # communication step, s


def _passes(at: Callable[[float], tuple[float, float]], total: float, compiled: bool = True) -> list[float]:
    """Peak Fc of two passes along the path ``at(s)`` (XY, m, of the arc length s, m), 0 <= s <= ``total``.

    Depth DEPTH, then 2 DEPTH. Each pass starts at ``at(0)`` (beside the stock: no plunge into material), lifts
    at its end and returns to the start in the air in one step. 5 mm/s, S6000, 1 ms steps.
    """
    cut = CuttingLoad("cut", tool_diameter=2 * R, flutes=2, stock_x_min=-5e-3, stock_x_max=5e-3,
                      stock_y_min=-5e-3, stock_y_max=5e-3, stock_z_min=-5e-3)
    cut.use_compiled = compiled  # this instance only (numpy reference when False)
    x0, y0 = at(0.0)
    cut.set("spindle_speed", RPM * 2 * math.pi / 60)
    for name, value in zip(("x_position", "y_position", "z_position"), (x0, y0, 1e-3)):
        cut.set(name, value)
    cut.setup(0.0)
    t, peaks = 0.0, []
    for z in (-DEPTH, -2 * DEPTH):
        for pos in ((x0, y0, 1e-3), (x0, y0, z)):  # back to the start in the air, down beside the stock
            for name, value in zip(("x_position", "y_position", "z_position"), pos):
                cut.set(name, value)
            cut.do_step(t, H)
            t += H
        peak, k = 0.0, 0
        while k * SPEED * H <= total:
            x, y = at(min(k * SPEED * H, total))
            cut.set("x_position", x)
            cut.set("y_position", y)
            cut.do_step(t, H)
            t, k = t + H, k + 1
            peak = max(peak, float(cut.get("fc_peak")[0]))
        cut.set("z_position", 1e-3)  # lift
        cut.do_step(t, H)
        t += H
        peaks.append(peak)
    return peaks


def _corner(fillet: float, x0: float, leg: float) -> tuple[Callable[[float], tuple[float, float]], float]:
    """Along +x from (x0, 0) to a left corner at (0, 0), rounded by a quarter circle of radius ``fillet``
    (0: sharp), then ``leg`` along +y; returns the path and its length."""
    straight, arc = -fillet - x0, 0.5 * math.pi * fillet

    def at(s: float) -> tuple[float, float]:
        if s <= straight:
            return x0 + s, 0.0
        if s <= straight + arc:
            a = (s - straight) / fillet
            return -fillet + fillet * math.sin(a), fillet - fillet * math.cos(a)
        return 0.0, fillet + (s - straight - arc)

    return at, straight + arc + leg - fillet


@pytest.mark.parametrize("fillet, x0", [(0.0, -8.35e-3), (5e-5, -8.3e-3), (1e-4, -8.4e-3)])
def test_pass_below_reads_only_its_own_depth_at_the_corner(fillet: float, x0: float) -> None:
    """The +y leg leaves the stock. Before the fix (stored points 0.1-0.25 mm short of the corner) the second
    pass peaked at 1.902, 1.895 and 1.618 x HAND."""
    first, second = _passes(*_corner(fillet, x0, 8.5e-3))
    assert first == pytest.approx(HAND, rel=1e-6)
    assert second == pytest.approx(HAND, rel=1e-6)
    assert second <= HAND * (1.0 + 1e-9)


def test_pass_below_reads_only_its_own_depth_where_the_pass_above_ended() -> None:
    """A slot ending inside the stock, a lift there, the return rapid diagonal: the second pass meets the end of
    the first one at its own depth (numpy reference and compiled alike, bit for bit). Before the fix the last
    stretch of the first pass (up to ``spacing`` long) was committed along the ramp to the rapid's end, and the
    second pass read the full 2 DEPTH there: 2.0 x HAND."""
    path = (lambda s: (-8.1e-3 + s, 0.0)), 3.5e-3  # the centre ends 0.4 mm inside the stock edge
    compiled = _passes(*path)
    assert compiled == pytest.approx([HAND, HAND], rel=1e-6)
    assert _passes(*path, compiled=False) == compiled


def test_turn_point() -> None:
    """Straight on: never; a corner or a reversal beyond TURN_TOL: always (the geometry of the rule)."""
    o, q = (0.0, 0.0, 0.0), (1e-3, 0.0, 0.0)
    assert not turn_point(*o, *q, 1.01e-3, 0.0, 0.0)  # straight on
    assert not turn_point(*o, *q, 1e-3, 0.0, 0.0)  # not moving
    assert turn_point(*o, *q, 1e-3, 1e-8, 0.0)  # 90 deg: L is 1 mm off the new line
    assert turn_point(*o, *q, 1e-3, 0.0, 1e-6)  # a lift at the end of a feed
    assert turn_point(*o, *q, 0.999e-3, 0.0, 0.0)  # reversal
    # L off the line of the move by 0.9 and 1.1 TURN_TOL (the move turned by atan(off / 1 mm))
    for off, stored in ((0.9, False), (1.1, True)):
        slope = off * TURN_TOL / 1e-3
        assert turn_point(*o, *q, 1e-3 + 1e-5, 1e-5 * slope, 0.0) is stored
        assert turn_point(*o, *q, 1e-3 + 1e-5, 0.0, -1e-5 * slope) is stored


@pytest.mark.parametrize("radius", [1e-4, 5e-3])
def test_arc_polyline_stays_within_tolerance(radius: float) -> None:
    """A quarter arc in 5 um steps: every position lies within TURN_TOL of the stored polyline.

    Numpy advance and compiled commit store the same points. On the R 5 mm arc the 0.3 mm chord's error,
    0.3^2 / (8 x 5) = 2.25 um, exceeds TURN_TOL, so points are added there too.
    """
    spacing, lag = np.array([0.1 * R]), np.array([1.0])  # lag: keep every point
    n = int(0.5 * math.pi * radius / 5e-6)
    a = np.linspace(0.0, 0.5 * math.pi, n + 1)
    pos = np.stack([radius * np.sin(a), radius - radius * np.cos(a), np.zeros_like(a)], axis=1)
    cap = 4096
    path_np = SweptPath(pos[:1], spacing, lag, cap)
    path_nb = SweptPath(pos[:1], spacing, lag, cap)
    heights = np.zeros((1, 1, 1), dtype=np.float32)
    grid = np.array([[0.0, 0.0, -1.0, 1.0, 1.0]])
    cells = np.zeros((1, 2), dtype=np.int64)  # no stock
    for p in pos[1:]:
        path_np.advance(p[None, :])
        commit_rows(heights, grid, cells, np.zeros(1), path_nb.points, path_nb.arc, path_nb.head, path_nb.count,
                    spacing, lag, p[None, :].copy(), np.array([R]))
    assert np.array_equal(path_np.points, path_nb.points) and np.array_equal(path_np.count, path_nb.count)
    stored = path_np.points[0, :path_np.count[0], :2]
    poly = np.vstack([stored, pos[-1:, :2]])  # and the open segment to the tool
    a0, b0 = poly[:-1][None], poly[1:][None]
    q = pos[:, None, :2]
    ab = b0 - a0
    s = np.clip(np.sum((q - a0) * ab, axis=2) / np.maximum(np.sum(ab * ab, axis=2), 1e-30), 0.0, 1.0)
    dist = np.linalg.norm(q - (a0 + s[..., None] * ab), axis=2).min(axis=1)
    assert dist.max() <= TURN_TOL
