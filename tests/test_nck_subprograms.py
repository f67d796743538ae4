"""FANUC subprograms in one file (M98/M99), as CAM posts write them: expected positions derived by hand."""
from __future__ import annotations

import re

import numpy as np
import pytest

from fmus_src.nck.blocks import Linear, Rapid, SpindleSpeed
from fmus_src.nck.errors import GCodeError, NCParameterError
from fmus_src.nck.interpreter import interpret
from fmus_src.nck.overrides import insert_spindle_commands, resolve_values
from fmus_src.nck.writer import rewrite_program

MPM = 1e-3 / 60.0  # mm/min -> m/s
RPM = 2.0 * np.pi / 60.0

# the Fusion/Mastercam layout of the task: main, M30, then O1001 before the closing %
POST = """%
O1000 (MAIN)
G90 G17 G21 G94
T1 M6
S6000 M3
G0 X0 Y0 Z5.
M98 P1001
G0 X10.
M98 P1001 L2
G0 Z50.
M30
O1001 (SLOT)
G91 G1 Z-6. F200
X5. F300
G0 Z6.
G90
M99
%
"""


def _mm(p):
    return [round(v * 1e3, 6) for v in p]


def _moves(program):
    return [(b.line, _mm(b.end)) for b in program.blocks if isinstance(b, (Rapid, Linear))]


def test_post_layout_three_slots_by_hand():
    program = interpret(POST)
    # O1001 is incremental: Z-6 from Z5 to Z-1, X+5, Z+6 back to Z5; it runs at X0, at X10, and again at X15
    # (the second run of L2 starts where the first ended). Then G90 (set by the subprogram) G0 Z50.
    def slot(x):
        return [(13, [x, 0, -1]), (14, [x + 5, 0, -1]), (15, [x + 5, 0, 5])]

    assert _moves(program) == ([(6, [0, 0, 5])] + slot(0) + [(8, [10, 0, 5])] + slot(10) + slot(15)
                               + [(10, [20, 0, 50])])
    assert program.blocks[-1].line == 11 and program.blocks[-1].reason == "M30"
    # the run order of the source lines: main 1-7, O1001 12-17, main 8-9, O1001 twice, main 10-11
    assert program.segments == ((1, 7), (12, 17), (8, 9), (12, 17), (12, 17), (10, 11))
    feeds = [(b.line, b.feed / MPM, b.feed_line) for b in program.blocks if isinstance(b, Linear)]
    assert feeds == [(13, pytest.approx(200), 13), (14, pytest.approx(300), 14)] * 3


def test_packed_p_and_l_repeat_the_same_way():
    with_l = interpret(POST)
    packed = interpret(POST.replace("M98 P1001 L2", "M98 P21001"))
    three = interpret(POST.replace("M98 P1001 L2", "M98 P31001"))
    assert packed.blocks == with_l.blocks
    assert len([b for b in three.blocks if isinstance(b, Linear)]) == 2 * 4  # 1 + 3 calls, 2 feeds each
    assert _mm(three.blocks[-2].end) == [25, 0, 50]  # slots at X0, X10, X15, X20 -> ends at X25


def test_program_without_calls_is_one_segment_and_text_after_m30_is_not_read():
    program = interpret("G0 X1\nM30\nthis is not G-code (\nO12\nG1 X1 F100\nM99\n")
    assert program.segments == ((1, 2),)
    assert _moves(program) == [(1, [1, 0, 0])]


def test_move_in_the_m98_block_runs_first_and_modes_carry_over():
    text = ("G90 G0 X0 Y0 Z0\nG1 F100\nX10. M98 P7\nX1.\nY2. F50\nM30\n"
            "O7\nG91 X1. F200\nM99\n")
    program = interpret(text)
    # line 3 moves to X10 (G90) and calls O7: G91 X+1 -> X11; O7 leaves G91 on, so line 4 is X+1 -> X12
    assert _moves(program) == [(1, [0, 0, 0]), (3, [10, 0, 0]), (8, [11, 0, 0]), (4, [12, 0, 0]),
                               (5, [12, 2, 0])]
    lin = {b.line: b for b in program.blocks if isinstance(b, Linear)}
    # the subprogram's F200 stays modal after the return: line 4 runs at 200 mm/min, set by line 8
    assert lin[4].feed == pytest.approx(200 * MPM) and lin[4].feed_line == 8
    assert lin[5].feed == pytest.approx(50 * MPM)


def test_nesting_two_deep():
    text = ("G0 X0 Y0 Z0\nM98 P1\nG0 Z9.\nM30\n"
            "O1\nG0 X1.\nM98 P2 L2\nG0 X5.\nM99\n"
            "(between programs)\n"
            "O2\nG91 G0 Y1.\nG90\nM99\n%\n")
    program = interpret(text)
    assert _moves(program) == [(1, [0, 0, 0]), (6, [1, 0, 0]), (12, [1, 1, 0]), (12, [1, 2, 0]),
                               (8, [5, 2, 0]), (3, [5, 2, 9])]
    assert program.segments == ((1, 2), (5, 7), (11, 14), (11, 14), (8, 9), (3, 4))


def test_canned_cycle_modal_through_a_subprogram_hole_pattern():
    text = ("G90 G0 X0 Y0 Z10.\nG81 Z-2. R1. F100 K0\nM98 P10\nG80\nM30\n"
            "O10\nX5. Y5.\nX15.\nM99\n")
    program = interpret(text)
    bottoms = [(b.line, _mm(b.end)) for b in program.blocks if isinstance(b, Linear)]
    assert bottoms == [(7, [5, 5, -2]), (8, [15, 5, -2])]


def test_overrides_of_subprogram_lines_equal_rewriting_the_file():
    # independent reference: the writer changes the words in the file, the interpreter runs it again
    text = ("G90 G0 X0 Y0 Z0\nS1000 M3\nG1 F100\nM98 P5\nG1 F120\nM98 P5 L2\nX0\nM30\n"
            "O5\nG91 X1.\nY1. F300\nG90\nM99\n")
    program = interpret(text)
    for feed_lines, spindle_lines in (({10: 77.0}, {}), ({5: 66.0}, {}), ({11: 55.0, 3: 44.0}, {10: 2000.0}),
                                      ({}, {7: 1500.0, 11: 900.0})):
        rewritten = interpret(rewrite_program(text, feed_lines, spindle_lines))
        blocks = insert_spindle_commands(program.blocks, list(spindle_lines), program.segments)
        feeds, speeds = resolve_values(blocks, 1, {k: v * MPM for k, v in feed_lines.items()},
                                       {k: v * RPM for k, v in spindle_lines.items()}, program.segments)
        assert [type(b) for b in blocks] == [type(b) for b in rewritten.blocks]
        assert [b.line for b in blocks] == [b.line for b in rewritten.blocks]
        for i, b in enumerate(rewritten.blocks):
            if isinstance(b, Linear):
                assert feeds[0, i] == pytest.approx(b.feed, rel=1e-12), (feed_lines, b)
            elif isinstance(b, SpindleSpeed):
                assert speeds[0, i] == pytest.approx(b.speed, rel=1e-12), (spindle_lines, b)


ONE_LINE_SUB = "G90 G0 X0 Y0 Z0\nS1000 M3\nG1 F100\nM98 P2\nM98 P2 L2\nM30\nO2\nG91 X1. M99\n"


@pytest.mark.parametrize("feed_lines, spindle_lines", [({}, {8: 2000.0}), ({}, {8: 2000.0, 5: 700.0}),
                                                       ({8: 50.0}, {8: 2500.0})])
def test_every_run_of_a_one_line_subprogram_gets_its_override(feed_lines, spindle_lines):
    # the runs of line 8 follow each other with no block in between (the M98 lines make none); the reference is
    # the file with the S (F) words written into line 8 (and line 5): a spindle command before each of the 3 runs
    from fmus_src.nck.overrides import apply_overrides

    program = interpret(ONE_LINE_SUB)
    rewritten = interpret(rewrite_program(ONE_LINE_SUB, feed_lines, spindle_lines))
    blocks, feeds, speeds = apply_overrides(program, 1, {k: v * MPM for k, v in feed_lines.items()},
                                            {k: v * RPM for k, v in spindle_lines.items()})
    assert [(type(b), b.line) for b in blocks] == [(type(b), b.line) for b in rewritten.blocks]
    assert sum(isinstance(b, SpindleSpeed) and b.line == 8 for b in blocks) == 3
    for i, b in enumerate(rewritten.blocks):
        if isinstance(b, Linear):
            assert feeds[0, i] == pytest.approx(b.feed, rel=1e-12)
        elif isinstance(b, SpindleSpeed):
            assert speeds[0, i] == pytest.approx(b.speed, rel=1e-12)


def test_kernel_batch_member_override_of_a_one_line_subprogram_reaches_every_run():
    from fmus_src.nck import NCKernel

    over = np.array([2000.0, 3000.0]) * RPM  # member 0, member 1
    k = NCKernel(program_text=ONE_LINE_SUB, batch=2)
    k.set_overrides(spindle={8: over, 5: np.array([500.0, 600.0]) * RPM})
    k.setup(0.0)
    kinds = [(type(b).__name__, b.line) for b in k.blocks_]
    run = [("SpindleSpeed", 8), ("Linear", 8)]
    # S1000 (line 2); run 1 of line 8; line 5's command; runs 2 and 3 of line 8, each with its own command
    assert kinds == ([("Rapid", 1), ("SpindleSpeed", 2)] + run + [("SpindleSpeed", 5)] + run + run
                     + [("ProgramEnd", 6)])
    # each member's commanded speed while a line-8 feed runs is its override of line 8 (G91 X1. three times)
    for m in range(2):
        moving = (k.plan_.line[m] == 8) & (k.plan_.position[m, :, 0] > 1e-6)
        x_end = k.plan_.position[m, -1, 0]
        assert x_end == pytest.approx(3e-3, abs=1e-9)
        assert moving.any() and np.allclose(k.plan_.spindle_ref[m, moving], over[m])


def test_a_spindle_override_on_a_line_that_never_runs_is_an_error():
    program = interpret(POST)
    with pytest.raises(NCParameterError, match="line 18: the line is never executed"):
        insert_spindle_commands(program.blocks, [18], program.segments)


@pytest.mark.parametrize("text, line, word, fragment", [
    ("M98 P2\nM30\nO1\nM99\nO3\nM99\n", 1, "M98 P2", "O1 (line 3), O3 (line 5)"),
    ("M98 P2\nM30\n", 1, "M98 P2", "none"),
    ("G0 X1\nM99\nM30\n", 2, "M99", "M99 in the main program"),
    ("M98 P1\nM30\nO1\nG0 X1\nM98 P1\nM99\n", 5, "M98 P1", "recursion"),
    ("M98 P1\nM30\nO1\nM99 P20\n", 4, "P20", "the main program has no block N20"),
    ("M98 P1\nM30\nN20 G0 X1\nO1\nM99 P20\n", 5, "P20", "the main program has no block N20"),  # after M30
    ("M98 P1\nN20 M30\nO1\nM99 P2.5\n", 4, "P2.5", "not a sequence number"),
    ("G0 X1\nM99 P10\nN10 M30\n", 2, "M99", "M99 in the main program"),
    ("O2000\nG0 X1.\nM99\nO1000\nM98 P2000\nM30\n%\n", 3, "M99", "M99 before program O1000 (line 4): "
     "subprograms written before the main program are not supported"),
    ("G0 X1 L2\nM30\n", 1, "L2", "outside an M98"),
    ("M98 P21001 L3\nM30\nO1001\nM99\n", 1, "P21001", "packs a repeat count"),
    ("M98 P1 L0\nM30\nO1\nM99\n", 1, "L0", "1..9999"),
    ("M98\nM30\n", 1, "M98", "without a P word"),
    ("M98 P1.5\nM30\n", 1, "P1.5", "not a program number"),
    ("M98 P1 M30\nO1\nM99\n", 1, "M30", "in separate blocks"),
    ("G4 P100 M98 P1\nM30\n", 1, "P1", "appears twice"),
    ("G28 Z0 M98 P1\nM30\nO1\nM99\n", 1, "G28", "G28 and M98"),
    ("M98 P1\nM30\nO1\nG0 X1\nO2\nM99\n", 3, "O1", "no M99 before line 5"),
    ("M98 P1\nM30\nO1\nG0 X1\n", 3, "O1", "before the end of the file"),
    ("M98 P1\nM30\nO1\nM99\nO1\nM99\n", 5, "O1", "defined twice (first at line 3)"),
    ("M98 P1\nM30\nO1\nG0 X1 (\nM99\n", 4, "(", "not closed"),
])
def test_errors_name_the_line(text, line, word, fragment):
    with pytest.raises(GCodeError) as info:
        interpret(text, "sub.nc")
    err = info.value
    assert err.line == line and err.word == word, str(err)
    assert fragment in str(err) and str(err).startswith(f"sub.nc:{line}: ")


def test_nesting_limit_is_ten_levels():
    def chain(depth: int) -> str:
        subs = "".join(f"O{n}\nM98 P{n + 1}\nM99\n" for n in range(1, depth)) + f"O{depth}\nG0 X1\nM99\n"
        return "M98 P1\nM30\n" + subs

    assert _moves(interpret(chain(10))) == [(31, [1, 0, 0])]  # O10 at line 3 + 3 * 9 = 30, its G0 at 31
    with pytest.raises(GCodeError, match="would nest 11 levels") as info:
        interpret(chain(11))
    assert info.value.line == 31  # the M98 P11 inside O10 (O<n> at line 3 + 3 (n - 1), O10 at line 30)


def test_optimize_keeps_the_subprogram_structure(tmp_path):
    from orchestrator.case import load_case
    from orchestrator.optimize import OptimizeSettings, build_reference, optimize
    from orchestrator.simulate import simulate

    # paper_part's stock and tool; the slots across the block are cut by the subprogram's line 16
    text = ("%\nO1000 (MAIN)\nG21 G17 G40 G49 G90 G94\nG54\nT1 M6\nS6000 M3\nG0 X-5. Y6. Z1.\nM98 P1001\n"
            "G0 X-5. Y14.\nM98 P1001\nG0 Z50.\nM5\nM30\n"
            "O1001 (SLOT)\nG91 G1 Z-2. F200\nX40. F600\nG0 Z2.\nG90\nM99\n%\n")
    (tmp_path / "case.toml").write_text('program = "sub.nc"\n[stock]\nmin = [0.0, 0.0, -10.0]\n'
                                        'max = [30.0, 20.0, 0.0]\n[tool]\ndiameter_mm = 6.0\nflutes = 2\n')
    (tmp_path / "sub.nc").write_text(text)
    settings = OptimizeSettings(objective="time", load_limit_N=200.0, feed_range=(100.0, 900.0), pop=4, gens=1,
                                seed=3, progress=False, plot=False, check_front=False)
    reference = build_reference(load_case(tmp_path), ranges=settings.ranges(), load_limit_N=settings.load_limit_N)
    assert reference.context.lines.tolist() == [16]  # one optimiser line, run twice
    out = tmp_path / "opt"
    result = optimize(case=tmp_path, settings=settings, out=out, reference=reference)
    written = (out / "optimized.nc").read_text()
    strip = re.compile(r"\s*[FS]\s*[0-9.]+")
    old, new = text.splitlines(), written.splitlines()
    assert [strip.sub("", ln) for ln in new] == [strip.sub("", ln) for ln in old]
    assert [ln for ln in new if "M98" in ln or "M99" in ln or ln.startswith("O")] == \
        [ln for ln in old if "M98" in ln or "M99" in ln or ln.startswith("O")]
    again = interpret(written, "optimized.nc")
    feed = result.X["L0016.feed"]
    line16 = [b for b in again.blocks if isinstance(b, Linear) and b.line == 16]
    assert len(line16) == 2 and all(b.feed == pytest.approx(feed * MPM, rel=1e-12) for b in line16)
    # the optimiser's batched (override) run of the chosen feeds equals the written file run alone
    alone = simulate(out / "optimized.nc", case=tmp_path, plot=False)
    assert alone.success and alone.summary["cycle_time_s"] == result.after["cycle_time_s"]


def test_runaway_repeat_counts_stop_with_an_error_naming_the_outer_call(monkeypatch):
    import fmus_src.nck.interpreter as interpreter

    monkeypatch.setattr(interpreter, "MAX_CALLED_LINES", 50)
    text = "G0 X0\nM98 P1 L9999\nM30\nO1\nM98 P2 L9999\nM99\nO2\nG91 G0 X1.\nM99\n"
    with pytest.raises(GCodeError, match="more than 50 lines") as info:
        interpret(text)
    assert info.value.line == 2


def test_block_deleted_m99_is_skipped_when_the_switch_is_on():
    from fmus_src.nck.interpreter import InterpreterSettings

    text = "M98 P1\nM30\nO1\nG0 X1.\n/M99\nG0 X2.\nM99\n"
    assert _moves(interpret(text)) == [(4, [1, 0, 0])]
    on = interpret(text, settings=InterpreterSettings(block_delete=True))
    assert _moves(on) == [(4, [1, 0, 0]), (6, [2, 0, 0])]


def test_g80_in_the_m98_block_and_a_drilling_code_rejected():
    assert _moves(interpret("G80 M98 P1\nM30\nO1\nG0 X3.\nM99\n")) == [(4, [3, 0, 0])]
    with pytest.raises(GCodeError, match="G81 and M98 in one block"):
        interpret("G81 Z-1. R1. F100 M98 P1\nM30\nO1\nM99\n")


# ------------------------------------------------------------------ M99 P<seq> (FANUC: return to N<seq>)
def test_m99_p_returns_to_the_sequence_number_in_the_main_program():
    text = "G90 G0 X0 Y0 Z0\nM98 P100\nN10 G0 X1.\nN20 G0 X2.\nM30\nO100\nG0 Y5.\nM99 P20\n"
    program = interpret(text)
    # line 3 (N10, the block after the M98) is skipped: the sub returns to N20 at line 4
    assert _moves(program) == [(1, [0, 0, 0]), (7, [0, 5, 0]), (4, [2, 5, 0])]
    assert program.segments == ((1, 2), (6, 8), (4, 5))


def test_m99_p_searches_the_calling_subprogram_not_the_main_program():
    # O2 is called by O1: M99 P6 goes to O1's N6 (line 7), not to the main program's N6 (line 2)
    text = "M98 P1\nN6 G0 X9.\nM30\nO1\nM98 P2\nN5 G0 X1.\nN6 G0 X2.\nM99\nO2\nG0 Y1.\nM99 P6\n"
    assert _moves(interpret(text)) == [(10, [0, 1, 0]), (7, [2, 1, 0]), (2, [9, 1, 0])]


def test_m99_p_repeats_the_subprogram_first_and_jumps_at_the_last_return():
    text = "M98 P100 L3\nG0 Z1.\nN20 G0 Y2.\nM30\nO100\nG91 G0 X1.\nG90\nM99 P20\n"
    assert _moves(interpret(text)) == [(6, [1, 0, 0]), (6, [2, 0, 0]), (6, [3, 0, 0]), (3, [3, 2, 0])]


def test_a_backward_jump_that_reaches_the_end_is_fine_and_an_endless_one_is_an_error():
    # N1 calls O2 (back to N3: M30) the second time round: O1 jumps back to N1 once, which then ends
    ok = "N1 M98 P2\nM98 P1\nN3 M30\nO1\nG0 X1.\nM99 P1\nO2\nG0 Y1.\nM99 P3\n"
    assert _moves(interpret(ok)) == [(8, [0, 1, 0])]
    ok2 = "N1 G0 Z1.\nM98 P1\nM30\nO1\nG91 G0 X1.\nG90\nM99 P1\n"
    with pytest.raises(GCodeError, match="repeats the program endlessly") as info:
        interpret(ok2)
    assert info.value.line == 7 and info.value.word == "P1"


def test_repeat_counts_are_projected_after_one_pass_without_macro_lines(monkeypatch):
    import fmus_src.nck.interpreter as interpreter

    # O2 runs 3 lines a pass (its O line, the move, M99); O1 runs its O line, the M98 P2 line, 9999 * 3 and its
    # M99 = 30000 lines in its first pass, and its 9998 passes still to come 9998 * 30000 more: far beyond a cap
    # of 10**6, which the first pass itself does not reach
    monkeypatch.setattr(interpreter, "MAX_CALLED_LINES", 10**6)
    text = "G0 X0\nM98 P1 L9999\nM30\nO1\nM98 P2 L9999\nM99\nO2\nG91 G0 X1.\nM99\n"
    with pytest.raises(GCodeError, match="more than 1000000 lines") as info:
        interpret(text)
    assert info.value.line == 2
    assert "O1 (called at line 2) ran 30000 lines in a pass" in str(info.value)
    assert f"{9998 * 30000} more" in str(info.value)


def test_repeat_counts_with_macro_lines_are_not_projected(monkeypatch):
    import fmus_src.nck.interpreter as interpreter

    # each pass of O1 counts #100; its passes stop counting once #100 reaches 3 (a GOTO skips the move), so the
    # lines of later passes are not those of the first: only the cap judges them, and 5 passes stay far below it
    monkeypatch.setattr(interpreter, "MAX_CALLED_LINES", 40)
    text = ("M98 P1 L5\nM30\nO1\n#100 = #100 + 1\nIF [#100 GT 3] GOTO 9\nG91 G0 X1.\nN9 M99\n")
    program = interpret(text)
    assert _moves(program) == [(6, [1, 0, 0]), (6, [2, 0, 0]), (6, [3, 0, 0])]
