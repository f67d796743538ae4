"""Identification checkpoints and ``--resume``: a killed job continues with the uninterrupted result.

The journal (:mod:`orchestrator.identify.journal`) writes one checkpoint
file per new expensive evaluation. Two invariants follow and are tested:

* killed at any point and resumed, a job gives exactly the result of an
  uninterrupted run (same seed), and the files of both runs together are the
  uninterrupted run's count (every evaluation journaled once);
* resuming a *finished* job evaluates nothing new (no new checkpoint file):
  the journal covers every expensive evaluation of the identifier.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from orchestrator.atomic import atomic_write_text
from orchestrator.experiments import write_experiment
from orchestrator.identify import IdentificationError, Imperfections, identify
from orchestrator.identify import friction as friction_module
from orchestrator.identify.synthetic import degrade, synthetic_case
from orchestrator.machine import machine_to_toml
from tests.test_identify_friction import SPEEDS, true_machine
from tests.test_identify_servo import TRUE_SCALES, known_machine

ROOT = Path(__file__).resolve().parents[1]


def checkpoints(out: Path) -> list[str]:
    return sorted(p.name for p in (out / "checkpoints").glob("identify_*.pkl"))


def same_report(a, b) -> None:
    ra, rb = a.report(), b.report()
    ra.pop("wall_time_s")
    rb.pop("wall_time_s")
    if ra.get("kind") == "friction":
        for dirs in list(ra["axes"].values()) + list(rb["axes"].values()):
            for fit in dirs.values():
                fit.pop("wall_time_s")
    assert ra == rb


@pytest.fixture(scope="module")
def servo_case(tmp_path_factory):
    root = tmp_path_factory.mktemp("servo_resume")
    folder = root / "case"
    write_experiment("servo", folder, axes=("x",), speeds_mm_min=(200.0, 500.0), plateau_s=0.3, dwell_s=0.1)
    clean, _ = synthetic_case(folder, known_machine().with_values("axis.x", **TRUE_SCALES),
                              Imperfections(0, 0, 0, 0, 0, 0))
    degrade(clean, Imperfections(), seed=21).write_csv(folder / "recording.csv")
    machine = atomic_write_text(root / "known.toml", machine_to_toml(known_machine()))
    return folder, machine


@pytest.fixture(scope="module")
def servo_straight(servo_case, tmp_path_factory):
    folder, machine = servo_case
    out = tmp_path_factory.mktemp("servo_straight")
    return identify("servo", [folder], out=out, machine=str(machine)), out


def test_servo_job_killed_after_its_first_checkpoint_resumes_to_the_same_result(servo_case, servo_straight, tmp_path):
    folder, machine = servo_case
    straight, straight_out = servo_straight
    cmd = [sys.executable, "-m", "orchestrator.cli", "identify", "servo", str(folder), "--machine", str(machine),
           "--out", str(tmp_path)]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)),
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    first = tmp_path / "checkpoints" / "identify_00001.pkl"
    deadline = time.monotonic() + 300.0
    while not first.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    assert first.exists(), proc.stderr.read().decode() if proc.stderr else ""
    assert not (tmp_path / "report.json").exists()  # killed mid-job
    done = len(checkpoints(tmp_path))
    assert 0 < done < len(checkpoints(straight_out))
    resumed = identify("servo", [folder], out=tmp_path, machine=str(machine), resume=True)
    same_report(resumed, straight)
    assert resumed.scales_ == straight.scales_ and resumed.fitness_ == straight.fitness_
    assert len(checkpoints(tmp_path)) == len(checkpoints(straight_out))  # each evaluation journaled once
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["axes"]["x"]["Spp"] == straight.scales_["x"]["Spp"]


def test_servo_ga_interrupted_after_three_generations_resumes_to_the_same_result(servo_case, servo_straight, tmp_path,
                                                                                  monkeypatch):
    """The paper's GA checkpoints every generation (its fitness arrays), after the least-squares fit that screens
    glitches (the default's stages); resumed, pymoo (same seed) asks for the same populations, the journal
    answers the first three, the rest are simulated."""
    from orchestrator.identify.journal import Journal

    folder, machine = servo_case
    least_squares = len(checkpoints(servo_straight[1]))  # the default's stages (no glitch in this log)
    straight = identify("servo", [folder], out=tmp_path / "straight", machine=str(machine), method="paper-ga")
    n_straight = len(checkpoints(tmp_path / "straight"))
    assert n_straight - least_squares == straight.iterations_ >= 4  # then one checkpoint per generation
    original = Journal.flush

    def stop_after_three(self):
        original(self)
        if self._files == least_squares + 3:  # noqa: SLF001
            raise KeyboardInterrupt

    monkeypatch.setattr(Journal, "flush", stop_after_three)
    with pytest.raises(KeyboardInterrupt):
        identify("servo", [folder], out=tmp_path / "killed", machine=str(machine), method="paper-ga")
    monkeypatch.undo()
    assert len(checkpoints(tmp_path / "killed")) == least_squares + 3
    resumed = identify("servo", [folder], out=tmp_path / "killed", machine=str(machine), method="paper-ga",
                       resume=True)
    same_report(resumed, straight)
    assert len(checkpoints(tmp_path / "killed")) == n_straight


def test_resuming_a_finished_servo_job_evaluates_nothing(servo_case, servo_straight):
    folder, machine = servo_case
    straight, out = servo_straight
    before = checkpoints(out)
    again = identify("servo", [folder], out=out, machine=str(machine), resume=True)
    assert checkpoints(out) == before
    same_report(again, straight)


def test_a_checkpoint_of_another_job_is_refused(servo_case, servo_straight):
    folder, machine = servo_case
    _, out = servo_straight
    with pytest.raises(IdentificationError, match=r"the checkpoint belongs to another job \(its seed differ"):
        identify("servo", [folder], out=out, machine=str(machine), seed=5, resume=True)
    with pytest.raises(IdentificationError, match=r"belongs to another job \(its method differ"):
        identify("servo", [folder], out=out, machine=str(machine), method="paper-ga", resume=True)


def test_a_checkpoint_of_other_data_is_refused(tmp_path):
    folder = tmp_path / "case"
    write_experiment("friction", folder, axes=("x",), speeds_mm_min=SPEEDS, plateau_s=0.3, dwell_s=0.1)
    clean, _ = synthetic_case(folder, true_machine(), Imperfections(0, 0, 0, 0, 0, 0))
    degrade(clean, Imperfections(), seed=1).write_csv(folder / "recording.csv")
    identify("friction", [folder], out=tmp_path / "out")
    degrade(clean, Imperfections(), seed=2).write_csv(folder / "recording.csv")  # another measurement
    with pytest.raises(IdentificationError, match=r"identify_00001.pkl: the checkpoint belongs to another job "
                                                  r"\(its input files differ"):
        identify("friction", [folder], out=tmp_path / "out", resume=True)
    # without --resume a new job starts and replaces the old journal
    identify("friction", [folder], out=tmp_path / "out")
    identify("friction", [folder], out=tmp_path / "out", resume=True)


def test_friction_paper_ga_interrupted_between_stages_resumes_to_the_same_result(tmp_path, monkeypatch):
    folder = tmp_path / "case"
    write_experiment("friction", folder, axes=("x",), speeds_mm_min=SPEEDS, plateau_s=0.3, dwell_s=0.1)
    clean, _ = synthetic_case(folder, true_machine(), Imperfections(0, 0, 0, 0, 0, 0))
    degrade(clean, Imperfections(), seed=3).write_csv(folder / "recording.csv")
    straight = identify("friction", [folder], out=tmp_path / "straight", method="paper-ga", seed=4)
    calls = {"n": 0}
    original = friction_module.fit_stribeck

    def dies_on_the_second_fit(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt  # the job is stopped while fitting the negative direction
        return original(*args, **kwargs)

    monkeypatch.setattr(friction_module, "fit_stribeck", dies_on_the_second_fit)
    with pytest.raises(KeyboardInterrupt):
        identify("friction", [folder], out=tmp_path / "killed", method="paper-ga", seed=4)
    monkeypatch.undo()
    assert checkpoints(tmp_path / "killed") == ["identify_00001.pkl"]
    resumed = identify("friction", [folder], out=tmp_path / "killed", method="paper-ga", seed=4, resume=True)
    same_report(resumed, straight)
    assert resumed.params_["x"]["negative"].coulomb == straight.params_["x"]["negative"].coulomb


def test_resume_needs_the_output_folder(servo_case):
    folder, _ = servo_case
    with pytest.raises(IdentificationError, match=r"resume needs the output folder"):
        identify("friction", [folder], resume=True)


def test_cli_resume_flag(servo_case, servo_straight, capsys):
    from orchestrator.cli import main

    folder, machine = servo_case
    straight, out = servo_straight
    assert main(["identify", "servo", str(folder), "--machine", str(machine), "--out", str(out), "--resume"]) == 0
    printed = capsys.readouterr().out
    assert json.loads(printed[: printed.index("\nwrote ")])["axes"]["x"]["Spp"] == straight.scales_["x"]["Spp"]
    assert np.isfinite(straight.scales_["x"]["Svi"])


def test_resuming_a_finished_cutting_job_evaluates_nothing(tmp_path_factory):
    """The phase scans (batched unit runs of the cutting component) are all journaled."""
    from tests.test_identify_cutting import CASE, PROGRAM

    folder = tmp_path_factory.mktemp("cut_resume") / "case"
    atomic_write_text(folder / "program.nc", PROGRAM)
    atomic_write_text(folder / "case.toml", CASE)
    from orchestrator.machine import load_machine

    truth = load_machine("default").with_values("material.A6061", kt_N_per_m2=0.95e9, ke=0.38)
    clean, _ = synthetic_case(folder, truth, Imperfections(0, 0, 0, 0, 0, 0))
    degrade(clean, Imperfections(), seed=7).write_csv(folder / "recording.csv")
    out = folder.parent / "out"
    straight = identify("cutting", [folder], out=out)
    files = checkpoints(out)
    assert 3 <= len(files) <= 5  # coarse scan, fine scan, 1 to 3 runs at the refined phase
    again = identify("cutting", [folder], out=out, resume=True)
    assert checkpoints(out) == files
    same_report(again, straight)
    assert again.kt_ == straight.kt_ and again.ke_ == straight.ke_
