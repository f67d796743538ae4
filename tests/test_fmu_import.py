"""FMU import: FMUComponent behind the component protocol, and its error reporting.

Every malformed input must end in one FMUError whose message names the file
and says what was expected.
"""
from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import pytest

from orchestrator import Master, MasterSettings, System
from orchestrator.errors import CncTwinError
from orchestrator.fmu import FMUComponent, FMUError, build_fmus, check_fmu
from fmus_src.servo.drive import DriveAxis


@pytest.fixture(scope="module")
def drive_fmu(tmp_path_factory):
    return build_fmus(tmp_path_factory.mktemp("fmus"), components=["DriveAxis"])[0]


def _zip(path: Path, files: dict[str, str]) -> Path:
    with zipfile.ZipFile(path, "w") as zf:
        for name, text in files.items():
            zf.writestr(name, text)
    return path


_MD = """<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="{version}" modelName="M" guid="{{0}}">
  {kind}
  <ModelVariables/>
  <ModelStructure/>
</fmiModelDescription>
"""


def test_fmu_error_is_a_project_error():
    assert issubclass(FMUError, CncTwinError)


def test_missing_file(tmp_path):
    with pytest.raises(FMUError, match=r"nothere\.fmu: FMU file not found"):
        FMUComponent(tmp_path / "nothere.fmu")


def test_not_a_zip(tmp_path):
    bad = tmp_path / "bad.fmu"
    bad.write_text("this is not an archive")
    with pytest.raises(FMUError, match=r"bad\.fmu: not an FMU \(not a zip archive\)"):
        FMUComponent(bad)


def test_zip_without_model_description(tmp_path):
    path = _zip(tmp_path / "empty.fmu", {"readme.txt": "hello"})
    with pytest.raises(FMUError, match=r"empty\.fmu: not an FMU \(no modelDescription\.xml"):
        FMUComponent(path)


@pytest.mark.parametrize("version", ["1.0", "2.1", "4.0"])
def test_wrong_fmi_version(tmp_path, version):
    path = _zip(tmp_path / "v.fmu", {"modelDescription.xml": _MD.format(
        version=version, kind='<CoSimulation modelIdentifier="M"/>')})
    with pytest.raises(FMUError, match=rf"v\.fmu: FMI version '{version}'; only FMI 2\.0 and FMI 3\.0 co-simulation"):
        FMUComponent(path)


def test_model_exchange_only(tmp_path):
    path = _zip(tmp_path / "me.fmu", {"modelDescription.xml": _MD.format(
        version="2.0", kind='<ModelExchange modelIdentifier="M"/>')})
    with pytest.raises(FMUError, match=r"me\.fmu: model-exchange-only FMU; a co-simulation FMU is required"):
        FMUComponent(path)


def test_no_binary_for_this_platform(tmp_path):
    path = _zip(tmp_path / "win.fmu", {
        "modelDescription.xml": _MD.format(version="2.0", kind='<CoSimulation modelIdentifier="M"/>'),
        "binaries/win64/M.dll": "MZ",
    })
    with pytest.raises(FMUError, match=r"win\.fmu: no binary binaries/linux64/M\.so .*\['win64'\]"):
        FMUComponent(path)


def test_check_fmu_raises_for_a_non_fmu(tmp_path):
    with pytest.raises(FMUError, match="not found"):
        check_fmu(tmp_path / "nothere.fmu")


def test_missing_role_variables_are_named(drive_fmu):
    with pytest.raises(FMUError) as info:
        FMUComponent(drive_fmu, name="mcu", role="mcu")
    text = str(info.value)
    assert str(drive_fmu) in text and "cannot stand in for role 'mcu'" in text
    assert "'x_ref'" in text and "'x_current_cmd'" in text and "mapping=" in text


def test_mapping_to_unknown_variable(drive_fmu):
    with pytest.raises(FMUError, match=r"mapping 'position' -> 'pos': the FMU has no variable 'pos'"):
        FMUComponent(drive_fmu, role="drive", mapping={"position": "pos"})


def test_mapping_with_incompatible_unit(drive_fmu):
    # their motor_force is in N; the role's position is in m
    with pytest.raises(FMUError, match=r"'position' \(FMU 'motor_force' \[N\]\).*cannot connect"):
        FMUComponent(drive_fmu, role="drive", mapping={"position": "motor_force", "motor_force": "position"})


def test_mapping_with_wrong_causality(drive_fmu):
    with pytest.raises(FMUError, match=r"'current_cmd' \(FMU 'mass'\) is a parameter, the role needs a input"):
        FMUComponent(drive_fmu, role="drive", mapping={"current_cmd": "mass"})


def test_batch_other_than_one_is_refused(drive_fmu):
    with pytest.raises(FMUError, match="one FMUComponent per population member"):
        FMUComponent(drive_fmu, batch=4)


def test_unknown_variable_and_output_parameter(drive_fmu):
    c = FMUComponent(drive_fmu, name="x_drive")
    with pytest.raises(FMUError, match=r"x_drive \(DriveAxis\.fmu\): no variable 'speed'"):
        c.variable("speed")
    with pytest.raises(FMUError, match="is an output"):
        FMUComponent(drive_fmu, parameters={"position": 1.0})
    c.close()


def test_protocol_surface_matches_the_native_component(drive_fmu):
    c = FMUComponent(drive_fmu, name="x_drive", role="drive")
    native = DriveAxis("x_drive")
    for causality in ("parameter", "input", "output"):
        assert c.names(causality) == native.names(causality)
    for name in native.names("parameter") + native.names("output"):
        assert c.variable(name).unit == native.variable(name).unit
    assert c.batch == 1 and c.state == "instantiated"
    assert all(v.shape == (1,) for v in c.values.values() if not isinstance(v, str))  # strings: whole batch
    assert c.values["mass"][0] == 600.0  # start value from the model description
    c.close()


def test_values_are_updated_in_place(drive_fmu):
    c = FMUComponent(drive_fmu, name="x_drive", parameters={"current_cmd": 3.0})
    arrays = {k: v for k, v in c.values.items()}
    c.setup(0.0)
    c.do_step(0.0, 1e-3)
    assert all(c.values[k] is arrays[k] for k in arrays)
    # u = I kt 2 pi / lead
    assert c.values["motor_force"][0] == pytest.approx(3.0 * 2 * np.pi / 0.012, rel=1e-14)
    assert c.state == "initialized"
    with pytest.raises(FMUError, match="set it before setup"):
        c.set("mass", 1.0)
    c.terminate()
    assert c.state == "terminated"
    with pytest.raises(FMUError, match="do_step\\(\\) called in state 'terminated'"):
        c.do_step(1e-3, 1e-3)
    c.close()


def test_fmu_component_runs_under_the_master(drive_fmu):
    """The FMU drive alone under the master, constant current, friction switched off."""
    system = System("one")
    system.add(FMUComponent(drive_fmu, name="x_drive", parameters={"current_cmd": 5.0, "viscous_positive": 0.0,
                                                                     "coulomb_positive": 0.0, "static_positive": 0.0}))
    result = Master(system, MasterSettings(step=1e-3, time_limit=0.1), ["x_drive.position"]).run()
    assert result.success
    # frictionless: x = u t^2 / (2 M) with u = 5 A * 2 pi / 0.012 m
    t = result.recording.t
    u = 5.0 * 2 * np.pi / 0.012
    np.testing.assert_allclose(result.recording["x_drive.position"], u * t**2 / (2 * 600.0), rtol=1e-9, atol=1e-15)


def test_a_script_that_runs_and_closes_a_pythonfmu_fmu_exits_cleanly(drive_fmu):
    """PythonFMU 0.7's fmi2FreeInstance corrupts the heap (PythonFMU#228): the script aborted at exit in about
    half of the runs. Its instances are not freed, so every run exits with status 0 (8 runs: a leftover abort
    rate of one half would pass all 8 with probability 0.4 %)."""
    import subprocess
    import sys

    script = (
        "from orchestrator import Master, MasterSettings, Probe, System\n"
        "from orchestrator.fmu import FMUComponent\n"
        f"drive = FMUComponent({str(drive_fmu)!r}, name='x', role='drive', parameters={{'current_cmd': 5.0}})\n"
        "system = System('exit'); system.add(drive)\n"
        "r = Master(system, MasterSettings(step=1e-3, time_limit=0.02), [Probe('x_mm', 'x.position', 'mm')]).run()\n"
        "drive.close()\n"
        "print(r.success)\n"
    )
    for _ in range(8):
        run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
        assert (run.returncode, run.stdout.strip()) == (0, "True"), run.stderr[-500:]
