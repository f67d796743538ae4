"""The end-disc quadrature's early exits change no result (issue 9: the Z-map step's cost).

:func:`fmus_src.cutting.axial.axial_cut` skips work that cannot add to its sums: the disc wholly off the
stock's grid, the tool not above the floor, near-field segments whose swept disc cannot reach a point, and
the rest of a point's walk once its top is at or below the step's bottom. The reference here is the full
quadrature as the module's docstring defines it, written out in Python without any of these exits (every
one of the 256 points, every segment, in the stored order): the results must be equal bit for bit, on
seeded random near fields (XY passes at a jittering Z, plunges, ramps) around and off the stock.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting.axial import AX_MRR, AX_THRUST, AX_TORQUE, RINGS, SECTORS, axial_cut
from fmus_src.cutting.engagement import RIM_TOL
from fmus_src.cutting.kernel import OMEGA_FLOOR
from fmus_src.cutting.stock import sweep_cover_z

R = 3e-3  # tool radius, m
CELL = 2.5e-4  # Z-map cell, m
KT, KA = 1.23e9, 0.28  # N/m2, 1
OMEGA = 6000.0 * 2.0 * math.pi / 60.0  # rad/s
H = 1e-3  # s


def _reference(heights, grid, cells, points, head, count, x0, y0, z0, x1, y1, z1):
    """The full quadrature (thrust, torque, removal rate) of stock row 0, no exits."""
    if not z1 < z0:
        return 0.0, 0.0, 0.0
    bottom = max(z1, grid[0, 2])
    dr = R / RINGS
    dth = 2.0 * math.pi / SECTORS
    cap = points.shape[1]
    vol = per_r = 0.0
    for i in range(RINGS):
        r = (i + 0.5) * dr
        ring = 0.0
        for j in range(SECTORS):
            a = (j + 0.5) * dth
            px, py = x1 + r * math.sin(a), y1 + r * math.cos(a)
            if not (px - x0) ** 2 + (py - y0) ** 2 < R * R:
                continue
            fx = math.floor((px - grid[0, 0]) / grid[0, 3])
            fy = math.floor((py - grid[0, 1]) / grid[0, 4])
            if not (0 <= fx < cells[0, 0] and 0 <= fy < cells[0, 1]):
                continue  # off the grid: no material
            top = float(heights[0, fx, fy])
            for k in range(count[0] - 1):
                a_, e = (head[0] + k) % cap, (head[0] + k + 1) % cap
                top = min(top, sweep_cover_z(px, py, *points[0, a_], *points[0, e], R, RIM_TOL))
            last = (head[0] + count[0] - 1) % cap
            top = min(top, sweep_cover_z(px, py, *points[0, last], x0, y0, z0, R, RIM_TOL))
            d = min(top, z0) - bottom
            if d > 0.0:
                ring += d
        vol += ring * r * dr * dth
        per_r += ring * dr * dth
    if not vol > 0.0:
        return 0.0, 0.0, 0.0
    w = max(OMEGA, OMEGA_FLOOR)
    mrr = vol / H
    return KA * KT * per_r / (H * w), KT * mrr / w, mrr


def _case(rng, kind):
    """Stock row 0 (10 x 8 mm, top 0, some cells lowered) and a ring buffer of 24 slots ending near the tool."""
    nx, ny = 40, 32
    heights = np.zeros((1, nx, ny), dtype=np.float32)
    heights[0, rng.integers(0, nx, 200), rng.integers(0, ny, 200)] = -rng.uniform(0.0, 2e-3, 200)
    grid = np.array([[0.0, 0.0, -5e-3, CELL, CELL]])
    cells = np.array([[nx, ny]], dtype=np.int64)
    cap = 24
    n = int(rng.integers(2, cap - 1))
    level = -rng.uniform(0.0, 1.5e-3)
    jitter = 10.0 ** rng.uniform(-12.0, -6.0)
    if kind == "pass":  # an XY pass at a jittering Z, ending at the tool
        xs = np.linspace(rng.uniform(-4e-3, 4e-3), rng.uniform(2e-3, 8e-3), n)
        ys = np.linspace(rng.uniform(0.0, 8e-3), rng.uniform(0.0, 8e-3), n)
        zs = level + jitter * rng.standard_normal(n)
    elif kind == "plunge":  # a pass above, then a descent on one axis
        xs = np.full(n, rng.uniform(-1e-3, 11e-3))
        ys = np.full(n, rng.uniform(-1e-3, 9e-3))
        xs[: n // 2] += np.linspace(-4e-3, 0.0, n // 2)
        zs = np.linspace(5e-4, level, n)
    else:  # "off": the whole path and disc beside the block
        xs = np.linspace(-12e-3, -9e-3, n)
        ys = np.linspace(-2e-3, 3e-3, n)
        zs = np.full(n, level)
    points = np.zeros((1, cap, 3))
    head = np.array([int(rng.integers(0, cap))], dtype=np.int64)
    count = np.array([n], dtype=np.int64)
    for k in range(n):
        points[0, (head[0] + k) % cap] = xs[k], ys[k], zs[k]
    last = points[0, (head[0] + n - 1) % cap]
    step = rng.uniform(0.0, 2e-4, 2) * rng.choice([-1.0, 1.0], 2)
    x0, y0 = last[0] + step[0], last[1] + step[1]
    z0 = last[2] + jitter * rng.standard_normal()
    move = rng.uniform(0.0, 1e-4, 2) * rng.choice([-1.0, 1.0], 2)
    dz = jitter * abs(rng.standard_normal()) if kind == "pass" else rng.uniform(0.0, 2e-5)
    return heights, grid, cells, points, head, count, x0, y0, z0, x0 + move[0], y0 + move[1], z0 - dz


@pytest.mark.parametrize("kind", ["pass", "plunge", "off"])
def test_axial_cut_equals_the_full_quadrature_bit_for_bit(kind):
    rng = np.random.default_rng({"pass": 1, "plunge": 2, "off": 3}[kind])
    out = np.zeros(3)
    nonzero = 0
    for _ in range(12):
        args = _case(rng, kind)
        axial_cut(*args[:6], 0, *args[6:], R, OMEGA, KT, KA, H, out)
        expected = _reference(*args)
        assert (out[AX_THRUST], out[AX_TORQUE], out[AX_MRR]) == expected
        nonzero += expected[2] > 0.0
    if kind == "off":
        assert nonzero == 0
    else:
        assert nonzero >= 3, nonzero  # the cases reach material (not only the exits)
