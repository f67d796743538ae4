"""The twin's chip is what the previous tooth left: the tool-centre displacement over the last tooth period.

Sim & Lee 2023 (Eq. 10-11) take the chip from the change of the tool-centre position over one tooth period
``T``; the cutting kernels take it as ``c(t + h) - c(t + h - T)`` from each member's record of its last steps
(:func:`fmus_src.cutting.kernel.chord_feed`). At a constant feed that is the step velocity times ``T`` (the
kernels' former chip); in a deceleration ``x = v t - a t^2 / 2`` it is ``v T - a T (2 t - T) / 2``, short of the
step velocity times ``T`` by ``a T (T - h) / 2``. Checked:

* the chord itself against that closed form, the fallbacks (no history, ``T <= h``, a stopped spindle);
* the Z-map component's force on a decelerating full slot against the closed form ``Kt a h_chord sin(phi)
  sqrt(1 + Ke^2)`` (one tooth of two in the slot), with the numpy and the compiled kernels bit-identical
  and a member's figures those of its solo run;
* the path-mode component against the independent truth on a slot that stops in the material: in
  ``tests/test_diagnose_cutting_two_flutes.py`` (the diagnosis replay without its step split).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting import CuttingLoad
from fmus_src.cutting.kernel import (CHIP_HISTORY_WIDTH, H_COUNT, chord_advance, chord_advance_all, chord_feed,
                                     chord_feeds)

OMEGA = 6000 * 2 * math.pi / 60  # rad/s
PERIOD = 2 * math.pi / (2 * OMEGA)  # 2 flutes: 5 ms
H = 1e-3
KT, KE = 1.23e9, 0.5
DEPTH = 2e-3
V0 = 7.5e-3  # 450 mm/min: 37.5 um per tooth
T_DEC, T_STOP = 0.02, 0.04  # constant feed until T_DEC, then a uniform stop over T_STOP
ACC = V0 / T_STOP


def slot_x(t):
    """Tool-centre x of the slot [m]: constant feed, then a uniform deceleration to a stop."""
    t = np.asarray(t, float)
    td = np.clip(t - T_DEC, 0.0, T_STOP)
    return 0.005 + V0 * np.minimum(t, T_DEC) + V0 * td - 0.5 * ACC * td ** 2


def test_chord_of_a_decelerating_path_and_its_fallbacks():
    hist = np.zeros(CHIP_HISTORY_WIDTH)
    t = np.arange(0, 40) * H
    x = V0 * t - 0.5 * 0.2 * t ** 2
    y = 0.3 * x  # a straight line at an angle: both components scale alike
    for k in range(1, t.size):
        dpx, dpy = x[k] - x[k - 1], y[k] - y[k - 1]
        fx, fy = chord_feed(hist, dpx, dpy, H, OMEGA, 2)
        if t[k] < PERIOD - 1e-9:  # the history does not reach back T yet: the step velocity times T
            assert (fx, fy) == (dpx / H * PERIOD, dpy / H * PERIOD)
        else:  # x(t) - x(t - T) = v T - a T (2 t - T) / 2, exactly (T is five steps)
            exact = V0 * PERIOD - 0.2 * PERIOD * (2 * t[k] - PERIOD) / 2
            assert fx == pytest.approx(exact, rel=1e-9)
            assert fy == pytest.approx(0.3 * exact, rel=1e-9)
            # the step velocity times T is short by a T (T - h) / 2 (0.2 * 5 ms * 4 ms / 2 = 2 um)
            assert fx - dpx / H * PERIOD == pytest.approx(0.2 * PERIOD * (PERIOD - H) / 2, rel=1e-6)
        chord_advance(hist, H, dpx, dpy, OMEGA)
    # T <= h: the chord lies within the step, the former formula bit for bit
    fast = 60000 * 2 * math.pi / 60  # 2 flutes at 60000 rpm: T = 0.5 ms
    assert chord_feed(hist, 3e-6, 1e-6, H, fast, 2) == (3e-6 / H * (math.pi / fast), 1e-6 / H * (math.pi / fast))
    # a step with the spindle stopped clears the history: the step velocity times T again
    chord_advance(hist, H, 1e-6, 0.0, 0.0)
    assert hist[H_COUNT] == 0.0
    assert chord_feed(hist, 7e-6, 0.0, H, OMEGA, 2) == (7e-6 / H * PERIOD, 0.0)


def test_chord_at_constant_feed_is_the_step_velocity_times_the_period():
    # 50 steps of 1 ms at 0.1 m/s along a line far from the origin, 3 members at 3 speeds (T = 5, 1.67, 0.5 ms)
    B = 3
    hist = np.zeros((B, CHIP_HISTORY_WIDTH))
    omega = np.array([OMEGA, 3 * OMEGA, 10 * OMEGA])
    flutes = np.array([2, 2, 2])
    p0 = np.array([0.4123, -0.2871, -0.002])
    step = np.array([0.1, 0.05, 0.0]) * H
    for k in range(50):
        a, b = p0 + k * step, p0 + (k + 1) * step
        dp = np.broadcast_to(b - a, (B, 3)).copy()
        feed = chord_feeds(hist, dp, H, omega, flutes)
        before = dp[:, :2] / H * (2 * math.pi / (flutes * omega))[:, None]
        np.testing.assert_allclose(feed, before, rtol=1e-12, atol=0)
        chord_advance_all(hist, H, dp, omega, np.zeros(B, bool))


def _slot(batch=1, **kw):
    params = dict(tool_diameter=6e-3, flutes=2, kt=KT, ke=KE, stock_x_min=0.0, stock_x_max=0.03,
                  stock_y_min=0.0, stock_y_max=0.02, stock_z_min=-0.01, stock_z_max=0.0)
    params.update(kw)
    comp = CuttingLoad("cut", batch=batch, **params)
    comp.set("x_position", slot_x(0.0))
    comp.set("y_position", 0.01)
    comp.set("z_position", -DEPTH)
    comp.set("spindle_speed", OMEGA)
    comp.setup(0.0)
    return comp


def _run_slot(comp, n_steps, x_of=slot_x):
    fc, chip, angle = [], [], []
    for k in range(n_steps):
        comp.set("x_position", x_of((k + 1) * H))
        comp.do_step(k * H, H)
        fc.append(comp.get("fc").copy())
        chip.append(comp.get("chip_thickness").copy())
        angle.append(comp.get("spindle_angle").copy())
    return np.array(fc), np.array(chip), np.array(angle)


@pytest.mark.parametrize("compiled", [False, True])
def test_zmap_force_in_a_deceleration_is_that_of_the_tooth_period_chip(monkeypatch, compiled):
    monkeypatch.setattr(CuttingLoad, "use_compiled", compiled)
    n = int(round((T_DEC + T_STOP) / H)) - 1  # up to 1 ms before the stop
    fc, chip, angle = _run_slot(_slot(), n)
    t = np.arange(1, n + 1) * H
    chord = slot_x(t) - slot_x(t - PERIOD)
    # one tooth of two in the full slot: phi in (0, pi) from +y clockwise, chip = chord sin(phi) (feed along +x)
    phi = np.mod(angle[:, 0], math.pi)
    ok = (t >= PERIOD - 1e-9) & (np.sin(phi) > 0.3)
    expected = KT * DEPTH * chord * np.sin(phi) * math.hypot(1.0, KE)
    assert ok.sum() > 20
    np.testing.assert_allclose(fc[ok, 0], expected[ok], rtol=1e-6)
    np.testing.assert_allclose(chip[ok, 0], (chord * np.sin(phi))[ok], rtol=1e-6)
    # in the deceleration the former chip (step velocity times T) would be a T (T - h) / 2 short: >= 5 %
    dec = ok & (t > T_DEC + PERIOD)
    former = (slot_x(t) - slot_x(t - H)) / H * PERIOD
    assert np.all(chord[dec] - former[dec] > 0.05 * chord[dec])
    # at the constant feed before it, the former chip (v T) within 1e-12
    const = ok & (t <= T_DEC)
    np.testing.assert_allclose(fc[const, 0], (KT * DEPTH * V0 * PERIOD * np.sin(phi) * math.hypot(1.0, KE))[const],
                               rtol=1e-9)


def test_zmap_chip_history_numpy_and_compiled_bit_identical_members_independent(monkeypatch):
    n = 45
    # member 1 decelerates harder and has another Kt: its figures are its own, whatever batch it is in
    def x2(t):
        t = np.asarray(t, float)
        return 0.005 + V0 * t - 0.5 * 0.1 * t ** 2
    runs = {}
    for compiled in (False, True):
        monkeypatch.setattr(CuttingLoad, "use_compiled", compiled)
        both = _slot(batch=2, kt=np.array([KT, 0.9 * KT]))
        res = []
        for k in range(n):
            both.set("x_position", np.array([slot_x((k + 1) * H), x2((k + 1) * H)]))
            both.do_step(k * H, H)
            res.append(np.stack([both.get("fx"), both.get("fy"), both.get("fx_mean"), both.get("spindle_torque")]))
        runs[compiled] = np.array(res)
        solo = _slot(kt=0.9 * KT)
        alone = []
        for k in range(n):
            solo.set("x_position", x2((k + 1) * H))
            solo.do_step(k * H, H)
            alone.append(np.stack([solo.get("fx"), solo.get("fy"), solo.get("fx_mean"), solo.get("spindle_torque")]))
        np.testing.assert_array_equal(runs[compiled][..., 1], np.array(alone)[..., 0])
    np.testing.assert_array_equal(runs[False], runs[True])
    assert np.abs(runs[True][:, 0]).max() > 50.0  # it did cut
