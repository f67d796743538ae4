"""FMI 3.0 co-simulation FMUs in the master (``FMUComponent``, ``check_fmu``, ``cnctwin check-fmu``).

The fixture ``tests/fixtures/fmu/lag3`` is written in C against the FMI 3.0 API
(compiled by ``tests/fixtures/fmu/cfmu.py``): a feed axis whose velocity
follows ``w = Iq / Ki - F_load / c`` with a first-order lag of time constant
``T`` (``v' = (w - v) / T``, ``x' = v``), positions in mm. With the inputs held
over a step of length ``h`` its solution is exact, so the expected numbers are
the closed form (derived, not taken from the code under test)::

    e = exp(-h / T)
    x_{k+1} = x_k + w_k h + (v_k - w_k) T (1 - e)
    v_{k+1} = w_k + (v_k - w_k) e

and for a constant input from rest at ``x0`` the continuous solution
``x(t) = x0 + w (t - T (1 - exp(-t / T)))`` at every communication point.
Both implementations use the same formula in double precision: agreement to
1e-12 relative (a few ulp).
"""
from __future__ import annotations

import math
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fmus_src.component import Component, Variable
from orchestrator import Master, MasterSettings, Probe, System
from orchestrator.fmu import FMUComponent, FMUError, check_fmu
from orchestrator.fmu.isolated import IsolatedFMUComponent
from orchestrator.fmu.master_loop import fast_fmu_support

sys.path.insert(0, str(Path(__file__).resolve().parent / "fixtures" / "fmu"))
import cfmu  # noqa: E402

needs_cc = pytest.mark.skipif(cfmu.compiler() is None, reason="no C compiler")

#: our name (drive role) -> the FMI 3.0 FMU's name
MAPPING = {"current_cmd": "Iq", "disturbance_force": "F_load", "position": "pos", "velocity": "vel",
           "initial_position": "x0"}
T, KI, C = 0.02, 200.0, 20000.0  # start values of the fixture: s, A/(m/s), N.s/m
LAG3_XML = (cfmu.HERE / "lag3" / "modelDescription.xml").read_text()


@pytest.fixture(scope="module")
def lag3(tmp_path_factory):
    """The compiled FMI 3.0 fixture (only tests marked ``needs_cc`` use it)."""
    return cfmu.build_c_fmu(cfmu.HERE / "lag3", tmp_path_factory.mktemp("lag3"))


def exact(currents: np.ndarray, h: float, force: float = 0.0, x0: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity (m, m/s) at t_0 ... t_n for current currents[k] held over step k."""
    x = np.empty(len(currents) + 1)
    v = np.empty(len(currents) + 1)
    x[0], v[0] = x0, 0.0
    e = math.exp(-h / T)
    for k, current in enumerate(currents):
        w = current / KI - force / C
        x[k + 1] = x[k] + w * h + (v[k] - w) * T * (1.0 - e)
        v[k + 1] = w + (v[k] - w) * e
    return x, v


class Staircase(Component):
    """Current command f(t) = 3 + 2 sin(40 t) A, output valid at the end of each step."""

    variables = (Variable("current", "output", "A", 0.0),)

    @staticmethod
    def f(t: float) -> float:
        return 3.0 + 2.0 * math.sin(40.0 * t)

    def _setup(self, t0: float) -> None:
        self.values["current"][...] = self.f(t0)

    def _do_step(self, t: float, h: float) -> None:
        self.values["current"][...] = self.f(t + h)


# ----------------------------------------------------------------------------- running under the master
@needs_cc
def test_lag_in_the_master_matches_the_exact_discrete_solution(lag3):
    h, n = 1e-3, 120
    system = System("fmi3")
    system.add(Staircase("source"))
    system.add(FMUComponent(lag3, name="lag", role="drive", mapping=MAPPING,
                            parameters={"disturbance_force": 100.0, "initial_position": 0.01}))
    system.connect("source.current", "lag.current_cmd")
    result = Master(system, MasterSettings(step=h, time_limit=n * h),
                    [Probe("x_mm", "lag.position", "mm"), Probe("v", "lag.velocity"),
                     Probe("i", "lag.current_cmd")]).run()
    assert result.success, result.message
    rec = result.recording
    np.testing.assert_allclose(rec.t, np.arange(n + 1) * h, rtol=0, atol=1e-15)
    # Gauss-Seidel, source first: the lag holds f(t_{k+1}) over step k (recorded at t_{k+1})
    held = np.array([Staircase.f(k * h + h) for k in range(n)])  # the source steps from t_k = k h
    np.testing.assert_array_equal(rec["i"][1:], held)
    x, v = exact(held, h, force=100.0, x0=0.01)
    assert x[-1] - x[0] > 1e-3  # it moved more than 1 mm
    np.testing.assert_allclose(rec["x_mm"], x * 1e3, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(rec["v"], v, rtol=1e-12, atol=1e-15)


@needs_cc
def test_an_all_fmi3_system_runs_on_the_compiled_loop_with_the_continuous_solution(lag3):
    h, n, current = 2e-3, 50, 4.0
    system = System("only_fmi3")
    system.add(FMUComponent(lag3, name="lag", parameters={"Iq": current, "x0": 2.0}))
    master = Master(system, MasterSettings(step=h, time_limit=n * h), ["lag.pos", "lag.vel"])
    assert master.settings.compiled
    assert fast_fmu_support(master) is None  # the compiled FMU loop calls FMI 3.0 too (test_fmu_fmi3_fast_loop)
    result = master.run()
    assert result.success, result.message
    t = result.recording.t
    w = current / KI  # m/s
    np.testing.assert_allclose(result.recording["lag.pos"], 2.0 + 1e3 * w * (t - T * (1 - np.exp(-t / T))),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(result.recording["lag.vel"], 1e3 * w * (1 - np.exp(-t / T)), rtol=1e-12, atol=1e-12)


# ----------------------------------------------------------------------------- variables, types, units
@needs_cc
def test_types_and_units_are_exchanged_as_declared(lag3):
    plain = FMUComponent(lag3, name="plain", parameters={"steps0": 40, "tag": "axis X", "Iq": 5.0, "level": -7})
    assert plain.fmi_version == "3.0"
    declared = {v.name: (v.causality, v.type, v.unit) for v in plain.declared_variables()}
    assert "time" not in declared  # the independent variable is not exchanged
    assert declared["pos"] == ("output", "Real", "mm")  # unit from declaredType="Position"
    assert declared["F_load"] == ("input", "Real", "N")  # Float32
    assert declared["steps"] == ("output", "Integer", "1")  # UInt32
    assert declared["hold"] == ("input", "Boolean", "1") and declared["echo"] == ("output", "String", "1")
    plain.setup(0.0)
    assert plain.values["echo"] == "axis X" and plain.values["level2"][0] == -14
    assert plain.values["steps"][0] == 40 and not plain.values["moving"][0]
    h = 1e-3
    for k in range(5):
        plain.do_step(k * h, h)
    x, v = exact(np.full(5, 5.0), h)
    assert plain.values["steps"][0] == 45 and plain.values["moving"][0]
    assert plain.values["pos"][0] == pytest.approx(x[-1] * 1e3, rel=1e-12)
    assert plain.values["vel32"][0] == np.float32(plain.values["vel"][0])  # single precision of the same value
    plain.values["hold"][0] = True  # frozen: the position stays put over the next step
    before = plain.values["pos"][0]
    plain.do_step(5 * h, h)
    assert plain.values["pos"][0] == before and plain.values["steps"][0] == 46
    plain.terminate()
    plain.close()


@needs_cc
def test_an_fmu_with_event_mode_is_instantiated_without_it(lag3):
    from fmpy.fmi3 import FMU3Slave

    from orchestrator.fmu import load_fmu

    loaded = load_fmu(lag3)
    assert 'hasEventMode="true"' in LAG3_XML
    # the fixture refuses eventModeUsed = true ...
    slave = FMU3Slave(guid=loaded.model_description.guid, unzipDirectory=str(loaded.unzip_dir),
                      modelIdentifier="Lag3", instanceName="direct")
    with pytest.raises(Exception, match="Failed to instantiate"):
        slave.instantiate(eventModeUsed=True, logMessage=lambda *args: None)
    # ... so an FMUComponent that instantiates and steps it passed eventModeUsed = false
    comp = FMUComponent(lag3, name="lag")
    comp.setup(0.0)
    comp.do_step(0.0, 1e-3)
    assert comp.values["steps"][0] == 1
    comp.close()


@needs_cc
def test_role_mapping_converts_millimetres_to_metres(lag3):
    mapped = FMUComponent(lag3, name="x_drive", role="drive", mapping=MAPPING,
                          parameters={"initial_position": 0.25, "current_cmd": 2.0})
    assert mapped.variable("position").unit == "m" and mapped.variable("velocity").unit == "m/s"
    mapped.setup(0.0)
    assert mapped.values["position"][0] == pytest.approx(0.25, rel=1e-15)  # 250 mm in the FMU
    h = 1e-3
    for k in range(10):
        mapped.do_step(k * h, h)
    x, v = exact(np.full(10, 2.0), h, x0=0.25)
    assert mapped.values["position"][0] == pytest.approx(x[-1], rel=1e-12)
    assert mapped.values["velocity"][0] == pytest.approx(v[-1], rel=1e-12)
    mapped.close()


# ----------------------------------------------------------------------------- failures
@needs_cc
def test_fmi3_error_status_is_an_fmu_error_naming_function_status_time_and_log(lag3):
    comp = FMUComponent(lag3, name="lag", parameters={"fail_time": 0.0045})
    comp.setup(0.0)
    with pytest.raises(FMUError) as info:
        for k in range(10):
            comp.do_step(k * 1e-3, 1e-3)
    e = info.value
    # steps end at 1, 2, 3, 4, 5 ms: the one starting at t = 4 ms passes 4.5 ms
    assert e.function == "fmi3DoStep" and e.status == 3 and e.time == pytest.approx(0.004)
    assert "lag: fmi3DoStep returned fmi3Error at t = 0.004000 s" in str(e)
    assert "[fmi3Error] injected failure" in str(e)
    assert comp.state == "terminated"
    comp.reset()  # a fresh instance after the failed one was freed
    comp.set("fail_time", -1.0)
    comp.setup(0.0)
    comp.do_step(0.0, 1e-3)
    assert comp.values["steps"][0] == 1
    comp.close()


@needs_cc
def test_fmi3_error_under_the_master_keeps_the_recording(lag3):
    system = System("failing")
    system.add(FMUComponent(lag3, name="lag", parameters={"Iq": 1.0, "fail_time": 0.05}))
    result = Master(system, MasterSettings(step=1e-3, time_limit=0.2), ["lag.pos"]).run()
    assert not result.success
    assert "fmi3DoStep" in result.message and "fmi3Error" in result.message and "t = 0.050000 s" in result.message
    np.testing.assert_allclose(result.recording.t, np.arange(51) * 1e-3, atol=1e-15)


@needs_cc
def test_terminate_simulation_and_early_return_are_fmu_errors(lag3):
    comp = FMUComponent(lag3, name="lag", parameters={"stop_time": 0.003})
    comp.setup(0.0)
    comp.do_step(0.0, 1e-3)
    comp.do_step(1e-3, 1e-3)
    with pytest.raises(FMUError, match=r"lag: fmi3DoStep returned terminateSimulation = true .* at t = 0\.002000 s"):
        comp.do_step(2e-3, 1e-3)
    assert comp.state == "terminated"
    comp = FMUComponent(lag3, name="lag", parameters={"early_time": 0.0015})
    comp.setup(0.0)
    comp.do_step(0.0, 1e-3)
    with pytest.raises(FMUError, match=r"earlyReturn = true \(lastSuccessfulTime = 0\.001500 s, expected a full step "
                                       r"to t \+ h = 0\.002000 s\); early return is not supported") as info:
        comp.do_step(1e-3, 1e-3)
    assert info.value.function == "fmi3DoStep"


@needs_cc
def test_isolated_fmi3_component_runs_and_names_fmi3_functions(lag3):
    comp = IsolatedFMUComponent(lag3, name="iso", parameters={"Iq": 3.0, "fail_time": 0.0025})
    try:
        comp.setup(0.0)
        comp.do_step(0.0, 1e-3)
        comp.do_step(1e-3, 1e-3)
        x, _ = exact(np.full(2, 3.0), 1e-3)
        assert comp.values["pos"][0] == pytest.approx(x[-1] * 1e3, rel=1e-12)
        with pytest.raises(FMUError, match=r"iso: fmi3DoStep returned fmi3Error at t = 0\.002000 s"):
            comp.do_step(2e-3, 1e-3)
    finally:
        comp.close()


# ----------------------------------------------------------------------------- files that are refused
def _zip(path: Path, files: dict[str, str]) -> Path:
    with zipfile.ZipFile(path, "w") as zf:
        for name, text in files.items():
            zf.writestr(name, text)
    return path


_CS = ('<CoSimulation modelIdentifier="Lag3" canHandleVariableCommunicationStepSize="true" hasEventMode="true"\n'
       '    canReturnEarlyAfterIntermediateUpdate="false" canGetAndSetFMUState="false" canSerializeFMUState="false"/>')


@pytest.mark.parametrize("interface, kind", [
    ('<ModelExchange modelIdentifier="Lag3"/>', "model-exchange-only FMU"),
    ('<ScheduledExecution modelIdentifier="Lag3"/>', "scheduled-execution-only FMU"),
])
def test_fmi3_fmu_without_co_simulation_is_refused_naming_its_interface(tmp_path, interface, kind):
    assert LAG3_XML.count(_CS) == 1
    path = _zip(tmp_path / "only.fmu", {"modelDescription.xml": LAG3_XML.replace(_CS, interface)})
    with pytest.raises(FMUError, match=rf"only\.fmu: {kind}; a co-simulation FMU is required"):
        FMUComponent(path)


def test_fmi3_binary_is_looked_up_under_the_platform_tuple(tmp_path):
    path = _zip(tmp_path / "v3.fmu", {"modelDescription.xml": LAG3_XML, "binaries/linux64/Lag3.so": "x"})
    with pytest.raises(FMUError, match=r"no binary binaries/x86_64-linux/Lag3\.so .*\['linux64'\]"):
        FMUComponent(path)


def test_array_variable_is_no_longer_refused(tmp_path):
    """An array parameter binds (as gains[1] .. gains[3], tests/test_fmu_arrays.py): what stops this archive is
    its placeholder binary, checked after the variables are bound."""
    array = ('<Float64 name="gains" valueReference="30" causality="parameter" variability="fixed" start="1 2 3">'
             '<Dimension start="3"/></Float64>\n  </ModelVariables>')
    md = LAG3_XML.replace("</ModelVariables>", array)
    path = _zip(tmp_path / "arr.fmu", {"modelDescription.xml": md, "binaries/x86_64-linux/Lag3.so": "x"})
    with pytest.raises(FMUError, match=r"binaries/x86_64-linux/Lag3\.so .*expected a shared library"):
        FMUComponent(path)


# ----------------------------------------------------------------------------- check_fmu / cnctwin check-fmu
@needs_cc
def test_check_fmu_reports_and_runs_an_fmi3_fmu(lag3):
    report = check_fmu(lag3, role="drive", mapping=MAPPING, parameters={"current_cmd": 5.0})
    assert report.fmi_version == "3.0" and report.problems == [] and report.smoke_ok and report.ok, report.to_text()
    types = {v.name: v.type for v in report.variables}
    assert types["F_load"] == "Float32" and types["steps"] == "UInt32" and types["time"] == "Float64"
    rows = {r.ours: r for r in report.role_rows}
    assert rows["position"].theirs == "pos" and "1 m = 1000 mm" in rows["position"].status
    # 50 steps of the default 1 ms at 5 A from rest: x(t) = w (t - T (1 - exp(-t/T))), w = 5 / 200 m/s;
    # the smoke run renames through the mapping but keeps the FMU's units (mm)
    t, w = 0.05, 5.0 / KI
    assert report.smoke_outputs["position"] == pytest.approx(1e3 * w * (t - T * (1 - math.exp(-t / T))), rel=1e-12)
    assert report.smoke_outputs["steps"] == 50 and report.smoke_outputs["echo"] == "lag3"
    assert "FMI 3.0" in report.to_text()


@needs_cc
def test_cnctwin_check_fmu_on_an_fmi3_fmu(lag3, capsys):
    import argparse

    from orchestrator.cli_fmu import add_parsers

    parser = argparse.ArgumentParser(prog="cnctwin")
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["check-fmu", str(lag3), "--role", "drive", "--map", "current_cmd=Iq",
                              "--map", "disturbance_force=F_load", "--map", "position=pos", "--map", "velocity=vel"])
    assert args.func(args) == 0
    out = capsys.readouterr().out
    assert "FMI 3.0" in out and "validation: no problems" in out and "verdict: OK" in out
