"""The optimiser keeps tapping lines (G84/G74: F = pitch x S) as written, or refuses naming the line."""
from __future__ import annotations

import pytest

from fmus_src.nck import interpret
from orchestrator.optimize.context import classify_lines
from orchestrator.optimize.errors import OptimizeError
from orchestrator.optimize.tapping import check_tapping_spindle, tapping_lines

HEAD = "G90 G0 X0 Y0 Z10\nS1000 M3\nG1 Z-1 F1000\nX20\nG0 Z10\n"  # line 4 cuts


def test_tapping_line_is_never_a_cutting_line_and_its_modal_f_is_pinned():
    program = interpret(HEAD + "G98 G84 X5 Y5 Z-10. R2.\nG80\nM30\n")  # line 6 taps with the modal F1000
    assert tapping_lines(program.blocks) == {6}
    lines, s_lines, pins, f0, s0 = classify_lines(program.blocks, {4: 5.0, 6: 5.0}, 0.1)
    assert lines == [4] and f0 == [1000.0] and s0 == [1000.0]  # the tap removed material, still no gene
    assert pins == {6: 1000.0}  # F1000 written on the G84 line: a new F on line 4 cannot reach the tap


def test_an_optimiser_s_word_governing_a_tap_is_refused_naming_the_line():
    program = interpret(HEAD + "G98 G84 X5 Y5 Z-10. R2.\nG80\nM30\n")
    _, s_lines, _, _, _ = classify_lines(program.blocks, {4: 5.0}, 0.1)
    assert s_lines == [2]  # the S word of line 4 goes on line 2, still in effect at the tap on line 6
    with pytest.raises(OptimizeError) as info:
        check_tapping_spindle(program, s_lines, "p.nc")
    assert "p.nc:6:" in str(info.value) and "tapping" in str(info.value)


@pytest.mark.parametrize("tap", ["S1000 M3\nG98 G84 X5 Y5 Z-10. R2. F1000.\n", "M29 S1000\nG84 X5 Y5 Z-10. R2.\n"])
def test_a_tap_with_its_own_s_word_is_kept(tap):
    program = interpret(HEAD + tap + "G80\nM30\n")
    _, s_lines, _, _, _ = classify_lines(program.blocks, {4: 5.0}, 0.1)
    check_tapping_spindle(program, s_lines, "p.nc")  # no error: the tap runs at its own S
