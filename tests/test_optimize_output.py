"""What ``optimized.nc`` looks like: F and S words only where they change something; G95 programs optimised.

Every assertion is derived from the genes: the words a machinist would write are the ones whose value differs
from the value in effect (per run of the line); the program with every word written (the writer's former output)
and the program with only these words plan the same motion bit for bit, and so does the batched evaluation with
every word as an NC-kernel override.
"""
from __future__ import annotations

import json
import math
import re
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck.blocks import Arc, Linear, SpindleSpeed
from fmus_src.nck.errors import GCodeError, NCParameterError
from fmus_src.nck.interpreter import interpret
from fmus_src.nck.settings import MM, RPM
from fmus_src.nck.writer import inch_lines, rewrite_program
from orchestrator.case import load_case
from orchestrator.optimize import OptimizeError, OptimizeSettings, Ranges, optimize
from orchestrator.optimize.context import ProblemContext, classify_lines
from orchestrator.optimize.reference import _per_revolution_lines
from orchestrator.simulate import simulate
from orchestrator.twin import build_twin
from tests.test_optimize_cases import CASE_TOML

N_ADAPTIVE = 200
ADAPTIVE_FIRST = 7  # line of the first of the 200 cutting lines


def _adaptive() -> str:
    """An adaptive-style toolpath as CAM posts write it: 200 short moves, one F word, one S word."""
    lines = ["%", "O0300 (ADAPTIVE)", "G21 G17 G90 G94 G54", "S5000 M3", "G0 X0. Y0. Z1.", "G1 Z-1. F200"]
    for k in range(N_ADAPTIVE):
        lines.append(f"X{0.15 * (k + 1):.3f} Y{0.3 if k % 2 else -0.3:.3f}" + (" F400" if k == 0 else ""))
    return "\n".join(lines + ["G0 Z1.", "M30", "%"]) + "\n"


ADAPTIVE = _adaptive()

#: A slot cut twice by a subprogram, with a main-program slot between the calls (the UNSEEN shape of
#: tests/test_optimize_unseen_programs.py, upper case).
SUBPROGRAM = """%
O0100
N10 G21 G17 G40 G90 G94
N20 G54
N30 S3000 M3
N40 G0 X-3.5 Y2. Z1.
N50 G1 Z-0.5 F600
N60 M98 P200
N70 G1 Z-1.
N80 X7.5 F400
N90 G0 Z1.
N100 X-3.5
N110 G1 Z-1.5 F600
N120 M98 P200
N130 M5
N140 M30
O200
N200 G1 X7.5 F300
N210 G0 Z1.
N220 X-3.5
N230 M99
%
"""

#: The two-line slot of tests/test_optimize_cases.py, cut in feed per revolution (0.1 mm/rev at S3000 is the
#: G94 program's F300); the retract (line 9) is a G95 feed line that inherits the cutting F: a pin, in mm/rev.
G95_SLOT = """%
O0095 (G95 SLOT)
G21 G17 G90 G94 G54
S3000 M3
G0 X-3.5 Y3. Z1.
G95 G1 Z-1. F0.2
X0.5 F0.1 (SLOT PART 1)
X2.5 (SLOT PART 2)
Z1.
G94 G0 X-3.5
M30
%
"""

_TOKEN = re.compile(r"\([^)]*\)|[A-Za-z]\s*(?:\[[^\]]*\]|#?[-+]?[0-9.]*)|\S")


def _word_diff(before: str, after: str) -> dict[int, tuple[list[str], list[str]]]:
    """Per changed line (1-based): the tokens only in the original and those only in the written line."""
    a_lines, b_lines = before.splitlines(), after.splitlines()
    assert len(a_lines) == len(b_lines)
    out = {}
    for n, (a, b) in enumerate(zip(a_lines, b_lines), start=1):
        ta, tb = Counter(_TOKEN.findall(a)), Counter(_TOKEN.findall(b))
        if ta != tb:
            out[n] = (sorted((ta - tb).elements()), sorted((tb - ta).elements()))
    return out


def _context(folder: Path, text: str, cutting: list[int], ranges: Ranges = Ranges()) -> ProblemContext:
    """The optimiser's problem for ``text`` with the given cutting lines (no reference run: the rules only)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "case.toml").write_text(CASE_TOML)
    (folder / "program.nc").write_text(text)
    case = load_case(folder)
    nck = build_twin(case, batch=1, program_text=text).nck
    nck.setup(0.0)
    program = nck.program_
    lines, s_lines, pins, f0, s0 = classify_lines(program.blocks, {n: 1.0 for n in cutting}, 0.1, program)
    assert lines == sorted(cutting)
    return ProblemContext(case, text, np.array(lines), np.array(s_lines), pins, np.array(f0), np.array(s0),
                          ranges, 60.0, inch_lines=frozenset(inch_lines(text, lines + list(pins))),
                          per_rev_lines=_per_revolution_lines(program.blocks, set(lines) | set(pins), "program.nc"),
                          program=program)


def _every_word(ctx: ProblemContext, feeds: np.ndarray, spindles: np.ndarray) -> str:
    """The program with an F word on every cutting and pinned line and an S word on every S-word line (the
    writer's output before words were left out where they change nothing)."""
    feed, per_rev = {}, {}
    for line, v in ctx.pinned_feeds.items():
        (per_rev if line in ctx.per_rev_lines else feed)[line] = v
    for i, line in enumerate(ctx.lines.tolist()):
        if line in ctx.per_rev_lines:
            per_rev[line] = ctx.feed_per_rev_word(line, feeds[i], spindles[i])
        else:
            feed[line] = float(feeds[i])
    spindle = dict(zip(ctx.spindle_lines.tolist(), np.asarray(spindles, float).tolist()))
    return rewrite_program(ctx.program_text, feed, spindle, feed_per_rev_by_line=per_rev)


def _plan(ctx: ProblemContext, text: str | None = None, feeds=None, spindles=None):
    """The NC kernel's plan of ``text`` alone, or of the original with a batch of overrides."""
    batch = 1 if feeds is None else len(feeds)
    nck = build_twin(ctx.case, batch=batch, program_text=text if text is not None else ctx.program_text).nck
    if feeds is not None:
        nck.set_overrides(*ctx.overrides(feeds, spindles))
    nck.setup(0.0)
    return nck


def _assert_same_plan(alone, batched, b: int) -> None:
    """Member ``b`` of ``batched`` plans exactly the motion of ``alone`` (bit for bit)."""
    assert alone.duration_[0] == batched.duration_[b]
    k = alone.plan_.position.shape[1]
    for name in ("position", "feed", "spindle_speed", "line"):
        np.testing.assert_array_equal(getattr(alone.plan_, name)[0], getattr(batched.plan_, name)[b, :k])


def _s_words(text: str) -> int:
    return sum(1 for t in _TOKEN.findall(text) if t[0] in "Ss" and t[1:].strip()[:1].isdigit())


@pytest.fixture(scope="module")
def adaptive(tmp_path_factory):
    cutting = list(range(ADAPTIVE_FIRST, ADAPTIVE_FIRST + N_ADAPTIVE))
    return _context(tmp_path_factory.mktemp("adaptive"), ADAPTIVE, cutting)


# ---------------------------------------------------------------------------- S and F words where they change
def test_original_genes_write_the_original_byte_for_byte(adaptive):
    assert adaptive.program_for(adaptive.original_feed, adaptive.original_spindle) == ADAPTIVE


def test_one_speed_for_200_lines_changes_the_one_s_word(adaptive):
    """Every line at S6000: the program's own S word changes and no line gets another S (the former writer put
    S6000 on each of the 200 lines)."""
    L = adaptive.n_lines
    written = adaptive.program_for(np.full(L, 400.0), np.full(L, 6000.0))
    assert _word_diff(ADAPTIVE, written) == {4: (["S5000"], ["S6000"])}
    assert _s_words(written) == 1
    assert _s_words(_every_word(adaptive, np.full(L, 400.0), np.full(L, 6000.0))) == 1 + L - 1


def test_s_and_f_words_only_where_the_genes_change(adaptive):
    """Blocks of equal genes: an S word where S changes, an F word where F changes, nothing else; the original
    S word keeps its text when its value is unchanged."""
    L = adaptive.n_lines
    k = np.arange(L)
    spindles = np.where((k // 50) % 2 == 0, 5000.0, 6000.0)  # 5000 (unchanged), 6000, 5000, 6000
    feeds = np.where(k < 120, 400.0, 450.0)
    written = adaptive.program_for(feeds, spindles)
    expected: dict[int, tuple[list[str], list[str]]] = {}
    for i in range(1, L):
        added = ([f"F{feeds[i]:g}"] if feeds[i] != feeds[i - 1] else []) + (
            [f"S{spindles[i]:g}"] if spindles[i] != spindles[i - 1] else [])
        if added:
            expected[ADAPTIVE_FIRST + i] = ([], sorted(added))
    assert _word_diff(ADAPTIVE, written) == expected
    assert sorted(expected) == [57, 107, 127, 157]  # the S changes at 50, 100, 150 and the F change at 120
    assert _s_words(written) == 1 + 3


def test_random_genes_words_exactly_where_values_change_and_the_same_motion(adaptive):
    """Random genes: F (S) on a line exactly where its gene differs from the previous line's; the written
    program, the every-word program and the batched overrides plan the same motion bit for bit."""
    rng = np.random.default_rng(11)
    L = adaptive.n_lines
    feeds, spindles = adaptive.snap(rng.choice([380.0, 400.0, 420.0], (3, L)),
                                    rng.choice([5000.0, 5500.0], (3, L), p=[0.8, 0.2]))
    batched = _plan(adaptive, feeds=feeds, spindles=spindles)
    for b in range(3):
        f, s = feeds[b], spindles[b]
        written = adaptive.program_for(f, s)
        diff = _word_diff(ADAPTIVE, written)
        for i in range(L):
            line = ADAPTIVE_FIRST + i
            prev_f = f[i - 1] if i else 400.0  # the first line's own F400
            prev_s = s[i - 1] if i else 5000.0
            removed, added = diff.get(line, ([], []))
            if i == 0:  # its own F word, rewritten only when changed; its S goes on line 4 (the S word)
                assert (removed, added) == (([], []) if f[0] == 400.0 else (["F400"], [f"F{f[0]:g}"]))
                continue
            assert removed == []
            assert added == sorted(([f"F{f[i]:g}"] if f[i] != prev_f else [])
                                   + ([f"S{s[i]:g}"] if s[i] != prev_s else [])), line
        assert diff.get(4, ([], [])) == (([], []) if s[0] == 5000.0 else (["S5000"], [f"S{s[0]:g}"]))
        alone = _plan(adaptive, written)
        _assert_same_plan(alone, _plan(adaptive, _every_word(adaptive, f, s)), 0)
        _assert_same_plan(alone, batched, b)


def test_subprogram_s_word_kept_when_one_call_runs_at_another_speed(tmp_path):
    """The subprogram's slot (line 18) runs after N50 and after the main slot (line 10): its S goes before the
    first call. With the main slot at another S, the second call needs it again: the S word stays even when it
    equals the program's S3000; with the main slot at S3000 too, no S word is written at all."""
    ctx = _context(tmp_path / "sub", SUBPROGRAM, [10, 18])
    assert ctx.lines.tolist() == [10, 18]
    s_line = dict(zip(ctx.lines.tolist(), ctx.spindle_lines.tolist()))
    feeds = ctx.original_feed.copy()
    same = ctx.program_for(feeds, np.array([3000.0, 3000.0]))
    assert same == SUBPROGRAM
    other = ctx.program_for(feeds, np.array([5000.0, 3000.0]))
    diff = _word_diff(SUBPROGRAM, other)
    assert sorted(w for _, added in diff.values() for w in added) == ["S3000", "S5000"]
    assert diff[s_line[10]][1] == ["S5000"]
    # every run of each slot at its own gene, and the motion of the every-word program
    speeds: dict[int, set[float]] = {10: set(), 18: set()}
    current = math.nan
    for b in interpret(other, "p.nc").blocks:
        if isinstance(b, SpindleSpeed):
            current = round(b.speed / RPM, 6)
        elif isinstance(b, (Linear, Arc)) and b.line in speeds:
            speeds[b.line].add(current)
    assert speeds == {10: {5000.0}, 18: {3000.0}}
    _assert_same_plan(_plan(ctx, other), _plan(ctx, _every_word(ctx, feeds, np.array([5000.0, 3000.0]))), 0)


# ---------------------------------------------------------------------------- G95 (feed per revolution)
def test_g95_words_are_gene_over_s_on_the_grid_and_overrides_plan_the_written_program(tmp_path):
    ctx = _context(tmp_path / "g95", G95_SLOT, [7, 8], Ranges((100.0, 600.0), (1000.0, 8000.0)))
    assert ctx.per_rev_lines == frozenset({7, 8, 9}) and ctx.pinned_feeds == {9: 0.1}  # the retract, mm/rev
    assert ctx.original_feed.tolist() == [300.0, 300.0]  # 0.1 mm/rev x 3000 rpm
    feeds = np.array([[370.0, 370.0], [400.0, 250.0], [600.0, 600.0], [100.0, 500.0]])
    spindles = np.array([[4500.0, 4500.0], [8000.0, 8000.0], [8000.0, 1000.0], [8000.0, 1000.0]])
    batched = _plan(ctx, feeds=feeds, spindles=spindles)
    for b in range(len(feeds)):
        written = ctx.program_for(feeds[b], spindles[b])
        blocks = interpret(written, "p.nc").blocks
        for i, line in enumerate((7, 8)):
            gene, s = feeds[b, i], spindles[b, i]
            # the F in effect on the line, mm/rev, as the written program reads it
            word = round(next(x.feed_per_rev for x in blocks if isinstance(x, Linear) and x.line == line) / MM, 9)
            assert abs(word * 1000.0 - round(word * 1000.0)) < 1e-6  # the 0.001 mm/rev grid
            lo, hi = math.ceil(100.0 / s * 1000 - 1e-9) / 1000, math.floor(600.0 / s * 1000 + 1e-9) / 1000
            assert word == pytest.approx(min(max(math.floor(gene / s * 1000 + 0.5) / 1000, lo), hi), abs=1e-12)
            assert 100.0 <= word * s <= 600.0 + 1e-9
        # the pin keeps its mm/rev wherever the cut's F would reach the retract
        retract = [x.feed_per_rev for x in blocks if isinstance(x, Linear) and x.line == 9]
        assert retract == [0.1 * MM]
        assert set(_word_diff(G95_SLOT, written)) <= {4, 7, 8, 9}
        _assert_same_plan(_plan(ctx, written), batched, b)
    # member 0: S4500 goes on the S word; F 370/4500 = 0.0822 -> F0.082 on line 7 only (line 8 inherits it)
    assert _word_diff(G95_SLOT, ctx.program_for(feeds[0], spindles[0])) == {
        4: (["S3000"], ["S4500"]), 7: (["F0.1"], ["F0.082"]), 9: ([], ["F0.1"])}


def test_inch_g95_words_are_in_per_rev_on_the_grid(tmp_path):
    text = G95_SLOT.replace("G21", "G20").replace("X-3.5 Y3. Z1.", "X-0.14 Y0.12 Z0.04").replace(
        "Z-1. F0.2", "Z-0.04 F0.008").replace("X0.5 F0.1", "X0.02 F0.004").replace("X2.5", "X0.1").replace(
        "Z1.\nG94 G0 X-3.5", "Z0.04\nG94 G0 X-0.14")
    ctx = _context(tmp_path / "g95in", text, [7, 8])
    assert ctx.inch_lines == frozenset({7, 8, 9}) and ctx.per_rev_lines == frozenset({7, 8, 9})
    assert ctx.pinned_feeds == {9: pytest.approx(0.004 * 25.4)}
    f, s = np.array([400.0, 400.0]), np.array([6000.0, 6000.0])
    written = ctx.program_for(f, s)
    # 400 mm/min / 25.4 / 6000 rpm = 0.002625 in/rev -> 0.0026 on the 0.0001 in/rev grid
    assert _word_diff(text, written) == {4: (["S3000"], ["S6000"]), 7: (["F0.004"], ["F0.0026"]),
                                         9: ([], ["F0.004"])}
    _assert_same_plan(_plan(ctx, written), _plan(ctx, feeds=f[None], spindles=s[None]), 0)


@pytest.fixture(scope="module")
def g95_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("g95run")
    (folder / "case.toml").write_text(CASE_TOML)
    (folder / "program.nc").write_text(G95_SLOT)
    settings = OptimizeSettings(objective="time", load_limit_N=60.0, feed_range=(100.0, 600.0), pop=4, gens=1,
                                seed=4, progress=False, plot=False, check_front=False)
    return folder, optimize(case=folder, settings=settings, out=folder / "opt")


def test_g95_program_optimised_and_resimulated_gives_after(g95_run):
    folder, result = g95_run
    written = (folder / "opt" / "optimized.nc").read_text()
    assert written == result.program_text
    diff = _word_diff(G95_SLOT, written)
    assert all(t[0] in "FS" for removed, added in diff.values() for t in removed + added)
    report = json.loads((folder / "opt" / "report.json").read_text())
    blocks = interpret(written, "p.nc").blocks
    for row in report["lines"]:
        gene, s = row["feed_gene_mm_per_min"], row["spindle_after_rpm"]
        assert (gene, s) == (result.X[f"L{row['line']:04d}.feed"], result.X[f"L{row['line']:04d}.spindle"])
        word = row["feed_after_mm_per_rev"]
        assert word == pytest.approx(round(gene / s, 3), abs=1e-12)  # inside the range here: no clipping
        assert row["feed_after_mm_per_min"] == pytest.approx(word * s, rel=1e-12)  # the feed in effect, F x S
        assert row["feed_before_mm_per_rev"] == 0.1
        runs = [x for x in blocks if isinstance(x, Linear) and x.line == row["line"]]
        assert [x.feed_per_rev for x in runs] == [word * MM] * len(runs)
        assert [x.feed for x in runs] == [word * MM * (s * RPM) / (2 * math.pi)] * len(runs)
    again = simulate(program=folder / "opt" / "optimized.nc", case=load_case(folder), plot=False)
    assert again.success
    assert again.summary["cycle_time_s"] == pytest.approx(report["after"]["cycle_time_s"], abs=1e-9)
    assert again.summary["max_cutting_load_N"] == pytest.approx(report["after"]["max_cutting_load_N"], rel=1e-9)
    assert report["after"]["max_cutting_load_N"] <= 60.0 < report["before"]["max_cutting_load_N"]


def test_g95_batched_evaluation_equals_the_written_program_alone(g95_run):
    """The search's batched member (m/rev overrides) and ``optimized.nc`` run alone: the same figures."""
    from orchestrator.optimize import build_reference, evaluate_population
    from orchestrator.optimize.evaluate import figures, run_twin

    folder, result = g95_run
    ctx = build_reference(load_case(folder), ranges=Ranges((100.0, 600.0))).context
    keys = ctx.keys
    f = np.array([result.X[k] for k in keys[0::2]])
    s = np.array([result.X[k] for k in keys[1::2]])
    batch = evaluate_population(ctx, np.stack([ctx.original_feed, f]), np.stack([ctx.original_spindle, s]))
    alone = figures(ctx, run_twin(ctx, None, None, 1, program_text=result.program_text), 1)
    assert batch.cycle_time_s[1] == alone.cycle_time_s[0]
    assert batch.max_load_N[1] == alone.max_load_N[0]
    assert batch.line_time_s[1].tolist() == alone.line_time_s[0].tolist()


def test_a_line_run_in_g94_and_g95_is_refused_naming_it():
    text = ("S3000 M3\nG0 X-3.5 Y3. Z1.\nG1 Z-1. F300\nM98 P10\nG95 G1 Z-1.5 F0.1\nM98 P10\nG94 G0 Z1.\nM30\n"
            "O10\nG1 X2.5\nG0 X-3.5\nM99\n")
    program = interpret(text, "p.nc")
    with pytest.raises(OptimizeError, match=r"p\.nc:10: the line runs in feed per minute \(G94\) and in feed "
                                            r"per revolution \(G95\)"):
        _per_revolution_lines(program.blocks, {10}, "p.nc")


def test_kernel_feed_per_rev_override_equals_the_rewritten_word_and_mode_errors():
    from fmus_src.nck import NCKernel

    text = "S6000 M3\nG95 G1 X30. F0.05\nX40.\nG94 G1 X50. F300.\nM30\n"
    k = NCKernel(program_text=text, batch=2)
    k.set_overrides(feed_per_rev={2: np.array([0.05, 0.08]) * MM})
    k.setup(0.0)
    for b, word in enumerate(("0.05", "0.08")):
        alone = NCKernel(program_text=text.replace("F0.05", "F" + word))
        alone.setup(0.0)
        _assert_same_plan(alone, k, b)
    for kwargs, match in (({"feed_per_rev": {4: 1e-4}}, "feed-per-revolution override of line 4 would govern "
                                                        "line 4, a feed per minute"),
                          ({"feed": {3: 0.01}}, "feed override of line 3 would govern line 3, a feed per rev"),
                          ({"feed": {2: 0.01}, "feed_per_rev": {2: 1e-4}}, "line 2 has a feed override")):
        k = NCKernel(program_text=text)
        k.set_overrides(**kwargs)
        with pytest.raises(NCParameterError, match=match):
            k.setup(0.0)


def _zigzag(n: int) -> str:
    """A slot through the 4 mm block in ``n`` short moves (an adaptive-style path), one F and one S word."""
    lines = ["G21 G17 G90 G94 G54", "S3000 M3", "G0 X-3.5 Y3. Z1.", "G1 Z-1. F600"]
    for k in range(n):
        lines.append(f"X{-3.5 + 11.0 * (k + 1) / n:.3f} Y{3.1 if k % 2 else 2.9:.1f}" + (" F300" if k == 0 else ""))
    return "\n".join(lines + ["G0 Z1.", "M30"]) + "\n"


def test_adaptive_program_end_to_end_words_where_genes_change_and_after_resimulated(tmp_path):
    text = _zigzag(30)
    (tmp_path / "case.toml").write_text(CASE_TOML)
    (tmp_path / "program.nc").write_text(text)
    settings = OptimizeSettings(objective="time", load_limit_N=60.0, feed_range=(100.0, 600.0), pop=4, gens=1,
                                seed=1, progress=False, plot=False, check_front=False)
    result = optimize(case=tmp_path, settings=settings, out=tmp_path / "opt")
    written = (tmp_path / "opt" / "optimized.nc").read_text()
    rows = result.lines
    assert len(rows) >= 15  # the moves through the block
    diff = _word_diff(text, written)
    assert all(t[0] in "FS" for removed, added in diff.values() for t in removed + added)
    # the air moves after the block inherit the F written on the first cutting line: they keep F300, written once
    cut = {row["line"] for row in rows}
    before = {b.line: b.feed for b in interpret(text, "p.nc").blocks if isinstance(b, Linear)}
    after = {b.line: b.feed for b in interpret(written, "p.nc").blocks if isinstance(b, Linear)}
    assert {n: f for n, f in after.items() if n not in cut} == {n: f for n, f in before.items() if n not in cut}
    first_air = max(cut) + 1
    assert diff.get(first_air, ([], []))[1] == ([] if rows[-1]["feed_after_mm_per_min"] == 300.0 else ["F300"])
    assert not any(diff.get(n) for n in range(first_air + 1, len(text.splitlines()) + 1))
    # consecutive cutting lines: an S (F) word exactly where the gene differs from the line before
    for prev, row in zip(rows, rows[1:]):
        assert row["line"] == prev["line"] + 1 and row["s_word_line"] == row["line"]
        added = diff.get(row["line"], ([], []))[1]
        assert sorted(t[0] for t in added) == sorted(
            (["F"] if row["feed_after_mm_per_min"] != prev["feed_after_mm_per_min"] else [])
            + (["S"] if row["spindle_after_rpm"] != prev["spindle_after_rpm"] else [])), row["line"]
    changes = sum(a["spindle_after_rpm"] != b["spindle_after_rpm"] for a, b in zip(rows, rows[1:]))
    assert _s_words(written) == 1 + changes
    again = simulate(program=tmp_path / "opt" / "optimized.nc", case=load_case(tmp_path), plot=False)
    assert again.success
    assert again.summary["cycle_time_s"] == pytest.approx(result.after["cycle_time_s"], abs=1e-9)
    assert again.summary["max_cutting_load_N"] == pytest.approx(result.after["max_cutting_load_N"], rel=1e-9)


def test_writer_feed_per_rev_words():
    text = "G21 G95 G1 X1. F0.1\nX2.\nG20\nx0.1\nM30\n"
    out = rewrite_program(text, None, None, feed_per_rev_by_line={1: 0.082, 2: 0.05, 4: 0.0026 * 25.4})
    assert out == "G21 G95 G1 X1. F0.082\nX2. F0.05\nG20\nx0.1 f0.0026\nM30\n"
    with pytest.raises(GCodeError, match="feed in mm/min cannot be written there") as info:  # a G95 line
        rewrite_program(text, {2: 300.0}, None, file="p.nc")
    assert (info.value.file, info.value.line) == ("p.nc", 2)
    with pytest.raises(GCodeError, match="feed per minute and a feed per revolution") as info:
        rewrite_program("G94 G1 X1. F300\nM30\n", {1: 300.0}, None, file="p.nc", feed_per_rev_by_line={1: 0.05})
    assert (info.value.file, info.value.line) == ("p.nc", 1)
