"""Bad recordings give clear IdentificationErrors naming the file; the CLI commands run."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from orchestrator.atomic import atomic_write_text
from orchestrator.cli_identify import add_parsers
from orchestrator.errors import CncTwinError
from orchestrator.identify import (
    IdentificationError, identify_cutting, identify_friction, identify_servo, stribeck_curve,
)
from orchestrator.recording import Recording

KF = 2.0 * math.pi / 0.012
CASE = 'program = "program.nc"\nrecording = "recording.csv"\n[machine]\nparameters = "default"\n'


def reciprocating(speeds_mm_s=(0.2, 0.5, 1.0, 2.0, 5.0, 20.0, 60.0), plateau=0.5, dt=1e-3):
    """Hand-built recording: out-and-back runs with the exact Stribeck force of X positive (paper Table 1)."""
    t_all, x_all, f_all = [], [], []
    t0, x = 0.0, 0.0
    for v in speeds_mm_s:
        for sign in (1.0, -1.0):
            n = int(round((plateau + 0.2) / dt))
            tt = t0 + dt * np.arange(n)
            vel = np.full(n, sign * v)
            vel[: int(0.05 / dt)] = 0.0
            vel[-int(0.05 / dt):] = 0.0
            xs = x + np.cumsum(vel) * dt
            force = np.where(vel != 0.0, sign * stribeck_curve(abs(v) * 1e-3, 641.6, 775.2, 0.0016, 7702.0), 0.0)
            t_all.append(tt), x_all.append(xs), f_all.append(force)
            t0, x = tt[-1] + dt, xs[-1]
    t = np.concatenate(t_all)
    xs = np.concatenate(x_all)
    return {"t_s": t, "x_ref_mm": xs, "x_mm": xs, "x_tcmd_A": np.concatenate(f_all) / KF}


def make_case(folder, channels):
    atomic_write_text(folder / "case.toml", CASE)
    atomic_write_text(folder / "program.nc", "%\nG21\nM30\n%\n")
    Recording.from_channels(channels).write_csv(folder / "recording.csv")
    return folder


def test_hand_built_recording_is_fitted(tmp_path):
    fit = identify_friction([make_case(tmp_path, reciprocating())])
    p = fit.params_["x"]["positive"]
    assert p.coulomb == pytest.approx(641.6, rel=1e-3)
    assert p.static == pytest.approx(775.2, rel=1e-3)


def test_missing_current_column_names_the_file(tmp_path):
    ch = reciprocating()
    del ch["x_tcmd_A"]
    folder = make_case(tmp_path, ch)
    with pytest.raises(IdentificationError, match=r"recording\.csv.*'<axis>_tcmd_A'"):
        identify_friction([folder])
    with pytest.raises(IdentificationError, match=r"recording\.csv.*x_tcmd_A"):
        identify_friction([folder], axes=["x"])


def test_no_constant_velocity_segment(tmp_path):
    t = np.arange(0.0, 2.0, 1e-3)
    x = 5.0 * np.sin(2.0 * np.pi * 1.0 * t)  # never constant velocity
    folder = make_case(tmp_path, {"t_s": t, "x_ref_mm": x, "x_mm": x, "x_tcmd_A": np.cos(t)})
    with pytest.raises(IdentificationError, match="no axis moves at constant velocity"):
        identify_friction([folder])
    with pytest.raises(IdentificationError, match="no constant-velocity segment found for axis x"):
        identify_friction([folder], axes=["x"])


def test_one_direction_only(tmp_path):
    ch = reciprocating()
    keep = ch["x_tcmd_A"] >= 0.0
    t = ch["t_s"][keep]
    x = np.cumsum(np.where(np.diff(ch["x_mm"], prepend=0.0)[keep] > 0, np.diff(ch["x_mm"], prepend=0.0)[keep], 0.0))
    folder = make_case(tmp_path, {"t_s": np.arange(t.size) * 1e-3, "x_ref_mm": x, "x_mm": x,
                                  "x_tcmd_A": ch["x_tcmd_A"][keep]})
    with pytest.raises(IdentificationError, match="only in one direction"):
        identify_friction([folder])


def test_non_monotonic_time(tmp_path):
    make_case(tmp_path, reciprocating())
    lines = (tmp_path / "recording.csv").read_text().splitlines()
    lines[10], lines[11] = lines[11], lines[10]
    (tmp_path / "recording.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(IdentificationError, match=r"recording\.csv:12: t_s goes back"):
        identify_friction([tmp_path])


def test_an_empty_cell_in_a_needed_column_leaves_its_row_out_and_says_so(tmp_path):
    """recording.md: an empty cell is "not measured at this sample". The whole log was refused for one; now
    that row is left out (the rest is unevenly sampled, which the contract allows) and the report names it."""
    ch = reciprocating()
    ch["x_tcmd_A"][100] = np.nan  # an empty cell in the CSV
    folder = make_case(tmp_path, ch)
    fit = identify_friction([folder])
    assert fit.params_["x"]["positive"].coulomb == pytest.approx(641.6, rel=1e-3)
    assert fit.params_["x"]["positive"].static == pytest.approx(775.2, rel=1e-3)
    assert fit.notes_ == [f"{folder / 'recording.csv'}:102: 1 of 9800 row(s) without x_tcmd_A (empty: not measured) "
                          "left out of friction identification of axis x (first at line(s) [102])"]  # row 100
    ch["x_tcmd_A"][2:] = np.nan  # 2 rows with a current: nothing to fit
    with pytest.raises(IdentificationError, match=r"recording\.csv: friction identification of axis x needs "
                                                  r"\['t_s', 'x_mm', 'x_tcmd_A'\] measured together in at least 3 "
                                                  r"rows; 2 of the 9800 rows"):
        identify_friction([make_case(tmp_path, ch)])


def test_missing_recording_file(tmp_path):
    atomic_write_text(tmp_path / "case.toml", CASE)
    with pytest.raises(IdentificationError, match="recording file not found"):
        identify_friction([tmp_path])


def test_servo_and_cutting_say_what_they_need(tmp_path):
    ch = reciprocating()
    del ch["x_ref_mm"]
    folder = make_case(tmp_path, ch)
    # without commands, the twin's run of the case's program stands in for them; this program does not move
    with pytest.raises(IdentificationError, match=r"no commanded positions \('<axis>_ref_mm' missing for axis x\) "
                                                  r"and cannot be aligned with the twin's run"):
        identify_servo([folder])
    with pytest.raises(IdentificationError, match="fx_N"):
        identify_cutting([folder])
    assert issubclass(IdentificationError, CncTwinError)


def _parser():
    import argparse

    parser = argparse.ArgumentParser(prog="cnctwin")
    add_parsers(parser.add_subparsers(dest="command", required=True))
    return parser


def test_cli_identify_friction_writes_outputs(tmp_path, capsys):
    folder = make_case(tmp_path / "case", reciprocating())
    args = _parser().parse_args(["identify", "friction", str(folder), "--out", str(tmp_path / "out")])
    assert args.func(args) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["axes"]["x"]["positive"]["coulomb_N"] == pytest.approx(641.6, rel=1e-3)
    assert (tmp_path / "out" / "machine.toml").is_file() and (tmp_path / "out" / "stribeck_x.png").is_file()
    assert "wrote machine" in capsys.readouterr().out


def test_cli_experiment(tmp_path):
    args = _parser().parse_args(["experiment", "servo", "--out", str(tmp_path / "exp"), "--axes", "y"])
    assert args.func(args) == 0
    assert "G1 Y" in (tmp_path / "exp" / "program.nc").read_text()
