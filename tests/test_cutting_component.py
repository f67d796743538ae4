"""CuttingLoad driven along prescribed tool paths, against closed-form milling mechanics.

Expected values are derived here by hand (Altintas, Manufacturing Automation, ch. 2): for feed
along +x with feed per tooth c, axial depth a, N teeth, Kr = Ke Kt, the mean force ON THE TOOL is

    Fx = N a c / (8 pi) [Kt cos 2p - Kr (2p - sin 2p)]  from p_st to p_ex
    Fy = N a c / (8 pi) [Kt (2p - sin 2p) + Kr cos 2p]  from p_st to p_ex

and the component outputs the force on the workpiece (the negative).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.component import ComponentError
from fmus_src.cutting import CuttingError, CuttingLoad

KT, KE = 1.23e9, 0.5
R = 3e-3
N = 2
H = 1e-3
TOOTH_PERIOD = 3.8e-3  # 19 steps = 5 tooth periods exactly
OMEGA = 2 * math.pi / (N * TOOTH_PERIOD)  # 7894.7 rpm


def mean_force_on_workpiece(a, c, p_st, p_ex, n=N):
    kr = KE * KT

    def fx(p):
        return KT * math.cos(2 * p) - kr * (2 * p - math.sin(2 * p))

    def fy(p):
        return KT * (2 * p - math.sin(2 * p)) + kr * math.cos(2 * p)

    k = n * a * c / (8 * math.pi)
    return np.array([-k * (fx(p_ex) - fx(p_st)), -k * (fy(p_ex) - fy(p_st))])


def make(batch=1, **kw):
    params = dict(tool_diameter=2 * R, flutes=N, kt=KT, ke=KE, stock_x_min=0.0, stock_x_max=0.012,
                  stock_y_min=-0.01, stock_y_max=0.01, stock_z_min=-0.01, stock_z_max=0.0)
    params.update(kw)
    return CuttingLoad("cut", batch=batch, **params)


def drive(comp, xs, ys, zs, omega=OMEGA, names=("fx_mean", "fy_mean", "fc", "fc_peak", "mrr", "spindle_angle"),
          k0=0):
    """Step the component through positions (K, B) (end of each step); returns dict of (K, B) arrays."""
    shape = (np.shape(xs)[0], comp.batch)
    xs, ys, zs = (np.broadcast_to(np.asarray(v, float), shape) for v in (xs, ys, zs))
    out = {n: [] for n in names}
    comp.set("spindle_speed", omega)
    for k in range(xs.shape[0]):
        comp.set("x_position", xs[k])
        comp.set("y_position", ys[k])
        comp.set("z_position", zs[k])
        comp.do_step((k0 + k) * H, H)
        for n in names:
            out[n].append(comp.get(n))
    return {n: np.array(v) for n, v in out.items()}


def straight_cut(comp, feed_per_tooth, depth, y=0.0, measure_steps=190, x_start=-R - 0.5e-3, steady_x=R + 0.2e-3):
    """Feed along +x at constant feed; mean workpiece force over measure_steps steady steps (integer periods)."""
    v = np.asarray(feed_per_tooth, float) / TOOTH_PERIOD
    comp.set("x_position", x_start)
    comp.set("y_position", y)
    comp.set("z_position", -np.asarray(depth, float))
    comp.set("spindle_speed", OMEGA)
    comp.setup(0.0)
    n_in = int(math.ceil((steady_x - x_start) / (np.min(v) * H)))
    k = np.arange(1, n_in + measure_steps + 1)[:, None]
    xs = x_start + v * k * H
    res = drive(comp, xs, y, -np.asarray(depth, float))
    sl = slice(n_in, n_in + measure_steps)
    return np.stack([res["fx_mean"][sl].mean(0), res["fy_mean"][sl].mean(0)], axis=-1), res


def test_slot_and_half_immersion_up_and_down_milling_match_closed_form():
    a, c = 2e-3, 5e-5
    # member 0: slot; 1: stock only at y >= 0 (up-milling half); 2: only y <= 0 (down-milling half)
    comp = make(batch=3, stock_y_min=[-0.01, 0.0, -0.01], stock_y_max=[0.01, 0.01, 0.0])
    f, _ = straight_cut(comp, c, a)
    expected = [mean_force_on_workpiece(a, c, 0, math.pi), mean_force_on_workpiece(a, c, 0, math.pi / 2),
                mean_force_on_workpiece(a, c, math.pi / 2, math.pi)]
    for got, exp in zip(f, expected):
        assert got == pytest.approx(exp, rel=0.02)
    # much better than the required 2 %: exact engagement from the near field, exact interval integration
    for got, exp in zip(f, expected):
        assert got == pytest.approx(exp, rel=2e-3)
    assert f[0] == pytest.approx([30.75, -61.5], rel=1e-6)  # N a c Kr / 4, -N a c Kt / 4


def test_force_scales_linearly_with_depth_and_feed_per_tooth():
    base_a, base_c = 1e-3, 3e-5
    comp = make(batch=4, stock_x_max=0.04)
    f, _ = straight_cut(comp, [base_c, 2 * base_c, base_c, 1.5 * base_c], [base_a, base_a, 2.5 * base_a, 2 * base_a])
    assert f[1] == pytest.approx(2 * f[0], rel=1e-6)
    assert f[2] == pytest.approx(2.5 * f[0], rel=1e-6)
    assert f[3] == pytest.approx(3 * f[0], rel=1e-6)


def test_mrr_equals_width_depth_feed_and_matches_removed_volume():
    a, c = 2e-3, 5e-5
    comp = make(batch=2, stock_y_min=[-0.01, 0.0])
    _, res = straight_cut(comp, c, a, measure_steps=190)
    v = c / TOOTH_PERIOD
    # steady MRR = radial width x depth x feed velocity (slot: 2R, half: R)
    steady = res["mrr"][-190:].mean(0)
    assert steady == pytest.approx([2 * R * a * v, R * a * v], rel=1e-3)
    # run on through the whole block and out, then the integral of MRR is the material removed:
    # exact analytic volume of the slot through the 12 mm block
    x_now = comp.get("x_position")
    k = np.arange(1, int((0.012 + R + 1e-3 - x_now[0]) / (v * H)) + 1)[:, None]
    more = drive(comp, x_now + v * k * H, 0.0, -a, k0=1000)
    total = (res["mrr"].sum(0) + more["mrr"].sum(0)) * H
    assert total == pytest.approx([0.012 * 2 * R * a, 0.012 * R * a], rel=2e-3)
    # the Z-map removed the same material up to its wall bias (cells within R + rho are cut)
    removed = comp.stock.removed_volume()
    assert removed == pytest.approx(total, rel=0.05)


def test_entry_and_exit_angles_of_partial_immersion_match_geometry():
    # radial immersion ae = 1.5 mm (25 %) on the +y side: up-milling from 0 to acos(1 - ae/R) = 60 deg;
    # on the -y side: down-milling from acos(ae/R - 1) = 120 deg to 180 deg
    a, c, ae = 2e-3, 5e-5, 1.5e-3
    omega = 2 * math.pi * 7777 / 60  # spindle angle at the sampling instants sweeps all phases
    comp = make(batch=2, stock_y_min=[R - ae, -0.01], stock_y_max=[0.01, -(R - ae)])
    x0 = 0.5e-3 + R
    comp.set("x_position", x0)
    comp.set("z_position", -a)
    comp.setup(0.0)
    v = c * N * omega / (2 * math.pi)
    k = np.arange(1, 400)[:, None]
    res = drive(comp, x0 + v * k * H, 0.0, -a, omega=omega)
    fc = res["fc"][20:]
    phi = np.mod(res["spindle_angle"][20:], math.pi)  # 2 teeth, pitch pi: fold onto one pitch
    tol = 0.02
    for m, (st, ex) in enumerate([(0.0, math.acos(1 - ae / R)), (math.acos(ae / R - 1), math.pi)]):
        inside = (phi[:, m] > st + tol) & (phi[:, m] < ex - tol)
        outside = (phi[:, m] < st - tol) | (phi[:, m] > ex + tol)
        if st == 0.0:
            outside &= phi[:, m] < math.pi - tol
            inside &= phi[:, m] > tol
        assert inside.sum() > 50 and outside.sum() > 50
        assert np.all(fc[inside, m] > 0.0)
        assert np.all(fc[outside, m] == 0.0)  # exactly zero between teeth (ae < tooth spacing)


def test_load_drops_to_zero_between_teeth_at_25_percent_immersion():
    a, c, ae = 2e-3, 5e-5, 1.5e-3
    comp = make(stock_y_min=R - ae)
    _, res = straight_cut(comp, c, a)
    fc = res["fc"][-190:, 0]
    # engaged 60 of 180 degrees per tooth pitch: one third of the samples carry load
    assert fc.min() == 0.0
    assert np.mean(fc > 0) == pytest.approx(1 / 3, abs=0.04)
    # the peak of an up-milling cut is at exit: Ft = Kt a c sin(60 deg), Fc = Ft sqrt(1 + Ke^2)
    peak_expected = KT * a * c * math.sin(math.acos(1 - ae / R)) * math.sqrt(1 + KE**2)
    assert res["fc_peak"][-190:, 0].max() == pytest.approx(peak_expected, rel=2e-3)
    assert np.all(res["fc_peak"] >= res["fc"] - 1e-9)


def test_slot_peak_load_is_caught_between_communication_points():
    a, c = 2e-3, 5e-5
    comp = make()
    _, res = straight_cut(comp, c, a)
    # slot with 2 teeth: one tooth engaged at a time, Fc = Kt a c sin(phi) sqrt(1 + Ke^2), max at 90 deg
    peak = KT * a * c * math.sqrt(1 + KE**2)
    fc_peak = res["fc_peak"][-190:, 0]
    assert fc_peak.max() == pytest.approx(peak, rel=1e-3)
    assert res["fc"][-190:, 0].max() <= peak * (1 + 1e-9)
    # every 1 ms step holds a maximum of the cycle or its neighbourhood: the per-step peak exceeds the sample
    assert np.all(fc_peak >= res["fc"][-190:, 0])


def test_second_pass_over_cut_material_is_an_air_cut():
    a, c = 2e-3, 5e-5
    comp = make(stock_x_max=0.008)
    x0, x1 = -R - 0.5e-3, 0.008 + R + 0.5e-3
    comp.set("x_position", x0)
    comp.set("z_position", -a)
    comp.setup(0.0)
    v = c / TOOTH_PERIOD
    n = int((x1 - x0) / (v * H)) + 1
    fwd = x0 + (x1 - x0) * np.arange(1, n + 1)[:, None] / n
    first = drive(comp, fwd, 0.0, -a)
    assert first["fc_peak"].max() > 50.0
    back = drive(comp, fwd[::-1], 0.0, -a, k0=n)  # return along the same path
    again = drive(comp, fwd, 0.0, -a, k0=2 * n)  # and once more in the cutting direction
    assert back["fc_peak"].max() == 0.0
    assert again["fc_peak"].max() == 0.0
    assert again["mrr"].max() == 0.0


def test_entering_and_leaving_the_part():
    a, c = 2e-3, 5e-5
    comp = make(stock_x_max=0.004)
    x0, x1 = -R - 0.5e-3, 0.004 + R + 0.5e-3
    comp.set("x_position", x0)
    comp.set("z_position", -a)
    comp.setup(0.0)
    v = c / TOOTH_PERIOD
    n = int((x1 - x0) / (v * H)) + 1
    xs = x0 + (x1 - x0) * np.arange(1, n + 1)[:, None] / n
    res = drive(comp, xs, 0.0, -a)
    x = xs[:, 0]
    fc = res["fc_peak"][:, 0]
    assert np.all(fc[x < -R - 1e-5] == 0.0)  # tool not yet touching the block face x = 0
    assert np.all(fc[x > 0.004 + R + 1e-5] == 0.0)  # tool left the block
    assert fc[(x > 1e-4) & (x < 0.004 - R)].min() > 0.0  # whole front half of the tool in the block


def test_plunge_gives_no_lateral_force_then_full_depth_when_feeding_sideways():
    comp = make()
    comp.set("x_position", 0.006)
    comp.set("z_position", 1e-3)
    comp.setup(0.0)
    zs = np.linspace(1e-3, -2e-3, 31)[1:, None]
    res = drive(comp, 0.006 + 0 * zs, 0.0, zs, names=("fc_peak", "axial_depth", "engaged_teeth"))
    # the 2D model has no chip without XY motion: no tooth is engaged while plunging
    assert res["fc_peak"].max() == 0.0 and res["engaged_teeth"].max() == 0
    v = 5e-5 / TOOTH_PERIOD
    xs = 0.006 + v * H * np.arange(1, 20)[:, None]
    side = drive(comp, xs, 0.0, -2e-3, names=("fc_peak", "axial_depth"), k0=30)
    assert side["fc_peak"].min() > 0.0
    assert side["axial_depth"].max() == pytest.approx(2e-3, abs=1e-8)


def test_spindle_angle_integrates_speed():
    comp = make(initial_spindle_angle=0.3, stock_x_max=0.0)
    comp.setup(0.0)
    res = drive(comp, np.zeros((7, 1)), 0.0, 0.0, omega=500.0, names=("spindle_angle",))
    k = np.arange(1, 8)
    assert res["spindle_angle"][:, 0] == pytest.approx(np.mod(0.3 + 500.0 * k * H, 2 * math.pi), abs=1e-9)


def test_batch_equals_separate_runs():
    a = 2e-3
    feeds = [4e-5, 6e-5, 8e-5]
    comp = make(batch=3)
    _, together = straight_cut(comp, feeds, a, measure_steps=38)
    for i, c in enumerate(feeds):
        single = make()
        _, alone = straight_cut(single, c, a, measure_steps=38, steady_x=R + 0.2e-3)
        n = alone["fc"].shape[0]
        for name in ("fx_mean", "fy_mean", "fc", "fc_peak", "mrr"):
            assert together[name][:n, i] == pytest.approx(alone[name][:, 0], rel=1e-9, abs=1e-9)


def test_air_only_stock_and_parameter_errors():
    comp = make(stock_x_max=0.0, stock_y_min=0.0, stock_y_max=0.0, stock_z_max=0.0)
    comp.setup(0.0)
    res = drive(comp, np.linspace(0, 0.01, 20)[:, None], 0.0, -1e-3)
    assert res["fc_peak"].max() == 0.0 and res["mrr"].max() == 0.0
    with pytest.raises(CuttingError, match="tool_diameter"):
        make(tool_diameter=-1.0).setup(0.0)
    with pytest.raises(ComponentError):
        make(spindle_rpm=1.0)


@pytest.mark.parametrize("alpha_deg", [90.0, 180.0, 225.0])
def test_slot_force_turns_with_the_feed_direction(alpha_deg):
    # the mechanics are invariant under a rotation about z (the spindle still turns clockwise):
    # feeding along (cos a, sin a) the mean force is the +x result rotated by a
    a, c = 2e-3, 5e-5
    al = math.radians(alpha_deg)
    u = np.array([math.cos(al), math.sin(al)])
    centre = np.array([0.01, 0.01])
    comp = make(stock_x_min=0.0, stock_x_max=0.02, stock_y_min=0.0, stock_y_max=0.02)
    v = c / TOOTH_PERIOD
    start = centre - 4e-3 * u
    comp.set("x_position", start[0])
    comp.set("y_position", start[1])
    comp.set("z_position", -a)
    comp.setup(0.0)
    n_in, n_meas = int(2e-3 / (v * H)), 190
    k = np.arange(1, n_in + n_meas + 1)[:, None]
    p = start + v * k * H * u
    res = drive(comp, p[:, 0:1], p[:, 1:2], -a)
    got = np.array([res["fx_mean"][n_in:, 0].mean(), res["fy_mean"][n_in:, 0].mean()])
    rot = np.array([[math.cos(al), -math.sin(al)], [math.sin(al), math.cos(al)]])
    assert got == pytest.approx(rot @ mean_force_on_workpiece(a, c, 0, math.pi), rel=2e-3, abs=0.05)


def test_reset_gives_a_fresh_stock():
    a, c = 2e-3, 5e-5
    comp = make()
    f1, _ = straight_cut(comp, c, a, measure_steps=38)
    comp.reset()
    f2, _ = straight_cut(comp, c, a, measure_steps=38)
    assert f2 == pytest.approx(f1, rel=1e-12)


def test_feeding_into_material_with_stopped_spindle_is_a_crash():
    comp = make(initial_spindle_angle=math.pi / 2)  # tooth 0 faces the feed direction
    comp.set("x_position", -R - 0.1e-3)
    comp.set("z_position", -1e-3)
    comp.setup(0.0)
    # 10 um per 1 ms step: the rim reaches the stock face x = 0 when the centre is at -R, after 10 steps
    expected = (r"cut: the tool feeds into the stock with the spindle stopped \(0 rpm\) at t = 0\.010000 s, "
                r"tool at X-3\.000 Y0\.000 Z-1\.000 mm: a crash")
    with pytest.raises(CuttingError, match=expected):  # no finite chip: a crash, not a force
        drive(comp, -R - 0.1e-3 + 1e-5 * np.arange(1, 30)[:, None], 0.0, -1e-3, omega=0.0)
