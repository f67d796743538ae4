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


# --- servo logs without commanded positions (Servo Guide style: actual position and TCMD only) -------------------

LOG_TRUTH = {"position_scale": 1.2, "velocity_p_scale": 0.8, "velocity_i_scale": 1.0}
LOG_OFFSET_S = 2.5
CURRENT_NOISE_A = 0.02
ENCODER_UM = 1.0


def _without(recording, drop):
    from orchestrator.recording import Recording

    keep = [n for n in recording.channels if n not in drop]
    return Recording.from_channels({n: np.asarray(recording[n]) for n in keep},
                                   {n: recording.units[n] for n in keep}, True, "", f"{recording.source} (log)")


@pytest.fixture(scope="module")
def servo_log(tmp_path_factory):
    """A 2 s air-cut servo run of a machine with Spp 1.2, Svp 0.8, logged with and without commands.

    Logger: clock shifted by 2.5 s, 1 µm encoder, seeded 0.02 A current noise.
    """
    folder = tmp_path_factory.mktemp("servo_log") / "case"
    write_experiment("servo", folder, axes=("x",), speeds_mm_min=(200.0, 500.0), plateau_s=0.3, dwell_s=0.1)
    truth = known_machine().with_values("axis.x", **LOG_TRUTH)
    clean, _ = synthetic_case(folder, truth, Imperfections(0, 0, 0, 0, 0, 0))
    logged = degrade(clean, Imperfections(0.0, ENCODER_UM, CURRENT_NOISE_A, 0.0, 0.0, LOG_OFFSET_S), seed=5)
    logged.write_csv(folder / "recording.csv")
    with_commands = identify_servo([folder], machine=known_machine())
    servo_guide = _without(logged, [n for n in logged.channels if n.endswith("_ref_mm") or n == "line"])
    servo_guide.write_csv(folder / "recording.csv")
    return folder, with_commands


def test_servo_log_without_commands_gives_the_known_scale_factors(servo_log, tmp_path):
    """The twin's commands, aligned with the log, replace the missing ones: same factors as with the commands."""
    folder, with_commands = servo_log
    fit = identify_servo([folder], machine=known_machine())
    for key, value in LOG_TRUTH.items():
        sym = SYMBOL[key]
        # the log's noise limits both fits alike (with commands: within 0.9 % here); the twin's commands add
        # little of their own: within 0.5 % of the fit with commands (0.15 % measured)
        assert fit.scales_["x"][sym] == pytest.approx(value, rel=0.02), fit.scales_
        assert fit.scales_["x"][sym] == pytest.approx(with_commands.scales_["x"][sym], rel=0.005), fit.scales_
    # residuals at the logger's noise: the encoder's quantisation 1 µm / sqrt(12) = 0.29 µm, the current's 0.02 A
    assert fit.rms_["x"]["following_error_um"] < 1.2 * ENCODER_UM / np.sqrt(12.0)
    assert fit.rms_["x"]["current_A"] < 1.2 * CURRENT_NOISE_A
    report = json.loads(fit.write(tmp_path / "out", plots=False)["report"].read_text())
    assert with_commands.report()["commands"] == {"case": "recorded"}
    text = report["commands"]["case"]
    assert text.startswith("twin, aligned: offset "), text
    offset = float(text.split("offset ")[1].split(" s")[0])
    # the clock offset comes back to within 0.05 ms (alignment on positions, then the joint fit with the factors)
    assert offset == pytest.approx(LOG_OFFSET_S, abs=5e-5), text


def test_replay_accepts_the_reference_as_a_function_of_tick_time(servo_case):
    """A callable giving the same linear interpolation as the sampled reference gives the same replay."""
    _, clean, truth = servo_case
    t, ref = np.asarray(clean.t), np.asarray(clean["x_ref_mm"]) * 1e-3
    x0 = {"x": clean["x_mm"][0] * 1e-3}
    sampled = replay(truth, t, {"x": ref}, initial_position=x0)
    called = replay(truth, t, {"x": lambda q: np.interp(q, t, ref)}, initial_position=x0)
    assert np.max(np.abs(called.position["x"] - sampled.position["x"])) < 1e-12  # m
    assert np.max(np.abs(called.current["x"] - sampled.current["x"])) < 1e-9  # A


def test_replay_disturbance_is_carried_by_the_current(servo_case):
    """A constant load F at constant velocity is taken up by the integrator: the current rises by F / (kt 2 pi / Lb)."""
    _, _, truth = servo_case
    t = np.linspace(0.0, 1.0, 1001)
    ref = {"x": 0.005 * t}  # 300 mm/min
    load = 300.0  # N
    free = replay(truth, t, ref)
    loaded = replay(truth, t, ref, disturbance={"x": lambda q: np.full(np.shape(q), load)})
    sec = truth.si("axis.x")
    per_amp = float(sec["torque_constant"]) * 2.0 * np.pi / float(sec["screw_lead"])
    rise = abs(float(np.mean(loaded.current["x"][-100:, 0] - free.current["x"][-100:, 0])))
    assert rise == pytest.approx(load / per_amp, rel=0.01)


def test_servo_log_that_cannot_be_aligned_is_refused_naming_the_file(servo_log, tmp_path):
    """A program whose axes never move gives the twin nothing to align the log with."""
    from orchestrator.identify import IdentificationError
    from orchestrator.recording import Recording

    folder = tmp_path / "still"
    folder.mkdir()
    (folder / "case.toml").write_text((servo_log[0] / "case.toml").read_text())
    (folder / "program.nc").write_text("G21 G90 G94 G17\nG4 P1000\nM30\n")
    t = 3.0 + 0.001 * np.arange(900)
    Recording.from_channels({"t_s": t, "x_mm": np.zeros_like(t), "x_tcmd_A": np.zeros_like(t)},
                            None, True, "", "still").write_csv(folder / "recording.csv")
    with pytest.raises(IdentificationError, match=r"recording\.csv.*cannot be aligned"):
        identify_servo([folder], machine=known_machine())


def test_a_log_taken_while_cutting_replays_the_twins_drive_load(tmp_path):
    """A log of the short part's slots (commands, positions, currents; no dynamometer) of a machine with Spp 1.2,
    Svp 0.8, Svi 1.1 on X: the case's [stock] makes the replay carry the cutting load the twin's drives carry.

    Replayed in the air, the slot's load (about 1 A on X) was fitted by the factors (Svp 0.839, Svi 1.147:
    +5 % / +4 %), and carried as the 1 ms samples of the instantaneous force, interpolated, it still moved Svp by
    3 % (a 2-flute tool at 6000 rpm repeats its tooth load every 5 ms).
    """
    from dataclasses import replace

    from orchestrator.case import load_case
    from orchestrator.recording import Recording
    from orchestrator.simulate import simulate
    from tests.test_diagnose_logger import PAPER_PART, PROGRAM

    folder = tmp_path / "cutting_log"
    folder.mkdir()
    (folder / "program.nc").write_text(PROGRAM)
    (folder / "case.toml").write_text('recording = "recording.csv"\n' + (PAPER_PART / "case.toml").read_text())
    case = load_case(folder)
    truth = case.machine.with_values("axis.x", position_scale=1.2, velocity_p_scale=0.8, velocity_i_scale=1.1)
    run = simulate(case=replace(case, machine=truth), plot=False).recording
    rng = np.random.default_rng(3)
    channels = {"t_s": np.asarray(run.t, float), "line": np.asarray(run["line"], float),
                "x_ref_mm": np.asarray(run["x_ref_mm"], float),
                "x_mm": np.round(np.asarray(run["x_mm"], float) * 1e3) / 1e3,                 # 1 µm encoder
                "x_tcmd_A": np.asarray(run["x_tcmd_A"], float) + rng.normal(0.0, CURRENT_NOISE_A, len(run))}
    Recording.from_channels(channels).write_csv(folder / "recording.csv")
    fit = identify_servo([folder])
    assert fit.commands_ == {"cutting_log": "recorded; cutting forces on the drives: predicted"}
    # the load is the twin's prediction with the machine file's factors (Spp 1): the truth's slower loop moves
    # its path and so its load a little (measured: Spp +0.06 %, Svp -0.7 %, Svi +1.2 %)
    assert fit.scales_["x"] == pytest.approx({"Spp": 1.2, "Svp": 0.8, "Svi": 1.1}, rel=0.02)
    assert fit.rms_["x"]["current_A"] < 1.2 * CURRENT_NOISE_A


def test_a_stock_the_program_never_cuts_needs_no_alignment(servo_case, tmp_path, monkeypatch):
    """An air run (the servo experiment) in a case with a [stock] far from its path: the drives carried no load,
    so a log the diagnosis's alignment cannot place is identified as before, not refused."""
    import shutil

    import orchestrator.diagnose.prepare as prepare_module
    from orchestrator.diagnose.errors import DiagnosisError

    folder, clean, _ = servo_case
    air = tmp_path / "air"
    shutil.copytree(folder, air)
    degrade(clean, Imperfections(), seed=21).write_csv(air / "recording.csv")
    (air / "case.toml").write_text((air / "case.toml").read_text()
                                   + "\n[stock]\nmin = [0.0, 0.0, -600.0]\nmax = [10.0, 10.0, -590.0]\n")

    def cannot_align(*args, **kwargs):
        raise DiagnosisError("cannot align")

    monkeypatch.setattr(prepare_module, "prepare", cannot_align)
    fit = identify_servo([air], machine=known_machine())
    assert fit.commands_ == {"air": "recorded"}
    for key, value in TRUE_SCALES.items():
        assert fit.scales_["x"][SYMBOL[key]] == pytest.approx(value, rel=0.05), fit.scales_
