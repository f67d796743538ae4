"""SSP 1.0: write the system, read it back (ours and another tool's), run it."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from orchestrator import Master, MasterSettings, System
from orchestrator.ssp import SSPError, build_system, read_ssd, system_to_ssp
from toys import Gain, Integrator


def loop(a=2.0, x0=1.0):
    system = System("loop")
    system.add(Integrator("integ", x0=x0))
    system.add(Gain("gain", a=a), rate=2)
    system.connect("integ.x", "gain.x")
    system.connect("gain.u", "integ.u")
    return system


def test_round_trip_reproduces_structure_parameters_and_results(tmp_path):
    settings = MasterSettings(step=0.01, time_limit=1.0)
    ssd, ssv = system_to_ssp(loop(a=3.0, x0=0.5), tmp_path / "loop.ssd", tmp_path / "loop.ssv", settings)
    spec = read_ssd(ssd)
    assert [e.name for e in spec.elements] == ["integ", "gain"]
    assert spec.elements[1].rate == 2
    assert spec.elements[1].parameters["a"] == (3.0, "1/s")
    assert ("integ", "x", "gain", "x") in spec.connections
    system, read_settings = build_system(spec)
    assert read_settings.step == 0.01 and read_settings.time_limit == pytest.approx(1.0)
    direct = Master(loop(a=3.0, x0=0.5), settings, ["integ.x"]).run().recording["integ.x"]
    again = Master(system, read_settings, ["integ.x"]).run().recording["integ.x"]
    np.testing.assert_array_equal(direct, again)
    # other tools must see standard SSP: FMU components with typed, unit-carrying connectors
    text = ssd.read_text()
    assert 'type="application/x-fmu-sharedlibrary"' in text and '<ssc:Real unit="1/s"' in text


FOREIGN_SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues"
    xmlns:cnctwin="https://github.com/cnctwin/cnctwin/ssp-annotations" version="1.0" name="foreign">
  <ssd:System name="foreign">
    <ssd:Elements>
      <ssd:Component name="integ" source="integ.fmu">
        <ssc:Annotations><ssc:Annotation type="org.cnctwin"><cnctwin:Component native="toys:Integrator"/></ssc:Annotation></ssc:Annotations>
        <ssd:ParameterBindings>
          <ssd:ParameterBinding>
            <ssd:ParameterValues>
              <ssv:ParameterSet version="1.0" name="p">
                <ssv:Parameters><ssv:Parameter name="x0"><ssv:Real value="250" unit="mm"/></ssv:Parameter></ssv:Parameters>
              </ssv:ParameterSet>
            </ssd:ParameterValues>
          </ssd:ParameterBinding>
        </ssd:ParameterBindings>
      </ssd:Component>
    </ssd:Elements>
  </ssd:System>
  <ssd:DefaultExperiment startTime="0" stopTime="0.5"/>
</ssd:SystemStructureDescription>
"""


def test_reads_inline_parameter_values_with_unit_conversion(tmp_path):
    path = tmp_path / "foreign.ssd"
    path.write_text(FOREIGN_SSD)
    system, settings = build_system(read_ssd(path))
    assert settings.step == 1e-3 and settings.time_limit == pytest.approx(0.5)
    result = Master(system, settings, ["integ.x"]).run()
    np.testing.assert_allclose(result.recording["integ.x"], 0.25)   # 250 mm -> 0.25 m, u = 0


@pytest.mark.parametrize(
    "change, match",
    [
        (("<ssd:Elements>", '<ssd:Elements><ssd:System name="nested"/>'), "only ssd:Component"),
        (('unit="mm"', 'unit="parsec"'), "unknown unit"),
        (('value="250"', 'value="abc"'), "not a valid Real"),
        (("</ssd:System>", "</ssd:Systm>"), "not well-formed"),
    ],
)
def test_bad_ssd_files_give_clear_errors(tmp_path, change, match):
    path = tmp_path / "bad.ssd"
    path.write_text(FOREIGN_SSD.replace(*change))
    with pytest.raises(SSPError, match=match):
        build_system(read_ssd(path))


def test_shipped_twin_ssp_is_generated_from_the_machine_file(tmp_path):
    from orchestrator.simulate import resolve_case
    from orchestrator.twin import write_twin_ssp

    root = Path(__file__).resolve().parent.parent
    shipped = read_ssd(root / "models" / "cnctwin.ssd")
    ssd, _ = write_twin_ssp(resolve_case(case=root / "models" / "examples" / "paper_part"), tmp_path / "cnctwin.ssd")
    fresh = read_ssd(ssd)
    assert fresh.connections == shipped.connections and fresh.order == shipped.order
    for a, b in zip(fresh.elements, shipped.elements):
        assert (a.name, a.native, a.rate) == (b.name, b.native, b.rate)
        pa = {k: v for k, v in a.parameters.items() if k != "program_file"}
        pb = {k: v for k, v in b.parameters.items() if k != "program_file"}
        assert pa == pb, f"models/cnctwin.ssv is stale for {a.name}: run `cnctwin export-ssp --case models/examples/paper_part --ssd models/cnctwin.ssd`"


def test_twin_from_ssd_equals_twin_from_case(tmp_path):
    from orchestrator.simulate import simulate, simulate_system_file

    root = Path(__file__).resolve().parent.parent
    from_ssd = simulate_system_file(root / "models" / "cnctwin.ssd", time_limit_s=0.6, plot=False).recording
    from_case = simulate(case=root / "models" / "examples" / "paper_part", time_limit_s=0.6, plot=False).recording
    assert from_ssd.channels == from_case.channels
    for name in from_case.channels:
        np.testing.assert_array_equal(from_ssd[name], from_case[name])


def test_foreign_drive_replaces_the_x_axis_through_the_system_file(tmp_path):
    """A vendor's drive FMU (C, other names, mm at its interface) swapped in by editing the SSD only."""
    import re
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent / "fixtures" / "fmu"))
    import cfmu
    from orchestrator.simulate import simulate_system_file

    if cfmu.compiler() is None:
        raise AssertionError("the test machine needs a C compiler (gcc) for the foreign FMU fixture")
    root = Path(__file__).resolve().parent.parent
    foreign = cfmu.build_c_fmu(cfmu.HERE / "foreign_drive", tmp_path / "fmu")
    program = tmp_path / "move.nc"
    program.write_text("%\nO0002\nG21 G90 G94\nG1 X5. F3000\nX-3.\nM30\n%\n")    # in the air above the stock

    ssv = (root / "models" / "cnctwin.ssv").read_text()
    ssv = re.sub(r'\s*<ssv:Parameter name="x_drive\.[^"]+">.*?</ssv:Parameter>', "", ssv, flags=re.S)
    ssv = re.sub(r'(<ssv:Parameter name="nck.program_file">\s*<ssv:String value=")[^"]*"', rf'\g<1>{program}"', ssv)
    (tmp_path / "cnctwin.ssv").write_text(ssv)
    native_ssd = root / "models" / "cnctwin.ssd"
    (tmp_path / "native.ssd").write_text(native_ssd.read_text())

    ssd = native_ssd.read_text()
    x_element = re.search(r'<ssd:Component name="x_drive".*?</ssd:Component>', ssd, flags=re.S).group(0)
    ssd = ssd.replace(x_element, (
        f'<ssd:Component name="x_drive" type="application/x-fmu-sharedlibrary" source="{foreign}">'
        '<ssc:Annotations><ssc:Annotation type="org.cnctwin"><cnctwin:Component rate="4"/></ssc:Annotation>'
        '</ssc:Annotations></ssd:Component>'))   # stepped at the 250 us velocity-loop period, no native class
    for ours, theirs in (("table_position", "pos"), ("position", "pos"), ("velocity", "vel"), ("current_cmd", "Iq"),
                         ("disturbance_force", "F_load")):
        ssd = re.sub(rf'(Element="x_drive" (?:start|end)Connector=")({ours})"', rf'\g<1>{theirs}"', ssd)
    (tmp_path / "foreign.ssd").write_text(ssd)

    reference = simulate_system_file(tmp_path / "native.ssd", plot=False)
    swapped = simulate_system_file(tmp_path / "foreign.ssd", plot=False)
    assert reference.success and swapped.success, swapped.message
    assert swapped.summary["cycle_time_s"] == pytest.approx(reference.summary["cycle_time_s"], abs=2e-3)
    n = min(len(reference.recording), len(swapped.recording))
    # mm at the foreign interface, m inside the twin: a wrong factor would be off by 1000x
    np.testing.assert_allclose(swapped.recording["x_mm"][:n], reference.recording["x_mm"][:n], atol=1e-4)
    # the 16 ms moving average after interpolation rounds the reversal at X5, the servo lag more so
    assert 4.9 < reference.recording["x_ref_mm"].max() <= 5.0 + 1e-9
    assert 4.0 < swapped.recording["x_mm"].max() < reference.recording["x_ref_mm"].max()
