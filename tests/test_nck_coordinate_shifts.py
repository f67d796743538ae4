"""G52 local coordinate system, G92 workpiece coordinate system setting, G92.1/G92.2/G92.3.

Expected machine positions are derived by hand: machine = programmed + work offset + G52 shift + G92 shift
(+ tool length on Z), the G92 shift chosen so that the current tool-tip position gets the given coordinates.
"""
from __future__ import annotations

import pytest

from fmus_src.nck import GCodeError, InterpreterSettings, Linear, Rapid, interpret

MM = 1e-3
G54 = (100.0, 50.0, -200.0)  # mm
G55 = (300.0, -40.0, -150.0)  # mm


def settings(**kw) -> InterpreterSettings:
    offsets = {54: tuple(v * MM for v in G54), 55: tuple(v * MM for v in G55)}
    return InterpreterSettings(work_offsets=offsets, **kw)


def ends(text: str, **kw) -> list[tuple[float, float, float]]:
    """Machine end points of the moves (mm)."""
    blocks = interpret(text, "shift.nc", settings(**kw)).blocks
    return [tuple(round(v / MM, 9) for v in b.end) for b in blocks if isinstance(b, (Rapid, Linear))]


def error(text: str, **kw) -> GCodeError:
    with pytest.raises(GCodeError) as info:
        interpret(text, "shift.nc", settings(**kw))
    assert str(info.value).startswith(f"shift.nc:{info.value.line}:")
    return info.value


def test_g92_makes_the_current_position_the_given_coordinates():
    # G0 X10 Y0 is at machine X 110; G92 X0 makes that X0, so X5 is machine 110 + 5 = offset + 15
    assert ends("G0 X10 Y0\nG92 X0 Y0\nG0 X5\nM30\n") == [(110.0, 50.0, 0.0), (115.0, 50.0, 0.0)]


def test_g92_names_axes_only_and_does_not_move():
    text = "G0 X10 Y20 Z30\nG92 X0\nG0 X1 Y1\nM30\n"
    blocks = interpret(text, "shift.nc", settings()).blocks
    assert [b.line for b in blocks if isinstance(b, Rapid)] == [1, 3]  # no block from line 2
    # X: 110 is now X0 -> X1 = 111; Y unshifted: Y1 = 50 + 1
    assert ends(text)[-1] == (111.0, 51.0, -170.0)


def test_g92_under_g91_adds_the_increment_to_the_current_coordinates():
    # X10 (machine 110), G91 G92 X5: the current position becomes X15, so G90 X20 is 5 further: 115
    assert ends("G0 X10\nG91 G92 X5\nG90 G0 X20\nM30\n")[-1][0] == 115.0


def test_g92_counts_the_tool_tip_and_keeps_the_tool_length_offset():
    # G43 H1 (100 mm) Z50: machine Z = -200 + 50 + 100 = -50. G92 Z0 makes the tip Z0; Z10 then goes 10 up
    text = "G43 H1 G0 Z50\nG92 Z0\nG0 Z10\nM30\n"
    assert ends(text, tool_lengths=(100 * MM,)) == [(0.0, 0.0, -50.0), (0.0, 0.0, -40.0)]


def test_g92_shifts_every_work_coordinate_system():
    # G92 X0 at machine 110 shifts by +10: G55 X0 is then 300 + 10; machine positions (G53) are not shifted
    text = "G0 X10\nG92 X0\nG55 G0 X0\nG53 X7\nM30\n"
    assert [e[0] for e in ends(text)] == [110.0, 310.0, 7.0]


def test_g52_local_origin_in_all_work_systems_and_per_axis_cancel():
    text = ("G52 X10 Y5\nG0 X1 Y1\n"  # G54 + (10, 5) + (1, 1)
            "G55 G0 X0 Y0\n"  # G55 + (10, 5)
            "G52 X0\nG0 X0 Y0\n"  # X cancelled, Y keeps its 5
            "M30\n")
    assert [e[:2] for e in ends(text)] == [(111.0, 56.0), (310.0, -35.0), (300.0, -35.0)]


def test_g52_does_not_move_and_machine_moves_ignore_it():
    text = "G0 X2\nG52 X10\nG53 X0\nG28 X0\nG0 X0\nM30\n"
    blocks = interpret(text, "shift.nc", settings()).blocks
    assert not [b for b in blocks if getattr(b, "line", 0) == 2]
    e = ends(text)
    assert e[1][0] == 0.0  # G53 X0: the machine zero
    assert e[2][0] == 110.0  # G28 X0: the intermediate point is a work position (local X0 = 100 + 10)
    assert e[3][0] == pytest.approx(380.0)  # then the reference position, unshifted
    assert e[4][0] == 110.0


def test_g92_cancels_the_g52_shift_of_the_named_axes():
    # G52 X10 Y10, G0 X0 Y0 at machine (110, 60). G92 X0 cancels the local X shift (the G92 shift becomes 10 so
    # that X stays 0); a new G52 X3 then adds 3 to the G92 shift: X0 -> 113. Y keeps the local 10 (G52 X3 does
    # not name Y): Y0 -> 60.
    text = "G52 X10 Y10\nG0 X0 Y0\nG92 X0\nG52 X3\nG0 X0 Y0\nM30\n"
    assert ends(text)[-1][:2] == (113.0, 60.0)


def test_g92_1_preset_cancels_g92_and_g52_on_the_named_axes():
    text = "G52 Y7\nG0 X10 Y0\nG92 X0\nG92.1 X0 Y0\nG0 X5 Y5\nM30\n"
    assert ends(text)[-1][:2] == (105.0, 55.0)
    text = "G52 Y7\nG0 X10 Y0\nG92 X0\nG92.1 X0\nG0 X5 Y5\nM30\n"  # Y keeps its local shift
    assert ends(text)[-1][:2] == (105.0, 62.0)


def test_linuxcnc_g92_1_g92_2_g92_3():
    base = "G0 X10 Y10\nG92 X0 Y0\n"
    assert ends(base + "G92.1\nG0 X1 Y1\nM30\n")[-1][:2] == (101.0, 51.0)
    # G92.2 suspends (X1 at 100 + 1), G92.3 restores (X1 at 110 + 1)
    e = ends(base + "G92.2\nG0 X1 Y1\nG92.3\nG0 X1 Y1\nM30\n")
    assert [p[:2] for p in e[-2:]] == [(101.0, 51.0), (111.0, 61.0)]
    # G92.3 without a suspended shift changes nothing; after G92.1 there is nothing to restore
    assert ends(base + "G92.3\nG0 X1\nM30\n")[-1][0] == 111.0
    assert ends(base + "G92.2\nG92.1\nG92.3\nG0 X1\nM30\n")[-1][0] == 101.0


def test_incremental_moves_and_the_programmed_position_after_a_shift():
    # after G92 X0 at machine 110, G91 X5 moves 5 (the shift does not move the tool); G90 X0 returns to 110
    assert [e[0] for e in ends("G0 X10\nG92 X0\nG91 G0 X5\nG90 G0 X0\nM30\n")] == [110.0, 115.0, 110.0]


@pytest.mark.parametrize("text, line, word, fragment", [
    ("G91 G52 X1\nM30\n", 1, "G52", "G91"),
    ("G52\nM30\n", 1, "G52", "without an axis word"),
    ("G92 I1\nM30\n", 1, "I1", "word I"),
    ("G0 X1\nG1 G92 X0 F100\nM30\n", 2, "G1", "motion G code"),
    ("G81 X0 Y0 Z-1 R1 F100\nG92 X0\nM30\n", 2, "G92", "canned-cycle mode"),
    ("G92.1 X1\nM30\n", 1, "X1", "G92.1"),
    ("G92.2 X0\nM30\n", 1, "X0", "alone"),
    ("G0 X0\nG41 D1 G1 X10 F100\nG92 X0\nM30\n", 3, "G92", "cutter compensation"),
    ("G52 X1 ,C1\nM30\n", 1, ",C1", "not a G1 move"),
])
def test_errors_name_the_line_and_word(text, line, word, fragment):
    exc = error(text, tool_radii=(3 * MM,))
    assert (exc.line, exc.word) == (line, word)
    assert fragment in str(exc)


def test_shifts_are_allowed_under_zero_radius_compensation():
    # a CAM "wear"-mode post (D = 0): G41 runs as programmed and G92 is fine
    assert ends("G41 D1 G0 X10\nG92 X0\nG1 X5 F100\nG40 G0 X0\nM30\n", tool_radii=(0.0,))[1][0] == 115.0
