"""Units of foreign FMUs: undeclared units, ``<UnitDefinitions>`` (kN, degC, rev/min), aliases without start.

``Scale`` (``tests/fixtures/fmu/units/scale.c``, FMI 2.0 around
``unseen/common2.c``) is ``y = k u + c``; each test writes its
``modelDescription.xml`` with the units it needs. ``Counter3`` (FMI 3.0,
from ``unseen/``) brings an FMI 3.0 output in ``degC``. Every run is made on
the Python loop and on the compiled FMU loop, which must agree bit for bit
(``_both`` of ``tests/test_master_fast_fmu.py``).
"""
from __future__ import annotations

import logging
import math
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
from orchestrator.ssp import build_system, read_ssd, system_to_ssp

sys.path.insert(0, str(Path(__file__).resolve().parent / "fixtures" / "fmu"))
import cfmu  # noqa: E402
from tests.test_master_fast_fmu import _both  # noqa: E402
from tests.test_master_fast_fmu import fast_runs  # noqa: E402,F401 (fixture)

needs_cc = pytest.mark.skipif(cfmu.compiler() is None, reason="no C compiler")
pytestmark = needs_cc

UNSEEN = cfmu.HERE / "unseen"
GUID = "{7d2c5a10-94be-4c61-8f3e-2b9d61c0e5a7}"
KN = '<Unit name="kN"><BaseUnit kg="1" m="1" s="-2" factor="1000"/></Unit>'
DEGC = '<Unit name="degC"><BaseUnit K="1" offset="273.15"/></Unit>'
REV_MIN = '<Unit name="rev/min"><BaseUnit s="-1" rad="1" factor="0.10471975511965977"/></Unit>'


def _unit(unit: str | None, extra: str = "") -> str:
    return (f' unit="{unit}"' if unit is not None else "") + extra


def scale_xml(u: str | None = None, y: str | None = None, definitions: str = "", u0: float = 0.0, k: float = 1.0,
              y_extra: str = "") -> str:
    """modelDescription.xml of Scale with units ``u``, ``y`` (and ``c``: y's unit); None: no unit attribute."""
    units = f"<UnitDefinitions>{definitions}</UnitDefinitions>" if definitions else ""
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="Scale" guid="{GUID}" generationTool="hand-written C">
  <CoSimulation modelIdentifier="Scale" canHandleVariableCommunicationStepSize="true"/>
  {units}
  <ModelVariables>
    <ScalarVariable name="u" valueReference="0" causality="input" variability="continuous"><Real start="{u0!r}"{_unit(u)}/></ScalarVariable>
    <ScalarVariable name="y" valueReference="1" causality="output" variability="continuous" initial="calculated"><Real{_unit(y, y_extra)}/></ScalarVariable>
    <ScalarVariable name="k" valueReference="2" causality="parameter" variability="tunable"><Real start="{k!r}"/></ScalarVariable>
    <ScalarVariable name="k_alias" valueReference="2" causality="parameter" variability="tunable"><Real/></ScalarVariable>
    <ScalarVariable name="c" valueReference="3" causality="parameter" variability="tunable"><Real start="0"{_unit(y)}/></ScalarVariable>
    <ScalarVariable name="gain.k" valueReference="4" causality="parameter" variability="tunable"><Real start="1"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="2" dependencies="1"/></Outputs>
    <InitialUnknowns><Unknown index="2" dependencies="1 3 5"/></InitialUnknowns></ModelStructure>
</fmiModelDescription>
"""


def _compile(name: str, source: Path, out: Path) -> bytes:
    text = source.read_text()
    if name != "counter3":  # FMI 2.0 models: their #defines, common2.c, then the model
        lines = text.splitlines(keepends=True)
        text = "".join(lines[:5]) + (UNSEEN / "common2.c").read_text() + "".join(lines[5:])
    (out / f"{name}.c").write_text(text)
    library = out / f"{name}.so"
    subprocess.run([cfmu.compiler() or "gcc", "-std=c99", "-O2", "-Wall", "-Wno-unused-parameter",
                    "-Wno-unused-function", "-shared", "-fPIC", "-o", str(library), str(out / f"{name}.c"), "-lm"],
                   check=True, capture_output=True, text=True)
    return library.read_bytes()


@pytest.fixture(scope="module")
def libraries(tmp_path_factory) -> dict[str, bytes]:
    out = tmp_path_factory.mktemp("units_lib")
    return {"scale": _compile("scale", cfmu.HERE / "units" / "scale.c", out),
            "counter3": _compile("counter3", UNSEEN / "counter3.c", out)}


@pytest.fixture
def make(libraries, tmp_path):
    """``make(name, xml)``: a Scale FMU file with that modelDescription.xml."""
    def build(name: str, xml: str) -> Path:
        path = tmp_path / f"{name}.fmu"
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("modelDescription.xml", xml)
            zf.writestr("binaries/linux64/Scale.so", libraries["scale"])
        return path
    return build


def _pair(src: Path, dst: Path, **dst_parameters) -> System:
    system = System("pair")
    system.add(FMUComponent(src, "s"))
    system.add(FMUComponent(dst, "t", parameters=dst_parameters))
    system.connect("s.y", "t.u")
    return system


# ----------------------------------------------------------------------------- <UnitDefinitions>
def test_kN_output_reads_as_N_x1000_on_both_loops(make, fast_runs):
    src = make("src", scale_xml(y="kN", definitions=KN, u0=2.5))
    dst = make("dst", scale_xml(u="N", y="N"))
    system = _pair(src, dst)
    assert (system.connections[0].factor, system.connections[0].offset) == (1000.0, 0.0)
    result, _ = _both(lambda: _pair(src, dst), ["t.y", Probe("s_N", "s.y", "N"), "s.y"], fast_runs,
                      time_limit=0.003)
    np.testing.assert_array_equal(result.recording["t.y"], 2500.0)
    np.testing.assert_array_equal(result.recording["s_N"], 2500.0)
    np.testing.assert_array_equal(result.recording["s.y"], 2.5)
    assert result.recording.units["s.y"] == "kN" and result.recording.units["s_N"] == "N"


def test_degC_20_is_293_15_K_on_both_loops(make, fast_runs):
    """An affine unit: K = degC + 273.15 through the connection (and a probe), identical on both loops."""
    src = make("src", scale_xml(y="degC", definitions=DEGC, u0=20.0))
    dst = make("dst", scale_xml(u="K", y="K"))
    system = _pair(src, dst)
    assert (system.connections[0].factor, system.connections[0].offset) == (1.0, 273.15)
    result, _ = _both(lambda: _pair(src, dst), ["t.y", Probe("s_K", "s.y", "K")], fast_runs, time_limit=0.003)
    np.testing.assert_allclose(result.recording["t.y"], 293.15, rtol=1e-15)
    np.testing.assert_allclose(result.recording["s_K"], 293.15, rtol=1e-15)
    back = make("back", scale_xml(u="degC", y="degC", definitions=DEGC))
    system = System("back")
    system.add(FMUComponent(dst, "k", parameters={"u": 300.0}))
    system.add(FMUComponent(back, "c"))
    system.connect("k.y", "c.u")
    result = Master(system, MasterSettings(step=1e-3, time_limit=0.002), ["c.y"]).run()
    np.testing.assert_allclose(result.recording["c.y"], 300.0 - 273.15, rtol=1e-14)


def test_a_relative_quantity_converts_without_the_offset(make, fast_runs):
    """relativeQuantity="true": a temperature difference of 20 degC is 20 K."""
    src = make("src", scale_xml(y="degC", definitions=DEGC, u0=20.0, y_extra=' relativeQuantity="true"'))
    dst = make("dst", scale_xml(u="K", y="K"))
    result, _ = _both(lambda: _pair(src, dst), ["t.y"], fast_runs, time_limit=0.002)
    np.testing.assert_array_equal(result.recording["t.y"], 20.0)


def test_an_fmi3_output_in_degC_into_an_fmi2_input_in_K_on_both_loops(libraries, make, tmp_path, fast_runs):
    xml = (UNSEEN / "counter3.xml").read_text().replace(
        '<Unit name="s"><BaseUnit s="1"/></Unit>', '<Unit name="s"><BaseUnit s="1"/></Unit>' + DEGC).replace(
        'name="x" valueReference="2" causality="output" variability="continuous" initial="exact" start="1"',
        'name="x" valueReference="2" causality="output" variability="continuous" initial="exact" start="1" '
        'unit="degC"')
    counter = tmp_path / "Counter3.fmu"
    with zipfile.ZipFile(counter, "w") as zf:
        zf.writestr("modelDescription.xml", xml)
        zf.writestr("binaries/x86_64-linux/Counter3.so", libraries["counter3"])
    dst = make("dst", scale_xml(u="K", y="K"))

    def system() -> System:
        s = System("mixed")
        s.add(FMUComponent(counter, "c", parameters={"k": 2.0}))
        s.add(FMUComponent(dst, "t"))
        s.connect("c.x", "t.u")
        return s

    result, _ = _both(system, ["c.x", "t.y"], fast_runs, time_limit=0.005)
    x = result.recording["c.x"]
    np.testing.assert_allclose(x, np.exp(-2.0 * result.recording["t_s"]), rtol=1e-12)
    np.testing.assert_array_equal(result.recording["t.y"][1:], x[1:] + 273.15)  # t reads c's output of its step


def test_rev_per_min_as_the_fmu_defines_it(make, fast_runs):
    """A unit the table lacks (rev/min), defined with rad: into rad/s by 2 pi / 60; one the table has (rpm) too."""
    src = make("src", scale_xml(y="rev/min", definitions=REV_MIN, u0=600.0))
    dst = make("dst", scale_xml(u="rad/s", y="rad/s"))
    result, _ = _both(lambda: _pair(src, dst), ["t.y"], fast_runs, time_limit=0.002)
    np.testing.assert_allclose(result.recording["t.y"], 20.0 * math.pi, rtol=1e-15)
    rpm = make("rpm", scale_xml(y="rpm", u0=600.0))
    assert _pair(rpm, dst).connections[0].factor == pytest.approx(2.0 * math.pi / 60.0, rel=1e-15)


def test_units_without_a_definition_or_of_other_base_units_are_refused(make):
    dst = make("dst", scale_xml(u="N", y="N"))
    undefined = make("kp", scale_xml(y="kp", u0=1.0))  # no <UnitDefinitions>: kp could be anything
    with pytest.raises(SystemDescriptionError, match=r"s.y \[kp\] -> t.u \[N\]: cannot convert 'kp' to 'N': "
                                                     r"unknown unit 'kp', neither in cnctwin's table"):
        _pair(undefined, dst)
    both_undefined = make("dst_kp2", scale_xml(u="kp2", y="kp2"))
    with pytest.raises(SystemDescriptionError, match="unknown unit 'kp'"):
        _pair(undefined, both_undefined)  # two symbols, no definitions: refused even if they might agree
    kn = make("kn", scale_xml(y="kN", definitions=KN))
    metres = make("m", scale_xml(u="m", y="m"))
    with pytest.raises(SystemDescriptionError, match=r"cannot connect 'kN' \(kg m s-2 \(defined in .*kn.fmu\)\) to "
                                                     r"'m' \(m\): different SI base units"):
        _pair(kn, metres)


# ----------------------------------------------------------------------------- no declared unit
def test_an_undeclared_unit_connects_unchanged_and_is_logged_once(make, fast_runs, caplog):
    """u without a unit is unknown, not "1": m into it passes unchanged; "1" declared stays refused."""
    src = make("src", scale_xml(y="m", u0=0.25))
    dst = make("dst", scale_xml())  # no units at all
    with caplog.at_level(logging.INFO, logger="orchestrator.system"):
        system = _pair(src, dst)
    assert system.connections[0].factor == 1.0 and system.component("t").variable("u").unit is None
    notes = [r.getMessage() for r in caplog.records if r.name == "orchestrator.system"]
    assert notes == ["pair: s.y [m] -> t.u [no unit declared]: no unit declared on the target; the value is "
                     "passed unchanged"]
    result, _ = _both(lambda: _pair(src, dst), ["t.y", Probe("y_mm", "t.y", "mm")], fast_runs, time_limit=0.002)
    np.testing.assert_array_equal(result.recording["t.y"], 0.25)
    np.testing.assert_array_equal(result.recording["y_mm"], 0.25)  # nothing to convert from
    assert result.recording.units["t.y"] is None and result.recording.units["y_mm"] == "mm"
    dimensionless = make("one", scale_xml(u="1", y="1"))
    with pytest.raises(SystemDescriptionError, match=r"cannot connect 'm' \(L\) to '1' \(1\)"):
        _pair(src, dimensionless)


# ----------------------------------------------------------------------------- aliases, messages
def test_a_parameter_alias_without_start_keeps_the_real_value(make, fast_runs):
    """k_alias shares k's value reference and has no start: setup must not write 0 over k = 3."""
    fmu = make("alias", scale_xml(u0=2.0, k=3.0))

    def one(**parameters) -> System:
        system = System("alias")
        system.add(FMUComponent(fmu, "a", parameters=parameters))
        return system

    result, _ = _both(one, ["a.y"], fast_runs, time_limit=0.002)
    np.testing.assert_array_equal(result.recording["a.y"], 6.0)
    comp = FMUComponent(fmu, "a")
    comp.setup(0.0)
    assert comp.values["k_alias"][0] == 3.0  # read back from the FMU
    fast_runs.clear()
    result, _ = _both(lambda: one(k_alias=5.0), ["a.y"], fast_runs, time_limit=0.002)
    np.testing.assert_array_equal(result.recording["a.y"], 10.0)  # the alias given, k's start not written over it
    with pytest.raises(FMUError, match=r"\['k', 'k_alias'\] are aliases \(value reference 2\) and were given "
                                       "different values"):
        Master(one(k=4.0, k_alias=5.0), MasterSettings(time_limit=0.002)).run()


def test_isolated_component_names_structured_variables_like_fmucomponent(make):
    fmu = make("names", scale_xml())
    direct = FMUComponent(fmu, "n")
    isolated = IsolatedFMUComponent(fmu, "n")
    try:
        for name in ("gain.k", "nothing"):
            with pytest.raises(FMUError) as want:
                direct.variable(name)
            with pytest.raises(FMUError) as got:
                isolated.variable(name)
            assert str(got.value) == str(want.value)
        assert "mapping={'your_name': 'gain.k'}" in str(want.value) or name == "nothing"
    finally:
        isolated.close()


# ----------------------------------------------------------------------------- SSP
def test_ssp_keeps_undeclared_units_and_unit_definitions(make, tmp_path):
    """Export: a connector without unit stays without one, kN carries the FMU's <BaseUnit>; import: the same
    factor again, and a parameter value in degC (defined in the SSV) lands in K."""
    src = make("src", scale_xml(y="kN", definitions=KN, u0=2.0))
    dst = make("dst", scale_xml(u="N", y="K"))
    system = _pair(src, dst)
    free = make("free", scale_xml())
    system.add(FMUComponent(free, "f"))
    system.connect("t.y", "f.u")
    ssd, ssv = system_to_ssp(system, tmp_path / "pair.ssd", tmp_path / "pair.ssv",
                             fmu_sources={"s": str(src), "t": str(dst), "f": str(free)})
    text = ssd.read_text()
    assert '<ssd:Connector name="u" kind="input">\n            <ssc:Real />' in text  # f.u: no unit attribute
    assert '<ssc:Unit name="kN">\n      <ssc:BaseUnit kg="1" m="1" s="-2" factor="1000.0" />' in text
    params = ssv.read_text().replace('name="t.c">\n      <ssv:Real value="0.0" unit="K" />',
                                     'name="t.c">\n      <ssv:Real value="20.0" unit="degC" />')
    assert params != ssv.read_text()
    ssv.write_text(params.replace("</ssv:ParameterSet>", "<ssv:Units><ssc:Unit name=\"degC\"><ssc:BaseUnit K=\"1\" "
                                  "offset=\"273.15\"/></ssc:Unit></ssv:Units></ssv:ParameterSet>"))
    rebuilt, _ = build_system(read_ssd(ssd), native=False)
    assert [(c.source, c.target, c.factor) for c in rebuilt.connections] == [("s.y", "t.u", 1000.0),
                                                                            ("t.y", "f.u", 1.0)]
    assert rebuilt.component("t").values["c"][0] == pytest.approx(293.15, rel=1e-15)


# ----------------------------------------------------------------------------- role mappings into affine units
HOME_MM = '<Unit name="mm_from_home"><BaseUnit m="1" factor="0.001" offset="0.25"/></Unit>'


@pytest.fixture
def thermal_role(monkeypatch):
    """A role in K (the twin's roles have no temperature): ``u`` an input, ``y`` an output."""
    from orchestrator.fmu import roles

    role = roles.Role("thermal", required=(roles._in("u", "K"), roles._out("y", "K")))
    monkeypatch.setitem(roles.ROLES, "thermal", role)
    return role


def test_a_role_mapping_into_degC_applies_the_offset_both_ways_on_both_loops(make, thermal_role, fast_runs):
    """Our u = 300 K is the FMU's 26.85 degC; its y = 2 u + 1 = 54.7 degC is our 327.85 K (exact: 2 × 300 - 273.15
    + 1). The FMU's start values come back in K (u0 = 20 degC: 293.15 K)."""
    src = make("src", scale_xml(u="K", y="K", u0=300.0))
    fmu = make("dst", scale_xml(u="degC", y="degC", definitions=DEGC, u0=20.0, k=2.0))
    component = FMUComponent(fmu, "t", role="thermal")
    assert component.variable("u").unit == "K" and component.values["u"][0] == pytest.approx(293.15, rel=1e-15)

    def system() -> System:
        s = System("affine")
        s.add(FMUComponent(src, "s"))
        s.add(FMUComponent(fmu, "t", role="thermal", parameters={"c": 1.0}))
        s.connect("s.y", "t.u")
        return s

    result, _ = _both(system, ["t.y"], fast_runs, time_limit=0.003)
    np.testing.assert_allclose(result.recording["t.y"], 2 * 300.0 - 273.15 + 1.0, rtol=1e-14)
    assert result.recording.units["t.y"] == "K"


def test_a_role_mapping_into_an_affine_length_unit(make, fast_runs, monkeypatch):
    """A position in mm from a home mark 0.25 m out: 0 mm_from_home is 0.25 m; our 0.3 m is 50 mm_from_home; y = u."""
    from orchestrator.fmu import roles

    monkeypatch.setitem(roles.ROLES, "axis", roles.Role("axis", required=(roles._in("u", "m"), roles._out("y", "m"))))
    fmu = make("home", scale_xml(u="mm_from_home", y="mm_from_home", definitions=HOME_MM))
    report = check_fmu(fmu, role="axis")
    assert [row.status for row in report.role_rows if row.ours in ("u", "y")] == [
        "ok (converted: x m = 1000 x -250 mm_from_home)"] * 2
    component = FMUComponent(fmu, "a", role="axis", parameters={"u": 0.3})
    system = System("axis")
    system.add(component)
    result = Master(system, MasterSettings(step=1e-3, time_limit=0.002), ["a.y"]).run()
    np.testing.assert_allclose(result.recording["a.y"], 0.3, rtol=1e-15)
    assert FMUComponent(fmu, "b", role="axis").values["u"][0] == 0.25  # its start, 0 mm_from_home


# ----------------------------------------------------------------------------- display units
FAHRENHEIT = '<Unit name="K"><BaseUnit K="1"/><DisplayUnit name="degF" factor="1.8" offset="-459.67"/></Unit>'


def test_a_probe_in_a_display_unit_the_fmu_defines_on_both_loops(make, fast_runs):
    """<DisplayUnit name="degF" factor="1.8" offset="-459.67"> of K: 300 K records as 1.8 × 300 - 459.67 = 80.33 degF;
    a display unit is a unit for probes only (values are exchanged in the variable's unit)."""
    fmu = make("fahrenheit", scale_xml(u="K", y="K", definitions=FAHRENHEIT, u0=300.0))

    def system() -> System:
        s = System("display")
        s.add(FMUComponent(fmu, "s"))
        return s

    result, _ = _both(system, ["s.y", Probe("s_F", "s.y", "degF")], fast_runs, time_limit=0.002)
    np.testing.assert_array_equal(result.recording["s.y"], 300.0)
    np.testing.assert_allclose(result.recording["s_F"], 80.33, rtol=1e-13)
    assert result.recording.units["s_F"] == "degF"
    isolated = System("isolated")
    isolated.add(IsolatedFMUComponent(fmu, "s"))
    result = Master(isolated, MasterSettings(step=1e-3, time_limit=0.001), [Probe("s_F", "s.y", "degF")]).run()
    np.testing.assert_allclose(result.recording["s_F"], 80.33, rtol=1e-13)
