"""Diagnosis of each drive/controller effect alone, concealed near the noise floor of a realistic logger.

Recordings come from the independent truth simulation (orchestrator.diagnose.truth) with a logger at
1.7 ms +- 0.1 ms, 1 µm encoder and 0.01 A current resolution, 0.3 µm / 0.02 A noise and a seeded clock
offset; noise floors are about 0.42 µm (following error) and 0.02 A (current). Expected values are the
hidden truths.
"""
from __future__ import annotations

import math

import pytest

from orchestrator.diagnose import diagnose
from orchestrator.diagnose.scorecard import write_case

KF = 2 * math.pi / 0.012  # N/A of the default Z drive

#: effect -> (hidden parameters, relative tolerance on the non-zero ones)
CASES = {
    "gravity": ({"force_N": 40.0}, 0.1),                                    # 0.076 A, ~4 noise floors
    "backlash": ({"width_um": 1.5}, 0.15),                                  # +-0.75 µm, < 2 noise floors
    "reversal_friction": ({"peak_N": 60.0, "decay_mm": 0.1}, 0.2),
    "friction_mismatch": ({"coulomb_N": 15.0}, 0.15),                       # 0.029 A
    "inertia_mismatch": ({"mass_kg": 30.0}, 0.15),
    "screw_compliance": ({"stiffness_N_per_um": 600.0}, 0.15),
    "pitch_error": ({"amplitude_um": 0.8, "period_mm": 12.0}, 0.15),
    "thermal_drift": ({"rate_um_per_min": 20.0}, 0.2),
    "torque_ripple": ({"amplitude_N": 12.0, "period_mm": 6.0}, 0.15),      # 0.023 A, ~1 noise floor
    "velocity_feedforward": ({"gain": 0.05}, 0.1),
    "servo_delay": ({"delay_ms": 0.3}, 0.15),
}


@pytest.mark.parametrize("effect", sorted(CASES))
def test_single_effect_is_found_alone_with_its_parameters(effect, tmp_path):
    truth, rtol = CASES[effect]
    folder = write_case(tmp_path / effect, {effect: truth}, seed=11)
    d = diagnose(folder)
    names = [e["effect"] for e in d.effects]
    assert names == [effect], (names, d.log)
    found = d.effects[0]
    assert found["axis"] == "z"
    for key, value in truth.items():
        assert found["parameters"][key] == pytest.approx(value, rel=rtol), (key, found["parameters"])
    # the model closes the gap: what is left is the noise floor
    assert d.rms_after["z_fe_um"] <= 1.15 * d.noise["z_fe_um"]
    assert d.rms_after["z_tcmd_A"] <= 1.15 * d.noise["z_tcmd_A"]
    assert d.unexplained == []


def test_gravity_under_a_pi_velocity_loop_moves_the_current_not_the_following_error(tmp_path):
    # the integrator carries the weight: the following error hardly changes, the current shifts by F / kf
    force = 40.0
    d = diagnose(write_case(tmp_path / "g", {"gravity": {"force_N": force}}, seed=5))
    assert d.rms_before["z_fe_um"] < 1.3 * d.noise["z_fe_um"]
    assert d.rms_before["z_tcmd_A"] == pytest.approx(force / KF, rel=0.15)
    assert [e["effect"] for e in d.effects] == ["gravity"]
    lo, hi = d.effects[0]["ci90"]["force_N"]
    assert lo <= force <= hi or abs(d.effects[0]["parameters"]["force_N"] - force) < 0.05 * force


def test_current_clipped_below_the_modelled_peak_is_current_saturation(tmp_path):
    d = diagnose(write_case(tmp_path / "sat", {"current_saturation": {"limit_A": 2.5}}, seed=3))
    assert [e["effect"] for e in d.effects] == ["current_saturation"]
    assert d.effects[0]["parameters"]["limit_A"] == pytest.approx(2.5, abs=0.05)
    assert d.rms_after["z_fe_um"] <= 1.15 * d.noise["z_fe_um"]
