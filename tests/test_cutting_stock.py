"""Z-map stock and swept-disc geometry (fmus_src.cutting.stock)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting.stock import StockError, ZMapStock, disc_sweep_cover, round_down_f32
from fmus_src.errors import CncTwinError


def _stock(lower, upper, cell, batch=1):
    return ZMapStock(np.tile(np.asarray(lower, float), (batch, 1)), np.tile(np.asarray(upper, float), (batch, 1)),
                     np.full(batch, cell))


def test_disc_sweep_cover_geometry():
    r = 3e-3
    # segment from (0,0) to (10,0) mm at z = -2 mm
    cov, z = disc_sweep_cover(np.array([5e-3, 5e-3, 14e-3, -2e-3]), np.array([2.9e-3, 3.1e-3, 0.0, 0.0]),
                              0.0, 0.0, -2e-3, 10e-3, 0.0, -2e-3, r)
    assert cov.tolist() == [True, False, False, True]
    assert z[0] == pytest.approx(-2e-3) and np.isinf(z[1])


def test_disc_sweep_cover_ramp_takes_lowest_covering_height():
    # ramp from z = 0 at x = 0 to z = -1 mm at x = 10 mm; point at x = 4 mm is covered for centres
    # x in [1, 7] mm, lowest tip there is at x = 7 mm: z = -0.7 mm
    cov, z = disc_sweep_cover(4e-3, 0.0, 0.0, 0.0, 0.0, 10e-3, 0.0, -1e-3, 3e-3)
    assert cov and z == pytest.approx(-0.7e-3)


def test_rim_tolerance_excludes_points_on_the_end_disc_rim():
    r = 3e-3
    phi = np.linspace(0.05, math.pi - 0.05, 50)  # front arc of a tool that moved +x to (1 mm, 0)
    px, py = 1e-3 + r * np.sin(phi), r * np.cos(phi)
    cov, _ = disc_sweep_cover(px, py, 0.0, 0.0, 0.0, 1e-3, 0.0, 0.0, r, 1e-9)
    assert not cov.any()
    back = np.linspace(math.pi + 0.05, 2 * math.pi - 0.05, 50)
    cov, _ = disc_sweep_cover(1e-3 + r * np.sin(back), r * np.cos(back), 0.0, 0.0, 0.0, 1e-3, 0.0, 0.0, r, 1e-9)
    assert cov.all()


def test_round_down_f32_never_rounds_up():
    rng = np.random.default_rng(3)
    z = rng.uniform(-0.1, 0.1, 1000)
    z32 = round_down_f32(z)
    assert z32.dtype == np.float32
    assert np.all(z32.astype(np.float64) <= z)
    assert np.all(z - z32 < 1e-8)


def test_grid_divides_block_exactly_and_memory():
    s = _stock((0, 0, -0.01), (0.0105, 0.02, 0), 1e-3)
    assert s.nx[0] == 11 and s.ny[0] == 20
    assert s.dx[0] * 11 == pytest.approx(0.0105) and s.dy[0] == pytest.approx(1e-3)
    assert s.memory_bytes == 11 * 20 * 4
    assert s.sample(np.array([0]), np.array([0.005]), np.array([0.005]))[0] == pytest.approx(0.0, abs=1e-9)
    assert s.sample(np.array([0]), np.array([-1e-6]), np.array([0.005]))[0] == -np.inf


def test_zero_volume_stock_has_no_material():
    s = _stock((0, 0, 0), (0, 0, 0), 1e-4)
    assert s.nx[0] == 0
    assert s.sample(np.array([0]), np.array([0.0]), np.array([0.0]))[0] == -np.inf
    s.remove_sweep(np.zeros((1, 3)), np.ones((1, 3)), np.array([3e-3]), np.array([True]))  # no-op
    assert s.removed_volume()[0] == 0.0


def test_straight_slot_removes_the_inflated_capsule_volume():
    # slot 2 mm deep, 10 mm long, through the middle of a 20 x 20 mm block; the removed area is the
    # capsule of radius R + rho (rho = half cell diagonal) up to the grid quantisation of its outline
    cell, r, depth, length = 1e-4, 3e-3, 2e-3, 10e-3
    s = _stock((0, 0, -0.01), (0.02, 0.02, 0.0), cell)
    a = np.array([[5e-3, 10e-3, -depth]])
    b = np.array([[15e-3, 10e-3, -depth]])
    s.remove_sweep(a, b, np.array([r]), np.array([True]))
    reach = r + s.rho[0]
    area = 2 * reach * length + math.pi * reach**2
    perimeter = 2 * length + 2 * math.pi * reach
    vol = s.removed_volume()[0]
    assert vol == pytest.approx(area * depth, abs=perimeter * cell * depth)
    # floor of the slot is exactly the tool tip (rounded down), elsewhere untouched
    h = s.sample(np.array([0, 0]), np.array([10e-3, 10e-3]), np.array([10e-3, 16e-3]))
    assert h[0] <= -depth and h[0] > -depth - 1e-8 and h[1] == pytest.approx(0.0, abs=1e-9)


def test_cut_below_the_block_bottom_stops_at_z_min():
    s = _stock((0, 0, -0.005), (0.01, 0.01, 0.0), 2e-4)
    s.remove_sweep(np.array([[5e-3, 5e-3, -0.02]]), np.array([[5e-3, 5e-3, -0.02]]), np.array([1e-3]),
                   np.array([True]))
    assert s.sample(np.array([0]), np.array([5e-3]), np.array([5e-3]))[0] == pytest.approx(-0.005, abs=1e-8)


def test_batch_members_are_independent():
    s = _stock((0, 0, -0.01), (0.02, 0.02, 0.0), 2e-4, batch=2)
    s.remove_sweep(np.array([[5e-3, 10e-3, -1e-3]] * 2), np.array([[15e-3, 10e-3, -1e-3]] * 2),
                   np.array([3e-3, 3e-3]), np.array([True, False]))
    v = s.removed_volume()
    assert v[0] > 0 and v[1] == 0.0


def test_invalid_block_raises_named_error():
    with pytest.raises(StockError, match="stock_y_max .* below stock_y_min") as err:
        _stock((0, 0.01, 0), (0.01, 0.0, 0.01), 1e-4)
    assert isinstance(err.value, CncTwinError)
    with pytest.raises(StockError, match="stock_cell"):
        _stock((0, 0, 0), (0.01, 0.01, 0.01), 0.0)
    with pytest.raises(StockError, match="GB"):
        _stock((0, 0, 0), (10.0, 10.0, 0.01), 1e-5)
