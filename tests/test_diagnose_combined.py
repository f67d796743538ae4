"""Diagnosis: clean recordings, several effects at once, effects concealed under others, phenomena outside
the table, the output files, the CLI and the errors."""
from __future__ import annotations

import argparse
import json
import tomllib

import numpy as np
import pytest

from orchestrator.diagnose import DiagnosisError, diagnose
from orchestrator.diagnose.scorecard import write_case
from orchestrator.diagnose.truth import Recorder

SPEC_KEYS = {"alignment", "effects", "unexplained", "rms_before", "rms_after", "model"}
EFFECT_KEYS = {"effect", "axis", "channels", "where", "parameters", "ci90", "confidence", "evidence"}


@pytest.mark.parametrize("seed", [1, 2])
def test_clean_recording_gives_no_effect(seed, tmp_path):
    d = diagnose(write_case(tmp_path / "clean", {}, seed=seed))
    assert d.effects == [] and d.unexplained == []
    assert d.rms_after["z_fe_um"] <= 1.1 * d.noise["z_fe_um"]


def test_three_effects_at_once(tmp_path):
    truth = {"gravity": {"force_N": 120.0}, "backlash": {"width_um": 3.0},
             "torque_ripple": {"amplitude_N": 25.0, "period_mm": 12.0}}
    d = diagnose(write_case(tmp_path / "three", truth, seed=3))
    found = {e["effect"]: e["parameters"] for e in d.effects}
    assert set(found) == set(truth), d.log
    assert found["gravity"]["force_N"] == pytest.approx(120.0, rel=0.05)
    assert found["backlash"]["width_um"] == pytest.approx(3.0, rel=0.1)
    assert found["torque_ripple"]["amplitude_N"] == pytest.approx(25.0, rel=0.1)
    assert found["torque_ripple"]["period_mm"] == 12.0
    confidences = [e["confidence"] for e in d.effects]
    assert confidences == sorted(confidences, reverse=True)


def test_gravity_concealed_under_a_coulomb_friction_error(tmp_path):
    # both move the current; gravity with the same sign on up- and down-strokes, friction with the sign of v
    truth = {"gravity": {"force_N": 60.0}, "friction_mismatch": {"coulomb_N": 50.0}}
    d = diagnose(write_case(tmp_path / "gf", truth, seed=4))
    found = {e["effect"]: e["parameters"] for e in d.effects}
    assert set(found) == {"gravity", "friction_mismatch"}
    assert found["gravity"]["force_N"] == pytest.approx(60.0, rel=0.1)
    assert found["friction_mismatch"]["coulomb_N"] == pytest.approx(50.0, rel=0.1)


def test_feedforward_told_apart_from_a_logger_time_offset(tmp_path):
    # no recorded command: the twin's NC output must be placed in time; a wrong offset mimics feed-forward
    rec = Recorder(drop=("z_ref_mm",))
    folder = write_case(tmp_path / "ff", {"velocity_feedforward": {"gain": 0.2}}, seed=6, recorder=rec,
                        offset_range_s=(1.3102, 1.3102))
    d = diagnose(folder)
    assert [e["effect"] for e in d.effects] == ["velocity_feedforward"]
    assert d.effects[0]["parameters"]["gain"] == pytest.approx(0.2, rel=0.1)
    assert d.alignment["time_offset_s"] == pytest.approx(1.3102, abs=5e-4)
    assert "z_ref_mm" not in d.alignment["channels"]


def test_phenomenon_outside_the_table_is_unexplained_where_it_is(tmp_path):
    def vibration(t: np.ndarray) -> np.ndarray:  # 60 Hz, 3 µm, program time 1.0 .. 1.4 s
        return np.where((t > 1.0) & (t < 1.4), 3.0 * np.sin(2 * np.pi * 60.0 * t), 0.0)

    folder = write_case(tmp_path / "vib", {}, seed=7, disturbance_um=vibration, offset_range_s=(0.5, 0.5))
    d = diagnose(folder)
    assert d.effects == []
    assert len(d.unexplained) == 1
    u = d.unexplained[0]
    assert u["channels"] == ["z_fe_um"]
    (w0, w1), = u["where"]["time_s"]
    assert w0 >= 1.45 and w0 <= 1.6 and w1 >= 1.8 and w1 <= 1.95  # logger clock = program + 0.5 s
    assert u["where"]["frequency_Hz"] == pytest.approx(60.0, abs=1.0)


def test_outputs_cli_and_holdout(tmp_path):
    from orchestrator.cli_diagnose import add_parsers

    truth = {"gravity": {"force_N": 150.0}}
    case = write_case(tmp_path / "case", truth, seed=8)
    hold = write_case(tmp_path / "hold", truth, seed=9)
    parser = argparse.ArgumentParser(prog="cnctwin")
    add_parsers(parser.add_subparsers())
    args = parser.parse_args(["diagnose", str(case), "--holdout", str(hold), "--out", str(tmp_path / "out"),
                              "--quiet"])
    assert args.func(args) == 0
    out = tmp_path / "out"
    j = json.loads((out / "diagnosis.json").read_text())
    assert set(j) == SPEC_KEYS
    assert set(j["alignment"]) == {"time_offset_s", "channels"}
    assert all(set(v) == {"scale", "offset"} for v in j["alignment"]["channels"].values())
    (e,) = j["effects"]
    assert set(e) == EFFECT_KEYS and e["effect"] == "gravity" and e["axis"] == "z"
    assert set(e["where"]) == {"time_s", "lines", "event", "frequency_Hz"}
    assert set(e["parameters"]) == {"force_N", "spring_N_per_mm"} == set(e["ci90"])
    assert set(j["rms_before"]) == set(j["rms_after"]) >= {"z_fe_um", "z_tcmd_A"}
    assert j["rms_after"]["z_tcmd_A"] < 0.2 * j["rms_before"]["z_tcmd_A"]
    hold_j = json.loads((out / "holdout.json").read_text())
    assert hold_j["rms_after"]["z_tcmd_A"] < 0.2 * hold_j["rms_before"]["z_tcmd_A"]
    machine = tomllib.loads((out / "machine.toml").read_text())
    effects = machine["axis"]["z"]["effects"]
    assert effects["gravity_force_N"]["value"] == pytest.approx(150.0, rel=0.05)
    assert effects["gravity_force_N"]["source"].startswith("diagnosed:")
    for name in ("report.md", "residual_map_z.png", "traces_z.png", "traces_z_holdout.png"):
        assert (out / name).stat().st_size > 0


def test_errors_name_the_problem(tmp_path):
    folder = write_case(tmp_path / "c", {}, seed=1)
    (folder / "recording.csv").unlink()
    with pytest.raises(DiagnosisError, match="needs a recording"):
        diagnose(folder)
    (folder / "recording.csv").write_text("t_s,line\n0.0,1\n0.1,1\n0.2,1\n")
    with pytest.raises(DiagnosisError, match="no axis|cannot align|holds no block"):
        diagnose(folder)


def test_nc_kernel_difference_is_reported_on_the_command_channel_not_as_physics(tmp_path):
    # the machine's controller smooths its commands more than the twin's NC kernel (extra 40 ms moving
    # average); the servo is driven by the recorded commands, so no other drive effect may appear
    folder = write_case(tmp_path / "nc", {"gravity": {"force_N": 100.0}}, seed=12, ref_filter_s=0.04)
    d = diagnose(folder)
    assert [e["effect"] for e in d.effects] == ["gravity"]
    assert d.rms_before["z_ref_mm"] > 0.005
    (u,) = [u for u in d.unexplained if u["channels"] == ["z_ref_mm"]]
    assert u["where"]["time_s"] and u["rms"] == d.rms_before["z_ref_mm"]


def test_interpolation_timing_difference_is_not_taken_for_a_servo_delay(tmp_path):
    # an 8 ms moving average delays the commands by 3.5 ms against the twin's: they still match it after
    # the shift, but the servo phase they imply is half a position period off; the timing check must
    # move the phase instead of inventing a delay or feed-forward
    folder = write_case(tmp_path / "nc8", {"gravity": {"force_N": 100.0}}, seed=12, ref_filter_s=0.008)
    d = diagnose(folder)
    assert [e["effect"] for e in d.effects] == ["gravity"]
    assert any(line.startswith("timing check") for line in d.log)
    assert d.rms_after["z_tcmd_A"] <= 1.15 * d.noise["z_tcmd_A"]


def test_two_axes_with_a_current_offset_artefact(tmp_path):
    from orchestrator.case import load_case
    from orchestrator.diagnose.prepare import twin_commands
    from orchestrator.diagnose.truth import record, simulate_truth

    folder = tmp_path / "xz"
    folder.mkdir()
    (folder / "program.nc").write_text("%\nO0009\nN10 G90 G21 G17\nN20 G01 X20. Z35. F2500\nN30 X-10. Z55. F1500\n"
                                       "N40 G04 P100\nN50 X15. Z38. F3000\nN60 X0. Z52. F900\nN70 M30\n%\n")
    (folder / "case.toml").write_text('program = "program.nc"\nrecording = "recording.csv"\n')
    case = load_case(folder)
    nc = twin_commands(case, case.machine)
    hidden = {"x": {"backlash": {"width_um": 3.0}, "friction_mismatch": {"coulomb_N": 30.0}},
              "z": {"gravity": {"force_N": 80.0}}}
    truth = simulate_truth(case.machine, nc, hidden, axes=("x", "z"))
    # an amplifier offset of 0.05 A on X: a recording artefact, not physics (X carries no weight)
    record(truth, Recorder(), seed=4, current_offset_A={"x": 0.05}).write_csv(folder / "recording.csv")
    d = diagnose(folder)
    found = {(e["effect"], e["axis"]): e["parameters"] for e in d.effects}
    assert set(found) == {("gravity", "z"), ("friction_mismatch", "x"), ("backlash", "x")}
    assert found[("gravity", "z")]["force_N"] == pytest.approx(80.0, rel=0.05)
    assert found[("backlash", "x")]["width_um"] == pytest.approx(3.0, rel=0.1)
    assert found[("friction_mismatch", "x")]["coulomb_N"] == pytest.approx(30.0, rel=0.1)
    assert d.alignment["channels"]["x_tcmd_A"]["offset"] == pytest.approx(0.05, abs=0.01)
    for ch in ("x_fe_um", "x_tcmd_A", "z_fe_um", "z_tcmd_A"):
        assert d.rms_after[ch] <= 1.15 * d.noise[ch]
