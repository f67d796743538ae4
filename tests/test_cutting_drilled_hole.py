"""A drilled hole stays empty for a later tool of the same radius, whatever path came before it.

Regression: the near-field ring buffer (:class:`fmus_src.cutting.engagement.SweptPath`) stores a point only
every ``spacing`` = 0.1 R of XY travel and otherwise lowers the last stored point in place. An approach that
ends up to ``spacing`` past the last stored point, followed by a plunge, recorded the hole up to 0.3 mm off the
tool's axis (R = 3 mm); a tap entering the hole on its true axis later cut a phantom sliver with its end disc
(1.24 mm3 in ``tests/fixtures/cam_posts/fusion_fanuc``, then a stalled plunge at the tap's reversal).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting.axial import AX_MRR, AX_THRUST, axial_cut
from fmus_src.cutting.engagement import SweptPath
from fmus_src.cutting.stock import ZMapStock
from fmus_src.cutting.zmap_numba import ZMapArrays, _ring, commit, commit_rows

R = 3e-3  # tool radius, m
SPACING = 0.1 * R  # component.PATH_SPACING * R, m
LAG = R + 2e-4  # R + 2 cells of 0.1 mm, m
HOLE = (0.015, 0.015)  # hole axis, m
DRILL_DEPTH = 0.008  # below the stock top z = 0, m
TAP_DEPTH = DRILL_DEPTH  # the tap to the drill's depth, m
CLEAR = 0.005  # R plane above the stock top, m
OMEGA = 2.0 * math.pi * 3000.0 / 60.0  # rad/s
H = 1e-3  # step, s


class _Twin:
    """Stock + ring buffer stepped as :meth:`fmus_src.cutting.component.CuttingLoad` does (compiled commit)."""

    def __init__(self, start: tuple[float, float, float]) -> None:
        self.stock = ZMapStock(np.array([[0.0, 0.0, -0.02]]), np.array([[0.1, 0.06, 0.0]]), np.array([1e-4]))
        self.z = ZMapArrays.of(self.stock)
        self.pos = np.array([start], dtype=np.float64)
        self.path = SweptPath(self.pos, np.array([SPACING]), np.array([LAG]),
                              int(np.ceil(LAG / SPACING)) + 4)
        self.volume = 0.0  # end-disc removal, m3
        self.thrust_max = 0.0  # largest end-edge thrust on the tool, N
        self._out = np.zeros(3)

    def move(self, target: tuple[float, float, float], step: float) -> None:
        """Straight move of the tool tip to ``target`` (m) in steps of at most ``step`` (m)."""
        start = self.pos[0].copy()
        d = np.asarray(target, dtype=np.float64) - start
        n = max(int(math.ceil(np.linalg.norm(d) / step - 1e-9)), 1)
        for k in range(1, n + 1):
            new = start + d * (k / n)
            axial_cut(self.z.heights, self.z.grid, self.z.cells, *_ring(self.path), 0, *self.pos[0], *new, R,
                      OMEGA, 7e8, 0.3, H, self._out)
            self.volume += self._out[AX_MRR] * H
            self.thrust_max = max(self.thrust_max, self._out[AX_THRUST])
            self.pos = new[None, :].copy()
            commit(self.z, self.path, self.pos, np.array([R]))


def _side(distance: float) -> tuple[float, float]:
    """The point ``distance`` (m) from the hole axis opposite the end-disc sample angle 16.875 deg (from +y)."""
    a = math.radians(16.875 + 180.0)
    return HOLE[0] + distance * math.sin(a), HOLE[1] + distance * math.cos(a)


def _drill_after_slot(offset: float) -> _Twin:
    """A slot elsewhere, an approach along +x whose last stored point is ``offset`` short of the hole, a drill."""
    twin = _Twin((0.045, 0.045, CLEAR))
    twin.move((0.045, 0.045, -0.001), 5e-5)  # plunge the slot's start
    twin.move((0.055, 0.045, -0.001), SPACING)  # the slot (elsewhere)
    twin.move((0.055, 0.045, CLEAR), 5e-5)
    # approach at the R plane: stored points every 1.02 SPACING, the last one `offset` short of the axis, on the
    # side opposite an outer sample point of the end disc
    x0, y0 = _side(offset + 10 * 1.02 * SPACING)
    twin.move((x0, y0, CLEAR), 1e-3)  # steps > SPACING: (x0, y0) is stored
    twin.move((*_side(offset), CLEAR), 1.02 * SPACING)  # 10 stored points, the last `offset` short
    twin.move((HOLE[0], HOLE[1], CLEAR), 1e-5)  # the rest of the approach, shorter than SPACING: not stored
    twin.volume, twin.thrust_max = 0.0, 0.0
    twin.move((HOLE[0], HOLE[1], -DRILL_DEPTH), 2.5e-5)  # the drill: 1.5 m/min
    return twin


@pytest.mark.parametrize("offset", [0.0, 0.15e-3, 0.295e-3])
def test_tap_in_drilled_hole_removes_nothing(offset: float) -> None:
    """Before the fix, offset 0.295 mm: the tap cut 3.31 mm3 = 2 outer samples (0.207 mm2 each) x 8 mm."""
    twin = _drill_after_slot(offset)
    # the drill's end disc removes the hole: pi R^2 depth (the quadrature's area is exact)
    assert twin.volume == pytest.approx(math.pi * R * R * DRILL_DEPTH, rel=1e-9)
    twin.move((HOLE[0], HOLE[1], CLEAR), 1e-4)
    # away the way it came (no committed segment sweeps the far side), so the hole is committed
    twin.move((*_side(0.012), CLEAR), SPACING)
    twin.move((HOLE[0], HOLE[1], CLEAR), 0.7 * SPACING)  # back, another alignment of stored points
    twin.volume, twin.thrust_max = 0.0, 0.0
    twin.move((HOLE[0], HOLE[1], -TAP_DEPTH), 2e-5)  # the tap (same radius) down the drilled hole
    assert twin.volume == 0.0
    assert twin.thrust_max == 0.0


def test_plunge_is_stored_on_the_tool_axis() -> None:
    """The ring buffer keeps the plunge at the tool's XY (numpy and compiled advance alike)."""
    start = np.array([[HOLE[0] - 0.28e-3 - 2 * SPACING, HOLE[1], 0.001]])
    path_np = SweptPath(start, np.array([SPACING]), np.array([LAG]), 16)
    path_nb = SweptPath(start, np.array([SPACING]), np.array([LAG]), 16)
    heights = np.zeros((1, 1, 1), dtype=np.float32)
    grid = np.array([[0.0, 0.0, -1.0, 1.0, 1.0]])
    cells = np.zeros((1, 2), dtype=np.int64)  # no stock: nothing to commit into
    moves = [start[0] + [SPACING * k, 0.0, 0.0] for k in (1, 2)]
    moves += [np.array([HOLE[0], HOLE[1], 0.001 - 1e-4 * k]) for k in range(0, 91)]
    for p in moves:
        pos = np.asarray(p, dtype=np.float64)[None, :]
        path_np.advance(pos)
        commit_rows(heights, grid, cells, np.zeros(1), path_nb.points, path_nb.arc, path_nb.head, path_nb.count,
                    path_np.spacing, path_np.lag, pos, np.array([R]))
    last = path_np.last()[0]
    assert last.tolist() == [HOLE[0], HOLE[1], pytest.approx(-0.008, abs=1e-12)]
    assert np.array_equal(path_np.points, path_nb.points)
    assert np.array_equal(path_np.count, path_nb.count) and np.array_equal(path_np.arc, path_nb.arc)
