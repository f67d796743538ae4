"""Diagnosis of the cutting process on recordings from the independent truth (orchestrator.diagnose.truth_cutting).

Recordings: the short cutting program (slots 1 and 2 mm deep, a 1 mm side pass 3 mm deep; 6 mm 3-flute end mill,
A6061, 6000 rpm), a dynamometer at 2.5 kHz with 1 N noise, the CNC logger of the drive tests (1.7 ms, 1 rpm
spindle resolution) and a seeded clock offset and spindle angle. Expected values are the hidden truths.
"""
from __future__ import annotations

import json
import math
import tomllib

import numpy as np
import pytest

from orchestrator.diagnose import diagnose
from orchestrator.diagnose.cutting_case import SHORT_PROGRAM, write_cutting_case
from orchestrator.diagnose.truth_cutting import Dynamometer

DYN = Dynamometer(period_s=0.4e-3)
SPEC_KEYS = {"effect", "channels", "where", "parameters", "ci90", "confidence", "evidence"}

#: effect -> (hidden parameters, relative tolerance on each)
SINGLE = {
    "runout": ({"eccentricity_um": 3.0, "phase_deg": 40.0}, 0.1),
    "edge_force": ({"kte_N_per_mm": 8.0, "kre_N_per_mm": 5.0}, 0.1),
    "tool_wear": ({"rate_percent_per_min": 200.0}, 0.1),
    "spindle_droop": ({"rpm_per_Nm": 30.0}, 0.1),
    "helix_angle": ({"helix_deg": 30.0}, 0.1),
}


def _case(tmp_path, name, effects, seed=11, dyn=DYN):
    folder = write_cutting_case(tmp_path / name, effects, seed, program=SHORT_PROGRAM, dynamometer=dyn)
    return folder, json.loads((folder / "truth.json").read_text())


@pytest.mark.parametrize("effect", sorted(SINGLE))
def test_each_cutting_effect_alone_is_found_with_its_parameters(effect, tmp_path):
    truth, rtol = SINGLE[effect]
    folder, hidden = _case(tmp_path, effect, {effect: truth})
    d = diagnose(folder, drives=False)
    assert [e["effect"] for e in d.effects] == [effect], d.log
    found = d.effects[0]
    assert set(found) == SPEC_KEYS  # no "axis" for the cutting process
    for key, value in truth.items():
        if key == "phase_deg":
            continue
        assert found["parameters"][key] == pytest.approx(value, rel=rtol), (key, found["parameters"])
    if effect == "runout":
        # which tooth is "tooth 0" is a convention of the alignment: the eccentricity's direction in the
        # spindle frame (angle of tooth 0 + phase) is what the forces fix
        true_dir = math.degrees(hidden["spindle_angle_at_first_force_sample_rad"]) + truth["phase_deg"]
        diff = d.alignment["spindle_angle_deg"] + found["parameters"]["phase_deg"] - true_dir
        assert abs((diff + 180.0) % 360.0 - 180.0) < 5.0
        assert found["where"]["frequency_Hz"] == pytest.approx(100.0, rel=0.01)  # 6000 rpm
    for ch in ("fx_N", "fy_N"):
        assert d.rms_after[ch] <= 1.1 * d.noise[ch]
    assert d.unexplained == []
    channel = "spindle_rpm" if effect == "spindle_droop" else "fy_N"
    assert d.rms_before[channel] > d.rms_after[channel]


def test_clean_cutting_recording_gives_no_effect_and_finds_the_coefficients(tmp_path):
    folder, _ = _case(tmp_path, "clean", {}, seed=3)
    d = diagnose(folder, drives=False)
    assert d.effects == [] and d.unexplained == []
    assert d.rms_after["fx_N"] <= 1.1 * d.noise["fx_N"]
    # Kt, Ke are refitted (identified, not an effect): the machine file's values come back
    assert d.cutting.model["coefficients"]["kt_N_per_m2"] == pytest.approx(1.23e9, rel=0.01)
    assert d.cutting.model["coefficients"]["ke"] == pytest.approx(0.5, abs=0.01)


def test_two_cutting_effects_at_once_and_the_outputs(tmp_path):
    # an edge force and a Kt error both raise the force; the edge force does not scale with the chip,
    # wear grows with cutting time: all three are told apart
    truth = {"edge_force": {"kte_N_per_mm": 8.0, "kre_N_per_mm": 5.0}, "tool_wear": {"rate_percent_per_min": 200.0},
             "kt_mismatch": {"factor": 1.1}}
    folder, _ = _case(tmp_path, "two", truth, seed=5)
    hold, _ = _case(tmp_path, "two_held_out", truth, seed=6)
    d = diagnose(folder, holdout=hold, drives=False)
    found = {e["effect"]: e["parameters"] for e in d.effects}
    assert set(found) == {"edge_force", "tool_wear"}, d.log
    assert found["edge_force"]["kte_N_per_mm"] == pytest.approx(8.0, rel=0.1)
    assert found["edge_force"]["kre_N_per_mm"] == pytest.approx(5.0, rel=0.1)
    assert found["tool_wear"]["rate_percent_per_min"] == pytest.approx(200.0, rel=0.1)
    assert d.cutting.model["coefficients"]["kt_N_per_m2"] == pytest.approx(1.1 * 1.23e9, rel=0.02)
    # the held-out case (own noise, spindle angle, clock offset) is only re-simulated: the model is general
    assert d.holdout["rms_after"]["fy_N"] < 1.15 * d.noise["fy_N"] < d.holdout["rms_before"]["fy_N"] / 2
    files = d.write(tmp_path / "out")
    j = json.loads(files["diagnosis"].read_text())
    assert {"alignment", "effects", "unexplained", "rms_before", "rms_after", "model"} == set(j)
    assert all("axis" not in e for e in j["effects"])
    assert {"fx_N", "fy_N", "fc_N", "spindle_rpm"} <= set(j["rms_before"])
    machine = tomllib.loads(files["machine"].read_text())
    assert machine["cutting"]["effects"]["kte_N_per_mm"]["value"] == pytest.approx(
        found["edge_force"]["kte_N_per_mm"], rel=1e-4)
    assert machine["material"]["A6061"]["kt_N_per_m2"]["value"] == pytest.approx(1.1 * 1.23e9, rel=0.02)
    assert files["cutting_map"].stat().st_size > 10_000
    assert "cutting process" in files["report"].read_text()


def test_chatter_is_a_growing_peak_off_the_spindle_harmonics(tmp_path):
    # a tool mode at 1150 Hz, 3 % damping, 30 N/um: the 2 mm slot is beyond the stability limit, the others not
    mode = {"frequency_Hz": 1150.0, "damping_ratio": 0.03, "stiffness_N_per_um": 30.0}
    folder, _ = _case(tmp_path, "chatter", {"chatter": mode})
    d = diagnose(folder, drives=False)
    assert [e["effect"] for e in d.effects] == ["chatter"], d.log
    f = d.effects[0]["parameters"]["frequency_Hz"]
    assert f == pytest.approx(1150.0, rel=0.08)           # regenerative chatter sits near the mode
    assert abs(f / 100.0 - round(f / 100.0)) > 0.05       # not a spindle harmonic (100 Hz)
    assert d.effects[0]["where"]["frequency_Hz"] == f
    assert len(d.effects[0]["where"]["time_s"]) == 1      # only the deep slot chatters
    assert d.unexplained == []
    # the tool mode is refitted from the envelope (growth within the cut, limit cycle) and the stability
    # relation; the spec's parameters stay frequency_Hz only, the mode goes to machine.toml and the evidence
    assert set(d.effects[0]["parameters"]) == {"frequency_Hz"}
    fit = d.cutting.chatter_fit
    # the product k zeta sets the stability limit. Twin and truth remember the same 5 surfaces: with the
    # truth's own mode the twin's limit cycle is 58.8 N against 58.0 N, it reaches half of it 10 ms later
    # (405 against 395 ms) and grows at 51 against 45 1/s. The refit matches the rise of the envelope with
    # a lower k zeta (0.65 against 0.90 N/um, 28 % low): 35 % allowed
    assert fit.stiffness_N_per_um * fit.damping_ratio == pytest.approx(30.0 * 0.03, rel=0.35)
    # zeta and k separately are NOT identified (README, Limits (cutting), chatter mode): along k zeta = 0.9
    # the twin's limit cycle moves only as zeta^0.16 and its growth as zeta^0.55, so a 13 % growth error
    # costs ~40 % in zeta; this case gives zeta 0.010 (the coarse grid's lowest), k 65 N/um: no bound on
    # the split is asserted, only what the recording fixes (k zeta, frequency, limit cycle, growth, power)
    assert fit.natural_frequency_Hz == pytest.approx(1150.0, rel=0.02)
    assert fit.amplitude_twin_N == pytest.approx(fit.amplitude_N, rel=0.3)   # 72 against 58 N
    # band power around the chatter frequency: without the mode only the noise is there (60 Hz of the
    # 1250 Hz band at 1 N against a ~58 N vibration: ~1e-5); with it, the refitted twin's limit cycle is
    # 24 % high (power 1.54x): x 2 allowed
    assert fit.band_power_before < 1e-3
    assert 0.5 < fit.band_power_ratio < 2.0
    assert fit.growth_twin_per_s == pytest.approx(fit.growth_per_s, rel=0.3)
    machine = tomllib.loads(d.write(tmp_path / "out", plots=False)["machine"].read_text())["cutting"]["effects"]
    assert machine["chatter_damping_ratio"]["value"] == pytest.approx(fit.damping_ratio, rel=1e-5)
    assert machine["chatter_stiffness_N_per_um"]["value"] == pytest.approx(fit.stiffness_N_per_um, rel=1e-5)
    assert f"damping ratio {fit.damping_ratio:.4f}" in d.effects[0]["evidence"]


def test_a_vibration_outside_the_table_is_unexplained_with_its_frequency(tmp_path):
    folder, _ = _case(tmp_path, "hum", {}, dyn=Dynamometer(period_s=0.4e-3, hum_N=5.0, hum_Hz=50.0))
    d = diagnose(folder, drives=False)
    assert d.effects == []  # present in the air too: not chatter
    assert [u["channels"] for u in d.unexplained] == [["fx_N"]]
    assert d.unexplained[0]["where"]["frequency_Hz"] == pytest.approx(50.0, abs=1.0)
    assert d.unexplained[0]["rms"] == pytest.approx(math.sqrt(5.0 ** 2 / 2), rel=0.15)


def test_tool_deflection_through_the_command_line(tmp_path):
    # the tool bends: the deeper the cut the more the force falls short (a Kt error would scale all cuts alike)
    import argparse

    from orchestrator import cli_diagnose

    folder, _ = _case(tmp_path, "cli", {"tool_deflection": {"stiffness_N_per_um": 10.0}}, seed=2)
    parser = argparse.ArgumentParser()
    cli_diagnose.add_parsers(parser.add_subparsers())
    args = parser.parse_args(["diagnose", str(folder), "--out", str(tmp_path / "o"), "--no-drives", "--no-plots",
                              "--quiet"])
    assert args.func(args) == 0
    j = json.loads((tmp_path / "o" / "diagnosis.json").read_text())
    assert [e["effect"] for e in j["effects"]] == ["tool_deflection"]
    assert j["effects"][0]["parameters"]["stiffness_N_per_um"] == pytest.approx(10.0, rel=0.1)
    assert j["rms_after"]["fy_N"] < j["rms_before"]["fy_N"]
    assert j["unexplained"] == []
    assert np.isfinite(j["alignment"]["spindle_angle_deg"])
