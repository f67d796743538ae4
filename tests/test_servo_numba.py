"""Compiled (numba) servo kernels against the numpy reference implementation.

The drive kernel evaluates ``exp`` with libm, numpy with its SIMD routine; the
two differ by at most 1 ulp, so drive traces are compared at 1e-12 relative
(elementwise ``rtol`` 1e-12 plus ``atol`` 1e-12 x the largest magnitude of the
trace, for values passing through zero). The control law has no
transcendental function: MCU outputs must be bit-identical.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.servo import MCU, DriveAxis, ServoError, StribeckParameters, stick_slip, stick_slip_numba
from fmus_src.servo.control_numba import mcu_kernel
from servo_harness import AXES, build, run

KF = 2.0 * math.pi / 0.012  # N/A, kt = 1 N.m/A, Lb = 12 mm
RTOL = 1e-12

#: Table 1 Y axis (steepest Stribeck slope of the paper's machine)
Y_TABLE1 = dict(mass=800.0, coulomb_positive=861.7, static_positive=1115.7, stribeck_velocity_positive=0.0006,
                viscous_positive=11962.0, coulomb_negative=865.4, static_negative=1052.7,
                stribeck_velocity_negative=0.0018, viscous_negative=8998.0)


def assert_same(compiled: np.ndarray, reference: np.ndarray, what: str) -> None:
    """Agreement to 1e-12 relative (elementwise, floor at 1e-12 of the trace's largest magnitude)."""
    scale = float(np.max(np.abs(reference)))
    np.testing.assert_allclose(compiled, reference, rtol=RTOL, atol=RTOL * scale, err_msg=what)


def symmetric(fc: float, fs: float, vs: float = 1e-3, mu: float = 0.0) -> dict[str, float]:
    return {f"{k}_{d}": val for k, val in (("coulomb", fc), ("static", fs), ("stribeck_velocity", vs),
                                           ("viscous", mu)) for d in ("positive", "negative")}


def random_friction(rng: np.random.Generator, batch: int) -> dict[str, np.ndarray]:
    """GA-like extreme parameter sets (as test_extreme_friction_parameters_stay_accurate)."""
    fc = rng.uniform(200, 1500, batch)
    fs = fc * rng.uniform(0.8, 2.0, batch)
    vs = 10 ** rng.uniform(-4, -2, batch)
    mu = rng.uniform(0, 15000, batch)
    return {"coulomb_positive": fc, "static_positive": fs, "stribeck_velocity_positive": vs, "viscous_positive": mu,
            "coulomb_negative": 1.05 * fc, "static_negative": 0.97 * fs, "stribeck_velocity_negative": 1.3 * vs,
            "viscous_negative": 0.8 * mu}


# ------------------------------------------------------------------------------------------ drive alone
def drive_traces(compiled: bool, program: list[tuple[object, float]], h: float, batch: int = 1,
                 **params: object) -> dict[str, np.ndarray]:
    """Run a force program [(force N, duration s)] on one DriveAxis; record every step end."""
    d = DriveAxis("d", batch=batch, **{"mass": 600.0, **params})
    d.use_compiled = compiled
    d.setup(0.0)
    rec: dict[str, list] = {"x": [], "v": [], "ff": [], "u": [], "dir": []}
    k = 0
    for force, duration in program:
        d.set("current_cmd", np.asarray(force) / KF)
        for _ in range(round(duration / h)):
            d.do_step(k * h, h)
            k += 1
            rec["x"].append(d.get("position"))
            rec["v"].append(d.get("velocity"))
            rec["ff"].append(d.get("friction_force"))
            rec["u"].append(d.get("motor_force"))
            rec["dir"].append(d._state.direction.copy())
    return {key: np.array(val) for key, val in rec.items()}


def assert_drive_paths_agree(program: list[tuple[object, float]], h: float, batch: int = 1,
                             **params: object) -> dict[str, np.ndarray]:
    a = drive_traces(True, program, h, batch, **params)
    b = drive_traces(False, program, h, batch, **params)
    for key, what in (("x", "position"), ("v", "velocity"), ("ff", "friction force"), ("u", "motor force")):
        assert_same(a[key], b[key], what)
    np.testing.assert_array_equal(a["dir"], b["dir"])  # identical stick/slip state machine
    np.testing.assert_array_equal(a["v"] == 0.0, b["v"] == 0.0)
    return b


def test_coulomb_reversals_and_stops():
    rec = assert_drive_paths_agree([(2000.0, 0.0101), (-300.0, 0.05), (-2000.0, 0.0203), (2500.0, 0.04),
                                    (0.0, 0.02)], 1e-4, **symmetric(600.0, 600.0, vs=1.0))
    assert np.count_nonzero(rec["v"] == 0.0) > 100 and rec["v"].max() > 0 and rec["v"].min() < 0


def test_table1_stribeck_reversals_with_stiction():
    rec = assert_drive_paths_agree([(1500.0, 0.02), (-900.0, 0.02), (-1300.0, 0.03), (1200.0, 0.03),
                                    (-1100.0, 0.02)], 1e-3, **Y_TABLE1)
    assert np.any(rec["v"] == 0.0) and rec["v"].max() > 0 and rec["v"].min() < 0


@pytest.mark.parametrize("factor", [1.0 - 1e-9, 1.0 + 1e-3])
def test_stiction_and_break_away_at_the_static_force(factor):
    forces = np.array([factor * 1115.7, -factor * 1052.7])
    rec = assert_drive_paths_agree([(forces, 0.05)], 1e-4, batch=2, **Y_TABLE1)
    assert np.all(rec["v"] == 0.0) if factor < 1.0 else np.all(rec["v"][-1] != 0.0)


def test_batch_with_different_parameters():
    sets = [symmetric(600.0, 700.0, 1e-3, 8000.0), symmetric(800.0, 1100.0, 6e-4, 12000.0),
            symmetric(0.0, 0.0, 1.0, 0.0)]
    forces = np.array([900.0, -1500.0, 300.0])
    assert_drive_paths_agree([(forces, 0.02), (-forces, 0.03), (0.2 * forces, 0.03)], 250e-6, batch=3,
                             mass=[600.0, 800.0, 500.0], **{k: [p[k] for p in sets] for k in sets[0]})


def test_extreme_friction_sets_through_many_reversals():
    rng = np.random.default_rng(11)
    batch = 24
    amplitude = rng.uniform(500.0, 4000.0, batch)
    program = [(amplitude * math.sin(2.0 * math.pi * j / 40.0), 0.0025) for j in range(120)]  # 25 ms pieces
    rec = assert_drive_paths_agree(program, 250e-6, batch=batch, mass=rng.uniform(400.0, 900.0, batch),
                                   **random_friction(rng, batch))
    assert np.count_nonzero(rec["v"] == 0.0) > 0


def test_module_level_advance_matches_reference():
    """``stick_slip_numba.advance`` has the reference's signature and results (direct call, random states)."""
    rng = np.random.default_rng(5)
    batch = 50
    p = random_friction(rng, batch)
    friction = StribeckParameters(p["coulomb_positive"], p["static_positive"], p["stribeck_velocity_positive"],
                                  p["viscous_positive"], p["coulomb_negative"], p["static_negative"],
                                  p["stribeck_velocity_negative"], p["viscous_negative"])
    mass = rng.uniform(400.0, 900.0, batch)
    step = 1e-5
    v0 = np.where(rng.random(batch) < 0.3, 0.0, rng.normal(scale=0.01, size=batch))
    x0 = rng.normal(size=batch)
    states = [stick_slip.SlipState(x0.copy(), v0.copy(), np.sign(v0).astype(np.int8)) for _ in range(2)]
    for j in range(200):
        force = 3000.0 * np.sin(0.05 * j + np.arange(batch))
        ff_c = stick_slip_numba.advance(states[0], force, mass, friction, 250e-6, step)
        ff_r = stick_slip.advance(states[1], force, mass, friction, 250e-6, step)
        assert_same(ff_c, ff_r, "friction")
        assert_same(states[0].position, states[1].position, "position")
        assert_same(states[0].velocity, states[1].velocity, "velocity")
        np.testing.assert_array_equal(states[0].direction, states[1].direction)


def test_failure_leaves_state_unchanged_and_raises_the_reference_message():
    """A huge viscous slope with a long substep makes a break-away run backwards: both paths refuse it."""
    messages = []
    for compiled in (True, False):
        d = DriveAxis("x_drive", mass=1.0, coulomb_positive=600.0, static_positive=700.0, viscous_positive=1e6,
                      integration_step=1e-3, initial_position=0.25)
        d.use_compiled = compiled
        d.setup(0.0)
        d.set("current_cmd", 701.0 / KF)
        with pytest.raises(ServoError, match="x_drive: .*moved backwards") as info:
            d.do_step(0.0, 1e-3)
        messages.append(str(info.value))
        assert d._state.position[0] == 0.25 and d._state.velocity[0] == 0.0 and d._state.direction[0] == 0
    assert messages[0] == messages[1]


# ------------------------------------------------------------------------------------------ MCU alone
def mcu_pair(batch: int, **params: object) -> tuple[MCU, MCU]:
    pair = (MCU("c", batch=batch, **params), MCU("r", batch=batch, **params))
    pair[1].use_compiled = False
    assert pair[0].use_compiled
    for m in pair:
        m.setup(0.0)
    return pair


@pytest.mark.parametrize("h", [250e-6, 1e-3])
def test_mcu_is_bit_identical_with_feedforward_saturation_and_batch(h):
    rng = np.random.default_rng(2)
    batch = 5
    params = {"x_position_gain": rng.uniform(20, 80, batch), "y_velocity_p_scale": rng.uniform(0.5, 2, batch),
              "z_velocity_i_scale": rng.uniform(0.5, 2, batch), "x_velocity_feedforward": 1.0,
              "y_acceleration_feedforward": 0.8, "z_peak_current": [40.0, 10.0, 5.0, 40.0, 1.0]}
    pair = mcu_pair(batch, **params)
    names = [f"{a}_{k}" for a in AXES for k in ("current_cmd", "velocity_cmd")] + ["in_position"]
    for j in range(300):
        inputs = {f"{a}_{kind}": rng.normal(scale=scale, size=batch) for a in AXES
                  for kind, scale in (("ref", 3e-4), ("position", 3e-4), ("velocity", 2e-3))}
        for m in pair:
            for name, val in inputs.items():
                m.set(name, val)
            m.do_step(j * h, h)
        for name in names:
            np.testing.assert_array_equal(pair[0].get(name), pair[1].get(name), err_msg=name)
        np.testing.assert_array_equal(pair[0]._state.block, pair[1]._state.block)
    assert np.any(np.abs(pair[0].get("z_current_cmd")) == 1.0)  # saturation was exercised


# ------------------------------------------------------------------------------------------ closed loop
def closed_loop(compiled: bool, batch: int, ref, n: int, **overrides):
    mcu, drives = build(batch=batch, **overrides)
    for c in (mcu, *drives.values()):
        c.use_compiled = compiled
    return run(mcu, drives, lambda t: np.broadcast_to(ref(t), (3, batch)), n)


def assert_loops_agree(batch: int, ref, n: int, **overrides):
    a, b = closed_loop(True, batch, ref, n, **overrides), closed_loop(False, batch, ref, n, **overrides)
    for key in ("position", "velocity", "current", "friction"):
        assert_same(getattr(a, key), getattr(b, key), key)
    np.testing.assert_array_equal(a.velocity == 0.0, b.velocity == 0.0)
    return b


def test_closed_loop_reciprocation_with_stiction():
    speeds = np.array([100.0, 500.0, 3000.0]) / 60e3  # m/s

    def ref(t):
        return 0.02 * np.sin(2.0 * np.pi * t / 0.2) * speeds / speeds.max()
    tr = assert_loops_agree(3, ref, 1600)
    assert np.any(tr.velocity == 0.0) and tr.velocity.max() > 0 and tr.velocity.min() < 0


def test_closed_loop_saturation():
    tr = assert_loops_agree(1, lambda t: np.full(1, 0.01), 1200)
    assert np.all(np.max(np.abs(tr.current[:, :, 0]), axis=0) == 40.0)


def test_closed_loop_extreme_parameter_batch():
    rng = np.random.default_rng(1)
    batch = 8
    drive_over = {a: random_friction(rng, batch) for a in AXES}
    mcu_over = {f"{a}_{k}": rng.uniform(0.5, 2.0, batch) for a in AXES
                for k in ("position_scale", "velocity_p_scale", "velocity_i_scale")}
    amp = rng.uniform(1e-3, 5e-3, batch)
    assert_loops_agree(batch, lambda t: amp * np.sin(2.0 * np.pi * t / 0.1), 800,
                       mcu_overrides=mcu_over, drive_overrides=drive_over)


# ------------------------------------------------------------------------------------------ protocol
def test_outputs_are_written_in_place_and_switching_mid_run_is_seamless(monkeypatch):
    """The master binds to ``values`` arrays: their identity never changes. Alternating implementations
    step by step (shared state) reproduces a pure reference run."""
    def ref(t):
        return np.full((3, 2), 2e-3 * math.sin(2.0 * math.pi * t / 0.05))
    mcu, drives = build(batch=2)
    comps = (mcu, *drives.values())
    bound = {(c.name, k): c.values[k] for c in comps for k in c.names("output")}
    flips = {"n": 0}
    original = DriveAxis._do_step

    def alternating(self, t, h):
        self.use_compiled = flips["n"] % 2 == 0
        flips["n"] += 1
        original(self, t, h)
    monkeypatch.setattr(DriveAxis, "_do_step", alternating)
    a = run(mcu, drives, ref, 400)
    monkeypatch.undo()
    assert all(c.values[k] is arr for (name, k), arr in bound.items() for c in comps if c.name == name)
    b = closed_loop(False, 2, lambda t: ref(t)[0], 400)
    for key in ("position", "velocity", "current", "friction"):
        assert_same(getattr(a, key), getattr(b, key), key)


def test_kernels_have_one_signature_each():
    """Keeps numba compile time bounded: every call site passes the same argument types."""
    mcu, drives = build(batch=3)
    run(mcu, drives, lambda t: np.full((3, 3), 1e-4), 4)
    # (a caller compiled with numba, e.g. the bench's fused loop, may add a literal-typed specialisation)
    def plain(kernel):
        return [sig for sig in kernel.signatures if not any("Literal" in str(t) for t in sig)]

    assert len(plain(stick_slip_numba.advance_kernel)) == 1
    assert len(plain(mcu_kernel)) == 1
