"""A foreign drive FMU (C, FMI 2.0 API, other names, millimetres) standing in for the native DriveAxis.

The C model (tests/fixtures/fmu/foreign_drive/foreign_drive.c) implements the
same equations independently. Tolerances:

* same internal step (25 us) in both: the two RK4 + zero-crossing
  implementations agree to round-off, |dx| <= 1e-12 m over a 90 mm stroke;
* each at its default step (native 125 us, C 25 us): the difference is the
  RK4 truncation error of the native model, measured 4e-11 m; asserted
  <= 1e-9 m (|dv| <= 1e-7 m/s);
* in the closed-loop twin (MCU feedback) with the C step set to 125 us:
  <= 1e-9 mm on the X position.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from fmus_src.servo.drive import DriveAxis
from orchestrator import Master, MasterSettings, Probe, System
from orchestrator.fmu import FMUComponent, check_fmu

sys.path.insert(0, str(Path(__file__).resolve().parent / "fixtures" / "fmu"))
import cfmu  # noqa: E402

pytestmark = pytest.mark.skipif(cfmu.compiler() is None, reason="no C compiler")

#: our name -> the foreign FMU's name
MAPPING = {
    "current_cmd": "Iq", "disturbance_force": "F_load", "position": "pos", "velocity": "vel",
    "motor_force": "F_motor", "friction_force": "F_fric", "mass": "Ms", "torque_constant": "Kt",
    "screw_lead": "lead", "initial_position": "x0",
    "coulomb_positive": "Fc_p", "static_positive": "Fs_p", "stribeck_velocity_positive": "vs_p",
    "viscous_positive": "cv_p", "coulomb_negative": "Fc_n", "static_negative": "Fs_n",
    "stribeck_velocity_negative": "vs_n", "viscous_negative": "cv_n",
}


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    return cfmu.build_c_fmu(cfmu.HERE / "foreign_drive", tmp_path_factory.mktemp("cfmu"))


def test_foreign_fmu_is_valid(foreign):
    assert validate_fmu(str(foreign)) == []


def test_check_fmu_reports_role_fit_with_and_without_mapping(foreign):
    bare = check_fmu(foreign, role="drive")
    assert bare.problems == [] and bare.smoke_ok and not bare.role_ok and not bare.ok
    assert {r.ours for r in bare.role_rows if r.required and r.status == "missing"} == {
        "current_cmd", "disturbance_force", "position", "velocity"}
    mapped = check_fmu(foreign, role="drive", mapping=MAPPING)
    assert mapped.ok
    rows = {r.ours: r for r in mapped.role_rows}
    assert rows["position"].theirs == "pos" and "1 m = 1000 mm" in rows["position"].status
    assert "mm" in mapped.to_text()


def _profile(t: float) -> float:
    """Current command, A: a 2 Hz sine with offset; |u| < Fs near its zero crossings (stick phases)."""
    return 12.0 * np.sin(2 * np.pi * 2.0 * t) + 0.5


def _run_pair(foreign_fmu, native_step, foreign_step, n=2400, h=250e-6):
    f = FMUComponent(foreign_fmu, name="x_drive", role="drive", mapping=MAPPING,
                     parameters={"initial_position": 0.01, "dt_max": foreign_step})
    nat = DriveAxis("x_drive", initial_position=0.01, integration_step=native_step)
    f.setup(0.0)
    nat.setup(0.0)
    out = np.zeros((n + 1, 2, 3))
    out[0] = [[c.values[k][0] for k in ("position", "velocity", "friction_force")] for c in (f, nat)]
    for k in range(n):
        t = k * h
        for c in (f, nat):
            c.values["current_cmd"][0] = _profile(t)
            c.values["disturbance_force"][0] = 300.0
            c.do_step(t, h)
        out[k + 1] = [[c.values[q][0] for q in ("position", "velocity", "friction_force")] for c in (f, nat)]
    f.terminate()
    f.close()
    return out


def test_foreign_drive_matches_native_to_round_off_at_equal_step(foreign):
    out = _run_pair(foreign, 25e-6, 25e-6)
    x, v = out[:, :, 0], out[:, :, 1]
    stroke = np.abs(x[:, 1] - 0.01).max()
    assert stroke > 0.05  # the profile moves the table tens of mm both ways
    stuck = v[:, 1] == 0.0
    assert 10 < stuck.sum() < len(v) / 2  # there are stick phases ...
    assert np.array_equal(stuck, v[:, 0] == 0.0)  # ... and both models stick at the same instants
    assert np.abs(x[:, 0] - x[:, 1]).max() <= 1e-12
    assert np.abs(v[:, 0] - v[:, 1]).max() <= 1e-10
    assert np.abs(out[:, 0, 2] - out[:, 1, 2]).max() <= 1e-6  # friction, N


def test_foreign_drive_matches_native_at_default_steps(foreign):
    out = _run_pair(foreign, 125e-6, 25e-6)
    assert np.abs(out[:, 0, 0] - out[:, 1, 0]).max() <= 1e-9
    assert np.abs(out[:, 0, 1] - out[:, 1, 1]).max() <= 1e-7


def test_fmi2_error_mid_run_ends_the_master_run_with_the_recording(foreign):
    system = System("failing")
    system.add(FMUComponent(foreign, name="x_drive", role="drive", mapping=MAPPING,
                            parameters={"current_cmd": 5.0, "fail_time": 0.05}))
    result = Master(system, MasterSettings(step=1e-3, time_limit=0.2),
                    [Probe("x_mm", "x_drive.position", "mm")]).run()
    assert not result.success
    msg = result.message
    assert "x_drive" in msg and "fmi2DoStep" in msg and "fmi2Error" in msg and "t = 0.050000 s" in msg
    assert "injected failure" in msg  # the FMU's own log line
    t = result.recording.t
    # steps up to [0.049, 0.050] succeed; the recording holds t = 0 ... 0.050
    np.testing.assert_allclose(t, np.arange(51) * 1e-3, atol=1e-15)
    x_mm = result.recording["x_mm"]
    assert x_mm[-1] > x_mm[0]  # 5 A * 2 pi / 12 mm = 2618 N > Fs: the table moved


def test_foreign_drive_stands_in_for_the_x_axis_of_the_twin(foreign, tmp_path):
    import orchestrator.twin as twin_mod
    from orchestrator.case import case_for_program

    program = tmp_path / "move.nc"
    program.write_text("%\nO0002\nG21 G90 G94 G54\nG1 X5. Y2. F3000\nX-3. Y0.\nG0 X0.\nM30\n%\n")

    def run(replace: bool):
        # the foreign drive implements the RK4 stick/slip scheme: compare with the twin's RK4 drives
        twin = twin_mod.build_twin(case_for_program(program), options=twin_mod.TwinOptions(drive_integrator="rk4"))
        system = twin.system
        if replace:
            native = system.components["x_drive"]
            params = {k: native.values[k][0] for k in native.names("parameter") if k in MAPPING}
            params["dt_max"] = float(native.values["integration_step"][0])
            system.components["x_drive"] = FMUComponent(foreign, name="x_drive", role="drive", mapping=MAPPING,
                                                        parameters=params)
        settings = MasterSettings(step=twin.options.step, time_limit=5.0, stop_when=twin.stop_when)
        # channels follow the wiring: a drive without table_position is recorded from what feeds mcu.x_position
        return Master(system, settings, twin_mod.twin_probes(system)).run()

    native, swapped = run(False), run(True)
    assert native.success and swapped.success
    assert len(native.recording) == len(swapped.recording)
    assert np.abs(native.recording["x_mm"]).max() > 2.0
    assert np.abs(native.recording["x_mm"] - swapped.recording["x_mm"]).max() <= 1e-9
    assert np.abs(native.recording["x_tcmd_A"] - swapped.recording["x_tcmd_A"]).max() <= 1e-6
