"""The truth generator of the diagnosis tests: independent of the twin's servo code, yet the same physics.

Without hidden effects it must reproduce the twin's servo loop (else the diagnosis would find "effects"
that are only implementation differences); with them, analytic signatures; its logger must do what it
says (offset, resolution, missing channels).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.diagnose.model import simulate
from orchestrator.diagnose.prepare import twin_commands
from orchestrator.diagnose.scorecard import write_case
from orchestrator.diagnose.truth import Recorder, record, simulate_truth

KF = 2 * math.pi / 0.012


@pytest.fixture(scope="module")
def nc_run(tmp_path_factory):
    folder = write_case(tmp_path_factory.mktemp("gen") / "c", {}, seed=0)
    case = load_case(folder)
    return case, twin_commands(case, case.machine)


def test_truth_without_effects_matches_the_twin_servo(nc_run):
    case, nc = nc_run
    truth = simulate_truth(case.machine, nc, {}, axes=("z",))
    t = truth.t[::4]
    twin = simulate(case.machine, truth.t_cmd, {"z": truth.ref["z"]}, [{}], t_start=float(truth.t_cmd[0]))
    # the twin's replay outputs at the tick ends, compared with the truth's
    fe_twin = np.interp(t, truth.t_cmd, twin.fe["z"][:, 0])
    fe_truth = np.interp(t, truth.t_cmd, truth.ref["z"] - np.interp(truth.t_cmd, truth.t, truth.table["z"])) * 1e6
    assert np.max(np.abs(fe_twin - fe_truth)) < 0.3  # µm, against a noise floor of 0.42 µm
    cur_twin = np.interp(t, truth.t_cmd, twin.current["z"][:, 0])
    cur_truth = np.interp(t, truth.t, truth.current["z"])
    assert np.sqrt(np.mean((cur_twin - cur_truth) ** 2)) < 0.005  # A, against 0.02 A


def test_truth_gravity_shifts_the_current_by_weight_over_force_constant(nc_run):
    case, nc = nc_run
    plain = simulate_truth(case.machine, nc, {}, axes=("z",))
    heavy = simulate_truth(case.machine, nc, {"z": {"gravity": {"force_N": 200.0}}}, axes=("z",))
    v = np.gradient(plain.motor["z"], plain.t)
    steady = (np.abs(v) > 0.01) & (np.abs(np.gradient(v, plain.t)) < 1e-3)
    shift = np.median((heavy.current["z"] - plain.current["z"])[steady])
    assert shift == pytest.approx(200.0 / KF, rel=0.01)


def test_truth_table_terms_are_kinematic(nc_run):
    case, nc = nc_run
    effects = {"z": {"thermal_drift": {"rate_um_per_min": 60.0}, "pitch_error": {"slope_um_per_m": 100.0}}}
    truth = simulate_truth(case.machine, nc, effects, axes=("z",))
    expected = truth.motor["z"] * (1 + 100e-6) + 1e-6 * (truth.t - truth.t_cmd[0])
    np.testing.assert_allclose(truth.table["z"], expected, rtol=0, atol=1e-12)


def test_recorder_offset_resolution_and_missing_channels(nc_run):
    case, nc = nc_run
    truth = simulate_truth(case.machine, nc, {}, axes=("z",))
    rec = record(truth, Recorder(time_offset_s=1.5, drop=("z_ref_mm",)), seed=3)
    assert "z_ref_mm" not in rec and "z_mm" in rec and "z_tcmd_A" in rec
    assert rec.t[0] >= 1.5 + truth.t[0] - 1e-12
    dt = np.diff(rec.t)
    assert 0.0016 < dt.min() and dt.max() < 0.0018  # 1.7 ms with 0.1 ms jitter
    np.testing.assert_allclose(rec["z_mm"] * 1e3, np.round(rec["z_mm"] * 1e3), atol=1e-6)  # 1 µm encoder
    np.testing.assert_allclose(rec["z_tcmd_A"] * 100, np.round(rec["z_tcmd_A"] * 100), atol=1e-6)


def test_rms_gap_closed_is_the_share_of_residual_power_above_noise_removed():
    from types import SimpleNamespace

    from orchestrator.diagnose.scorecard import rms_gap_closed

    # a: 5 -> 3 over a noise floor of 1: (25 - 9) / (25 - 1) = 2/3; b sits on the noise floor; c is not recorded
    d = SimpleNamespace(rms_before={"a": 5.0, "b": 1.1}, rms_after={"a": 3.0, "b": 1.0}, noise={"a": 1.0, "b": 1.0})
    assert rms_gap_closed(d, ("a", "b", "c")) == pytest.approx(2.0 / 3.0)
    assert rms_gap_closed(d, ("b",)) is None
