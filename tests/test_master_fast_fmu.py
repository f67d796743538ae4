"""The master's compiled FMU path (FastFMULoop) gives the Python loop's results bit for bit.

Every run is made twice on freshly built systems: with the Python loop
(``MasterSettings(compiled=False)``) and with the default (the compiled FMU
loop when every component is an FMUComponent). Recordings (every channel,
``t_s``, decimation), every RunResult field, the progress calls and the values
the components hold afterwards must be equal. Where a number can be derived
independently it is checked too: the lag ring against its exact
zero-order-hold recursion (orchestrator.bench.systems.ring_exact, numpy), the
toy Accumulator FMU (tests/fixtures/fmu/fmu_toys.py) against its one-line
equations (done after ``limit`` steps, x = offset + gain·u·h per step).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from orchestrator import Master, MasterSettings, Probe
from orchestrator.bench.cfmu import build_lag_fmu, lag_ring
from orchestrator.bench.systems import build_servo_fmus, ring_exact, servo_fmu_system
from orchestrator.fmu import FMUComponent, build_fmu
from orchestrator.fmu import fast_loop
from orchestrator.fmu.master_loop import fast_fmu_support

sys.path.insert(0, str(Path(__file__).resolve().parent / "fixtures" / "fmu"))
import fmu_toys  # noqa: E402

H = 1e-3
RING = ["a.y", "b.y", "c.y", "d.y"]


@pytest.fixture(scope="module")
def lag_fmu(tmp_path_factory):
    return build_lag_fmu(tmp_path_factory.mktemp("lag"))


@pytest.fixture(scope="module")
def acc_fmu(tmp_path_factory):
    return build_fmu(fmu_toys.Accumulator, tmp_path_factory.mktemp("acc"))


@pytest.fixture
def fast_runs(monkeypatch):
    """Counts FastFMULoop.run calls (the compiled path was taken)."""
    calls = []
    original = fast_loop.FastFMULoop.run

    def run(self, *args, **kwargs):
        calls.append(args)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(fast_loop.FastFMULoop, "run", run)
    return calls


def _run(make, probes, compiled, expected_duration=None, strings=False, **settings):
    """One run; returns its result, progress calls and the values the components hold (Strings if ``strings``)."""
    calls = []
    system = make()
    master = Master(system, MasterSettings(step=H, compiled=compiled, **settings), probes,
                    progress=lambda t, total: calls.append((t, total)), expected_duration=expected_duration)
    result = master.run()
    held = {(n, v): c.values[v] if isinstance(c.values[v], str) else np.array(c.values[v])
            for n, c in system.components.items() for v in c.names("output") + c.names("input")
            if strings or not isinstance(c.values[v], str)}
    return result, calls, held


def _both(make, probes, fast_runs, expected_duration=None, strings=False, **settings):
    """Python loop and default master on fresh systems; everything must be equal. Returns the default's result.

    ``strings``: also compare the String values the components hold afterwards.
    """
    py, py_calls, py_held = _run(make, probes, False, expected_duration, strings, **settings)
    assert not fast_runs
    fast, fast_calls, fast_held = _run(make, probes, True, expected_duration, strings, **settings)
    assert fast_runs, "the compiled FMU path was not taken"
    for name in ("success", "message", "steps", "t_end", "failures"):
        assert getattr(fast, name) == getattr(py, name), name
    np.testing.assert_array_equal(fast.stopped_at, py.stopped_at)
    np.testing.assert_array_equal(fast.failed, py.failed)
    assert fast.recording.channels == py.recording.channels
    assert fast.recording.units == py.recording.units
    assert (fast.recording.success, fast.recording.message) == (py.recording.success, py.recording.message)
    for ch in py.recording.channels:
        assert np.array_equal(fast.recording[ch], py.recording[ch], equal_nan=True), ch
    assert fast_calls == py_calls
    assert fast_held.keys() == py_held.keys()
    for key in py_held:
        if isinstance(py_held[key], str):
            assert fast_held[key] == py_held[key], key
        else:
            assert np.array_equal(fast_held[key], py_held[key], equal_nan=True), key
    return fast, fast_calls


def test_time_limit_multi_rate_decimation_progress(lag_fmu, fast_runs):
    def make():
        system = lag_ring(lag_fmu, k_last=-0.8)
        system.rates.update({"b": 2, "c": 4})
        return system

    probes = RING + [Probe("a_mm", "a.y", "1")]
    result, calls = _both(make, probes, fast_runs, time_limit=0.3, decimation=7, expected_duration=0.25)
    assert result.success and result.message == "time limit of 0.3 s reached" and result.steps == 300
    ks = np.r_[np.arange(0, 301, 7), 300]  # every 7th step, and the last one
    np.testing.assert_array_equal(result.recording["t_s"], ks * H)
    assert [round(t / H) for t, _ in calls] == list(range(2, 301, 2))  # every 1 % of 0.25 s
    assert len(fast_runs) > 100  # chunks end at progress reports


@pytest.mark.parametrize("method", ["gauss-seidel", "jacobi"])
def test_time_limit_matches_exact_recursion(lag_fmu, fast_runs, method):
    result, _ = _both(lambda: lag_ring(lag_fmu, tau=0.02, k_last=-0.8), RING, fast_runs, time_limit=0.2,
                      method=method)
    if method == "gauss-seidel":
        exact = ring_exact(200, H, tau=0.02, k_last=-0.8)
        got = np.column_stack([result.recording[p] for p in RING])
        np.testing.assert_allclose(got, exact, rtol=0, atol=1e-14)


def test_stop_on_a_boolean_output(lag_fmu, acc_fmu, fast_runs):
    def make():
        system = lag_ring(lag_fmu, k_last=-0.8)
        system.add(FMUComponent(acc_fmu, "acc", parameters={"limit": 137, "gain": 3.0, "u": 0.5, "offset": 0.25}))
        system.set_execution_order(["a", "b", "c", "d", "acc"])
        return system

    probes = ["a.y", "acc.x", "acc.steps", "acc.done"]
    result, _ = _both(make, probes, fast_runs, time_limit=1.0, stop_when="acc.done", decimation=4)
    assert result.success and result.message == "acc.done at t = 0.137 s"
    assert result.steps == 137 and result.stopped_at[0] == 137 * H
    rec = result.recording
    np.testing.assert_array_equal(rec["t_s"], np.r_[np.arange(0, 137, 4), 137] * H)
    np.testing.assert_array_equal(rec["acc.steps"], np.r_[np.arange(0, 137, 4), 137])
    np.testing.assert_array_equal(rec["acc.done"], (rec["acc.steps"] >= 137).astype(float))
    np.testing.assert_allclose(rec["acc.x"], 0.25 + 3.0 * 0.5 * H * rec["acc.steps"], rtol=1e-12)


def test_stop_signal_never_reached(lag_fmu, acc_fmu, fast_runs):
    def make():
        system = lag_ring(lag_fmu)
        system.add(FMUComponent(acc_fmu, "acc", parameters={"limit": 10_000}))
        system.set_execution_order(["acc", "a", "b", "c", "d"])
        return system

    result, _ = _both(make, ["acc.steps"], fast_runs, time_limit=0.05, stop_when=("acc.done", "a.y"))
    assert not result.success and result.failed.tolist() == [True]
    # the master's final check raises with the member's reason when no member is left
    assert result.message == "simulation did not reach acc.done and a.y by the time limit of 0.05 s"
    assert result.failures == ["did not reach acc.done and a.y by the time limit of 0.05 s"]


def test_fmu_error_ends_the_run_with_the_recording_so_far(lag_fmu, fast_runs):
    make = lambda: lag_ring(lag_fmu, k_last=-0.8, fail_time=0.0505, fail_at="c")  # noqa: E731
    result, _ = _both(make, RING, fast_runs, time_limit=0.3, decimation=3)
    assert not result.success and result.steps == 50 and result.t_end == 50 * H
    assert result.message.startswith("simulation failed at t = 0.050000 s: c: fmi2DoStep returned fmi2Error "
                                     "at t = 0.050000 s")
    assert result.failures == [result.message] and result.failed.tolist() == [True]
    np.testing.assert_array_equal(result.recording["t_s"], np.arange(0, 49, 3) * H)  # the last sample before
    np.testing.assert_allclose(result.recording["d.y"], ring_exact(48, H, k_last=-0.8)[::3, 3], rtol=0, atol=1e-14)


def test_limit_exceeded_at_a_check_step(lag_fmu, fast_runs):
    make = lambda: lag_ring(lag_fmu, k_last=-6.0)  # noqa: E731 - a growing oscillation
    result, _ = _both(make, RING, fast_runs, time_limit=2.0, limits={"d.y": (-2.0, 2.0)}, check_every=10,
                      decimation=5)
    exact = ring_exact(2000, H, k_last=-6.0)[:, 3]
    k_fail = next(k for k in range(10, 2001, 10) if abs(exact[k]) > 2.0)
    assert not result.success and result.steps == k_fail
    assert result.message.startswith(f"simulation diverged at t = {k_fail * H:.6f} s: d.y = ")
    assert result.message.endswith("is outside [-2, 2]")
    assert k_fail % 5 == 0  # a sampling step: the check comes first, so that sample is not taken
    assert result.recording["t_s"][-1] == (k_fail - 5) * H


def test_non_finite_connection(lag_fmu, fast_runs):
    make = lambda: lag_ring(lag_fmu, k_last=-1e300)  # noqa: E731 - overflows to inf, then NaN
    result, _ = _both(make, ["d.y"], fast_runs, time_limit=1.0, check_every=3)
    with np.errstate(over="ignore", invalid="ignore"):
        exact = ring_exact(30, H, k_last=-1e300)
    k_fail = next(k for k in range(3, 31, 3) if not np.isfinite(exact[k]).all())
    assert not result.success and result.steps == k_fail and "is not finite" in result.message


def test_unsupported_runs_fall_back_to_the_python_loop(lag_fmu):
    master = Master(lag_ring(lag_fmu), MasterSettings(step=H, time_limit=0.01), ["b.u"])
    assert "probe b.u is a Real input" in fast_fmu_support(master)
    assert fast_fmu_support(Master(lag_ring(lag_fmu), MasterSettings(step=H), RING)) is None


def test_pythonfmu_servo_system(tmp_path_factory, fast_runs):
    mcu, drive = build_servo_fmus(tmp_path_factory.mktemp("servo"))
    probes = [Probe("x_um", "x_drive.position", "um"), "x_drive.position", "mcu.x_current_cmd", "z_drive.velocity"]
    result, calls = _both(lambda: servo_fmu_system(mcu, drive), probes, fast_runs, time_limit=0.02, decimation=3)
    assert result.success and result.steps == 20 and len(calls) == 20  # progress every 1 % of 20 ms
    rec = result.recording
    np.testing.assert_array_equal(rec["x_um"], rec["x_drive.position"] * 1e6)
    assert math.isfinite(rec["x_um"][-1]) and rec["x_um"][-1] > 0.0  # moving towards +1 mm
