"""The compiled servo replay (fmus_src/servo/replay.py) against the components stepped tick by tick.

The tick-by-tick loop of ``orchestrator.identify.closed_loop.run_servo_ticks`` over the MCU and DriveAxis
components is the specification; the compiled path must give the same traces: bit for bit where the
same operations run (the control law, the drive step, ripple, pitch, backlash, compliance, drift, delay),
to the rounding of ``exp`` where numpy's vector ``exp`` and the C library's differ (reversal friction).
"""
from __future__ import annotations

import numpy as np
import pytest

import fmus_src.servo.replay as compiled_replay
from fmus_src.servo import MCU, DriveAxis, ServoError
from orchestrator.diagnose.replay import run_replay
from orchestrator.identify.closed_loop import run_servo_samples, run_servo_ticks
from orchestrator.machine import load_machine
from orchestrator.twin import drive_parameters, mcu_parameters

B = 4


@pytest.fixture(scope="module")
def machine():
    return load_machine("default")


def _commands(duration: float = 1.5) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    t = np.arange(0.0, duration, 1e-3)
    return t, {"x": 0.004 * np.sin(2 * np.pi * t / 0.7), "y": 0.002 * np.sin(2 * np.pi * t / 0.5) ** 3,
               "z": 0.003 * np.sin(2 * np.pi * t / 0.9)}


def _effects(reversal: bool) -> tuple[dict, dict]:
    rng = np.random.default_rng(7)
    x = {"gravity_force": rng.uniform(0, 50, B), "ripple_amplitude": rng.uniform(0, 20, B),
         "ripple_period": np.full(B, 0.004)}
    if reversal:
        x.update(reversal_friction_peak=rng.uniform(10, 80, B), reversal_friction_decay=np.full(B, 2e-4))
    drives = {"x": x,
              "y": {"screw_stiffness": np.full(B, 2e8), "backlash_width": rng.uniform(0, 3e-6, B),
                    "pitch_slope": np.full(B, 2e-5), "pitch_amplitude": np.full(B, 1e-6),
                    "pitch_period": np.full(B, 0.012), "thermal_drift_rate": np.full(B, 1e-7)},
              "z": {"gravity_force": np.full(B, 300.0), "gravity_spring": np.full(B, 1000.0)}}
    mcu = {"x_servo_delay": rng.uniform(0, 2e-3, B), "y_velocity_feedforward": np.full(B, 0.5),
           "z_velocity_p_scale": rng.uniform(0.8, 1.2, B)}
    return mcu, drives


def _both(run):
    fast = run()
    with compiled_replay.stepped_tick_by_tick():
        slow = run()
    assert compiled_replay.ENABLED
    return fast, slow


def test_compiled_replay_is_bit_identical_without_exp_terms(machine):
    t, cmds = _commands()
    mcu_values, drive_values = _effects(reversal=False)
    disturbance = {"x": lambda q: 30.0 * np.sin(40.0 * q), "y": lambda q: 10.0 + 0.0 * q}
    fast, slow = _both(lambda: run_replay(machine, t, cmds, t, batch=B, mcu_values=mcu_values,
                                                       drive_values=drive_values, disturbance=disturbance))
    for name in ("table", "motor", "force", "current"):
        for a in "xyz":
            assert np.array_equal(getattr(fast, name)[a], getattr(slow, name)[a]), (name, a)
    # the effects are on: the table differs from the motor side on Y, the delayed X command differs per member
    assert np.max(np.abs(fast.table["y"] - fast.motor["y"])) > 1e-7
    assert np.ptp(fast.current["x"][-1]) > 0.0


def test_compiled_replay_with_reversal_friction_to_rounding(machine):
    t, cmds = _commands()
    mcu_values, drive_values = _effects(reversal=True)
    fast, slow = _both(lambda: run_replay(machine, t, cmds, t, batch=B, mcu_values=mcu_values,
                                                       drive_values=drive_values))
    for name, atol in (("table", 1e-15), ("motor", 1e-15), ("force", 1e-9), ("current", 1e-12)):
        for a in "xyz":
            np.testing.assert_allclose(getattr(fast, name)[a], getattr(slow, name)[a], rtol=1e-12, atol=atol)


def _components(machine, batch: int, mcu_values: dict | None = None, integrator: str = "exponential"):
    params = mcu_parameters(machine)
    params.update(mcu_values or {})
    mcu = MCU("mcu", batch=batch, **params)
    drives = {}
    for a in "xyz":
        drives[a] = DriveAxis(f"{a}_drive", batch=batch, initial_position=0.0,
                              **{**drive_parameters(machine, a), "integrator": integrator})
    mcu.setup(0.0)
    for d in drives.values():
        d.setup(0.0)
    return mcu, drives


def _every_tick(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Samples at the ticks themselves: tick ``j`` with weight 1 gives the output after tick ``j`` exactly."""
    return np.arange(1, n + 1), np.ones(n)


def test_not_covered_cases_fall_back(machine):
    tv = float(machine.si("servo")["velocity_loop_period"])
    n = 400
    ref = {a: np.linspace(0.0, 0.002, n + 1) for a in "xyz"}
    j, w = _every_tick(n)
    mcu, drives = _components(machine, 2, integrator="rk4")
    assert compiled_replay.compiled_samples(mcu, drives, ref, 0.0, tv, n, j, w) is None  # RK4 drives
    mcu, drives = _components(machine, 2)
    assert compiled_replay.compiled_samples(mcu, drives, ref, 0.0, 2 * tv, n, j, w) is None  # another tick grid
    traces = compiled_replay.compiled_samples(mcu, drives, ref, 0.0, tv, n, j, w)
    assert traces is not None and traces["position"]["x"].shape == (n, 2)


def test_samples_equal_the_ticks_interpolated_in_any_order(machine):
    """Samples between ticks, unsorted and repeated: the tick-by-tick traces interpolated, bit for bit."""
    tv = float(machine.si("servo")["velocity_loop_period"])
    n = 600
    ref = {"x": 0.003 * np.sin(np.linspace(0.0, 6.0, n + 1)), "z": np.linspace(0.0, -0.002, n + 1)}
    rng = np.random.default_rng(3)
    j = rng.integers(1, n + 1, 250)
    w = rng.uniform(0.0, 1.0, 250)
    mcu, drives = _components(machine, 3, {"x_servo_delay": np.array([0.0, 3e-4, 7e-4])})
    fast = run_servo_samples(mcu, {a: drives[a] for a in ref}, ref, 0.0, tv, n, j, w,
                             ("table_position", "position", "motor_force"))
    mcu, drives = _components(machine, 3, {"x_servo_delay": np.array([0.0, 3e-4, 7e-4])})
    ticks = run_servo_ticks(mcu, {a: drives[a] for a in ref}, ref, 0.0, tv, n,
                            ("table_position", "position", "motor_force"))
    for name, per_axis in ticks.items():
        for a, arr in per_axis.items():
            expected = arr[j - 1] * (1.0 - w[:, None]) + arr[j] * w[:, None]
            assert np.array_equal(fast[name][a], expected), (name, a)


def test_alarm_falls_back_to_the_components_message(machine):
    """A member over its excess-error limit: the compiled path steps back, the MCU names the alarm."""
    tv = float(machine.si("servo")["velocity_loop_period"])
    n = 400
    ramp = np.linspace(0.0, 0.01, n + 1)  # 10 mm in 0.1 s: a following error of millimetres
    ref = {"x": ramp}
    j, w = _every_tick(n)
    limits = {"x_excess_error_in_motion": np.array([1.0, 1e-5])}  # member 1 alarms, member 0 does not
    mcu, drives = _components(machine, 2, limits)
    assert compiled_replay.compiled_samples(mcu, {"x": drives["x"]}, ref, 0.0, tv, n, j, w) is None
    mcu, drives = _components(machine, 2, limits)
    traces = run_servo_samples(mcu, {"x": drives["x"]}, ref, 0.0, tv, n, j, w)
    assert mcu.failed_members.tolist() == [False, True]
    assert np.all(np.isfinite(traces["position"]["x"][:, 0]))
    mcu, drives = _components(machine, 1, {"x_excess_error_in_motion": 1e-5})
    with pytest.raises(ServoError, match="SV0411"):
        run_servo_samples(mcu, {"x": drives["x"]}, ref, 0.0, tv, n, j, w)
