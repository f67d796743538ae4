"""Reliability with faulty FMUs: bad files, failing FMI calls and FMUs that crash the process.

A small C FMU ("Faulty", written below and compiled with
``tests/fixtures/fmu/cfmu.py``) computes ``y = t + h`` (end time of the last
step) and ``x = integral of u``; its parameter ``mode`` makes the step that
passes ``fail_time`` return fmi2Error (1) or fmi2Discard (2), call abort()
(3), write through a NULL pointer (4), exit(3) (5) or spin forever (6).

* In-process (:class:`FMUComponent`): fmi2Error/fmi2Discard become an FMUError
  naming the component, function, time and the FMU's log; under the master
  the run ends with ``success = False`` and the recording up to the failure.
* Isolated (:class:`IsolatedFMUComponent`): the same, and an abort / segfault /
  exit / hang kills only the worker: FMUError "... crashed (signal 6, SIGABRT)
  in fmi2DoStep at t = ...", the caller carries on, the recording is kept.
"""
from __future__ import annotations

import os
import signal
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fmus_src.servo.drive import DriveAxis
from orchestrator import Master, MasterSettings, System
from orchestrator.fmu import FMUComponent, FMUError
from orchestrator.fmu.isolated import IsolatedFMUComponent

sys.path.insert(0, str(Path(__file__).resolve().parent / "fixtures" / "fmu"))
import cfmu  # noqa: E402

pytestmark = pytest.mark.skipif(cfmu.compiler() is None, reason="no C compiler")

MODES = {"error": 1, "discard": 2, "abort": 3, "segfault": 4, "exit": 5, "hang": 6}

FAULTY_C = r"""
#include <stdlib.h>
#include <string.h>
#include "fmi2Functions.h"

enum { VR_FAIL_TIME, VR_U, VR_Y, VR_X, VR_COUNT };
typedef struct { double r[VR_COUNT]; int mode; int init; char *name; fmi2CallbackFunctions cb; } M;

static void say(M *m, fmi2Status s, const char *text) {
    if (m->cb.logger) m->cb.logger(m->cb.componentEnvironment, m->name, s, "logStatusError", "%s", text);
}
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat; return fmi2OK;
}
fmi2Component fmi2Instantiate(fmi2String name, fmi2Type type, fmi2String guid, fmi2String res,
                              const fmi2CallbackFunctions *f, fmi2Boolean vis, fmi2Boolean log) {
    (void)guid; (void)res; (void)vis; (void)log;
    if (type != fmi2CoSimulation || !f) return NULL;
    M *m = (M *)calloc(1, sizeof(M));
    m->name = (char *)malloc(strlen(name) + 1);
    strcpy(m->name, name);
    m->cb = *f;
    m->r[VR_FAIL_TIME] = -1.0;
    return m;
}
void fmi2FreeInstance(fmi2Component c) { M *m = (M *)c; if (m) { free(m->name); free(m); } }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real t0, fmi2Boolean d, fmi2Real e) {
    M *m = (M *)c; (void)a; (void)b; (void)d; (void)e; m->r[VR_Y] = t0; return fmi2OK;
}
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { ((M *)c)->init = 1; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) {
    M *m = (M *)c; memset(m->r, 0, sizeof m->r); m->r[VR_FAIL_TIME] = -1.0; m->mode = 0; m->init = 0; return fmi2OK;
}
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    M *m = (M *)c;
    for (size_t i = 0; i < n; ++i) { if (vr[i] >= VR_COUNT) return fmi2Error; v[i] = m->r[vr[i]]; }
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    M *m = (M *)c;
    for (size_t i = 0; i < n; ++i) { if (vr[i] > VR_U) return fmi2Error; m->r[vr[i]] = v[i]; }
    return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    M *m = (M *)c;
    for (size_t i = 0; i < n; ++i) { if (vr[i] != 100) return fmi2Error; v[i] = m->mode; }
    return fmi2OK;
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) {
    M *m = (M *)c;
    for (size_t i = 0; i < n; ++i) { if (vr[i] != 100) return fmi2Error; m->mode = v[i]; }
    return fmi2OK;
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) {
    (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK;
}
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; (void)s; return fmi2Error; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) {
    (void)c; (void)s; (void)n; return fmi2Error;
}
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c; (void)s; (void)b; (void)n; return fmi2Error;
}
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)c; (void)b; (void)n; (void)s; return fmi2Error;
}
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dv[], fmi2Real dz[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dv; (void)dz; return fmi2Error;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                       const fmi2Integer o[], const fmi2Real v[]) {
    (void)c; (void)vr; (void)n; (void)o; (void)v; return fmi2Error;
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                        const fmi2Integer o[], fmi2Real v[]) {
    (void)c; (void)vr; (void)n; (void)o; (void)v; return fmi2Error;
}
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    M *m = (M *)c;
    (void)noSetPrior;
    if (m->r[VR_FAIL_TIME] >= 0.0 && t + h > m->r[VR_FAIL_TIME] * (1.0 + 1e-12)) {
        volatile int *null = NULL;
        volatile unsigned long spin = 0;
        switch (m->mode) {
        case 1: say(m, fmi2Error, "injected fmi2Error"); return fmi2Error;
        case 2: say(m, fmi2Discard, "injected fmi2Discard"); return fmi2Discard;
        case 3: abort();
        case 4: *null = 1; break;
        case 5: exit(3);
        case 6: for (;;) ++spin;
        default: break;
        }
    }
    m->r[VR_X] += m->r[VR_U] * h;
    m->r[VR_Y] = t + h;
    return fmi2OK;
}
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) {
    (void)c; (void)s; (void)v; return fmi2Error;
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) {
    (void)c; (void)s; (void)v; return fmi2Error;
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) {
    (void)c; (void)s; (void)v; return fmi2Error;
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) {
    (void)c; (void)s; (void)v; return fmi2Error;
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) {
    (void)c; (void)s; (void)v; return fmi2Error;
}
"""

FAULTY_XML = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Faulty" guid="{6d1f0a52-2b1c-4f0e-9d7a-faulty000001}"
  generationTool="hand-written" variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="Faulty" canHandleVariableCommunicationStepSize="true"/>
  <UnitDefinitions>
    <Unit name="s"><BaseUnit s="1"/></Unit>
    <Unit name="m"><BaseUnit m="1"/></Unit>
    <Unit name="m/s"><BaseUnit m="1" s="-1"/></Unit>
  </UnitDefinitions>
  <ModelVariables>
    <ScalarVariable name="fail_time" valueReference="0" causality="parameter" variability="fixed"><Real start="-1" unit="s"/></ScalarVariable>
    <ScalarVariable name="mode" valueReference="100" causality="parameter" variability="fixed"><Integer start="0"/></ScalarVariable>
    <ScalarVariable name="u" valueReference="1" causality="input" variability="continuous"><Real start="0" unit="m/s"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="2" causality="output" variability="continuous" initial="exact"><Real start="0" unit="s"/></ScalarVariable>
    <ScalarVariable name="x" valueReference="3" causality="output" variability="continuous" initial="exact"><Real start="0" unit="m"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="4"/><Unknown index="5"/></Outputs>
  </ModelStructure>
</fmiModelDescription>
"""


@pytest.fixture(scope="module")
def faulty(tmp_path_factory):
    src = tmp_path_factory.mktemp("faulty_src")
    (src / "faulty.c").write_text(FAULTY_C)
    (src / "modelDescription.xml").write_text(FAULTY_XML)
    return cfmu.build_c_fmu(src, tmp_path_factory.mktemp("faulty"))


def run_with_drive(component, time_limit=0.02):
    """The faulty FMU next to a native drive axis (constant current), recorded every 1 ms step."""
    system = System("mixed")
    system.add(component)
    drive = DriveAxis("x_drive", coulomb_positive=0.0, static_positive=0.0, viscous_positive=0.0)
    drive.set("current_cmd", 2.0)
    system.add(drive)
    return Master(system, MasterSettings(step=1e-3, time_limit=time_limit),
                  ["faulty.y", "faulty.x", "x_drive.position"]).run()


def step_until_failure(comp, n=20, h=1e-3):
    comp.setup(0.0)
    for k in range(n):
        comp.values["u"][0] = 2.0
        comp.do_step(k * h, h)
    raise AssertionError("the FMU did not fail")


# ----------------------------------------------------------------------------- bad files (both kinds)
def _zip(path: Path, files: dict[str, str]) -> Path:
    with zipfile.ZipFile(path, "w") as zf:
        for name, text in files.items():
            zf.writestr(name, text)
    return path


@pytest.mark.parametrize("kind", [FMUComponent, IsolatedFMUComponent])
def test_bad_fmu_files_raise_before_any_process_starts(tmp_path, faulty, kind):
    with pytest.raises(FMUError, match=r"gone\.fmu: FMU file not found"):
        kind(tmp_path / "gone.fmu")
    (tmp_path / "text.fmu").write_text("not a zip")
    with pytest.raises(FMUError, match=r"text\.fmu: not an FMU \(not a zip archive\)"):
        kind(tmp_path / "text.fmu")
    md = FAULTY_XML.replace('fmiVersion="2.0"', 'fmiVersion="1.0"')
    with pytest.raises(FMUError, match=r"v1\.fmu: FMI version '1.0'"):
        kind(_zip(tmp_path / "v1.fmu", {"modelDescription.xml": md}))
    md = FAULTY_XML.replace('<CoSimulation modelIdentifier="Faulty" canHandleVariableCommunicationStepSize="true"/>',
                            '<ModelExchange modelIdentifier="Faulty"/>')
    with pytest.raises(FMUError, match=r"me\.fmu: model-exchange-only FMU"):
        kind(_zip(tmp_path / "me.fmu", {"modelDescription.xml": md}))


@pytest.mark.parametrize("kind", [FMUComponent, IsolatedFMUComponent])
def test_missing_role_variables_are_named(faulty, kind):
    with pytest.raises(FMUError, match=r"cannot stand in for role 'drive': missing required variable\(s\) "
                                       r"\['current_cmd', 'disturbance_force', 'position', 'velocity'\]"):
        kind(faulty, name="x_drive", role="drive")


# ----------------------------------------------------------------------------- FMI status failures
@pytest.mark.parametrize("mode, status", [("error", "fmi2Error"), ("discard", "fmi2Discard")])
def test_status_failure_in_process_names_component_function_time_and_log(faulty, mode, status):
    comp = FMUComponent(faulty, name="faulty", parameters={"fail_time": 0.0045, "mode": MODES[mode]})
    with pytest.raises(FMUError) as info:
        step_until_failure(comp)
    e = info.value
    # steps end at 1, 2, 3, 4, 5 ms: the one starting at t = 4 ms passes 4.5 ms
    assert e.component == "faulty" and e.function == "fmi2DoStep" and e.time == pytest.approx(0.004)
    assert f"faulty: fmi2DoStep returned {status} at t = 0.004000 s" in str(e)
    assert f"injected {status}" in str(e)
    assert comp.state == "terminated"


@pytest.mark.parametrize("mode", ["error", "discard"])
def test_status_failure_under_the_master_keeps_the_recording(faulty, mode):
    result = run_with_drive(FMUComponent(faulty, name="faulty",
                                         parameters={"fail_time": 0.0075, "mode": MODES[mode], "u": 1.0}))
    assert not result.success
    assert "faulty: fmi2DoStep returned" in result.message and "t = 0.007000 s" in result.message
    rec = result.recording
    # samples at 0..7 ms were recorded; y = end time of each step, x = u t with u = 1 m/s
    np.testing.assert_allclose(rec.t, np.arange(8) * 1e-3, atol=1e-15)
    np.testing.assert_allclose(rec["faulty.y"], rec.t, atol=1e-15)
    np.testing.assert_allclose(rec["faulty.x"], rec.t, atol=1e-15)


# ----------------------------------------------------------------------------- crashes, isolated
def test_isolated_component_matches_in_process_results(faulty):
    iso = IsolatedFMUComponent(faulty, name="faulty", parameters={"u": 1.0})
    inproc = FMUComponent(faulty, name="faulty", parameters={"u": 1.0})
    try:
        assert [v.name for v in iso.declared_variables()] == [v.name for v in inproc.declared_variables()]
        assert iso.names("output") == ["y", "x"] and iso.variable("x").unit == "m"
        a, b = run_with_drive(iso), run_with_drive(inproc)
        assert a.success and b.success
        for name in a.recording.channels:
            np.testing.assert_array_equal(a.recording[name], b.recording[name])
        np.testing.assert_allclose(a.recording["faulty.x"], a.recording.t, atol=1e-15)  # x = u t
        assert iso.state == "terminated" and iso.pid != os.getpid()
        iso.reset()
        assert iso.state == "instantiated" and iso.values["x"][0] == 0.0 and iso.values["u"][0] == 1.0
    finally:
        iso.close()
        inproc.close()


@pytest.mark.parametrize("mode, how", [
    ("abort", f"crashed (signal {int(signal.SIGABRT)}, SIGABRT)"),
    ("segfault", f"crashed (signal {int(signal.SIGSEGV)}, SIGSEGV)"),
    ("exit", "exited with status 3"),
])
def test_a_crashing_fmu_cannot_take_the_caller_down(faulty, mode, how):
    comp = IsolatedFMUComponent(faulty, name="faulty", parameters={"fail_time": 0.0075, "mode": MODES[mode]})
    try:
        result = run_with_drive(comp)
        assert not result.success
        assert f"faulty: the FMU {how} in fmi2DoStep at t = 0.007000 s" in result.message
        assert str(comp.path) in result.message
        rec = result.recording  # kept up to the crash
        np.testing.assert_allclose(rec.t, np.arange(8) * 1e-3, atol=1e-15)
        np.testing.assert_allclose(rec["faulty.y"], rec.t, atol=1e-15)
        # the native drive beside it ran normally: frictionless x = u t^2 / (2 M), u = 2 A * 2 pi / lead
        drive = DriveAxis("x_drive")
        u = 2.0 * float(drive.values["torque_constant"][0]) * 2 * np.pi / float(drive.values["screw_lead"][0])
        mass = float(drive.values["mass"][0])
        np.testing.assert_allclose(rec["x_drive.position"], u * rec.t**2 / (2 * mass), rtol=1e-6, atol=1e-12)
        assert comp.state == "terminated"
        if mode != "abort":
            return
        # a dead worker is replaced on reset; the component runs again
        old = comp.pid
        comp.reset()
        assert comp.pid != old
        comp.set("fail_time", -1.0)
        comp.setup(0.0)
        comp.do_step(0.0, 1e-3)
        assert comp.values["y"][0] == pytest.approx(1e-3)
    finally:
        comp.close()


def test_a_hanging_fmu_is_killed_after_the_timeout(faulty):
    comp = IsolatedFMUComponent(faulty, name="faulty", parameters={"fail_time": 0.0025, "mode": MODES["hang"]},
                                timeout=1.0)
    try:
        with pytest.raises(FMUError, match=r"faulty: the FMU did not answer within 1 s \(worker killed\) in "
                                           r"fmi2DoStep at t = 0.002000 s") as info:
            step_until_failure(comp)
        assert info.value.component == "faulty" and info.value.time == pytest.approx(0.002)
        assert comp.state == "terminated"
    finally:
        comp.close()
