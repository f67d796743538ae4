"""An inch (G20) program through the optimiser, end to end, against its mm (G21) twin.

The two programs cut the same slot: every inch dimension is a multiple of 0.005 in = 0.127 mm, so the mm program
writes the same numbers times 25.4 exactly (X0.025 in = X0.635 mm, F10. in/min = F254 mm/min). The stock is given
in mm in case.toml (the case file's unit) for both.
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck.blocks import Arc, Linear
from fmus_src.nck.interpreter import interpret
from orchestrator.case import load_case
from orchestrator.optimize import OptimizeSettings, build_reference, evaluate_population, optimize
from orchestrator.optimize.evaluate import figures, run_twin
from orchestrator.simulate import simulate

INCH_MM = 25.4
FEED_RANGE = (100.0, 600.0)  # mm/min
STOCK = '[stock]\nmin = [0.0, 0.0, -2.54]\nmax = [5.08, 7.62, 0.0]\n'  # 0.2 x 0.3 x 0.1 in

# a 6 mm end mill enters a 0.2 in wide block from in, cuts a 0.05 in deep slot in two lines
INCH = ("G20 G17 G90 G94 G54\nS3000 M3\nG0 X-0.15 Y0.15 Z0.1\nG1 Z-0.05 F20.\n"
        "X0.025 F10.\nX0.125\nG0 Z0.1\nM30\n")
MM = ("G21 G17 G90 G94 G54\nS3000 M3\nG0 X-3.81 Y3.81 Z2.54\nG1 Z-1.27 F508.\n"
      "X0.635 F254.\nX3.175\nG0 Z2.54\nM30\n")
CUTTING_LINES = [5, 6]


def _settings() -> OptimizeSettings:
    return OptimizeSettings(objective="time", load_limit_N=60.0, feed_range=FEED_RANGE, pop=4, gens=2, seed=5,
                            progress=False, plot=False, check_front=False)


def _case(folder: Path, name: str, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "case.toml").write_text(f'program = "{name}"\n{STOCK}')
    (folder / name).write_text(text)
    return folder


@pytest.fixture(scope="module")
def inch_run(tmp_path_factory):
    case_dir = _case(tmp_path_factory.mktemp("inch"), "slot_in.nc", INCH)
    settings = _settings()
    reference = build_reference(load_case(case_dir), ranges=settings.ranges(), load_limit_N=settings.load_limit_N)
    out = case_dir / "opt"
    result = optimize(case=case_dir, settings=settings, out=out, reference=reference)
    return case_dir, reference, result, out


@pytest.fixture(scope="module")
def mm_reference(tmp_path_factory):
    case_dir = _case(tmp_path_factory.mktemp("mm"), "slot_mm.nc", MM)
    settings = _settings()
    return build_reference(load_case(case_dir), ranges=settings.ranges(), load_limit_N=settings.load_limit_N)


def _f_words(text: str) -> dict[int, float]:
    out = {}
    for number, line in enumerate(text.splitlines(), start=1):
        m = re.search(r"F\s*([0-9.]+)", line)
        if m:
            out[number] = float(m.group(1))
    return out


def test_same_lines_and_before_as_the_mm_twin(inch_run, mm_reference):
    _, reference, _, _ = inch_run
    ctx, ctx_mm = reference.context, mm_reference.context
    assert ctx.lines.tolist() == ctx_mm.lines.tolist() == CUTTING_LINES
    # F10. in/min is 254 mm/min; the SI feeds differ by at most a rounding of 25.4e-3 / 60 (1 ulp)
    assert ctx.original_feed.tolist() == pytest.approx([254.0, 254.0], rel=1e-12)
    before, before_mm = reference.evaluation.member(0), mm_reference.evaluation.member(0)
    # same geometry and feeds to ~1e-16 relative: the cycle time is the same count of 1 ms steps (a 1-ulp
    # difference in a coordinate could at most move the in-position instant by one step)
    assert abs(before["cycle_time_s"] - before_mm["cycle_time_s"]) <= 1e-3 + 1e-12
    # the load (Eq. 10-13) is smooth in the engagement and the feed per tooth, whose SI inputs agree to ~1e-16
    # relative: 1e-9 leaves room for the engagement's clipping at the stock edge, nothing for a unit error
    assert before["max_cutting_load_N"] == pytest.approx(before_mm["max_cutting_load_N"], rel=1e-9)
    assert before["max_cutting_load_N"] > 10.0  # the slot really cuts


def test_written_program_is_inch_with_feeds_in_ipm_on_the_grid(inch_run):
    case_dir, reference, result, out = inch_run
    written = (out / "optimized.nc").read_text()
    assert written.splitlines()[0] == "G20 G17 G90 G94 G54"
    # only F and S words change
    strip = re.compile(r"\s*[FS]\s*[0-9.]+")
    assert [strip.sub("", ln) for ln in written.splitlines()] == [strip.sub("", ln) for ln in INCH.splitlines()]
    words = _f_words(written)
    lo_in, hi_in = FEED_RANGE[0] / INCH_MM, FEED_RANGE[1] / INCH_MM  # 3.937..23.622 in/min
    report = json.loads((out / "report.json").read_text())
    rows = {row["line"]: row for row in report["lines"]}
    assert sorted(rows) == CUTTING_LINES
    for line in CUTTING_LINES:
        # the F word in effect: the line's own, or the previous line's when the gene is the same (no word then)
        f_in = words[max(n for n in words if n <= line)]
        if line not in words:
            assert rows[line]["feed_after_mm_per_min"] == rows[line - 1]["feed_after_mm_per_min"]
        assert lo_in <= f_in <= hi_in
        assert abs(f_in * 10.0 - round(f_in * 10.0)) < 1e-9, f"F{f_in} is not on the 0.1 in/min grid"
        # the report's mm/min is the written inch word times 25.4
        assert rows[line]["feed_after_mm_per_min"] == pytest.approx(f_in * INCH_MM, rel=1e-12)
        assert rows[line]["feed_after_in_per_min"] == f_in
        assert result.X[f"L{line:04d}.feed"] == rows[line]["feed_after_mm_per_min"]
    # the plunge (line 4, F20. in/min) is not a cutting line and keeps its feed word
    assert words[4] == 20.0
    # re-interpreting the written file: every block feed equals the report's per-line feed (mm/min -> m/s)
    program = interpret(written, file="optimized.nc")
    seen = set()
    for b in program.blocks:
        if isinstance(b, (Linear, Arc)) and b.line in rows:
            expected = rows[b.line]["feed_after_mm_per_min"] * 1e-3 / 60.0
            assert b.feed == pytest.approx(expected, rel=1e-9)
            seen.add(b.line)
    assert seen == set(CUTTING_LINES)


def test_after_equals_an_independent_simulation_of_the_written_file(inch_run):
    case_dir, _, result, out = inch_run
    alone = simulate(out / "optimized.nc", case=case_dir, plot=False)
    assert alone.success
    assert alone.summary["cycle_time_s"] == result.after["cycle_time_s"]
    assert result.after["max_cutting_load_N"] == pytest.approx(alone.summary["max_cutting_load_N"], rel=1e-12)


def test_batched_member_equals_the_written_inch_program_alone(inch_run):
    _, reference, result, out = inch_run
    ctx = reference.context
    f = np.array([result.X[f"L{line:04d}.feed"] for line in CUTTING_LINES])
    s = np.array([result.X[f"L{line:04d}.spindle"] for line in CUTTING_LINES])
    # the chosen individual beside the original, in one batch (as the search evaluates them)
    batch = evaluate_population(ctx, np.stack([ctx.original_feed, f]), np.stack([ctx.original_spindle, s]))
    written = (out / "optimized.nc").read_text()
    alone = figures(ctx, run_twin(ctx, None, None, 1, program_text=written), 1)  # same path-mode cutting
    assert batch.cycle_time_s[1] == alone.cycle_time_s[0]
    assert batch.max_load_N[1] == alone.max_load_N[0]
    assert batch.line_time_s[1].tolist() == alone.line_time_s[0].tolist()
    assert batch.cycle_time_s[0] == reference.evaluation.cycle_time_s[0]
    assert math.isfinite(batch.cycle_time_s[1])


def test_inch_grid_words_read_back_as_the_genes():
    """Every gene of the 0.1 in/min grid in the default range: the written word converts to the gene's SI feed."""
    from fmus_src.nck.interpreter import INCH
    from fmus_src.nck.writer import feed_word_value, inch_lines, rewrite_program

    text = "G21 G90\nG1 X1. F100.\nG20\nG1 X0.1 F4.\nM30\n"
    assert inch_lines(text, [2, 3, 4]) == {3, 4}
    for k in range(40, 197):  # 4.0 .. 19.6 in/min = 101.6 .. 497.84 mm/min, inside 100..500 mm/min
        gene = k * 2.54  # mm/min, as the optimiser's grid holds it
        written = rewrite_program(text, {4: gene})
        word = float(re.search(r"F([0-9.]+)", written.splitlines()[3]).group(1))
        assert word == k / 10.0  # the machinist's number: one decimal in in/min
        assert word == feed_word_value(gene, True)
        feed = [b.feed for b in interpret(written).blocks if isinstance(b, Linear) and b.line == 4][0]
        assert feed == word * INCH / 60.0  # the optimiser's override conversion, bit for bit
        assert feed == pytest.approx(gene * 1e-3 / 60.0, rel=1e-12)


def test_cli_passes_the_grids_to_the_settings(monkeypatch, tmp_path):
    """``--feed-step``, ``--feed-step-in-per-min`` and ``--spindle-step`` reach ``OptimizeSettings`` unchanged."""
    import orchestrator.optimize as optimize_package
    from orchestrator.cli import main as cnctwin_main

    seen = {}

    class Result:
        before = after = {"cycle_time_s": 1.0, "cost_KRW": 1.0, "max_cutting_load_N": 1.0}
        evaluations, front, files = 0, [], {}

    def fake_optimize(program=None, case=None, settings=None, out=None, machine=None):
        seen["settings"] = settings
        return Result()

    monkeypatch.setattr(optimize_package, "optimize", fake_optimize)
    assert cnctwin_main(["optimize", "--case", str(tmp_path), "--feed-step", "5", "--feed-step-in-per-min", "0.5",
                         "--spindle-step", "100", "--out", str(tmp_path / "o")]) == 0
    s = seen["settings"]
    assert (s.feed_step, s.feed_step_in_per_min, s.spindle_step) == (5.0, 0.5, 100.0)
    assert s.ranges().feed_step_in_per_min == 0.5
