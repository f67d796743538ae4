"""DriveAxis effect terms (diagnosis): gravity, spring, ripple, reversal friction, table-side terms.

Expected values are analytic (free fall, energy balance, kinematic relations
of the motor-to-table terms); the compiled kernel must agree with the numpy
reference with the effects switched on.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.servo import DriveAxis, effect_parameters

KF = 2.0 * math.pi / 0.012
M = 600.0
H = 250e-6


def friction(fc: float, fs: float, vs: float = 1e-3, mu: float = 0.0) -> dict[str, float]:
    return {f"{k}_{d}": val for k, val in (("coulomb", fc), ("static", fs), ("stribeck_velocity", vs),
                                           ("viscous", mu)) for d in ("positive", "negative")}


def run(forces: list[tuple[float, float]], compiled: bool = True, h: float = H, batch: int = 1,
        **params: object) -> dict[str, np.ndarray]:
    d = DriveAxis("d", batch=batch, **{"mass": M, **params})
    d.use_compiled = compiled
    d.setup(0.0)
    rec: dict[str, list] = {"t": [], "x": [], "v": [], "xt": [], "u": []}
    k = 0
    for force, duration in forces:
        d.set("current_cmd", np.asarray(force) / KF)
        for _ in range(round(duration / h)):
            d.do_step(k * h, h)
            k += 1
            rec["t"].append(k * h)
            rec["x"].append(d.get("position"))
            rec["v"].append(d.get("velocity"))
            rec["xt"].append(d.get("table_position"))
            rec["u"].append(d.get("motor_force"))
    return {key: np.array(val) for key, val in rec.items()}


PROGRAM = [(900.0, 0.02), (-900.0, 0.04), (900.0, 0.03)]
BASE = friction(600.0, 700.0, 1e-3, 5000.0)


@pytest.mark.parametrize("compiled", [True, False])
def test_effects_off_table_equals_motor_and_results_unchanged(compiled):
    plain = run(PROGRAM, compiled, **BASE)
    zeros = {k: 0.0 for k in ("gravity_force", "gravity_spring", "reversal_friction_peak", "backlash_width",
                              "screw_stiffness", "pitch_slope", "thermal_drift_rate")}
    again = run(PROGRAM, compiled, **BASE, **zeros)
    np.testing.assert_array_equal(plain["x"], again["x"])
    np.testing.assert_array_equal(plain["xt"], plain["x"])


def test_gravity_alone_is_free_fall():
    # frictionless, no motor force: M x'' = -Fg -> x = -Fg t^2 / (2 M), exact (force constant)
    rec = run([(0.0, 0.02)], **friction(0.0, 0.0), gravity_force=1200.0)
    np.testing.assert_allclose(rec["x"][:, 0], -1200.0 / (2 * M) * rec["t"] ** 2, rtol=1e-12)


def test_gravity_with_spring_oscillates_about_the_balance_point():
    # M x'' = -Fg - k x: x(t) = -Fg/k + Fg/k cos(w t); the load is held per step (error O(w h))
    fg, k = 600.0, 6.0e6
    rec = run([(0.0, 0.05)], **friction(0.0, 0.0), gravity_force=fg, gravity_spring=k)
    w = math.sqrt(k / M)
    expected = -fg / k * (1.0 - np.cos(w * rec["t"]))
    amplitude = 2 * fg / k
    assert np.max(np.abs(rec["x"][:, 0] - expected)) < 2 * w * H * amplitude


def test_ripple_conserves_energy():
    # frictionless motion through the ripple potential U = A P / (2 pi) cos(2 pi x / P) (force A sin)
    amp, period = 80.0, 0.004
    d = DriveAxis("d", mass=M, **friction(0.0, 0.0), ripple_amplitude=amp, ripple_period=period)
    d.setup(0.0)
    d.set("current_cmd", 3000.0 / KF)
    for k in range(40):  # accelerate to ~0.2 m/s, then coast
        d.do_step(k * H, H)
    d.set("current_cmd", 0.0)
    x0, v0 = float(d.get("position")[0]), float(d.get("velocity")[0])

    def energy(x: float, v: float) -> float:
        return 0.5 * M * v * v + amp * period / (2 * math.pi) * math.cos(2 * math.pi * x / period)

    e0 = energy(x0, v0)
    spread = []
    for k in range(40, 440):
        d.do_step(k * H, H)
        spread.append(energy(float(d.get("position")[0]), float(d.get("velocity")[0])) - e0)
    ripple_energy = amp * period / math.pi
    # the velocity visibly changes with the ripple, the energy stays within the step-hold error
    assert np.max(np.abs(spread)) < 0.02 * ripple_energy


def test_reversal_friction_raises_break_away_and_follows_the_work_energy_balance():
    fc, peak, decay = 500.0, 200.0, 2e-4
    params = dict(**friction(fc, fc, 1e-3, 0.0), reversal_friction_peak=peak, reversal_friction_decay=decay)
    stuck = run([(fc + 0.5 * peak, 0.01)], **params)
    assert np.all(stuck["x"] == 0.0)
    f = fc + 1.5 * peak
    rec = run([(f, 0.03)], h=25e-6, **params)
    s, v = rec["x"][:, 0], rec["v"][:, 0]
    # 1/2 M v^2 = (F - Fc) s - Fr d (1 - exp(-s/d))
    expected = np.sqrt(2.0 / M * ((f - fc) * s - peak * decay * (1.0 - np.exp(-s / decay))))
    moving = s > 2 * decay
    np.testing.assert_allclose(v[moving], expected[moving], rtol=2e-3)
    without = run([(f, 0.03)], h=25e-6, **friction(fc, fc, 1e-3, 0.0))
    assert without["x"][-1, 0] > s[-1]


def test_reversal_friction_rearms_at_each_reversal():
    fc, peak, decay = 500.0, 300.0, 1e-4
    params = dict(**friction(fc, fc, 1e-3, 0.0), reversal_friction_peak=peak, reversal_friction_decay=decay)
    # forward, then a force that would reverse without the glitch but cannot break it
    rec = run([(1500.0, 0.02), (-(fc + 0.5 * peak), 0.05)], **params)
    base = run([(1500.0, 0.02), (-(fc + 0.5 * peak), 0.05)], **friction(fc, fc, 1e-3, 0.0))
    assert base["x"][-1, 0] < base["x"][:, 0].max() - 1e-4  # reverses without the term
    # stuck at the top: the term is re-armed at the first step after the sign change (step-hold), so the
    # reversal may start within that one step: nanometres, against 0.1 mm without the term
    np.testing.assert_allclose(rec["x"][-1, 0], rec["x"][:, 0].max(), rtol=0, atol=1e-8)


def test_table_side_terms_are_kinematic():
    k, b, slope, amp, period, rate = 2.0e8, 6e-6, 20e-6, 3e-6, 0.012, 1e-6
    rec = run(PROGRAM, **BASE, screw_stiffness=k, pitch_slope=slope, pitch_amplitude=amp, pitch_period=period,
              thermal_drift_rate=rate)
    x, u, t = rec["x"][:, 0], rec["u"][:, 0], rec["t"]
    expected = x + slope * x + amp * np.sin(2 * math.pi * x / period) - u / k + rate * t
    np.testing.assert_allclose(rec["xt"][:, 0], expected, rtol=0, atol=1e-15)


def test_backlash_lags_by_half_the_width_after_each_direction():
    b = 10e-6
    rec = run(PROGRAM, **BASE, backlash_width=b)
    x, xt, v = rec["x"][:, 0], rec["xt"][:, 0], rec["v"][:, 0]
    assert np.all(np.abs(x - xt) <= b / 2 + 1e-15)
    # steady motion forward: the table trails by b/2; backward: it leads by b/2
    fwd = np.flatnonzero(v > 0.005)
    bwd = np.flatnonzero(v < -0.005)
    np.testing.assert_allclose((x - xt)[fwd[fwd > 20]], b / 2, atol=1e-15)
    np.testing.assert_allclose((x - xt)[bwd[-20:]], -b / 2, atol=1e-15)


@pytest.mark.parametrize("effect", [
    dict(gravity_force=300.0, gravity_spring=2e5),
    dict(ripple_amplitude=60.0, ripple_period=0.006),
    dict(reversal_friction_peak=150.0, reversal_friction_decay=5e-5),
    dict(backlash_width=8e-6, screw_stiffness=1.5e8, pitch_amplitude=2e-6, pitch_period=0.012),
])
def test_compiled_kernel_matches_reference_with_effects(effect):
    a = run(PROGRAM, True, **BASE, **effect)
    r = run(PROGRAM, False, **BASE, **effect)
    for key in ("x", "v", "xt"):
        scale = float(np.max(np.abs(r[key])))
        np.testing.assert_allclose(a[key], r[key], rtol=1e-12, atol=1e-12 * scale, err_msg=key)


def test_batch_members_with_different_effects_equal_single_runs():
    gravity = np.array([0.0, 250.0, -100.0])
    peak = np.array([100.0, 0.0, 50.0])
    both = run(PROGRAM, batch=3, **BASE, gravity_force=gravity, reversal_friction_peak=peak,
               reversal_friction_decay=1e-4)
    for b in range(3):
        single = run(PROGRAM, **BASE, gravity_force=gravity[b], reversal_friction_peak=peak[b],
                     reversal_friction_decay=1e-4)
        np.testing.assert_array_equal(both["x"][:, b], single["x"][:, 0])


def test_effect_parameters_split_machine_section():
    drive, mcu = effect_parameters("z", {"gravity_force": 600.0, "servo_delay": 5e-4})
    assert drive == {"gravity_force": 600.0} and mcu == {"z_servo_delay": 5e-4}
    with pytest.raises(KeyError, match="no parameter"):
        effect_parameters("z", {"gravity": 1.0})
