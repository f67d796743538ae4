"""Z-map resolution study: the error against the closed form falls as the grid is refined."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting.study import CASES, engagement_angles, format_rows, reference_force, resolution_study


def test_engagement_angles_from_radial_immersion():
    assert engagement_angles(1.0, 0) == (0.0, math.pi)
    assert engagement_angles(0.5, 1) == pytest.approx((0.0, math.pi / 2))
    assert engagement_angles(0.5, -1) == pytest.approx((math.pi / 2, math.pi))
    assert engagement_angles(0.25, 1)[1] == pytest.approx(math.radians(60))
    assert engagement_angles(0.25, -1)[0] == pytest.approx(math.radians(120))


def test_reference_slot_force():
    # slot, 2 mm deep, 0.05 mm/tooth: on the workpiece (+N a c Kr / 4, -N a c Kt / 4)
    assert reference_force("slot") == pytest.approx([30.75, -61.5])


def test_error_falls_with_cell_size_and_slot_is_exact():
    rows = resolution_study(cells=(4e-4, 1e-4), cases=("slot", "50% up"), repeats=2, seed=7)
    err = {(r.cell, r.case): r.max_error for r in rows}
    assert err[(4e-4, "slot")] < 1e-3 and err[(1e-4, "slot")] < 1e-3
    # first order in the cell size: the wall of the earlier cut is biased outward by about 0.7 cell
    assert err[(1e-4, "50% up")] < err[(4e-4, "50% up")] / 2
    assert err[(1e-4, "50% up")] < 0.06
    mem = {r.cell: r.memory_reference for r in rows}
    assert mem[1e-4] == 4 * 1000 * 1000 and mem[4e-4] == 4 * 250 * 250
    table = format_rows(rows)
    assert table.count("\n") == len(rows) + 1 and "50% up" in table
    assert set(CASES) >= {"slot", "50% up", "50% down", "25% up", "25% down"}
    assert np.isfinite([r.time_per_step for r in rows]).all()
