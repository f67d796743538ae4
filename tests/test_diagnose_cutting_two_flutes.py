"""The cutting diagnosis on a 2-flute end mill (the paper's tool), against the independent truth.

A 2-flute tool at 6000 rpm has a 5 ms tooth period: sampled at 1 kHz the dynamometer sees five instants per
tooth, and the chip of a cut that stops in the material (a slot or side pass ending inside the stock, blended
into the retract) changes within one tooth period. Three things are checked:

* the replay's chip at a deceleration is the tool-centre displacement over the last tooth period (what the
  previous tooth left, the truth's definition, the component's own chip), not the step velocity times the
  period: the replay matches the independent truth there, where the step velocity would be several percent low;
* a clean 2-flute truth recording at 1 kHz names nothing and leaves nothing unexplained;
* a 10 um runout at phase 0 (all of it on the line of the two teeth) is refitted within 3 %, and nothing is
  left unexplained where the side pass decelerates in the material (the chip of the surface a revolution
  back is the displacement over that revolution).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting.table import build_engagement_table
from orchestrator.case import load_case
from orchestrator.diagnose import diagnose
from orchestrator.diagnose.cutting_case import CASE_TOML, SHORT_PROGRAM, write_cutting_case
from orchestrator.diagnose.cutting_replay import ForceInputs, run_force_replay
from orchestrator.diagnose.scorecard_cutting import observable_runout
from orchestrator.diagnose.truth_cutting import Dynamometer, cutting_parameters_packed, simulate_cutting

TWO_FLUTES = CASE_TOML.replace("flutes = 3", "flutes = 2")
OMEGA = 6000 * 2 * math.pi / 60
PERIOD = 2 * math.pi / (2 * OMEGA)  # tooth period, 5 ms


def test_replay_chip_at_a_stop_in_the_material_is_the_truths(tmp_path):
    # a full slot 2 mm deep along x at y = 10 mm in the case's stock, decelerating uniformly from 450 mm/min to a
    # stop at x = 6 mm inside the block; the truth (20 us grid, chip c(t) - c(t - T)) against the replay at 1 ms
    (tmp_path / "program.nc").write_text(SHORT_PROGRAM)
    (tmp_path / "case.toml").write_text(TWO_FLUTES.replace('recording = "recording.csv"\n', ""))
    case = load_case(tmp_path)
    path = np.array([[-0.004, 0.01, -0.002], [0.012, 0.01, -0.002]])
    table = build_engagement_table(path, 6e-3, [0.0, 0.0, -0.006], [0.016, 0.02, 0.0], 2e-5)
    v, t_stop = 7.5e-3, 0.04
    x_stop = 0.006
    dt = 20e-6
    t_f = np.arange(0.0, 1.0, dt)
    t_dec = 1.0 - t_stop  # deceleration starts here and ends at 1.0 s, x = x_stop
    x0 = x_stop - v * t_dec - 0.5 * v * t_stop

    def x_of(t):
        a = v / t_stop
        return np.where(t < t_dec, x0 + v * t, x0 + v * t_dec + v * (t - t_dec) - 0.5 * a * (t - t_dec) ** 2)

    pos = np.column_stack([x_of(t_f), np.full_like(t_f, 0.01), np.full_like(t_f, -0.002)])
    packed = cutting_parameters_packed(case.machine, case.material, 6e-3, 2, None, 0.3)
    run = simulate_cutting(table, t_f, pos, np.full(t_f.size, OMEGA), packed)
    ts = np.arange(0.9, 1.0 + 1e-9, 1e-3)
    inputs = ForceInputs(ts, np.column_stack([x_of(ts), np.full_like(ts, 0.01), np.full_like(ts, -0.002)]),
                         np.full(ts.size, OMEGA), "spindle_rpm")
    theta = float(np.interp(ts[0], t_f, run.theta)) % (2 * math.pi)
    sim = run_force_replay(case, table, inputs, [{}], theta)
    fx, fy = np.interp(ts, t_f, run.fx), np.interp(ts, t_f, run.fy)
    # the truth's instantaneous force: Kt = 1.23e9 N/m2, 2 mm, fz = 37.5 um -> ~100 N at the chip's crest
    peak = float(np.hypot(fx, fy).max())
    assert peak > 80.0
    err = np.hypot(sim.fx[:, 0] - fx, sim.fy[:, 0] - fy)
    # in the deceleration (a = 0.19 m/s2) the step velocity times T is short of the chord by a T (T - h) / 2 =
    # 0.19 * 5 ms * 4 ms / 2 = 1.9 um of the 37.5 um chip at its start (5 %, growing as the feed falls; the
    # component took that until its chip became the tooth-period chord over its record of the steps,
    # kernel.chord_feed). T is five samples and 250 truth steps here, so both take the same chord of the quadratic
    # path exactly: what is left is rounding
    dec = (ts > t_dec + PERIOD) & (ts < 1.0 - 1e-9)
    assert np.abs(err[dec]).max() < 1e-6 * peak, err[dec]


@pytest.fixture(scope="module")
def clean_case(tmp_path_factory):
    folder = tmp_path_factory.mktemp("two_flutes") / "clean"
    return write_cutting_case(folder, {}, seed=3, dynamometer=Dynamometer(period_s=1e-3), program=SHORT_PROGRAM,
                              case_toml=TWO_FLUTES)


def test_clean_two_flute_recording_names_nothing(clean_case):
    d = diagnose(clean_case, drives=False)
    assert d.effects == [] and d.unexplained == [], (d.effects, d.unexplained, d.log)
    # what is left is the dynamometer's 1 N noise
    for c in ("fx_N", "fy_N"):
        assert d.rms_after[c] <= 1.1 * Dynamometer().force_noise_N, (c, d.rms_after)


def test_two_flute_runout_is_refitted(tmp_path):
    truth = {"runout": {"eccentricity_um": 10.0, "phase_deg": 0.0}}
    folder = write_cutting_case(tmp_path / "runout", truth, seed=3, dynamometer=Dynamometer(period_s=1e-3),
                                program=SHORT_PROGRAM, case_toml=TWO_FLUTES)
    d = diagnose(folder, drives=False)
    assert [e["effect"] for e in d.effects] == ["runout"], d.log
    # at phase 0 the whole eccentricity lies on the line of the two teeth (observable_runout: 10 um * cos 0)
    expected = observable_runout(truth["runout"], 2)["eccentricity_um"]
    assert expected == pytest.approx(10.0)
    assert d.effects[0]["parameters"]["eccentricity_um"] == pytest.approx(expected, rel=0.03)
    # The side pass ends in the material (Y8), and the rapid after it waits until the axes are in position, so
    # the tool creeps the last 0.1 mm with the feed decaying towards zero. With a 10 um runout of two flutes one
    # tooth cuts the surface it left itself one revolution (two tooth periods) earlier, and its chip is the
    # tool's displacement over that revolution: at 5.3922 s, 7.9243 - 7.8740 = 0.0503 mm, 16 % more than twice
    # the last tooth period's chord, 2 x (7.9243 - 7.9026) = 0.0434 mm, which the twin took before
    # (kernel.chords_back): nothing is left unexplained there now (the fy residual over those 50 ms was
    # 3.4 N rms, the recorded tooth peak 126.7 N against the twin's 110.4 N; now 1.3 N and 127.9 N)
    assert d.unexplained == [], d.unexplained
    for c in ("fx_N", "fy_N"):  # what is left is the dynamometer's 1 N noise (fy was 1.15 N with the chord rule)
        assert d.rms_after[c] <= 1.1 * Dynamometer().force_noise_N, (c, d.rms_after)


def test_observable_runout_of_two_teeth():
    # two teeth half a turn apart: rho cos(lambda) on their line, the sign as the phase (0 or 180 deg)
    assert observable_runout({"eccentricity_um": 3.0, "phase_deg": 40.0}, 2) == pytest.approx(
        {"eccentricity_um": 3.0 * math.cos(math.radians(40.0)), "phase_deg": 0.0})
    assert observable_runout({"eccentricity_um": 3.0, "phase_deg": 120.0}, 2) == pytest.approx(
        {"eccentricity_um": 1.5, "phase_deg": 180.0})
    assert observable_runout({"eccentricity_um": 3.0, "phase_deg": 120.0}, 3) == {"eccentricity_um": 3.0,
                                                                                "phase_deg": 120.0}
