"""The independent truth's end-edge thrust (orchestrator.diagnose.truth_thrust), against numbers by hand.

6 mm 2-flute end mill, Kt = 1230 N/mm2, ka = 0.28, S6000, plunge at F600: axial feed per tooth
h_a = F / (N S) = 0.05 mm, thrust N ka Kt h_a R = 103.32 N at every instant once the tool is a tooth period
into solid; with the axis on the stock's edge, half the end disc is in material (half the thrust); a slot at
constant depth has no axial chip (0 N); in the air 0 N.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from orchestrator.diagnose.truth_thrust import truth_thrust

KT, KA, R, N = 1.23e9, 0.28, 3e-3, 2
OMEGA = 6000.0 * 2 * math.pi / 60.0
VZ = 600.0 / 60e3   # m/s
THRUST = N * KA * KT * (VZ * 2 * math.pi / (N * OMEGA)) * R
LOWER, UPPER = np.array([0.0, 0.0, -0.01]), np.array([0.02, 0.02, 0.0])


def _run(x, y, z):
    t = 20e-6 * np.arange(x.size)
    pos = np.column_stack([x, y, z])
    omega = np.full(t.size, OMEGA)
    return t, truth_thrust(t, pos, omega, OMEGA * t + 0.3, R, N, KT, KA, LOWER, UPPER)


def _plunge(x0):
    n = 15000   # 0.3 s: from 0.5 mm above the top face to 2.5 mm deep
    t = 20e-6 * np.arange(n)
    z = 0.5e-3 - VZ * t
    return _run(np.full(n, x0), np.full(n, 0.01), z)


def test_hand_value():
    assert THRUST == pytest.approx(103.32, abs=1e-9)


def test_plunge_into_solid_thrust_by_hand():
    t, thrust = _plunge(0.01)
    z = 0.5e-3 - VZ * t
    deep = z < -0.2e-3           # more than a tooth period (0.05 mm) into the stock
    assert thrust[deep] == pytest.approx(THRUST, rel=2e-3)
    assert np.all(thrust[z > 1e-9] == 0.0)           # in the air
    assert np.all(thrust <= THRUST * (1 + 2e-3))      # entering: the chip grows from 0


def test_plunge_on_the_stock_edge_engages_half_the_end_disc():
    t, thrust = _plunge(0.0)
    z = 0.5e-3 - VZ * t
    # 12 points along each edge over the revolution: half of them in material on average
    assert float(np.mean(thrust[z < -0.2e-3])) == pytest.approx(0.5 * THRUST, rel=0.02)


def test_a_slot_at_constant_depth_has_no_thrust():
    n = 10000
    t = 20e-6 * np.arange(n)
    x = -4e-3 + 10e-3 * t          # 600 mm/min along +x at 1 mm depth, into the stock
    _, thrust = _run(x, np.full(n, 0.01), np.full(n, -1e-3))
    assert np.all(thrust == 0.0)
