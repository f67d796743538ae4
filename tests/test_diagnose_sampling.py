"""Coarsely sampled forces and where a recording's errors are: the spindle angle decides, the file line names.

* A force logger whose spacing is a whole number of spindle revolutions (10 ms at 6000 rpm) sees every sample
  at the same spindle angle: runout (once per revolution) and the tooth-pulse shape (helix, edge force) alias
  to a constant, which Kt already is. Such effects are not offered, the report says why, and the amplitude at
  the spindle frequency is never the ill-conditioned least-squares number (1.2e13 N) it once was
  (`orchestrator.diagnose.cutting_sampling`).
* Recording errors name the file and its 1-based line, blank lines counted (`FileLines`).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from orchestrator.diagnose.cutting import CuttingData
from orchestrator.diagnose.cutting_align import Cuts
from orchestrator.diagnose.cutting_replay import ForceInputs
from orchestrator.diagnose.cutting_sampling import largest_gap, resolution, sinusoid_amplitude, unresolved_effects
from orchestrator.recording import Recording, RecordingError
from orchestrator.recording_csv import FileLines
from orchestrator.validation import validate_recording


def _data(spacing_s: float, rpm: float, flutes: int, duration_s: float = 2.0) -> CuttingData:
    """Force samples every ``spacing_s`` through one cut at constant ``rpm`` (only what the criterion reads)."""
    t = np.arange(0.0, duration_s, spacing_s)
    omega = np.full(t.size, rpm * 2 * math.pi / 60.0)
    inputs = ForceInputs(t, np.zeros((t.size, 3)), omega, "spindle_rpm")
    cuts = Cuts([(0, t.size)], np.zeros(1))
    return CuttingData(None, None, inputs, np.arange(t.size), np.zeros((t.size, 2)), 1e9, 0.3, flutes, cuts, 0.3,
                       0.5 * (omega[1:] + omega[:-1]), 0.5, np.zeros(0, int), np.zeros(0), float("nan"), None)


@pytest.mark.parametrize("spacing_ms, runout_gap, pitch_gap, unresolved", [
    (1.0, 36.0, 36.0, []),                   # 10 angles a revolution, 5 a pitch
    (2.0, 72.0, 36.0, []),                   # 0.2 rev a sample: 5 angles, folded onto the pitch 5 again
    (4.0, 72.0, 36.0, ["chatter"]),          # 0.4 rev: 5 angles; Nyquist 125 Hz < the 200 Hz tooth passing
    (5.0, 180.0, 180.0, ["runout", "helix_angle", "edge_force", "chatter"]),  # half a revolution: 2 angles
    (10.0, 360.0, 180.0, ["runout", "helix_angle", "edge_force", "chatter"]),  # one revolution: one angle
])
def test_the_spindle_angles_at_the_samples_decide_not_the_spacing_alone(spacing_ms, runout_gap, pitch_gap,
                                                                          unresolved):
    res = resolution(_data(spacing_ms * 1e-3, 6000.0, 2), np.arange(int(2.0 / (spacing_ms * 1e-3))))
    assert res["runout"].gap_deg == pytest.approx(runout_gap, abs=1e-6)
    assert res["helix_angle"].gap_deg == pytest.approx(pitch_gap, abs=1e-6)
    assert (res["runout"].limit_deg, res["helix_angle"].limit_deg) == (180.0, 45.0)
    assert unresolved_effects(res) == unresolved
    for e in unresolved:
        assert res[e].text.endswith("not offered (the sampling cannot resolve it)") or e == "chatter"
    assert "10 ms at 6000 rpm" in _text_at(10.0)


def _text_at(spacing_ms: float) -> str:
    return resolution(_data(spacing_ms * 1e-3, 6000.0, 2), np.arange(100))["runout"].text


def test_the_same_spacing_resolves_another_speed():
    # 10 ms at 5700 rpm: 0.95 rev a sample, the angles walk back 18 deg a sample round the revolution
    res = resolution(_data(10e-3, 5700.0, 2), np.arange(200))
    assert res["runout"].resolved and res["runout"].gap_deg == pytest.approx(18.0, abs=1e-6)
    assert res["helix_angle"].resolved and res["helix_angle"].gap_deg == pytest.approx(18.0, abs=1e-6)
    assert largest_gap(np.array([0.1]), 2 * math.pi) == 2 * math.pi


def test_the_amplitude_at_the_spindle_frequency_is_nan_when_the_angles_do_not_spread():
    rng = np.random.default_rng(1)
    same = np.full(400, 0.7) + 1e-13 * rng.standard_normal(400)   # every sample one revolution apart
    y = 40.0 + 1e-6 * rng.standard_normal(400)
    assert math.isnan(sinusoid_amplitude(same, y))                 # was 1e13 N from the ill-conditioned fit
    spread = np.arange(400) * 2 * math.pi * 0.1                     # 1 ms at 6000 rpm
    assert sinusoid_amplitude(spread, 40.0 + 3.0 * np.cos(spread - 0.4)) == pytest.approx(3.0, rel=1e-12)


# ----------------------------------------------------------------------------- file lines in errors
def test_range_errors_name_the_file_line_with_blank_lines_counted(tmp_path):
    path = tmp_path / "log.csv"
    # header, 2 rows, 2 blank lines, a row, a blank line, the bad row (file line 8, data row 4)
    path.write_text("t_s,x_mm\n0,1\n0.001,1\n\n\n0.002,1\n\n0.003,1e9\n")
    rec = Recording.read_csv(path)
    assert rec.file_lines.of(np.arange(4)).tolist() == [2, 3, 6, 8]
    with pytest.raises(RecordingError) as info:
        validate_recording(rec)
    assert str(info.value).startswith(f"{path}:8: column 'x_mm' (t_s = 0.003): 1000000000.0 is outside the "
                                      "plausible range [-10000, 10000] mm")
    # a subset keeps its rows' lines; a recording built in memory names its row
    assert rec.take(np.array([False, True, False, True])).file_lines.of(np.arange(2)).tolist() == [3, 8]
    mem = Recording.from_channels({"t_s": [0.0, 1.0], "x_mm": [0.0, -2e4]})
    with pytest.raises(RecordingError, match=r"^<memory>: column 'x_mm', row 2 \(t_s = 1\): -20000.0 is outside"):
        validate_recording(mem)


def test_a_quoted_cell_spanning_lines_keeps_the_next_rows_lines(tmp_path):
    path = tmp_path / "log.csv"
    path.write_text('t_s,x_mm,note\n0,1,"two\nlines"\n0.001,1,ok\n0.002,-20000,ok\n')
    rec = Recording.read_csv(path)
    assert rec.file_lines.of(np.arange(3)).tolist() == [2, 4, 5]
    with pytest.raises(RecordingError, match=r"log.csv:5: column 'x_mm' \(t_s = 0.002\)"):
        validate_recording(rec)


def test_file_lines_are_runs_not_one_number_a_row():
    lines = FileLines.from_numbers("a.csv", np.arange(2, 600_002))  # a 10-minute 1 kHz log without blank lines
    assert lines.starts.size == 1 and lines.rows == 600_000 and lines.line(599_999) == 600_001
    gappy = FileLines.from_numbers("a.csv", np.array([2, 3, 5, 6, 7, 10]))
    assert gappy.starts.tolist() == [0, 2, 5] and gappy.of(np.arange(6)).tolist() == [2, 3, 5, 6, 7, 10]
    with pytest.raises(IndexError, match="row 6 is not one of its 6 rows"):
        gappy.line(6)
