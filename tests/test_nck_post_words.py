"""Words found by the CAM post sweep (``tests/fixtures/cam_posts``) that leave the tool path alone.

Mazak EIA ``G61.1 [P0..P3]`` (geometry compensation, a continuous cutting mode like G64) and ``G5 P2``
(high-speed machining mode), read without effect on the path; rotary words at 0 (Mastercam's ``A0.``, also in
G10 and G28 blocks). L as a canned cycle's repeat count: ``test_nck_unseen_programs.py``.
"""
from __future__ import annotations

import re

import pytest

from fmus_src.nck.blocks import Dwell, Linear, Rapid
from fmus_src.nck.component import N_TOOL_LENGTHS
from fmus_src.nck.errors import GCodeError
from fmus_src.nck.interpreter import interpret
from fmus_src.nck.settings import InterpreterSettings

PATH = "G0 X0 Y0 Z5.\nG1 Z-1. F300.\nX10.\nY10.\nX0.\n"


def _exact(text: str) -> list[bool]:
    return [b.exact_stop for b in interpret(text, "m.nc").blocks if isinstance(b, Linear)]


@pytest.mark.parametrize("mode", ["G61.1", "G61.1 P0", "G61.1 P3"])
def test_mazak_geometry_compensation_is_a_continuous_cutting_mode(mode):
    """G61.1 after G61 ends the exact stop, as G64 does; the blocks equal those of the program under G64."""
    text = f"G61\n{mode}\n{PATH}"
    assert _exact(text) == [False] * 4
    assert interpret(text, "m.nc").blocks == interpret(f"G61\nG64\n{PATH}", "m.nc").blocks
    assert _exact(f"{mode}\nG61\n{PATH}") == [True] * 4  # G61 after it stops at every block


def test_path_mode_system_variable_reads_61_1():
    # #4015 / 100 as a dwell in seconds (input increment 0.001 s): 0.611 s under G61.1, 0.64 s under G64
    program = interpret("G61.1 P2\n#1 = #4015\nG4 X[#1 / 100]\nG64\n#1 = #4015\nG4 X[#1 / 100]\n", "m.nc")
    assert [b.seconds for b in program.blocks if isinstance(b, Dwell)] == pytest.approx([0.611, 0.64])


@pytest.mark.parametrize("text, word, message", [
    ("G61.1 P5\n", "P5", r"G61\.1 P5 is not a machining-mode level \(Mazak: P0 rough"),
    ("G61.1 P1.\n", "P1.", r"not a machining-mode level"),
    ("G0 Z5.\nG81 X1. Z-1. R1. F100. G61.1 P1\n", "P1", r"P would be read twice"),
])
def test_mazak_geometry_compensation_level_errors_name_the_word(text, word, message):
    with pytest.raises(GCodeError, match=message) as info:
        interpret(text, "m.nc")
    assert info.value.word == word and info.value.line == text.count("\n")


def test_mazak_high_speed_mode_g5_p2_is_read_like_hpcc():
    assert interpret(f"G5 P2\n{PATH}G5 P0\n", "m.nc").blocks == interpret(f"G5 P10000\n{PATH}G5 P0\n", "m.nc").blocks
    with pytest.raises(GCodeError, match=r"G5 P3 is not a supported mode; expected G5 P0, G5 P2, G5 P10000"):
        interpret("G5 P3\n", "m.nc")


@pytest.mark.parametrize("block", ["G90 G10 L2 P1 X1. Y2. Z3. B0.", "G0 G90 G54 X5. Y5. A0. S5000 M3", "G28 X0. Y0. C0.",
                                   "A0.", "G91 G0 X1. A0."])
def test_rotary_word_at_zero_changes_nothing(block):
    """Mastercam's 4-axis-ready 3-axis output: the rotary word at 0 is dropped wherever it stands."""
    text = f"G0 X1. Y1. Z10.\n{block}\nG90 G1 X10. F300.\nM30\n"
    without = re.sub(r" ?[ABC]0\.", "", text)
    assert interpret(text, "m.nc").blocks == interpret(without, "m.nc").blocks


def test_e_word_outside_g187_names_where_e_is_read():
    """E changes the motion where posts write it outside G187 (Haas G0 rapid rate in percent), so it stays an error."""
    with pytest.raises(GCodeError, match=r"address E is not supported here \(E is read only in a G187 block: the "
                                         r"Haas corner rounding; E in other blocks, e\.g\. the Haas rapid rate") as info:
        interpret("G187 P1 E0.05\nG0 X10. E50.\n", "h.nc")
    assert (info.value.file, info.value.line, info.value.word) == ("h.nc", 2, "E50.")


def test_a_post_writing_h_equal_to_t_reaches_tool_150():
    """200 H registers (a Haas NGC's table): G43 H150 adds register 150's length to the commanded Z."""
    lengths = [0.0] * N_TOOL_LENGTHS
    lengths[149] = 0.1205  # H150 = 120.5 mm
    settings = InterpreterSettings(tool_lengths=lengths, tool_radii=[0.0] * N_TOOL_LENGTHS)
    blocks = interpret("G90 G0 X0 Y0\nG43 H150 Z25.\n", "m.nc", settings).blocks
    assert N_TOOL_LENGTHS == 200
    assert [b.end[2] for b in blocks if isinstance(b, Rapid)][-1] == pytest.approx(0.1455)  # 25 + 120.5 mm
    with pytest.raises(GCodeError, match=r"expected H0\.\.H200 \(integers\)"):
        interpret("G43 H201 Z25.\n", "m.nc", settings)
