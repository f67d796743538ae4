"""The optimiser on case folders unlike the bundled parts (``tests/fixtures/unseen_parts``).

Each folder follows ``shared/spec/recording.md`` (case.toml + program.nc; stock, tool, machine "default"): a
pocket with G2/G3 by I/J and by R, cutter compensation G41/G42 with D, a subprogram called at three depths, a
macro WHILE loop of facing passes, an end mill and a drill (T1/T2 M6) with G81/G83 between two slots, an inch
program, a feed-per-revolution program, an air cut and a program whose every feed line cuts. Every written
program changes only F and S words, re-simulates to the reported ``after`` figures and stays within the load
limit; the report's per-line feeds of a G95 line are the feeds in effect (F x S). Small budgets: a few
simulations per case.
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from fmus_src.cutting.table import EngagementTable
from fmus_src.nck.blocks import Arc, Linear
from fmus_src.nck.interpreter import interpret
from orchestrator.case import load_case
from orchestrator.optimize import OptimizeError, OptimizeSettings, optimize, reference
from orchestrator.simulate import simulate
from orchestrator.twin import cutting_parameters, reference_path

PARTS = Path(__file__).resolve().parent / "fixtures" / "unseen_parts"
MM_PER_MIN_PER_M_S = 60000.0
_TOKEN = re.compile(r"\([^)]*\)|[A-Za-z]\s*(?:\[[^\]]*\]|#?[-+]?[0-9.]*)|\S")


def _without_f_and_s(text: str) -> list[list[str]]:
    """Each line's tokens other than F and S words (comments, words, macro text)."""
    return [[t for t in _TOKEN.findall(line) if t[0].upper() not in "FS"] for line in text.splitlines()]


def _run(name: str, tmp_path: Path, objective: str = "time", **kw):
    settings = OptimizeSettings(objective=objective, pop=3, gens=1, seed=1, progress=False, plot=False, **kw)
    out = tmp_path / name
    return optimize(case=PARTS / name, settings=settings, out=out), out


def _check_outputs(name: str, result, out: Path) -> dict:
    """The written program changes only F/S words, re-simulates to ``after``, stays within the limit."""
    original = (PARTS / name / "program.nc").read_text()
    written = (out / "optimized.nc").read_text()
    assert written == result.program_text
    assert _without_f_and_s(written) == _without_f_and_s(original)
    report = json.loads((out / "report.json").read_text())
    for side in ("before", "after"):
        assert {"cycle_time_s", "cost_KRW", "max_cutting_load_N", "tool_life_used"} <= set(report[side])
    for row in report["lines"]:
        assert {"line", "feed_before_mm_per_min", "feed_after_mm_per_min", "spindle_before_rpm",
                "spindle_after_rpm", "time_before_s", "time_after_s", "max_load_before_N",
                "max_load_after_N"} <= set(row)
    again = simulate(program=out / "optimized.nc", case=load_case(PARTS / name), plot=False)
    assert again.success
    assert again.summary["cycle_time_s"] == pytest.approx(report["after"]["cycle_time_s"], abs=1e-9)
    assert again.summary["max_cutting_load_N"] == pytest.approx(report["after"]["max_cutting_load_N"], rel=1e-9)
    assert report["after"]["max_cutting_load_N"] <= 60.0
    return report


@pytest.mark.parametrize("name", ["pocket_arcs", "cutter_comp"])
def test_milling_programs_change_only_f_and_s_and_resimulate_to_after(name, tmp_path):
    result, out = _run(name, tmp_path)
    report = _check_outputs(name, result, out)
    assert report["search_cutting_model"] == "path" and report["notes"] == []


def test_two_tools_and_peck_drilling(tmp_path):
    """T1 end mill, T2 drill (G81, G83), T1 again. The drill's plunges remove their holes with the end edges
    (the axial chip: pi R^2 depth, the case's 6 mm tool, a little less than the 3 and 4 mm programmed where
    the servo lag turns the tool back early) but give no lateral load, so they are not cutting lines and keep
    their F; the two slots are the cutting lines. The pecks of G83 reverse on one line faster than the servo
    follows (it turns back 0.14-0.50 mm short of R): the path-mode engagement re-finds the tool across the
    reversal, so the search runs in path mode, and its reference run of the original agrees with the Z-map
    model (within 0.1 N) and with the hand calculation of slot 2. The report says that both tools' loads are
    computed with the case's one [tool]."""
    result, out = _run("drill_two_tools", tmp_path)
    report = _check_outputs("drill_two_tools", result, out)
    assert [row["line"] for row in report["lines"]] == [9, 23]  # the two slots
    removed = report["removed_mm3_by_line"]
    assert removed["14"] == 0.0  # the rapid to the first hole
    for line, depth_mm in (("15", 3.0), ("16", 4.0)):  # G81 to Z-3, G83 to Z-4 (each layer of the pecks once)
        assert 0.97 * math.pi * 9.0 * depth_mm < removed[line] <= math.pi * 9.0 * depth_mm * (1 + 1e-9)
    assert report["search_cutting_model"] == "path"
    assert report["tool_changes"] == [{"line": 5, "tool": 1}, {"line": 12, "tool": 2}, {"line": 19, "tool": 1}]
    assert len(report["notes"]) == 1 and "T1, T2" in report["notes"][0] and "6 mm, 2 flutes" in report["notes"][0]
    zmap = simulate(case=load_case(PARTS / "drill_two_tools"), plot=False)
    assert report["before"]["max_cutting_load_N"] == pytest.approx(zmap.summary["max_cutting_load_N"], abs=0.1)
    # slot 2: full slot 1.2 mm deep, F350, S6000, 2 flutes: Kt a fz sqrt(1 + Ke^2) = 48.13 N (A6061: 1.23e9, 0.5)
    assert report["before"]["max_cutting_load_N"] == pytest.approx(
        1.23e9 * 1.2e-3 * 350.0 / (6000 * 2) * 1e-3 * math.sqrt(1.25), abs=0.05)
    # the slots remove 6 mm x 40 mm x (1.0 + 1.2) mm (their servo-lag tails counted on the lines after them),
    # the holes what their lines removed (checked above)
    assert sum(removed.values()) == pytest.approx(6.0 * 40.0 * 2.2 + removed["15"] + removed["16"], rel=1e-3)


def test_the_search_falls_back_to_the_zmap_model_when_the_path_mode_loses_the_tool(tmp_path, monkeypatch):
    """A table whose path runs 1 mm beside the program's: the path mode loses the tool on the original program,
    so the search runs on the Z-map model, and the report's notes say why, naming the line."""
    def beside(case, options=None, program_text=None):
        path = reference_path(case, options, program_text) + np.array([0.0, 1e-3, 0.0])
        return EngagementTable.from_parameters(path, cutting_parameters(case))

    monkeypatch.setattr(reference, "engagement_table", beside)
    result, out = _run("all_cut", tmp_path)
    report = _check_outputs("all_cut", result, out)
    assert report["search_cutting_model"] == "zmap"
    assert len(report["notes"]) == 1
    assert re.search(r"path-mode cutting load loses the tool on the original program \(.*all_cut/program\.nc:\d+: "
                     r".*farther than path_tolerance.*\): the search ran on the Z-map cutting model",
                     report["notes"][0])


def test_g95_report_gives_the_feed_in_effect(tmp_path):
    """On a G95 line ``feed_after_mm_per_min`` is the written word (mm/rev) times S, the feed the NC kernel runs
    (checked against the interpreted optimized.nc), and the gene is kept as ``feed_gene_mm_per_min``."""
    result, out = _run("feed_per_rev", tmp_path)
    report = _check_outputs("feed_per_rev", result, out)
    blocks = interpret((out / "optimized.nc").read_text(), "optimized.nc").blocks
    assert report["lines"]
    for row in report["lines"]:
        runs = [b for b in blocks if isinstance(b, (Linear, Arc)) and b.line == row["line"]]
        assert runs and all(b.feed_per_rev > 0.0 for b in runs)
        in_effect = runs[0].feed * MM_PER_MIN_PER_M_S
        assert row["feed_after_mm_per_min"] == pytest.approx(in_effect, rel=1e-9)
        assert row["feed_after_mm_per_min"] == pytest.approx(row["feed_after_mm_per_rev"] * row["spindle_after_rpm"],
                                                             rel=1e-12)
        assert row["feed_gene_mm_per_min"] == result.X[f"L{row['line']:04d}.feed"]
        # within one grid step x S of the gene
        assert abs(row["feed_after_mm_per_min"] - row["feed_gene_mm_per_min"]) <= 0.0005 * row[
            "spindle_after_rpm"] + 1e-9
        assert row["feed_before_mm_per_min"] == pytest.approx(row["feed_before_mm_per_rev"] * row["spindle_before_rpm"])


def test_program_without_cutting_is_refused_naming_the_file(tmp_path):
    with pytest.raises(OptimizeError, match=r"no_cut/program\.nc: no cutting line found: no feed move removes "
                                            r"material from the stock \[0\.0, 0\.0, -10\.0\]\.\.\[40\.0, 30\.0, "
                                            r"0\.0\] mm .*expected at least one G1/G2/G3 move through the stock"):
        _run("no_cut", tmp_path)


def test_program_whose_every_feed_line_cuts(tmp_path):
    """No air move: every feed line is a cutting line; the S word goes on the line that starts the spindle."""
    result, out = _run("all_cut", tmp_path)
    report = _check_outputs("all_cut", result, out)
    feed_lines = sorted({b.line for b in interpret((PARTS / "all_cut" / "program.nc").read_text(), "p.nc").blocks
                         if isinstance(b, (Linear, Arc))})
    assert [row["line"] for row in report["lines"]] == feed_lines
    assert report["lines"][0]["s_word_line"] == 3
    assert all(math.isfinite(row["time_after_s"]) for row in report["lines"])


def test_a_program_that_crashes_the_twin_is_refused_naming_the_line(tmp_path):
    """The pocket with ``M3`` but no S: the plunge (line 8) feeds into the stock with the spindle stopped."""
    folder = tmp_path / "no_speed"
    folder.mkdir()
    (folder / "case.toml").write_text((PARTS / "pocket_arcs" / "case.toml").read_text())
    text = (PARTS / "pocket_arcs" / "program.nc").read_text()
    assert text.splitlines()[7].startswith("N60 G1 Z-1.5")
    (folder / "program.nc").write_text(text.replace("N40 S5000 M3", "N40 M3"))
    settings = OptimizeSettings(pop=2, gens=1, progress=False, plot=False)
    with pytest.raises(OptimizeError, match=r"no_speed/program\.nc:8: the original program fails on the twin: .*"
                                            r"spindle stopped .*start the spindle \(M3\) before the cut"):
        optimize(case=folder, settings=settings)
