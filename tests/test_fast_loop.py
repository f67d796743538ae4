"""FastFMULoop: the compiled stepping loop gives the Python master's recordings bit for bit.

Fixtures: the four-lag ring of C FMUs (orchestrator/bench/lag_fmu) and the
foreign drive C FMU (millimetres at its interface, so unit factors are
exercised). Expected values: the Python master over the same FMUs (same
calls, same floating-point operations: equality is exact), and for the ring
the exact zero-order-hold recursion y <- k u + (y - k u) exp(-h / tau),
evaluated independently in numpy (agreement to a few ulp: numpy's and the C
library's exp may differ in the last bit).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi2 import FMU2Slave

from orchestrator import Master, MasterSettings
from orchestrator.bench.cfmu import build_lag_fmu, lag_ring
from orchestrator.bench.systems import ring_exact
from orchestrator.fmu import FMUComponent, FMUError, load_fmu
from orchestrator.fmu.fast_loop import FastFMULoop, compiler

sys.path.insert(0, str(Path(__file__).resolve().parent / "fixtures" / "fmu"))
import cfmu  # noqa: E402

pytestmark = pytest.mark.skipif(compiler() is None, reason="no C compiler")

PROBES = ["a.y", "b.y", "c.y", "d.y"]
H = 1e-3


@pytest.fixture(scope="module")
def lag_fmu(tmp_path_factory):
    return build_lag_fmu(tmp_path_factory.mktemp("lag"))


def _master(system, n, method="gauss-seidel"):
    run = Master(system, MasterSettings(step=H, time_limit=n * H, method=method), PROBES).run()
    assert run.success, run.message
    return run.recording


@pytest.mark.parametrize("method", ["gauss-seidel", "jacobi"])
def test_ring_bit_identical_to_master(lag_fmu, method):
    n = 400
    rec = _master(lag_ring(lag_fmu, k_last=-0.8), n, method)
    loop = FastFMULoop.from_system(lag_ring(lag_fmu, k_last=-0.8), PROBES, method=method)
    res = loop.run(n, H)
    np.testing.assert_array_equal(res.t, rec["t_s"])
    for p in PROBES:
        np.testing.assert_array_equal(res[p], rec[p])


def test_ring_matches_exact_recursion(lag_fmu):
    n = 300
    res = FastFMULoop.from_system(lag_ring(lag_fmu, tau=0.02, k_last=-0.8), PROBES).run(n, H)
    exact = ring_exact(n, H, tau=0.02, k_last=-0.8)
    np.testing.assert_allclose(res.values, exact, rtol=0, atol=1e-14)
    # the ring oscillates (complex poles) and decays (|k_last| < 1)
    assert np.any(np.diff(np.sign(exact[:, 0])) != 0) and abs(exact[-1, 0]) < abs(exact[0, 0])


def test_continued_runs_equal_one_run(lag_fmu):
    one = FastFMULoop.from_system(lag_ring(lag_fmu), PROBES).run(250, H)
    loop = FastFMULoop.from_system(lag_ring(lag_fmu), PROBES)
    first = loop.run(100, H)
    second = loop.run(150, H)
    np.testing.assert_array_equal(np.vstack([first.values, second.values[1:]]), one.values)
    np.testing.assert_array_equal(second.t, one.t[100:])
    # the final outputs are handed back to the FMUComponents
    system_values = [c.values["y"][0] for c in loop.objects.values()]
    np.testing.assert_array_equal(system_values, one.values[-1])


def test_multi_rate_bit_identical_to_master(lag_fmu):
    def build():
        system = lag_ring(lag_fmu, k_last=-0.5)
        system.rates.update({"b": 2, "c": 4})  # b at 500 us, c at 250 us
        return system

    n = 200
    rec = _master(build(), n)
    res = FastFMULoop.from_system(build(), PROBES).run(n, H)
    for p in PROBES:
        np.testing.assert_array_equal(res[p], rec[p])


def test_failure_names_component_function_and_time(lag_fmu):
    system = lag_ring(lag_fmu, fail_time=0.0505, fail_at="c")
    with pytest.raises(FMUError) as info:
        FastFMULoop.from_system(system, PROBES).run(100, H)
    err = info.value
    assert err.component == "c" and err.function == "fmi2DoStep" and err.status == 3
    assert err.time == pytest.approx(0.050, abs=1e-12)  # the step [0.050, 0.051] passes 0.0505
    assert "c: fmi2DoStep returned fmi2Error at t = 0.050000 s" in str(err)
    # the Python master reports the same failure
    run = Master(lag_ring(lag_fmu, fail_time=0.0505, fail_at="c"), MasterSettings(step=H, time_limit=0.1)).run()
    assert not run.success and run.message.endswith(str(err))


def _raw_slave(fmu: Path, name: str, params: dict[str, float]) -> FMU2Slave:
    md = read_model_description(str(fmu))
    loaded = load_fmu(fmu)
    slave = FMU2Slave(guid=md.guid, unzipDirectory=str(loaded.unzip_dir), modelIdentifier="Lag", instanceName=name)
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    vrs = {v.name: v.valueReference for v in md.modelVariables}
    slave.setReal([vrs[k] for k in params], list(params.values()))
    slave.exitInitializationMode()
    return slave


def test_raw_fmpy_slaves(lag_fmu):
    slaves = {n: _raw_slave(lag_fmu, n, {"tau": 0.01, "k": 1.0, "y0": 1.0 if n == "a" else 0.0}) for n in "abcd"}
    conns = [("a.y", "b.u"), ("b.y", "c.u"), ("c.y", "d.u"), ("d.y", "a.u")]
    res = FastFMULoop(slaves, conns, PROBES).run(300, H)
    ref = FastFMULoop.from_system(lag_ring(lag_fmu), PROBES).run(300, H)
    np.testing.assert_array_equal(res.values, ref.values)
    for s in slaves.values():
        s.terminate()
        s.freeInstance()


def test_bad_references_raise(lag_fmu):
    system = lag_ring(lag_fmu)
    with pytest.raises(FMUError, match="no Real output 'nope'"):
        FastFMULoop.from_system(system, ["a.nope"])
    with pytest.raises(FMUError, match="no instance 'z'"):
        FastFMULoop(system.components, [("z.y", "a.u")])
    with pytest.raises(FMUError, match="connected twice"):
        FastFMULoop(system.components, [("a.y", "b.u"), ("c.y", "b.u")])


def test_unit_factors_match_fmucomponent_stepping(lag_fmu, tmp_path):
    """Foreign drive (mm inside, m outside) driven by a lag: FMUComponent.do_step by hand vs the compiled loop."""
    from test_fmu_foreign import MAPPING  # the drive-role mapping of the foreign C drive

    foreign = cfmu.build_c_fmu(cfmu.HERE / "foreign_drive", tmp_path)

    def build():
        lag = FMUComponent(lag_fmu, "lag", parameters={"tau": 0.05, "k": 1.0, "y0": 5.0})
        drive = FMUComponent(foreign, "drive", role="drive", mapping=MAPPING,
                             parameters={"initial_position": 0.002, "dt_max": 125e-6})
        return lag, drive

    n = 300
    lag, drive = build()
    lag.setup(0.0)
    drive.values["current_cmd"][0] = lag.values["y"][0]
    drive.setup(0.0)
    expected = np.empty((n + 1, 2))
    expected[0] = drive.values["position"][0], drive.values["velocity"][0]
    for k in range(n):
        t = k * H
        lag.do_step(t, H)
        drive.values["current_cmd"][0] = lag.values["y"][0]
        drive.do_step(t, H)
        expected[k + 1] = drive.values["position"][0], drive.values["velocity"][0]
    lag2, drive2 = build()
    res = FastFMULoop({"lag": lag2, "drive": drive2}, [("lag.y", "drive.current_cmd")],
                      ["drive.position", "drive.velocity"]).run(n, H)
    np.testing.assert_array_equal(res.values, expected)
    assert 0.002 < expected[-1, 0] < 1.0  # it moved (5 A -> 2.6 kN > static friction), in metres
