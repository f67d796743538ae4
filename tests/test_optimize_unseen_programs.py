"""Programs as CAM posts and machinists write them, through the optimiser.

Subprograms called from several places, Custom Macro B loops, modal F, N numbers, comments, M0/M1, lower-case
letters and ``%``: the written program changes only F and S words, every run of a cutting line runs at its own
S gene, a non-cutting line keeps its feed in every run, and ``optimized.nc`` re-simulated gives ``after``.
"""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from fmus_src.nck.blocks import Arc, Linear, SpindleSpeed
from fmus_src.nck.interpreter import interpret
from fmus_src.nck.writer import rewrite_program
from orchestrator.case import load_case
from orchestrator.optimize import OptimizeSettings, optimize
from orchestrator.optimize.context import classify_lines
from orchestrator.simulate import simulate

RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
MM_PER_MIN_PER_M_S = 60000.0

CASE_TOML = """program = "program.nc"
[stock]
min = [0.0, 0.0, -4.0]
max = [4.0, 6.0, 0.0]
[tool]
diameter_mm = 6.0
flutes = 2
[machine]
parameters = "default"
"""

#: The main program cuts a slot (line 12) after a subprogram call whose slot (line 16) is cut first: placed by
#: line numbers, the subprogram's S word went on line 13, which runs after every cut.
SUB_AFTER_MAIN = """%
O5200 (MAIN)
N1 G21 G17 G40 G90 G94
N2 G54
N3 S5000 M3
N4 G0 X-5. Y5. Z1.
N5 G1 Z-1. F200
N6 M98 P5300
N7 G0 Z1.
N8 Y25.
N9 G1 Z-1. F200
N10 X45. F300
N11 G0 Z1.
N12 M30
O5300 (SLOT)
N100 G1 X45. F300
N110 G0 Z1.
N120 X-5.
N130 M99
%
"""

#: A WHILE loop steps down in Z; the plunge (line 11, beside the stock) has no F of its own: its first run takes
#: F200 from line 7, the later runs the cutting line's F (line 12).
LOOP_MODAL_F = """%
O6200
N1 G21 G17 G40 G90 G94
N2 G54
N3 S5000 M3
N4 G0 X-5. Y5. Z1.
N5 G1 Z0. F200
#1 = 0
WHILE [#1 GT -1.5] DO1
#1 = #1 - 0.5
G1 Z#1
X45. F300
G0 Z1.
X-5.
END1
N20 M5
N30 M30
%
"""

#: Everything at once, lower case: N numbers, a comment on every line, modal F, a subprogram called twice,
#: a WHILE loop stepping down whose plunge inherits F, M0 and M1, and %.
UNSEEN = """%
o0100 (unseen program)
n10 g21 g17 g40 g90 g94 (metric)
n20 g54 (work offset)
n30 s3000 m3 (spindle on)
n40 g0 x-3.5 y2. z1. (approach)
n50 g1 z-0.5 f600 (plunge beside the block)
n60 m98 p200 (first pass)
n70 g1 z-1. (second depth, modal f)
n80 m0 (check chips)
n90 m98 p200 (second pass)
#1 = -1.0 (depth)
while [#1 gt -2.0] do1 (step down)
#1 = #1 - 0.5 (next depth)
g1 z#1 (plunge, modal f)
x7.5 f400 (slot)
g0 z1. (retract)
x-3.5 (back)
end1 (loop end)
n100 m1 (optional stop)
n110 m5 (spindle off)
n120 m30 (end)
o200 (slot pass)
n200 g1 x7.5 f300 (slot)
n210 g0 z1. (retract)
n220 x-3.5 (back)
n230 m99 (return)
%
"""

_TOKEN = re.compile(r"\([^)]*\)|[A-Za-z]\s*(?:\[[^\]]*\]|#?[-+]?[0-9.]*)|\S")


def _tokens(text: str) -> list[list[str]]:
    """Each line's tokens other than F and S words (comments, words, macro text)."""
    return [[t for t in _TOKEN.findall(line) if t[0].upper() not in "FS"] for line in text.splitlines()]


def _speeds_at_cutting_runs(text: str, lines: list[int]) -> dict[int, set[float]]:
    """Spindle speed (rpm) in effect at every feed block of the given lines, over all their runs."""
    program = interpret(text, "p.nc")
    out: dict[int, set[float]] = {line: set() for line in lines}
    speed = math.nan
    for b in program.blocks:
        if isinstance(b, SpindleSpeed):
            speed = round(b.speed * RPM_PER_RAD_S, 6)
        elif isinstance(b, (Linear, Arc)) and b.line in out:
            out[b.line].add(speed)
    return out


def _feeds_of(text: str, line: int) -> list[float]:
    """Feed (mm/min) of every run of ``line``."""
    return [round(b.feed * MM_PER_MIN_PER_M_S, 6) for b in interpret(text, "p.nc").blocks
            if isinstance(b, (Linear, Arc)) and b.line == line]


def test_s_word_of_a_subprogram_line_governs_its_runs():
    """The S gene of the subprogram's slot goes before its call (line 5), the main slot's in the subprogram's
    retract that runs before it (line 17); each slot then runs at its own S in the written program."""
    program = interpret(SUB_AFTER_MAIN, "p.nc")
    lines, s_lines, pins, _, _ = classify_lines(program.blocks, {12: 10.0, 16: 10.0}, 0.1, program)
    assert lines == [12, 16]
    assert s_lines == [17, 5]
    text = rewrite_program(SUB_AFTER_MAIN, {12: 450.0, 16: 350.0}, dict(zip(s_lines, [7000.0, 4000.0])))
    assert _speeds_at_cutting_runs(text, lines) == {12: {7000.0}, 16: {4000.0}}


def test_subprogram_called_twice_keeps_its_s_on_each_run():
    """A subprogram slot run by two calls: whatever line carries its S word governs both runs."""
    program = interpret(UNSEEN, "p.nc")
    cut = {24: 10.0, 16: 10.0}  # the subprogram's slot and the loop's slot
    lines, s_lines, _, _, _ = classify_lines(program.blocks, cut, 0.1, program)
    assert lines == [16, 24]
    text = rewrite_program(UNSEEN, None, dict(zip(s_lines, [6500.0, 2500.0])))
    assert _speeds_at_cutting_runs(text, lines) == {16: {6500.0}, 24: {2500.0}}


def test_plunge_in_a_loop_keeps_its_feed_in_every_run():
    """The loop's plunge (line 11) inherits the cutting line's F from its second run on: it is pinned, at the
    lowest of its original feeds, so no run of it moves faster than in the original."""
    program = interpret(LOOP_MODAL_F, "p.nc")
    assert _feeds_of(LOOP_MODAL_F, 11) == [200.0, 300.0, 300.0]
    lines, _, pins, _, _ = classify_lines(program.blocks, {12: 50.0}, 0.1, program)
    assert lines == [12] and pins == {11: 200.0}
    text = rewrite_program(LOOP_MODAL_F, {12: 500.0, **pins})
    assert _feeds_of(text, 11) == [200.0, 200.0, 200.0]
    assert _feeds_of(text, 12) == [500.0, 500.0, 500.0]


def test_lower_case_program_gets_lower_case_words():
    text = rewrite_program("n10 g1 x5. (cut)\nN20 G1 X6.\n", {1: 300.0, 2: 310.0}, {1: 4000.0})
    assert text == "n10 g1 x5. f300 s4000 (cut)\nN20 G1 X6. F310\n"


@pytest.fixture(scope="module")
def unseen_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("unseen")
    (folder / "case.toml").write_text(CASE_TOML)
    (folder / "program.nc").write_text(UNSEEN)
    settings = OptimizeSettings(objective="time", load_limit_N=60.0, feed_range=(100.0, 600.0), pop=4, gens=1,
                                seed=2, progress=False, plot=False)
    out = folder / "opt"
    return folder, out, optimize(case=folder, settings=settings, out=out)


def test_unseen_program_changes_only_f_and_s_words(unseen_run):
    folder, out, result = unseen_run
    written = (out / "optimized.nc").read_text()
    assert written == result.program_text
    assert _tokens(written) == _tokens(UNSEEN)
    assert written.startswith("%\n") and written.endswith("%\n")
    added = re.findall(r"(?<![(\w])[FS]\d", written)  # an appended upper-case word in this lower-case program
    assert added == []
    # every run of every cutting line at its own S gene, every non-cutting feed line at its original feeds
    ctx_lines = [entry["line"] for entry in result.lines]
    speeds = _speeds_at_cutting_runs(written, ctx_lines)
    assert speeds == {e["line"]: {e["spindle_after_rpm"]} for e in result.lines}
    feed_lines = {b.line for b in interpret(UNSEEN, "p.nc").blocks if isinstance(b, (Linear, Arc))}
    for line in sorted(feed_lines - set(ctx_lines)):
        before, after = _feeds_of(UNSEEN, line), _feeds_of(written, line)
        assert all(a <= b for a, b in zip(after, before)), line  # never faster than the original
        if len(set(before)) == 1:
            assert after == before, line


def test_unseen_program_resimulated_gives_after(unseen_run):
    folder, out, result = unseen_run
    report = json.loads((out / "report.json").read_text())
    for key in ("before", "after"):
        assert {"cycle_time_s", "cost_KRW", "max_cutting_load_N"} <= set(report[key])
    again = simulate(program=out / "optimized.nc", case=load_case(folder), plot=False)
    assert again.success
    assert again.summary["cycle_time_s"] == pytest.approx(report["after"]["cycle_time_s"], abs=1e-9)
    assert again.summary["max_cutting_load_N"] == pytest.approx(report["after"]["max_cutting_load_N"], rel=1e-9)
    assert again.summary["max_cutting_load_N"] <= 60.0
    assert np.isfinite(report["after"]["cost_KRW"])
