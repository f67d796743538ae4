"""Cutting-effect terms (fmus_src.cutting.effects) against closed-form values."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting import effects as fx


def test_runout_offsets_and_chip_thickness_conserve_the_feed():
    r = fx.runout_radius_offsets(2, 10e-6, 0.0)
    np.testing.assert_allclose(r, [10e-6, -10e-6], atol=1e-18)
    h = fx.runout_chip_thickness(np.array([50e-6, 50e-6]), 2, 10e-6, 0.0)
    np.testing.assert_allclose(h, [70e-6, 30e-6], atol=1e-18)
    # over one revolution the teeth remove the nominal feed in total (while none loses contact)
    h4 = fx.runout_chip_thickness(np.full(4, 30e-6), 4, 5e-6, 0.7)
    assert h4.sum() == pytest.approx(4 * 30e-6, rel=1e-12)
    assert np.all(fx.runout_chip_thickness(np.array([5e-6, 5e-6]), 2, 10e-6, 0.0) >= 0.0)


def test_helix_lag_and_smoothing_keep_the_mean():
    assert fx.helix_lag_angle(6e-3, 6e-3, math.radians(30)) == pytest.approx(2 * math.tan(math.radians(30)))
    n = 360
    phi = 2 * np.pi * np.arange(n) / n
    force = np.where(np.sin(phi) > 0, np.sin(phi), 0.0)  # half-immersion pulse
    smooth = fx.helix_smoothed(phi, force, math.radians(40.5))
    assert smooth.mean() == pytest.approx(force.mean(), rel=1e-12)
    assert smooth.max() < force.max()
    np.testing.assert_array_equal(fx.helix_smoothed(phi, force, 0.0), force)


def test_edge_forces_only_on_engaged_teeth():
    ft, fr = fx.edge_forces(20e3, 10e3, np.array([2e-3, 2e-3]), np.array([True, False]))
    np.testing.assert_allclose(ft, [40.0, 0.0])
    np.testing.assert_allclose(fr, [20.0, 0.0])


def test_deflection_balances_the_radial_force():
    kt, ke, d, k, h0 = 1.23e9, 0.5, 2e-3, 2e6, 50e-6
    h = fx.deflected_chip_thickness(np.array(h0), kt, ke, np.array(d), k)
    assert h0 - h == pytest.approx(ke * kt * d * h / k, rel=1e-12)  # removed chip = deflection
    assert fx.deflected_chip_thickness(np.array(h0), kt, ke, np.array(d), 0.0) == h0


def test_wear_and_droop():
    np.testing.assert_allclose(fx.wear_factor(np.array([0.0, 60.0]), 0.05 / 60.0), [1.0, 1.05])
    assert fx.drooped_speed(np.array(800.0), np.array(2.0), 5.0) == pytest.approx(790.0)


def test_chatter_frequency_off_the_spindle_harmonics():
    rng = np.random.default_rng(0)
    t = np.arange(0, 0.5, 1e-4)
    spindle = 6000.0  # 100 Hz, 2 flutes: tooth passing 200 Hz
    forced = 50 * np.sin(2 * np.pi * 200 * t) + 20 * np.sin(2 * np.pi * 100 * t)
    assert fx.chatter_frequency(t, forced + rng.normal(0, 1, t.size), spindle) is None
    chatter = forced + 40 * np.sin(2 * np.pi * 1234 * t)
    assert fx.chatter_frequency(t, chatter, spindle) == pytest.approx(1234, abs=2.0)
