"""The master's compiled FMU loop (FastFMULoop) over FMI 3.0 FMUs, alone and mixed with FMI 2.0 ones.

Every master run is made twice on freshly built systems: with the Python loop
(``MasterSettings(compiled=False)``) and with the default (the compiled FMU
loop); recordings, every RunResult field, the progress calls and the values the
components hold afterwards must be equal, bit for bit.

The FMI 3.0 fixture is ``tests/fixtures/fmu/lag3`` (C against the FMI 3.0
headers): ``v' = (w - v) / T``, ``x' = v`` with ``w = Iq / Ki - (F_load + F_ext) / c``
and the output ``Iq_eq = Ki v``. Three instances wired ``a.Iq_eq -> b.Iq ->
... -> c.Iq_eq -> a.Iq`` and driven by a constant ``F_load`` on ``a`` follow,
with the inputs held over each step, the exact recursion (:func:`ring_exact`,
derived from the model, numpy only)::

    e = exp(-h / T_i)
    w_i = Iq_i / Ki_i - F_i / c
    x_i <- x_i + w_i h + (v_i - w_i) T_i (1 - e),   v_i <- w_i + (v_i - w_i) e
    Iq_eq_i = Ki_i v_i

Gauss–Seidel: ``Iq_i`` is the source's output of the same tick (``a`` takes
``c`` of the previous step); Jacobi: of the previous step.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from orchestrator import Master, MasterSettings, Probe, System
from orchestrator.bench.cfmu import build_lag_fmu, lag_ring
from orchestrator.bench.systems import ring_exact as lag_ring_exact
from orchestrator.fmu import FMUComponent, FMUError, fmi3, load_fmu
from orchestrator.fmu.fast_loop import FastFMULoop
from orchestrator.fmu.master_loop import fast_fmu_support

sys.path.insert(0, str(Path(__file__).resolve().parent / "fixtures" / "fmu"))
import cfmu  # noqa: E402
from tests.test_master_fast_fmu import _both as _same_runs  # noqa: E402
from tests.test_master_fast_fmu import fast_runs  # noqa: E402,F401 (fixture)

needs_cc = pytest.mark.skipif(cfmu.compiler() is None, reason="no C compiler")
pytestmark = needs_cc  # every test builds a C FMU (and the compiled loop needs the compiler too)

H = 1e-3
C = 20000.0  # N.s/m, the fixture's c
STAGES = ("a", "b", "c")
KI = {"a": 200.0, "b": 400.0, "c": 100.0}  # A/(m/s)
TAU = {"a": 0.02, "b": 0.01, "c": 0.03}  # s
F_LOAD_A = -100.0  # N, drives stage a forward: w = 100 / 20000 = 5 mm/s
RING = [f"{s}.pos" for s in STAGES] + ["b.vel", "c.Iq_eq"]


@pytest.fixture(scope="module")
def lag3(tmp_path_factory):
    return cfmu.build_c_fmu(cfmu.HERE / "lag3", tmp_path_factory.mktemp("lag3"))


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    return cfmu.build_c_fmu(cfmu.HERE / "foreign_drive", tmp_path_factory.mktemp("foreign"))


@pytest.fixture(scope="module")
def lag_fmu(tmp_path_factory):
    return build_lag_fmu(tmp_path_factory.mktemp("lag2"))


def lag3_ring(fmu: Path, **extra: dict) -> System:
    """Stages a, b, c of the FMI 3.0 lag in a ring through Iq_eq -> Iq; ``extra[stage]``: more parameters."""
    system = System("lag3_ring")
    for s in STAGES:
        params = {"Ki": KI[s], "T": TAU[s], **extra.get(s, {})}
        if s == "a":
            params["F_load"] = F_LOAD_A
        system.add(FMUComponent(fmu, s, parameters=params))
    for src, dst in zip(STAGES, STAGES[1:] + STAGES[:1]):
        system.connect(f"{src}.Iq_eq", f"{dst}.Iq")
    system.set_execution_order(list(STAGES))
    return system


def ring_exact(n: int, h: float, jacobi: bool = False) -> dict[str, np.ndarray]:
    """pos (mm), vel (mm/s) and Iq_eq (A) of every stage at t_0 ... t_n (see the module docstring)."""
    x = dict.fromkeys(STAGES, 0.0)
    v = dict.fromkeys(STAGES, 0.0)
    out = {f"{s}.{q}": np.zeros(n + 1) for s in STAGES for q in ("pos", "vel", "Iq_eq")}
    source = {"a": "c", "b": "a", "c": "b"}
    force = {"a": F_LOAD_A, "b": 0.0, "c": 0.0}
    for k in range(n):
        before = {s: KI[s] * v[s] for s in STAGES}
        for s in STAGES:
            iq = before[source[s]] if jacobi else KI[source[s]] * v[source[s]]
            w = iq / KI[s] - force[s] / C
            e = math.exp(-h / TAU[s])
            x[s], v[s] = x[s] + w * h + (v[s] - w) * TAU[s] * (1.0 - e), w + (v[s] - w) * e
        for s in STAGES:
            out[f"{s}.pos"][k + 1] = x[s] * 1e3
            out[f"{s}.vel"][k + 1] = v[s] * 1e3
            out[f"{s}.Iq_eq"][k + 1] = KI[s] * v[s]
    return out


def _both(make, probes, fast_runs, expected_duration=None, **settings):
    """The Python loop and the compiled FMU loop give the same everything, String values included."""
    return _same_runs(make, probes, fast_runs, expected_duration, strings=True, **settings)[0]


# ----------------------------------------------------------------------------- same results, exact numbers
@pytest.mark.parametrize("method", ["gauss-seidel", "jacobi"])
def test_fmi3_ring_matches_the_python_loop_and_the_exact_recursion(lag3, fast_runs, method):
    make = lambda: lag3_ring(lag3)  # noqa: E731
    assert fast_fmu_support(Master(make(), MasterSettings(step=H), RING)) is None
    result = _both(make, RING, fast_runs, time_limit=0.2, method=method)
    assert result.success and result.steps == 200
    exact = ring_exact(200, H, jacobi=method == "jacobi")
    assert exact["c.pos"][-1] > 0.1  # the last stage moved more than 0.1 mm
    for ref in RING:
        np.testing.assert_allclose(result.recording[ref], exact[ref], rtol=1e-12, atol=1e-12, err_msg=ref)


def test_values_the_loop_does_not_read_every_step_are_refreshed(lag3, fast_runs):
    """Float32 vel32, UInt32 steps, Boolean moving, String echo: read once after the run, as after the last step."""
    result = _both(lambda: lag3_ring(lag3), ["a.pos"], fast_runs, time_limit=0.05)
    assert result.steps == 50  # _both compared every held value; here the numbers derived by hand
    system = lag3_ring(lag3)
    master = Master(system, MasterSettings(step=H, time_limit=0.05), ["a.pos"])
    master.run()
    a = system.components["a"]
    assert a.values["steps"][0] == 50 and a.values["moving"][0] and a.values["echo"] == "lag3"
    assert a.values["vel32"][0] == np.float32(ring_exact(50, H)["a.vel"][-1])


def test_time_limit_multi_rate_decimation_progress(lag3, fast_runs):
    def make():
        system = lag3_ring(lag3)
        system.rates.update({"b": 2, "c": 4})
        return system

    probes = RING + [Probe("c_um", "c.pos", "um")]
    result = _both(make, probes, fast_runs, time_limit=0.3, decimation=7, expected_duration=0.25)
    assert result.success and result.message == "time limit of 0.3 s reached" and result.steps == 300
    ks = np.r_[np.arange(0, 301, 7), 300]  # every 7th step, and the last one
    np.testing.assert_array_equal(result.recording["t_s"], ks * H)
    np.testing.assert_allclose(result.recording["c_um"], result.recording["c.pos"] * 1e3, rtol=1e-15)
    assert len(fast_runs) > 100  # chunks end at the progress reports (every 1 % of 0.25 s)


def test_mixed_fmi2_and_fmi3_system(lag3, foreign, lag_fmu, fast_runs):
    """The FMI 2.0 lag ring, and an FMI 3.0 lag feeding the FMI 2.0 drive, whose motor force loads it back."""
    def make():
        system = lag_ring(lag_fmu, k_last=-0.8)
        system.add(FMUComponent(lag3, "x", parameters={"Iq": 4.0, "c": 1e6}))
        system.add(FMUComponent(foreign, "drive"))
        system.connect("x.Iq_eq", "drive.Iq")
        system.connect("drive.F_motor", "x.F_ext")
        system.set_execution_order(["a", "b", "c", "d", "x", "drive"])
        return system

    probes = ["a.y", "d.y", "x.pos", "x.Iq_eq", "drive.pos", "drive.F_motor"]
    result = _both(make, probes, fast_runs, time_limit=0.2, decimation=2)
    assert result.success and result.steps == 200
    rec = result.recording
    np.testing.assert_allclose(rec["d.y"], lag_ring_exact(200, H, k_last=-0.8)[::2, 3], rtol=0, atol=1e-14)
    assert rec["drive.pos"][-1] > 0.0 and rec["drive.F_motor"][-1] > 0.0  # the FMI 3.0 lag drove the 2.0 drive


def test_limit_exceeded_at_a_check_step(lag3, fast_runs):
    limit = 0.5  # mm
    result = _both(lambda: lag3_ring(lag3), RING, fast_runs, time_limit=2.0, limits={"c.pos": (-limit, limit)},
                   check_every=10, decimation=5)
    exact = ring_exact(2000, H)["c.pos"]
    k_fail = next(k for k in range(10, 2001, 10) if abs(exact[k]) > limit)
    assert not result.success and result.steps == k_fail
    assert result.message.startswith(f"simulation diverged at t = {k_fail * H:.6f} s: c.pos = ")
    assert result.message.endswith("is outside [-0.5, 0.5]")


# ----------------------------------------------------------------------------- errors
def test_fmi3_error_ends_the_run_with_the_recording_so_far(lag3, fast_runs):
    make = lambda: lag3_ring(lag3, b={"fail_time": 0.0505})  # noqa: E731
    result = _both(make, RING, fast_runs, time_limit=0.3, decimation=3)
    # steps of b end at 1, 2, ... ms: the one from 50 ms to 51 ms passes 50.5 ms
    assert not result.success and result.steps == 50 and result.t_end == 50 * H
    assert result.message.startswith("simulation failed at t = 0.050000 s: b: fmi3DoStep returned fmi3Error "
                                     "at t = 0.050000 s")
    assert "[fmi3Error] injected failure" in result.message
    np.testing.assert_array_equal(result.recording["t_s"], np.arange(0, 49, 3) * H)  # the last sample before
    np.testing.assert_allclose(result.recording["c.pos"], ring_exact(48, H)["c.pos"][::3], rtol=1e-12, atol=1e-12)


def test_fmi2_error_in_a_mixed_system(lag3, foreign, fast_runs):
    def make():
        system = System("mixed")
        system.add(FMUComponent(lag3, "x", parameters={"Iq": 4.0, "c": 1e6}))
        system.add(FMUComponent(foreign, "drive", parameters={"fail_time": 0.0205}))
        system.connect("x.Iq_eq", "drive.Iq")
        system.connect("drive.F_motor", "x.F_ext")
        return system

    result = _both(make, ["x.pos", "drive.pos"], fast_runs, time_limit=0.1)
    assert not result.success and result.steps == 20
    assert result.message.startswith("simulation failed at t = 0.020000 s: drive: fmi2DoStep returned fmi2Error "
                                     "at t = 0.020000 s")


def test_terminate_simulation_with_multi_rate(lag3, fast_runs):
    def make():
        system = lag3_ring(lag3, c={"stop_time": 0.0125})
        system.rates.update({"c": 4})
        return system

    result = _both(make, RING, fast_runs, time_limit=0.1)
    # c steps 0.25 ms at t = k/4 ms: the step from 12.25 ms ends at 12.5 ms, inside communication step 12
    assert not result.success and result.steps == 12
    assert result.message.startswith("simulation failed at t = 0.012000 s: c: fmi3DoStep returned "
                                     "terminateSimulation = true (the FMU asks to end the simulation) "
                                     "at t = 0.012250 s")


def test_early_return(lag3, fast_runs):
    result = _both(lambda: lag3_ring(lag3, a={"early_time": 0.0305}), RING, fast_runs, time_limit=0.1)
    assert not result.success and result.steps == 30
    assert ("a: fmi3DoStep returned earlyReturn = true (lastSuccessfulTime = 0.030500 s, expected a full step to "
            "t + h = 0.031000 s); early return is not supported" in result.message)
    assert "at t = 0.030000 s" in result.message


# ----------------------------------------------------------------------------- what stays on the Python loop
@pytest.mark.parametrize("probes, stop, reason, steps", [
    (["a.moving"], None, "probe a.moving is an FMI 3.0 Boolean output", 20),
    (["a.vel32"], None, "probe a.vel32 is an FMI 3.0 Float32 output", 20),
    (["a.pos"], "b.steps", "stop signal b.steps is an FMI 3.0 UInt32 output", 1),  # b.steps = 1 after step 1
])
def test_non_float64_probes_of_fmi3_fmus_fall_back(lag3, fast_runs, probes, stop, reason, steps):
    settings = {"time_limit": 0.02} | ({"stop_when": stop} if stop else {})
    master = Master(lag3_ring(lag3), MasterSettings(step=H, **settings), probes)
    assert fast_fmu_support(master) == f"{reason} (the FMU loop takes Float64 outputs of FMI 3.0 FMUs only)"
    result = master.run()
    assert result.success and result.steps == steps and not fast_runs


def test_a_float32_connection_falls_back(lag3, foreign, fast_runs):
    system = System("float32")
    system.add(FMUComponent(foreign, "drive", parameters={"Iq": 2.0}))
    system.add(FMUComponent(lag3, "x"))
    system.connect("drive.F_motor", "x.F_load")
    master = Master(system, MasterSettings(step=H, time_limit=0.01), ["x.pos"])
    assert fast_fmu_support(master) == ("connection drive.F_motor -> x.F_load: x.F_load is an FMI 3.0 Float32 "
                                        "input (the FMU loop connects Float64 variables of FMI 3.0 FMUs only)")
    assert master.run().success and not fast_runs


def test_fast_loop_refuses_a_boolean_record_of_an_fmi3_fmu(lag3):
    with pytest.raises(FMUError, match=r"x\.moving is an FMI 3\.0 FMU's variable other than Float64; the compiled "
                                       r"loop connects and records Float64 variables only"):
        FastFMULoop({"x": FMUComponent(lag3, "x")}, record=["x.moving"])


# ----------------------------------------------------------------------------- a bare fmpy FMU3Slave
def _slave(lag3: Path, name: str, **params: float):
    loaded = load_fmu(lag3)
    slave, *callbacks = fmi3.instantiate_co_simulation("Lag3", loaded.model_description.guid, loaded.unzip_dir,
                                                       name, lambda *args: None)
    vrs = {v.name: v.valueReference for v in loaded.model_description.modelVariables}
    slave.fmi3EnterInitializationMode(slave.component, False, 0.0, 0.0, False, 0.0)
    for key, value in params.items():
        slave.setFloat64([vrs[key]], [value])
    slave.fmi3ExitInitializationMode(slave.component)
    return slave, callbacks


def test_bare_fmu3_slaves_follow_the_continuous_solution(lag3):
    a, keep_a = _slave(lag3, "a", Iq=4.0)
    b, keep_b = _slave(lag3, "b", Ki=400.0)
    loop = FastFMULoop({"a": a, "b": b}, [("a.Iq_eq", "b.Iq")], record=["a.pos", "b.vel"])
    result = loop.run(100, 2e-3)
    t = result.t
    w = 4.0 / 200.0  # m/s; T = 0.02 s from rest: x(t) = w (t - T (1 - exp(-t / T)))
    np.testing.assert_allclose(result["a.pos"], 1e3 * w * (t - 0.02 * (1 - np.exp(-t / 0.02))), rtol=1e-12,
                               atol=1e-12)
    assert 0.0 < result["b.vel"][-1] < 1e3 * w / 2  # b follows a at half the gain (Ki 400), lagging
    for s in (a, b):
        s.terminate()
        s.freeInstance()


def test_bare_fmu3_slave_terminate_simulation_is_an_fmu_error(lag3):
    a, keep = _slave(lag3, "a", Iq=1.0, stop_time=0.0035)
    loop = FastFMULoop({"a": a}, record=["a.pos"])
    with pytest.raises(FMUError, match=r"^a: fmi3DoStep returned terminateSimulation = true \(the FMU asks to end "
                                       r"the simulation\) at t = 0\.003000 s \(FastFMULoop\)$") as info:
        loop.run(10, 1e-3)
    assert info.value.function == "fmi3DoStep" and info.value.time == pytest.approx(3e-3)
    assert loop.partial is not None and loop.partial.values.shape == (4, 1)  # rows at 0, 1, 2, 3 ms
    a.freeInstance()
