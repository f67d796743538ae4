"""FMUs the master has never seen: legal FMI 2.0 / 3.0 co-simulation FMUs as other exporters write them.

Small C FMUs modelled on the Modelica Association's Reference FMUs, compiled
once per module from ``tests/fixtures/fmu/unseen`` (``common2.c`` is the
FMI 2.0 slave around each ``<model>.c``; ``counter3.c`` is FMI 3.0):

* ``Dahlquist`` (``dahlquist-1.2.fmu``: the file name is not the
  ``modelIdentifier``): ``x' = -k x`` stepped exactly, ``x = x0 exp(-k t)``;
  Latin-1 ``modelDescription.xml`` with a comment and a namespace
  declaration, a GUID with braces, ``<UnitDefinitions>`` with display units,
  ``<Derivatives>``/``<InitialUnknowns>``, a ``calculatedParameter``, an
  output with ``initial="calculated"``, and
  ``canHandleVariableCommunicationStepSize="false"`` (it returns fmi2Error
  when the step size changes);
* ``Stair``: an Integer counter of time events at ``t0 + n period``, a Boolean
  ``odd`` and a String label; parameters make a step return fmi2Discard,
  fmi2Error or fmi2Pending and ``fmi2Terminate`` return a status; it logs in
  ``fmi2Terminate`` and ``fmi2FreeInstance``;
* ``Feedthrough``: Real/Integer/Enumeration/Boolean/String inputs to outputs,
  fixed and tunable parameters;
* ``Resource``: reads ``resources/y.txt`` through ``fmuResourceLocation``;
* ``Counter3`` (FMI 3.0): Dahlquist and the stair counter with a String
  label, ``fail_time`` makes ``fmi3DoStep`` return fmi3Error.

Every FMU checks the communication point it is given against the end of its
last step (as the Reference FMUs do). Master runs are made on the Python loop
and the compiled FMU loop and must agree bit for bit (``_both`` of
``tests/test_master_fast_fmu.py``).
"""
from __future__ import annotations

import math
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from orchestrator import Master, MasterSettings, Probe, System
from orchestrator.errors import SystemDescriptionError
from orchestrator.fmu import FMUComponent, FMUError, check_fmu
from orchestrator.fmu.isolated import IsolatedFMUComponent

sys.path.insert(0, str(Path(__file__).resolve().parent / "fixtures" / "fmu"))
import cfmu  # noqa: E402
from tests.test_master_fast_fmu import _both  # noqa: E402
from tests.test_master_fast_fmu import fast_runs  # noqa: E402,F401 (fixture)

needs_cc = pytest.mark.skipif(cfmu.compiler() is None, reason="no C compiler")
pytestmark = needs_cc  # every test uses the C FMUs built below

SOURCES = cfmu.HERE / "unseen"
#: source name -> (modelIdentifier, FMU file name, binary folder)
MODELS = {
    "dahlquist": ("Dahlquist", "dahlquist-1.2.fmu", "linux64"),
    "stair": ("Stair", "Stair.fmu", "linux64"),
    "feedthrough": ("Feedthrough", "Feedthrough.fmu", "linux64"),
    "resource": ("Resource", "Resource.fmu", "linux64"),
    "counter3": ("Counter3", "Counter3.fmu", "x86_64-linux"),
}
RESOURCE_Y = 42.5


def _compile(name: str, out: Path) -> bytes:
    """The shared library of model ``name`` (FMI 2.0 models: its #defines, common2.c, then the model)."""
    text = (SOURCES / f"{name}.c").read_text()
    if name != "counter3":  # the model's leading #defines, the generic slave, then the rest of the model
        lines = text.splitlines(keepends=True)
        n = next(i for i, line in enumerate(lines) if not line.startswith("#define"))
        text = "".join(lines[:n]) + (SOURCES / "common2.c").read_text() + "".join(lines[n:])
    source = out / f"{name}.c"
    source.write_text(text)
    library = out / f"{name}.so"
    subprocess.run([cfmu.compiler() or "gcc", "-std=c99", "-O2", "-Wall", "-Wno-unused-parameter",
                    "-Wno-unused-function", "-shared", "-fPIC", "-o", str(library), str(source), "-lm"],
                   check=True, capture_output=True, text=True)
    return library.read_bytes()


def _pack(fmu: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return fmu


def _variant(fmu: Path, out: Path, edit, drop: str | None = None) -> Path:
    """A copy of ``fmu`` with ``modelDescription.xml`` edited (as text in its own encoding), members under ``drop``
    removed."""
    members = {}
    with zipfile.ZipFile(fmu) as zf:
        for name in zf.namelist():
            if drop is not None and name.startswith(drop):
                continue
            members[name] = zf.read(name)
    xml = members["modelDescription.xml"]
    encoding = "iso-8859-1" if b'encoding="ISO-8859-1"' in xml else "utf-8"
    members["modelDescription.xml"] = edit(xml.decode(encoding)).encode(encoding)
    return _pack(out, members)


@pytest.fixture(scope="module")
def fmus(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("unseen")
    built = {}
    for name, (identifier, file_name, platform) in MODELS.items():
        members = {"modelDescription.xml": (SOURCES / f"{name}.xml").read_bytes(),
                   f"binaries/{platform}/{identifier}.so": _compile(name, out)}
        if name == "resource":
            members["resources/y.txt"] = f"{RESOURCE_Y}\n".encode()
        built[name] = _pack(out / file_name, members)
    return built


def _one(fmu: Path, name: str, rate: int = 1, **parameters) -> System:
    system = System(name)
    system.add(FMUComponent(fmu, name, parameters=parameters), rate=rate)
    return system


# ----------------------------------------------------------------------------- numbers from the FMUs' own solutions
@pytest.mark.parametrize("rate", [1, 3])
def test_dahlquist_follows_the_exact_decay_on_both_loops(fmus, fast_runs, rate):
    """x = x0 exp(-k t) at every communication point, in m and in mm; at rate 3 every step is h / 3 (the FMU
    refuses a changing step: canHandleVariableCommunicationStepSize="false")."""
    result, _ = _both(lambda: _one(fmus["dahlquist"], "d", rate, k=2.0, x0=0.5),
                      ["d.x", Probe("x_mm", "d.x", "mm")], fast_runs, time_limit=1.0)
    assert result.success and result.steps == 1000
    t = result.recording["t_s"]
    np.testing.assert_allclose(result.recording["d.x"], 0.5 * np.exp(-2.0 * t), rtol=5e-13, atol=0)
    np.testing.assert_allclose(result.recording["x_mm"], 500.0 * np.exp(-2.0 * t), rtol=5e-13, atol=0)


def test_stair_counts_its_time_events_on_both_loops(fmus, fast_runs):
    """Events at 3, 6, 9 ms: the Integer counter and the Boolean odd flag, recorded and held, and the String
    label the component holds at the end."""
    result, _ = _both(lambda: _one(fmus["stair"], "st", period=0.003), ["st.counter", "st.odd"], fast_runs,
                      strings=True, time_limit=0.01)
    expected = np.floor(np.round(result.recording["t_s"] / 0.003, 9))
    np.testing.assert_array_equal(result.recording["st.counter"], expected)
    np.testing.assert_array_equal(result.recording["st.odd"], expected % 2)
    assert expected[-1] == 3


def test_fmi3_counter_decays_and_counts_on_both_loops(fmus, fast_runs):
    result, _ = _both(lambda: _one(fmus["counter3"], "c", k=50.0, period=0.0025), ["c.x"], fast_runs, strings=True,
                      time_limit=0.01)
    np.testing.assert_allclose(result.recording["c.x"], np.exp(-50.0 * result.recording["t_s"]), rtol=5e-13)


def test_resource_file_is_found_through_the_resource_location(fmus, fast_runs):
    result, _ = _both(lambda: _one(fmus["resource"], "r"), ["r.y"], fast_runs, time_limit=0.003)
    np.testing.assert_array_equal(result.recording["r.y"], RESOURCE_Y)


def test_feedthrough_passes_every_type(fmus):
    system = System("ft")
    a = FMUComponent(fmus["feedthrough"], "a", parameters={"string_param": "A", "real_tunable": 1.0})
    for name, value in (("real_in", 3.0), ("int_in", 7), ("bool_in", True), ("enum_in", 2), ("string_in", "héllo")):
        a.set(name, value)
    system.add(a)
    system.add(FMUComponent(fmus["feedthrough"], "b"))
    for kind in ("real", "int", "bool", "enum"):
        system.connect(f"a.{kind}_out", f"b.{kind}_in")
    result = Master(system, MasterSettings(step=0.1, time_limit=0.2),
                    ["b.real_out", "b.int_out", "b.bool_out", "b.enum_out", "a.real_fixed_out"]).run()
    assert result.success, result.message
    last = {channel: result.recording[channel][-1] for channel in result.recording.channels}
    assert last == {"t_s": 0.2, "b.real_out": 4.25, "b.int_out": 7, "b.bool_out": 1, "b.enum_out": 2,
                    "a.real_fixed_out": 0.5}
    assert (a.values["string_out"], system.components["b"].values["string_out"]) == ("A:héllo", "p:")


# ----------------------------------------------------------------------------- what other exporters write
def test_model_description_quirks(fmus):
    """Latin-1 XML with a comment and a namespace, GUID in braces, file name != modelIdentifier; a
    calculatedParameter and a local derivative are not exchanged, and asking for them says why."""
    d = FMUComponent(fmus["dahlquist"])
    assert d.name == "Dahlquist" and d.model_description.guid == "{1ad4c1e8-5a1f-4d5e-9b60-7f3c0d2e9a11}"
    assert [(v.name, v.causality, v.unit) for v in d.declared_variables()] == [
        ("x", "output", "m"), ("k", "parameter", "1/s"), ("x0", "parameter", "m")]
    assert "\u00b0" in d.model_description.description
    with pytest.raises(FMUError, match=r"no variable 'tau' \(the FMU's 'tau' is a calculatedParameter variable, "
                                       r"which the twin does not exchange\)"):
        d.variable("tau")
    with pytest.raises(FMUError, match=r"no variable 'der\(x\)' \(the FMU's 'der\(x\)' is a local variable"):
        FMUComponent(fmus["dahlquist"], parameters={"der(x)": 1.0})
    report = check_fmu(fmus["dahlquist"])
    assert report.ok and report.problems == [] and report.smoke_outputs["x"] == pytest.approx(math.exp(-5.0))


def test_an_isolated_fmu_cancels_its_pending_step_in_the_worker(fmus):
    system = System("isolated")
    system.add(IsolatedFMUComponent(fmus["stair"], "st", parameters={"period": 0.002, "fail_time": 0.0035, "mode": 5}))
    result = Master(system, MasterSettings(step=1e-3, time_limit=0.01), ["st.counter"]).run()
    assert not result.success and result.steps == 3
    assert ("fmi2DoStep returned fmi2Pending" in result.message
            and "; fmi2CancelStep returned fmi2OK, the step was cancelled; FMU log:" in result.message)


def _once(text: str) -> str:
    return text.replace('<CoSimulation modelIdentifier="Stair"',
                        '<CoSimulation modelIdentifier="Stair" canBeInstantiatedOnlyOncePerProcess="true"')


def test_an_fmu_instantiable_once_per_process_gets_one_live_instance(fmus, tmp_path):
    """canBeInstantiatedOnlyOncePerProcess="true" (Simulink and other code generators keep the state in the
    library): a second live instance of one file is refused before fmi2Instantiate; after close() a new one may
    be made; a copy of the file is a library of its own; IsolatedFMUComponent runs one in its own process."""
    once = _variant(fmus["stair"], tmp_path / "once.fmu", _once)
    a = FMUComponent(once, "a")
    with pytest.raises(FMUError, match=r"^b: once.fmu declares canBeInstantiatedOnlyOncePerProcess=\"true\" and its "
                                       r"instance 'a' is alive in this process; close\(\) that one first, or load "
                                       r"each instance as orchestrator.fmu.isolated.IsolatedFMUComponent") as caught:
        FMUComponent(once, "b")
    assert caught.value.function == "fmi2Instantiate"
    a.close()
    b = FMUComponent(once, "b", parameters={"period": 0.002})
    copy = FMUComponent(shutil.copy(once, tmp_path / "copy.fmu"), "c", parameters={"period": 0.003})
    isolated = IsolatedFMUComponent(once, "d", parameters={"period": 0.004})
    system = System("three")
    for component in (b, copy, isolated):
        system.add(component)
    result = Master(system, MasterSettings(step=1e-3, time_limit=0.012), ["b.counter", "c.counter", "d.counter"]).run()
    assert result.success, result.message
    assert [result.recording[f"{n}.counter"][-1] for n in "bcd"] == [6, 4, 3]  # 12 ms / 2, 3, 4 ms
    assert any("canBeInstantiatedOnlyOncePerProcess" in note for note in check_fmu(copy.path).notes)


def test_an_fmu_needing_its_tool_says_so_when_it_cannot_be_instantiated(fmus, tmp_path):
    """needsExecutionTool="true" (a tool-coupling FMU): when fmi2Instantiate returns NULL the error names the tool."""
    tool = _variant(fmus["stair"], tmp_path / "tool.fmu", lambda s: s.replace(
        '<CoSimulation modelIdentifier="Stair"', '<CoSimulation modelIdentifier="Stair" needsExecutionTool="true"')
        .replace('generationTool="hand-written C"', 'generationTool="SomeTool 2024"')
        .replace("{2b7e15f0-0c0e-4b8e-8d1f-3c2d1e0f9a22}", "{00000000-0000-0000-0000-000000000000}"))
    with pytest.raises(FMUError, match=r"^st: fmi2Instantiate failed \(FMU .*tool.fmu\); FMU log: \[fmi2Error\] wrong "
                                       r"type 1 or GUID .*; the FMU declares needsExecutionTool=\"true\": it runs only "
                                       r"where its tool \(SomeTool 2024\) is installed \(and licensed\)$"):
        FMUComponent(tool, "st")


def test_structured_parameter_name_must_be_mapped(fmus, tmp_path):
    dotted = _variant(fmus["dahlquist"], tmp_path / "dotted.fmu", lambda s: s.replace('name="k"', 'name="decay.k"'))
    with pytest.raises(FMUError, match=r"no variable 'decay.k' \(the FMU's parameter 'decay.k' is not an identifier; "
                                       r"give it one through mapping=\{'your_name': 'decay.k'\}\)"):
        FMUComponent(dotted, "d", parameters={"decay.k": 2.0})
    d = FMUComponent(dotted, "d", mapping={"k": "decay.k"}, parameters={"k": 2.0, "x0": 1.0})
    system = System("s")
    system.add(d)
    result = Master(system, MasterSettings(step=0.1, time_limit=0.5), ["d.x"]).run()
    assert result.recording["d.x"][-1] == pytest.approx(math.exp(-1.0), rel=1e-13)


def test_mapping_collisions_are_refused(fmus):
    with pytest.raises(FMUError, match=r"mapping 'k' -> 'x0': the FMU has its own variable 'k', which would share "
                                       r"the name; map it to another name too"):
        FMUComponent(fmus["dahlquist"], mapping={"k": "x0"})
    with pytest.raises(FMUError, match=r"mapping 'a' and 'b' both -> 'x0'"):
        FMUComponent(fmus["dahlquist"], mapping={"a": "x0", "b": "x0"})
    swapped = FMUComponent(fmus["dahlquist"], mapping={"k": "x0", "x0": "k"})  # a rename of both is fine
    assert (swapped.variable("k").unit, swapped.variable("x0").unit) == ("m", "1/s")


def test_units_the_twin_does_not_know(fmus, fast_runs, tmp_path):
    """kV (declared in the FMU's UnitDefinitions, unknown to the twin's table): recorded and connected in its own
    unit, and converted through the FMU's <BaseUnit> (x 1000 into V); without a definition a conversion is refused
    naming the probe (tests/test_fmu_units.py has the rest)."""
    kv = _variant(fmus["dahlquist"], tmp_path / "kv.fmu", lambda s: s.replace(
        '<Unit name="m"><BaseUnit m="1"/><DisplayUnit name="mm" factor="1000"/></Unit>',
        '<Unit name="kV"><BaseUnit kg="1" m="2" s="-3" A="-1" factor="1000"/></Unit>'
        '<Unit name="V"><BaseUnit kg="1" m="2" s="-3" A="-1"/></Unit>').replace(
        'unit="m" displayUnit="mm"', 'unit="kV"'))
    result, _ = _both(lambda: _one(kv, "d"), ["d.x"], fast_runs, time_limit=0.005)
    np.testing.assert_allclose(result.recording["d.x"], np.exp(-result.recording["t_s"]), rtol=1e-14)
    fast_runs.clear()
    volts, _ = _both(lambda: _one(kv, "d"), [Probe("x_V", "d.x", "V")], fast_runs, time_limit=0.005)
    np.testing.assert_array_equal(volts.recording["x_V"], result.recording["d.x"] * 1000.0)
    undefined = _variant(kv, tmp_path / "kv_undefined.fmu", lambda s: s.replace(
        '<Unit name="kV"><BaseUnit kg="1" m="2" s="-3" A="-1" factor="1000"/></Unit>', ''))
    with pytest.raises(SystemDescriptionError, match=r"probe 'x_V': d.x \[kV\] -> \[V\]: cannot convert 'kV' to "
                                                     r"'V': unknown unit 'kV', neither in cnctwin's table"):
        Master(_one(undefined, "d"), MasterSettings(), [Probe("x_V", "d.x", "V")])
    ft_kv = _variant(fmus["feedthrough"], tmp_path / "ft_kv.fmu", lambda s: s.replace(
        '<ModelVariables>', '<UnitDefinitions><Unit name="kV"><BaseUnit kg="1" m="2" s="-3" A="-1" factor="1000"/>'
        '</Unit></UnitDefinitions><ModelVariables>').replace(
        'name="real_in" valueReference="2" causality="input" variability="continuous"><Real start="0"/>',
        'name="real_in" valueReference="2" causality="input" variability="continuous"><Real start="0" unit="kV"/>'))
    system = _one(kv, "d")
    system.add(FMUComponent(ft_kv, "f"))
    system.connect("d.x", "f.real_in")
    assert system.connections[0].factor == 1.0


# ----------------------------------------------------------------------------- failures: file, function, status
@pytest.mark.parametrize("mode, status", [(2, "fmi2Discard"), (3, "fmi2Error"), (5, "fmi2Pending")])
def test_a_failing_step_names_file_function_status_and_log(fmus, fast_runs, mode, status):
    result, _ = _both(lambda: _one(fmus["stair"], "st", period=0.002, fail_time=0.0075, mode=mode), ["st.counter"],
                      fast_runs, strings=True, time_limit=0.01)
    assert not result.success and result.steps == 7
    asynchronous = (" (the FMU runs the step asynchronously; asynchronous steps are not supported: cnctwin's "
                    "master steps every FMU synchronously and does not wait for fmi2StepFinished)") if mode == 5 else ""
    # FMI 2.0, 4.2.2: the pending step is cancelled before the instance is freed (the fixture logs an error when
    # an instance with a step in progress is freed, or when fmi2CancelStep comes without a pending step)
    cancelled = "; fmi2CancelStep returned fmi2OK, the step was cancelled" if mode == 5 else ""
    cancel_log = " | [fmi2OK] fmi2CancelStep: the step from t = 0.007 is cancelled" if mode == 5 else ""
    assert result.message == (f"simulation failed at t = 0.007000 s: st: fmi2DoStep returned {status}{asynchronous} "
                              f"at t = 0.007000 s (FMU {fmus['stair']}){cancelled}; FMU log: [{status}] injected "
                              f"status {mode} at t = 0.007{cancel_log}")
    np.testing.assert_array_equal(result.recording["st.counter"], [0, 0, 1, 1, 2, 2, 3, 3])


@pytest.mark.parametrize("compiled", [False, True])
def test_a_pending_step_is_cancelled_before_the_instance_is_freed(fmus, compiled):
    """fmi2CancelStep is the only call after fmi2Pending (then fmi2FreeInstance); a cancel that fails leaves the
    instance allocated, since its step may still run."""
    for cancel_status, expected in ((0, "fmi2CancelStep returned fmi2OK, the step was cancelled"),
                                    (3, "fmi2CancelStep returned fmi2Error: the step may still run, so the "
                                        "instance is left allocated (not freed)")):
        system = _one(fmus["stair"], "st", period=0.002, fail_time=0.0035, mode=5, cancel_status=cancel_status)
        component = system.components["st"]
        result = Master(system, MasterSettings(step=1e-3, time_limit=0.01, compiled=compiled), ["st.counter"]).run()
        assert not result.success and result.steps == 3
        assert expected in result.message
        logs = list(component.messages)
        cancelled = "fmi2CancelStep: the step from t = 0.003 is cancelled"
        # cancelled: freed (the fixture logs in fmi2FreeInstance); a failed cancel: left allocated
        assert logs[-2:] == ([f"[fmi2OK] {cancelled}", "[fmi2OK] freeing st"] if cancel_status == 0
                             else ["[fmi2Pending] injected status 5 at t = 0.003", f"[fmi2Error] {cancelled}"])
        assert component.state == "terminated" and not any("in progress" in line for line in logs)
        component.close()  # freed already (or left allocated): no further FMI call
        assert list(component.messages) == logs


def test_a_failing_fmi3_step_holds_the_outputs_of_its_last_good_step(fmus, fast_runs):
    result, _ = _both(lambda: _one(fmus["counter3"], "c", period=0.002, fail_time=0.0075), ["c.x"], fast_runs,
                      strings=True, time_limit=0.01)
    assert "c: fmi3DoStep returned fmi3Error at t = 0.007000 s" in result.message


@pytest.mark.parametrize("status, success", [(1, True), (3, False)])
def test_fmi2_terminate_failing_fails_the_run_and_keeps_the_recording(fmus, fast_runs, status, success):
    result, _ = _both(lambda: _one(fmus["stair"], "st", term_status=status, period=0.004), ["st.counter"], fast_runs,
                      time_limit=0.01)
    assert result.success is success and result.steps == 10 and len(result.recording["st.counter"]) == 11
    if not success:
        assert result.message == (f"simulation failed at t = 0.010000 s: st: fmi2Terminate returned fmi2Error at "
                                  f"t = 0.010000 s (FMU {fmus['stair']}); FMU log: [fmi2Error] terminating after "
                                  "2 events")
        assert result.failures == [result.message]


def test_a_failing_terminate_after_a_failed_step_is_appended(fmus):
    system = _one(fmus["stair"], "st", term_status=3)
    system.add(FMUComponent(fmus["stair"], "bad", parameters={"fail_time": 0.25}))
    result = Master(system, MasterSettings(step=0.1, time_limit=1.0, compiled=False), ["st.counter"]).run()
    assert result.message.startswith("simulation failed at t = 0.200000 s: bad: fmi2DoStep returned fmi2Error")
    assert result.message.endswith("; terminating then failed too: st: fmi2Terminate returned fmi2Error at "
                                   f"t = 0.300000 s (FMU {fmus['stair']}); FMU log: [fmi2Error] terminating after "
                                   "0 events")


def test_check_fmu_reports_a_failing_terminate_and_free_logs(fmus):
    report = check_fmu(fmus["stair"], parameters={"term_status": 3})
    assert not report.smoke_ok and not report.ok
    assert report.smoke_message.startswith("smoke: fmi2Terminate returned fmi2Error at t = 10.000000 s")
    component = FMUComponent(fmus["stair"], "st")
    component.setup()
    component.terminate()
    component.close()
    assert list(component.messages)[-2:] == ["[fmi2OK] terminating after 0 events", "[fmi2OK] freeing st"]


def test_source_only_and_windows_only_fmus_are_refused_naming_what_they_have(fmus, tmp_path):
    source_only = _variant(fmus["dahlquist"], tmp_path / "src.fmu", lambda s: s, drop="binaries/")
    with zipfile.ZipFile(source_only, "a") as zf:
        zf.writestr("sources/dahlquist.c", (SOURCES / "dahlquist.c").read_text())
    with pytest.raises(FMUError, match=r"src\.fmu: no binary binaries/linux64/Dahlquist\.so for this platform \(the "
                                       r"FMU has no binaries and C sources: compile them for linux64 first"):
        FMUComponent(source_only)
    windows = _variant(fmus["dahlquist"], tmp_path / "win.fmu", lambda s: s, drop="binaries/")
    with zipfile.ZipFile(windows, "a") as zf:
        zf.writestr("binaries/win64/Dahlquist.dll", b"MZ")
    with pytest.raises(FMUError, match=r"win\.fmu: no binary binaries/linux64/Dahlquist\.so for this platform \(the "
                                       r"FMU has binaries for \['win64'\]\)$"):
        check_fmu(windows)


# ----------------------------------------------------------------------------- command line
def test_cli_check_fmu_and_simulate_an_ssd_of_unseen_fmus(fmus, tmp_path, capsys):
    from orchestrator.cli import main

    assert main(["check-fmu", str(fmus["dahlquist"]), "--set", "k=2"]) == 0
    text = capsys.readouterr().out
    assert "model Dahlquist, FMI 2.0" in text and "verdict: OK" in text
    ssd = tmp_path / "unseen.ssd"
    ssd.write_text(f"""<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="unseen">
  <ssd:System name="unseen">
    <ssd:Elements>
      <ssd:Component name="d" type="application/x-fmu-sharedlibrary" source="{fmus['dahlquist']}">
        <ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues>
          <ssv:ParameterSet version="1.0" name="p"><ssv:Parameters>
            <ssv:Parameter name="x0"><ssv:Real value="250" unit="mm"/></ssv:Parameter>
          </ssv:Parameters></ssv:ParameterSet>
        </ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>
      </ssd:Component>
      <ssd:Component name="st" type="application/x-fmu-sharedlibrary" source="{fmus['stair']}"/>
    </ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="2"/>
</ssd:SystemStructureDescription>
""")
    out = tmp_path / "out"
    assert main(["simulate", "--system", str(ssd), "--out", str(out)]) == 0
    from orchestrator.recording import Recording

    recording = Recording.read_csv(out / "recording.csv")
    np.testing.assert_allclose(recording["d.x"], 0.25 * np.exp(-recording["t_s"]), rtol=1e-10)  # 12 digits in CSV
    np.testing.assert_array_equal(recording["st.counter"], np.floor(np.round(recording["t_s"], 9)))


# ----------------------------------------------------------------------------- a failed FMU's held values
@pytest.mark.parametrize("stair", ["stair", "counter3"])
def test_a_failed_fmu_holds_the_discrete_outputs_of_its_last_good_step(fmus, fast_runs, stair):
    """Neither recorded nor connected: Integer/Boolean/String outputs of FMI 2.0 and Integer/String of FMI 3.0 after
    a failure at 7 ms are those after the step to 7 ms (3 events of a 2 ms period), on both loops."""
    name = "st" if stair == "stair" else "c"
    parameters = {"period": 0.002, "fail_time": 0.0075}
    result, _ = _both(lambda: _one(fmus[stair], name, **parameters), [], fast_runs, strings=True, time_limit=0.05)
    assert not result.success and result.steps == 7
    system = _one(fmus[stair], name, **parameters)
    Master(system, MasterSettings(), []).run()
    held = system.components[name].values
    assert (int(held["counter"][0]), held["label"]) == (3, "n=3")
    if stair == "stair":
        assert bool(held["odd"][0]) is True


def test_each_fmi2_instance_gets_its_own_log_lines(fmus):
    """fmpy's formatting proxy keeps one Python logger per process; the messages must still reach their instance."""
    a = FMUComponent(fmus["stair"], "a", parameters={"term_status": 1, "period": 0.002})
    b = FMUComponent(fmus["stair"], "b", parameters={"term_status": 1})
    for component in (a, b):
        component.setup()
    for k in range(3):
        a.do_step(k * 1e-3, 1e-3)
    a.terminate()
    b.terminate()
    assert list(a.messages) == ["[fmi2Warning] terminating after 1 events"]
    assert list(b.messages) == ["[fmi2Warning] terminating after 0 events"]
