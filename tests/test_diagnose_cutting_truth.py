"""The truth cutting generator (orchestrator.diagnose.truth_cutting) against closed forms and against the twin.

Two implementations of the same physics written independently (the truth sums axial slices tooth by tooth
with the chip from the path, the twin integrates the helical flute and chip forms in closed form) must agree on a
straight full slot at constant feed; closed forms come from the per-tooth mechanistic model (Altintas ch. 2).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting.path_component import PathCuttingLoad
from fmus_src.cutting.table import build_engagement_table
from orchestrator.diagnose.truth_cutting import CUTTING_PARAMETERS, _Q, simulate_cutting

R, N, KT, KE, DEPTH = 3e-3, 3, 1.23e9, 0.5, 2e-3
V, OMEGA, DT = 7.5e-3, 6000 * 2 * math.pi / 60, 20e-6
STOCK = ([0.0, 0.0, -0.006], [0.02, 0.02, 0.0])


def _packed(**effects):
    q = dict.fromkeys(_Q, 0.0)
    q.update(radius=R, flutes=N, kt=KT, kr=KE * KT, theta0=0.3)
    for (effect, name), (key, factor) in CUTTING_PARAMETERS.items():
        if effect in effects and name in effects[effect]:
            q[key] = effects[effect][name] * factor
    return np.array([q[k] for k in _Q])


@pytest.fixture(scope="module")
def slot():
    path = np.array([[-0.01, 0.01, -DEPTH], [0.03, 0.01, -DEPTH]])
    table = build_engagement_table(path, 2 * R, *STOCK, 1e-4)
    t = np.arange(0.0, 1.8, DT)
    pos = np.column_stack([-0.01 + V * t, np.full_like(t, 0.01), np.full_like(t, -DEPTH)])
    return table, t, pos


def _truth(slot, **effects):
    table, t, pos = slot
    return simulate_cutting(table, t, pos, np.full(t.size, OMEGA), _packed(**effects))


def _analytic(theta, kt=KT, ke=KE, depth=DEPTH, scale=1.0):
    """Force on the workpiece of a full slot: per tooth Ft = Kt d h, Fr = Ke Ft, h = fz sin(phi) on [0, pi)."""
    fz = V * 2 * math.pi / (N * OMEGA)
    fx = np.zeros_like(theta)
    fy = np.zeros_like(theta)
    for j in range(N):
        phi = np.mod(theta + j * 2 * math.pi / N, 2 * math.pi)
        h = np.where(phi < math.pi, fz * np.sin(phi), 0.0) * scale
        ft = kt * depth * h
        fr = ke * ft
        fx += ft * np.cos(phi) + fr * np.sin(phi)
        fy += -ft * np.sin(phi) + fr * np.cos(phi)
    return fx, fy


def test_truth_slot_equals_the_per_tooth_closed_form(slot):
    run = _truth(slot)
    m = (run.t > 1.5) & (run.t < 1.6)
    fx, fy = _analytic(run.theta[m])
    np.testing.assert_allclose(run.fx[m], fx, atol=1e-9 * np.abs(fx).max())
    np.testing.assert_allclose(run.fy[m], fy, atol=1e-9 * np.abs(fy).max())
    # the slot's mean force on the workpiece: (N a c / 4)(Kr, -Kt) (Altintas)
    fz = V * 2 * math.pi / (N * OMEGA)
    period = (run.t > 1.5) & (run.t <= 1.5 + 2 * math.pi / OMEGA)  # the tool fully in the slot
    assert run.fx[period].mean() == pytest.approx(N * DEPTH * fz * KE * KT / 4, rel=2e-3)
    assert run.fy[period].mean() == pytest.approx(-N * DEPTH * fz * KT / 4, rel=2e-3)


def test_truth_deflection_of_one_tooth_is_the_closed_form(slot):
    # with one tooth's own radial force: h = h0 / (1 + Kr d / k); for N = 3 two teeth may cut at once, the
    # per-tooth model still gives each tooth that factor
    k = 10e6
    run = _truth(slot, tool_deflection={"stiffness_N_per_um": 10.0})
    m = (run.t > 1.5) & (run.t < 1.6)
    fx, fy = _analytic(run.theta[m], scale=1.0 / (1.0 + KE * KT * DEPTH / k))
    np.testing.assert_allclose(run.fx[m], fx, atol=1e-6)
    np.testing.assert_allclose(run.fy[m], fy, atol=1e-6)


def test_truth_wear_and_droop(slot):
    ref = _truth(slot)
    run = _truth(slot, tool_wear={"rate_percent_per_min": 60.0})
    cut_time = np.cumsum(run.cutting) * DT
    m = run.cutting & (run.t > 1.0)
    # wear: 60 %/min = 1 %/s of cutting time; every coefficient is (1 + 0.01 t_cut) times the fresh tool's
    ratio = np.hypot(run.fx[m], run.fy[m]).mean() / np.hypot(ref.fx[m], ref.fy[m]).mean()
    assert ratio == pytest.approx(1.0 + 0.01 * cut_time[m].mean(), rel=2e-4)
    # droop: steady speed drop = droop x mean torque
    run = _truth(slot, spindle_droop={"rpm_per_Nm": 100.0})
    m = run.cutting & (run.t > 1.4)  # the tool fully in the slot: torque periodic
    drop_rpm = (OMEGA - run.omega[m].mean()) * 60 / (2 * math.pi)
    assert drop_rpm == pytest.approx(100.0 * run.torque[m].mean(), rel=0.01)


@pytest.mark.parametrize("effects, component", [
    ({}, {}),
    ({"runout": {"eccentricity_um": 3.0, "phase_deg": 40.0}},
     {"runout_eccentricity": 3e-6, "runout_phase": math.radians(40.0)}),
    ({"edge_force": {"kte_N_per_mm": 8.0, "kre_N_per_mm": 5.0}},
     {"edge_force_tangential": 8e3, "edge_force_radial": 5e3}),
    ({"tool_deflection": {"stiffness_N_per_um": 10.0}}, {"tool_stiffness": 1e7}),
    ({"helix_angle": {"helix_deg": 30.0}}, {"helix_angle": math.radians(30.0)}),
])
def test_truth_agrees_with_the_twins_cutting_component(slot, effects, component):
    table, t, pos = slot
    run = _truth(slot, **effects)
    ts = np.arange(0.0, 1.8, 2e-4)
    p = np.column_stack([np.interp(ts, t, pos[:, i]) for i in range(3)])
    comp = PathCuttingLoad("cutting", batch=1, tool_diameter=2 * R, flutes=N, kt=KT, ke=KE,
                           stock_x_min=0.0, stock_y_min=0.0, stock_z_min=-0.006, stock_x_max=0.02, stock_y_max=0.02,
                           stock_z_max=0.0, initial_spindle_angle=float(np.interp(0.0, t, run.theta)), **component)
    comp.attach_table(table)
    for i, a in enumerate("xyz"):
        comp.set(f"{a}_position", p[0, i])
    comp.setup(0.0)
    out = np.zeros((ts.size, 2))
    for k in range(ts.size - 1):
        for i, a in enumerate("xyz"):
            comp.values[f"{a}_position"][...] = p[k + 1, i]
        comp.values["spindle_speed"][...] = OMEGA
        comp.do_step(ts[k], ts[k + 1] - ts[k])
        out[k + 1] = comp.values["fx"][0], comp.values["fy"][0]
    m = (ts > 1.3) & (ts < 1.7)
    peak = float(np.abs(np.interp(ts[m], t, run.fy)).max())
    ex = out[m, 0] - np.interp(ts[m], t, run.fx)
    ey = out[m, 1] - np.interp(ts[m], t, run.fy)
    if "helix_angle" in effects:
        # the twin's exact axial integral against 50 um slices (each cutting with its fraction in the arc):
        # a midpoint rule in z, error (50 um tan(30 deg) / R)^2 / 24 ~ 4e-6 of a flute's force, plus the
        # truth's 20 us grid against the twin's step (the same instants here)
        assert np.abs(np.hypot(ex, ey)).max() < 5e-5 * peak
    else:
        assert np.abs(np.hypot(ex, ey)).max() < 1e-6


# ------------------------------------------------------------------ chatter: how many surfaces to remember
CHATTER = {"frequency_Hz": 1150.0, "damping_ratio": 0.03, "stiffness_N_per_um": 30.0}


def _chatter_run(slot, passes=0, dt=DT):
    from orchestrator.diagnose.truth_cutting import fine_grid

    table, t, pos = slot
    if dt != DT:
        t = fine_grid(0.0, float(t[-1]), dt)
        pos = np.column_stack([-0.01 + V * t, np.full_like(t, 0.01), np.full_like(t, -DEPTH)])
    q = _packed(chatter=CHATTER)
    q[_Q.index("passes")] = passes
    run = simulate_cutting(table, t, pos, np.full(t.size, OMEGA), q)
    from orchestrator.diagnose.cutting_chatter import envelope

    step = max(int(round(1e-4 / dt)), 1)   # 10 kHz is plenty for a 1150 Hz vibration
    tc, env = envelope(run.t[::step], run.fx[::step], run.fy[::step], 1145.0)
    tail = run.t > run.t[-1] - 0.3           # the limit cycle: the last 0.3 s of the 2 mm slot
    return float(np.median(env[tc > run.t[-1] - 0.3])), run.lookback[tail & run.cutting]


def test_truth_chatter_remembers_as_many_surfaces_as_the_limit_cycle_needs(slot):
    # beyond the stability limit (the 2 mm slot, 1150 Hz, 3 %, 30 N/um) teeth jump out of the cut and the next
    # ones cut the lowest surface left by ANY earlier tooth (multiple regeneration, Altintas ch. 3)
    from fmus_src.cutting.effect_model import MAX_PASSES
    from orchestrator.diagnose.truth_cutting import CHATTER_PASSES

    assert MAX_PASSES == CHATTER_PASSES   # one modelling choice in the twin and the truth
    lc_default, _ = _chatter_run(slot)
    lc_wide, back = _chatter_run(slot, passes=2 * CHATTER_PASSES)
    lc_rev, _ = _chatter_run(slot, passes=N)
    assert lc_wide > 20.0                                       # it does chatter
    # with twice as many surfaces allowed, teeth look back CHATTER_PASSES periods in > 1 % of the cutting
    # instants and further in < 0.5 %: the limit cycle is converged
    assert np.mean(back == CHATTER_PASSES) > 0.01 and np.mean(back > CHATTER_PASSES) < 0.005
    assert lc_default == pytest.approx(lc_wide, rel=0.01)
    assert lc_rev > 1.1 * lc_wide                               # one revolution is not enough


def test_truth_chatter_limit_cycle_is_converged_in_the_time_step(slot):
    # the dynamic chip is taken at the middle of the step over which the force is held: a 4x finer step
    # gives the same limit cycle (start-of-step u and end-of-step delayed u gave 77 against 70.6 N)
    lc_20us, _ = _chatter_run(slot)
    lc_5us, _ = _chatter_run(slot, dt=5e-6)
    assert lc_20us == pytest.approx(lc_5us, rel=0.02)
