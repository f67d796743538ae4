"""End to end: `simulate` (Python) and `cnctwin simulate` (CLI) on short programs."""
from __future__ import annotations

import json

import numpy as np
import pytest

from orchestrator import Recording
from orchestrator.cli import main
from orchestrator.recording import SPEC_COLUMNS
from orchestrator.simulate import simulate

AIR_PROGRAM = """%
O0001 (AIR CUT)
G21 G90 G17
G0 X0 Y0 Z5.
G1 X20. F300
M30
%
"""


@pytest.fixture(scope="module")
def air_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("air")
    program = folder / "air.nc"
    program.write_text(AIR_PROGRAM)
    return simulate(program, out=folder / "out"), folder


def test_air_cut_writes_spec_recording_summary_and_figure(air_run):
    result, folder = air_run
    assert result.success, result.message
    out = folder / "out"
    assert {p.name for p in out.iterdir()} == {"recording.csv", "summary.json", "overview.png"}
    rec = Recording.read_csv(out / "recording.csv")
    assert set(rec.channels) >= {"t_s", "line", "x_ref_mm", "x_mm", "x_tcmd_A", "spindle_ref_rpm", "spindle_rpm"}
    assert all(rec.units[c] == u for c, u in SPEC_COLUMNS.items() if c in rec.channels)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["cycle_time_s"] == pytest.approx(result.summary["cycle_time_s"])
    assert set(summary["rms_following_error_um"]) == {"x", "y", "z"}
    assert [row["line"] for row in summary["lines"]][:2] == [4, 5]


def test_ramp_following_error_is_v_over_position_gain(air_run):
    result, _ = air_run
    rec = result.recording
    v_mm_s = 300.0 / 60.0
    ramp = (rec["line"] == 5) & (np.abs(np.gradient(rec["x_ref_mm"], rec.t) - v_mm_s) < 1e-6)
    steady = ramp & (rec.t > rec.t[ramp][0] + 0.2)       # 10 time constants (1/Pp = 20 ms) after the ramp starts
    fe = rec.following_error_um("x")[steady]
    assert fe.size > 1000
    np.testing.assert_allclose(fe, v_mm_s / 50.0 * 1000.0, rtol=2e-3)   # v / (Pp Spp), Pp = 50 1/s, Spp = 1


def test_cycle_time_covers_the_planned_moves(air_run):
    result, _ = air_run
    # X20 at 300 mm/min takes at least 4 s; the rapid from Z50 to Z5 at 30 m/min at least 0.09 s
    assert 4.09 < result.summary["cycle_time_s"] < 4.09 + 0.5
    assert result.recording["x_mm"][-1] == pytest.approx(20.0, abs=0.02)   # in-position width 20 um


def test_cli_simulate_and_bad_gcode_message(tmp_path, capsys):
    program = tmp_path / "bad.nc"
    program.write_text("G21 G90\nG1 X10\nM30\n")
    code = main(["simulate", str(program), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2
    assert "bad.nc:2" in err and "Traceback" not in err
    assert not (tmp_path / "out" / "recording.csv").exists()


def test_cli_needs_program_or_case(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["simulate", "--out", str(tmp_path)])
    assert "needs a PROGRAM" in capsys.readouterr().err


def test_missing_program_names_the_file(tmp_path, capsys):
    code = main(["simulate", str(tmp_path / "nope.nc"), "--out", str(tmp_path / "o")])
    assert code == 2
    assert "nope.nc: program file not found" in capsys.readouterr().err


def test_cli_version_is_the_installed_distributions(capsys):
    """``cnctwin --version`` prints pyproject.toml's version (as installed) and exits 0."""
    import tomllib
    from pathlib import Path

    expected = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())["project"]["version"]
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0
    assert capsys.readouterr().out.strip() == f"cnctwin {expected}"
