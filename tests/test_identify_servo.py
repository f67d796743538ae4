"""Servo identification: exact closed-loop replay and scale factors recovered from noisy recordings.

A servo experiment is run on the twin with non-default scale factors (and
non-default friction, known to the identifier), degraded with logger
imperfections and identified back.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from orchestrator.experiments import write_experiment
from orchestrator.identify import Imperfections, identify_servo, replay
from orchestrator.identify.synthetic import degrade, synthetic_case
from orchestrator.machine import load_machine

FRICTION = {"coulomb_N": 700.0, "static_N": 905.0, "stribeck_velocity_m_per_s": 0.0011, "viscous_Ns_per_m": 6000.0}
TRUE_SCALES = {"position_scale": 0.9, "velocity_p_scale": 1.2, "velocity_i_scale": 0.8}
SYMBOL = {"position_scale": "Spp", "velocity_p_scale": "Svp", "velocity_i_scale": "Svi"}


def known_machine():
    """What the user knows before servo identification: friction identified, scale factors 1."""
    m = load_machine("default")
    for d in ("positive", "negative"):
        m = m.with_values(f"axis.x.friction.{d}", **FRICTION)
    return m


@pytest.fixture(scope="module")
def servo_case(tmp_path_factory):
    folder = tmp_path_factory.mktemp("servo") / "case"
    write_experiment("servo", folder, axes=("x",), speeds_mm_min=(200.0, 500.0), plateau_s=0.3, dwell_s=0.1)
    truth = known_machine().with_values("axis.x", **TRUE_SCALES)
    clean, _ = synthetic_case(folder, truth, Imperfections(0, 0, 0, 0, 0, 0))
    return folder, clean, truth


def test_replay_reproduces_the_twin_exactly(servo_case):
    """The replay (MCU + DriveAxis on the recorded reference) is the twin's loop: same positions, same current."""
    _, clean, truth = servo_case
    run = replay(truth, clean.t, {"x": clean["x_ref_mm"] * 1e-3}, initial_position={"x": clean["x_mm"][0] * 1e-3})
    assert np.max(np.abs(run.position["x"][:, 0] * 1e3 - clean["x_mm"])) < 1e-9  # mm
    assert np.max(np.abs(run.current["x"][:, 0] - clean["x_tcmd_A"])) < 1e-9  # A


def test_scale_factors_within_5_percent(servo_case, tmp_path):
    folder, clean, _ = servo_case
    degrade(clean, Imperfections(), seed=21).write_csv(folder / "recording.csv")
    fit = identify_servo([folder], machine=known_machine())
    for key, value in TRUE_SCALES.items():
        assert fit.scales_["x"][SYMBOL[key]] == pytest.approx(value, rel=0.05), fit.scales_
    # residuals at the noise level: following error ~ quantisation (1 µm / sqrt 12 plus 0.3 µm), current 0.02 A
    assert fit.rms_["x"]["following_error_um"] < 1.0
    assert fit.rms_["x"]["current_A"] < 0.05
    files = fit.write(tmp_path / "out")
    fitted = load_machine(files["machine"])
    assert fitted.table("axis.x")["velocity_p_scale"] == pytest.approx(fit.scales_["x"]["Svp"])
    assert fitted.table("axis.x.friction.positive")["coulomb_N"] == 700.0
    assert json.loads(files["report"].read_text())["axes"]["x"]["Spp"] == pytest.approx(fit.scales_["x"]["Spp"])
    assert files["servo_x"].stat().st_size > 1000


def test_ten_times_the_noise_degrades_gracefully(servo_case):
    folder, clean, _ = servo_case
    degrade(clean, Imperfections().scaled(10.0), seed=22).write_csv(folder / "recording.csv")
    fit = identify_servo([folder], machine=known_machine())
    assert fit.scales_["x"]["Spp"] == pytest.approx(0.9, rel=0.02)
    assert fit.scales_["x"]["Svp"] == pytest.approx(1.2, rel=0.10)
    assert fit.scales_["x"]["Svi"] == pytest.approx(0.8, rel=0.15)
