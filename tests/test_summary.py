"""Run summary: per-line times and loads, following-error statistics (synthetic recordings)."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator import Recording
from orchestrator.cost import CostModel
from orchestrator.summary import summarize


def ramp_recording():
    # 3 s at 1 kHz; lines 10 (1 s), 20 (1.5 s), 30 (0.5 s); x follows a ramp with a constant lag
    t = np.arange(3001) * 1e-3
    line = np.where(t < 1.0, 10, np.where(t < 2.5, 20, 30)).astype(float)
    v = 5.0  # mm/s
    x_ref = v * t
    lag_mm = 0.1
    load = np.where(line == 20, 40.0 + 10.0 * np.sin(2 * np.pi * 50 * t), 0.0)
    return Recording.from_channels({
        "t_s": t, "line": line,
        "x_ref_mm": x_ref, "x_mm": x_ref - lag_mm,
        "y_ref_mm": np.zeros_like(t), "y_mm": np.zeros_like(t),
        "z_ref_mm": np.zeros_like(t), "z_mm": np.full_like(t, 0.002),
        "spindle_rpm": np.full_like(t, 6000.0),
        "fc_N": load,
    })


def test_line_times_add_up_to_the_cycle_and_match_the_schedule():
    s = summarize(ramp_recording(), cycle_time_s=3.0)
    times = {row["line"]: row["time_s"] for row in s["lines"]}
    assert [row["line"] for row in s["lines"]] == [10, 20, 30]
    assert times[10] == pytest.approx(1.0, abs=1e-9)
    assert times[20] == pytest.approx(1.5, abs=1e-9)
    assert times[30] == pytest.approx(0.5, abs=1.1e-3)   # the last sample carries no time
    assert sum(times.values()) == pytest.approx(3.0, abs=1.1e-3)


def test_following_error_statistics():
    s = summarize(ramp_recording(), cycle_time_s=3.0)
    assert s["rms_following_error_um"]["x"] == pytest.approx(100.0, rel=1e-9)
    assert s["max_following_error_um"]["x"] == pytest.approx(100.0, rel=1e-9)
    assert s["rms_following_error_um"]["y"] == 0.0
    assert s["rms_following_error_um"]["z"] == pytest.approx(-(-2.0), rel=1e-9)


def test_loads_per_line_and_cost():
    s = summarize(ramp_recording(), cycle_time_s=3.0, cost_model=CostModel(), tool_diameter_mm=6.0)
    rows = {row["line"]: row for row in s["lines"]}
    assert s["max_cutting_load_N"] == pytest.approx(50.0, abs=0.05)
    assert rows[20]["max_load_N"] == pytest.approx(50.0, abs=0.05)
    assert rows[20]["mean_load_N"] == pytest.approx(40.0, abs=0.05)   # 75 full sine periods average out
    assert rows[10]["max_load_N"] == 0.0
    assert s["cost_KRW"] == pytest.approx(3.0 * 2.841 + s["cost"]["tool_KRW"])


def test_tool_changes_are_listed_and_a_second_tool_on_a_cutting_case_is_noted(tmp_path):
    from orchestrator.simulate import simulate
    from orchestrator.summary import tool_notes

    table, notes = tool_notes([(2, 1), (9, 2), (15, 1)], True, 6.0, 2)
    assert table == [{"line": 2, "tool": 1}, {"line": 9, "tool": 2}, {"line": 15, "tool": 1}]
    assert len(notes) == 1 and "T1, T2" in notes[0] and "line 9" in notes[0] and "6 mm, 2 flutes" in notes[0]
    assert tool_notes([(2, 1), (9, 1)], True, 6.0, 2)[1] == []          # one tool: nothing to say
    assert tool_notes([(2, 1), (9, 2)], False, 6.0, 2)[1] == []         # no stock: no cutting load at all
    # a program that drills with T2 after milling with T1, on a case with a stock
    (tmp_path / "case.toml").write_text('program = "p.nc"\n[stock]\nmin = [0.0, 0.0, -10.0]\nmax = [30.0, 20.0, 0.0]\n'
                                        '[tool]\ndiameter_mm = 6.0\nflutes = 2\n[machine]\nparameters = "default"\n')
    (tmp_path / "p.nc").write_text("G21 G90\nT1 M6\nS6000 M3\nG0 X-5. Y6. Z1.\nG1 Z-0.5 F200\nX35. F300\nG0 Z5.\n"
                                   "T2 M6\nS3000 M3\nG0 X10. Y10.\nG81 Z-3. R2. F100\nG80\nM30\n")
    summary = simulate(case=tmp_path, plot=False).summary
    assert summary["tool_changes"] == [{"line": 2, "tool": 1}, {"line": 8, "tool": 2}]
    assert "line 8" in summary["notes"][0]
