"""DriveAxis: Eq. (1)-(3) of Sim & Lee 2023 with stick/slip friction, against analytic solutions."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.servo import DriveAxis, ServoError, StribeckParameters, stribeck_force

KF = 2.0 * math.pi / 0.012  # N/A for kt = 1 N.m/A, Lb = 12 mm
M = 600.0
H = 250e-6


def friction(fc: float, fs: float, vs: float = 1e-3, mu: float = 0.0) -> dict[str, float]:
    """Symmetric friction parameters."""
    return {f"{k}_{d}": val for k, val in (("coulomb", fc), ("static", fs), ("stribeck_velocity", vs),
                                           ("viscous", mu)) for d in ("positive", "negative")}


def drive(batch: int = 1, **params: object) -> DriveAxis:
    d = DriveAxis("d", batch=batch, **{"mass": M, **params})
    d.setup(0.0)
    return d


def force_program(d: DriveAxis, forces: list[tuple[float, float]], h: float = H) -> dict[str, np.ndarray]:
    """Apply motor forces [N] for durations [s] (multiples of h); record at every step end."""
    rec: dict[str, list] = {"t": [], "x": [], "v": [], "ff": []}
    k = 0
    for force, duration in forces:
        d.set("current_cmd", np.asarray(force) / KF)
        for _ in range(round(duration / h)):
            d.do_step(k * h, h)
            k += 1
            rec["t"].append(k * h)
            rec["x"].append(d.get("position"))
            rec["v"].append(d.get("velocity"))
            rec["ff"].append(d.get("friction_force"))
    return {key: np.array(val) for key, val in rec.items()}


def test_stribeck_curve_is_eq3():
    p = StribeckParameters(*(np.full(3, v) for v in (641.6, 775.2, 0.0016, 7702.0, 661.9, 756.8, 0.0014, 7242.0)))
    v = np.array([0.01, -0.002, 0.0])
    expected_pos = 7702.0 * 0.01 + 641.6 + (775.2 - 641.6) * math.exp(-0.01 / 0.0016)
    expected_neg = 7242.0 * -0.002 - (661.9 + (756.8 - 661.9) * math.exp(-0.002 / 0.0014))
    np.testing.assert_allclose(stribeck_force(v, p), [expected_pos, expected_neg, 0.0], rtol=1e-14)


def test_free_mass_constant_force_is_a_parabola():
    d = drive(**friction(0.0, 0.0))
    rec = force_program(d, [(1000.0, 0.01)])
    t = rec["t"]
    np.testing.assert_allclose(rec["v"][:, 0], 1000.0 / M * t, rtol=1e-12)
    np.testing.assert_allclose(rec["x"][:, 0], 0.5 * 1000.0 / M * t**2, rtol=1e-12)
    np.testing.assert_allclose(d.get("motor_force"), 1000.0, rtol=1e-12)


def test_viscous_only_matches_exponential_solution():
    mu, f = 9000.0, 2000.0
    d = drive(**friction(0.0, 0.0, mu=mu))
    rec = force_program(d, [(f, 0.2)])
    t, tau = rec["t"], M / mu
    v_exact = f / mu * (1.0 - np.exp(-t / tau))
    x_exact = f / mu * (t - tau * (1.0 - np.exp(-t / tau)))
    np.testing.assert_allclose(rec["v"][:, 0], v_exact, rtol=1e-10)
    np.testing.assert_allclose(rec["x"][:, 0], x_exact, rtol=1e-10)
    np.testing.assert_allclose(rec["ff"][-1, 0], mu * v_exact[-1], rtol=1e-10)


@pytest.mark.parametrize("direction", [1, -1])
def test_stiction_below_static_force_never_moves(direction):
    fs_pos, fs_neg = 775.2, 756.8
    fs = fs_pos if direction > 0 else fs_neg
    d = drive(coulomb_positive=641.6, static_positive=fs_pos, coulomb_negative=661.9, static_negative=fs_neg,
              initial_position=0.1)
    applied = direction * (1.0 - 1e-9) * fs
    rec = force_program(d, [(applied, 0.5)])
    assert np.all(rec["x"] == 0.1) and np.all(rec["v"] == 0.0)
    np.testing.assert_allclose(rec["ff"], applied, rtol=1e-15)  # static friction balances the force


@pytest.mark.parametrize("direction", [1, -1])
def test_just_above_static_force_breaks_away(direction):
    fs_pos, fs_neg, fc = 775.2, 756.8, 641.6
    fs = fs_pos if direction > 0 else fs_neg
    d = drive(coulomb_positive=fc, static_positive=fs_pos, coulomb_negative=fc, static_negative=fs_neg,
              stribeck_velocity_positive=1e-3, stribeck_velocity_negative=1e-3,
              viscous_positive=7702.0, viscous_negative=7702.0)
    excess = 1e-3 * fs
    rec = force_program(d, [(direction * (fs + excess), 0.02)], h=1e-4)
    assert np.all(direction * rec["v"] > 0.0)
    # first step: linearised Stribeck branch near v = 0, M v' = excess + k v, k = (Fs - Fc) / vs - mu_v
    # -> v(t) = excess / k * (exp(k t / M) - 1); the neglected O(v^2) terms are < 1e-4 relative here
    k = (fs - fc) / 1e-3 - 7702.0
    np.testing.assert_allclose(rec["v"][0, 0], direction * excess / k * math.expm1(k * 1e-4 / M), rtol=1e-4)
    # with F > Fs > Fc it keeps accelerating through the Stribeck dip (friction only drops)
    assert np.all(np.diff(direction * rec["v"][:, 0]) > 0.0)


def test_disturbance_force_resists_positive_motion():
    d = drive(**friction(600.0, 700.0))
    d.set("disturbance_force", -701.0)  # Fd < 0 pushes the table towards +x
    d.do_step(0.0, H)
    assert d.get("velocity")[0] > 0.0
    d2 = drive(**friction(600.0, 700.0))
    d2.set("current_cmd", 1000.0 / KF)
    d2.set("disturbance_force", 350.0)  # net 650 N < Fs: stays
    d2.do_step(0.0, H)
    assert d2.get("velocity")[0] == 0.0
    np.testing.assert_allclose(d2.get("friction_force"), 650.0, rtol=1e-15)


def coulomb_reference(forces: list[tuple[float, float]], fc: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact piecewise-parabolic motion under Coulomb friction (Fs = Fc, no viscous), evaluated at t."""
    x, v, t_now = 0.0, 0.0, 0.0
    xs, vs = np.empty_like(t), np.empty_like(t)
    events = []  # (t_start, x, v, accel) constant-acceleration arcs
    for force, duration in forces:
        t_end = t_now + duration
        while t_now < t_end - 1e-15:
            if v == 0.0:
                if abs(force) <= fc:
                    events.append((t_now, x, 0.0, 0.0))
                    t_now = t_end
                    continue
                s = math.copysign(1.0, force)
            else:
                s = math.copysign(1.0, v)
            a = (force - s * fc) / M
            t_stop = t_now - v / a if v != 0.0 and a * v < 0.0 else math.inf
            t_seg = min(t_end, t_stop)
            events.append((t_now, x, v, a))
            dt = t_seg - t_now
            x, v = x + v * dt + 0.5 * a * dt * dt, (0.0 if t_seg == t_stop else v + a * dt)
            t_now = t_seg
    starts = np.array([e[0] for e in events])
    for i, ti in enumerate(t):
        j = np.searchsorted(starts, ti, side="right") - 1
        t0, x0, v0, a = events[j]
        xs[i] = x0 + v0 * (ti - t0) + 0.5 * a * (ti - t0) ** 2
        vs[i] = v0 + a * (ti - t0)
    return xs, vs


def test_reversal_and_stop_with_coulomb_friction_are_exact():
    """Crossings inside substeps are located exactly: the Coulomb case is piecewise parabolic."""
    fc = 600.0
    program = [(2000.0, 0.0101), (-300.0, 0.05), (-2000.0, 0.0203), (2500.0, 0.04), (0.0, 0.02)]
    d = drive(**friction(fc, fc, vs=1.0))
    rec = force_program(d, program, h=1e-4)
    x_ref, v_ref = coulomb_reference(program, fc, rec["t"])
    np.testing.assert_allclose(rec["x"][:, 0], x_ref, rtol=0, atol=1e-13)
    np.testing.assert_allclose(rec["v"][:, 0], v_ref, rtol=0, atol=1e-12)
    assert np.count_nonzero(rec["v"][:, 0] == 0.0) > 100  # it really stuck (during -300 N and at the end)


def reversal_trace(step: float) -> dict[str, np.ndarray]:
    """Table 1 Y-axis friction (steepest Stribeck slope), push, brake below Fs, reverse, reverse again."""
    d = drive(mass=800.0, coulomb_positive=861.7, static_positive=1115.7, stribeck_velocity_positive=0.0006,
              viscous_positive=11962.0, coulomb_negative=865.4, static_negative=1052.7,
              stribeck_velocity_negative=0.0018, viscous_negative=8998.0, integration_step=step)
    program = [(1500.0, 0.02), (-900.0, 0.02), (-1300.0, 0.03), (1200.0, 0.03), (-1100.0, 0.02)]
    return force_program(d, program, h=1e-3)


def test_reversal_trace_does_not_depend_on_internal_step():
    """Halving the default internal step (125 -> 62.5 us) changes the 1 ms trace by < 2e-11 m,
    2e-9 m/s and 3e-4 N (friction ~1000 N), and the change shrinks ~16x per halving (4th order),
    so the trace is the step-independent solution, not a step-dependent friction artefact."""
    a, b, c = reversal_trace(125e-6), reversal_trace(62.5e-6), reversal_trace(31.25e-6)
    assert np.count_nonzero(a["v"][:, 0] == 0.0) > 0  # the run includes stick phases
    assert np.any(a["v"][:, 0] > 0) and np.any(a["v"][:, 0] < 0)
    np.testing.assert_allclose(a["x"], b["x"], rtol=0, atol=2e-11)
    np.testing.assert_allclose(a["v"], b["v"], rtol=0, atol=2e-9)
    np.testing.assert_allclose(a["ff"], b["ff"], rtol=0, atol=3e-4)
    np.testing.assert_array_equal(a["v"] == 0.0, b["v"] == 0.0)  # identical stick phases
    for key in ("x", "v", "ff"):
        ratio = np.abs(a[key] - b[key]).max() / np.abs(b[key] - c[key]).max()
        assert ratio > 10.0, (key, ratio)


def test_no_chattering_when_force_is_below_both_static_forces():
    """A table braked to rest under a small force stays at exactly zero velocity (no sign flipping)."""
    d = drive(**friction(600.0, 700.0, vs=1e-3, mu=8000.0))
    rec = force_program(d, [(1500.0, 0.01), (200.0, 0.2)])
    v = rec["v"][:, 0]
    stop = np.argmax((v == 0.0) & (np.arange(v.size) > 40))
    assert stop > 0 and np.all(v[stop:] == 0.0)
    np.testing.assert_allclose(rec["ff"][stop:, 0], 200.0, rtol=1e-15)


def test_batch_equals_single_runs():
    params = [friction(600.0, 700.0, 1e-3, 8000.0), friction(800.0, 1100.0, 6e-4, 12000.0),
              friction(0.0, 0.0, 1.0, 0.0)]
    forces = np.array([900.0, -1500.0, 300.0])
    batch = DriveAxis("b", batch=3, mass=[600.0, 800.0, 500.0],
                      **{k: [p[k] for p in params] for k in params[0]})
    batch.setup(0.0)
    rec_b = force_program(batch, [(forces, 0.02), (-forces, 0.03)])
    for i, p in enumerate(params):
        single = DriveAxis("s", mass=[600.0, 800.0, 500.0][i], **p)
        single.setup(0.0)
        rec_s = force_program(single, [(forces[i], 0.02), (-forces[i], 0.03)])
        for key in ("x", "v", "ff"):
            np.testing.assert_allclose(rec_b[key][:, i], rec_s[key][:, 0], rtol=1e-13, atol=1e-18)


@pytest.mark.parametrize("bad", [{"mass": 0.0}, {"stribeck_velocity_positive": 0.0}, {"static_negative": -1.0},
                                 {"integration_step": -1e-4}])
def test_invalid_parameters_are_rejected(bad):
    d = DriveAxis("bad", **bad)
    with pytest.raises(ServoError, match=next(iter(bad))):
        d.setup(0.0)


def test_reset_restores_the_initial_state():
    d = drive(**friction(600.0, 700.0), initial_position=0.05)
    first = force_program(d, [(1500.0, 0.01)])
    d.reset()
    d.setup(0.0)
    assert d.get("position")[0] == 0.05 and d.get("velocity")[0] == 0.0
    again = force_program(d, [(1500.0, 0.01)])
    np.testing.assert_array_equal(first["x"], again["x"])
