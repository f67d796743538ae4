"""Interpreter: modal behaviour, coordinates, arcs, units, offsets, errors with line numbers."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.errors import CncTwinError
from fmus_src.nck import (
    Arc, Coolant, Dwell, GCodeError, InterpreterSettings, Linear, ProgramEnd, Rapid, SpindleSpeed, SpindleStop,
    ToolChange, interpret,
)

MM = 1e-3


def motions(text: str, **kw):
    return [b for b in interpret(text, "t.nc", InterpreterSettings(**kw) if kw else None).blocks
            if isinstance(b, (Rapid, Linear, Arc))]


def test_modal_motion_feed_and_line_numbers():
    prog = "%\nO0001 (demo)\nG90 G21 G17\nG0 X10 Y5\nG1 Z-2 F120\nX20 ; still G1\n\nY8\nM30\n%\n"
    blocks = interpret(prog, "t.nc").blocks
    rap, l1, l2, l3, end = blocks
    assert isinstance(rap, Rapid) and rap.line == 4 and rap.end == pytest.approx((10 * MM, 5 * MM, 0.0))
    assert isinstance(l1, Linear) and l1.line == 5 and l1.feed == pytest.approx(120 * MM / 60)
    assert isinstance(l2, Linear) and l2.line == 6 and l2.start == l1.end and l2.feed_line == 5
    assert l2.end == pytest.approx((20 * MM, 5 * MM, -2 * MM))
    assert isinstance(l3, Linear) and l3.line == 8 and l3.end == pytest.approx((20 * MM, 8 * MM, -2 * MM))
    assert end == ProgramEnd(9, "M30")


def test_incremental_g91_and_back_to_g90():
    ms = motions("G91 G1 X10 Y10 F100\nX10\nG90 X0\n")
    assert [m.end for m in ms] == [pytest.approx(e) for e in
                                   [(0.01, 0.01, 0), (0.02, 0.01, 0), (0.0, 0.01, 0)]]


def test_inch_mode_scales_coordinates_and_feed():
    (m,) = motions("G20 G1 X1 F10\n")
    assert m.end[0] == pytest.approx(25.4 * MM)
    assert m.feed == pytest.approx(10 * 25.4 * MM / 60)


def test_work_offsets_and_tool_length():
    settings = dict(work_offsets={54: (0.1, 0.2, 0.3), 55: (-0.1, 0.0, 0.0)}, tool_lengths=[0.05, 0.07])
    ms = motions("G54 G0 X1 Y2 Z3\nG55 X1\nG43 H2 Z3\nG49 Z3\n", **settings)
    assert ms[0].end == pytest.approx((0.101, 0.202, 0.303))
    assert ms[1].end == pytest.approx((-0.099, 0.202, 0.303))  # Y, Z not programmed: they do not move
    assert ms[2].end == pytest.approx((-0.099, 0.202, 0.003 + 0.07))  # no Z work offset in G55
    assert ms[3].end[2] == pytest.approx(0.003)


def test_initial_position_and_unprogrammed_axes():
    (m,) = motions("G1 X5 F100\n", initial=(0.01, 0.02, 0.03))
    assert m.start == (0.01, 0.02, 0.03)
    assert m.end == pytest.approx((0.005, 0.02, 0.03))


def test_r_and_ijk_arcs_agree():
    a_r = motions("G1 X10 Y0 F100\nG2 X20 Y10 R10\n")[1]
    a_ijk = motions("G1 X10 Y0 F100\nG2 X20 Y10 I10 J0\n")[1]
    assert a_r.center == pytest.approx(a_ijk.center, abs=1e-12)
    assert a_r.center == pytest.approx((0.02, 0.0, 0.0))
    assert a_r.sweep == pytest.approx(-math.pi / 2)
    assert a_r.length == pytest.approx(math.pi / 2 * 0.01)


def test_negative_r_gives_the_long_arc():
    short = motions("G3 X10 Y10 R10 F100\n")[0]
    long = motions("G3 X10 Y10 R-10 F100\n")[0]
    assert short.sweep == pytest.approx(math.pi / 2)
    assert long.sweep == pytest.approx(3 * math.pi / 2)
    # CCW from (0,0) to (10,10): the short arc turns about (0,10), the long one about (10,0)
    assert short.center == pytest.approx((0.0, 0.01, 0.0))
    assert long.center == pytest.approx((0.01, 0.0, 0.0))


def test_full_circle_with_ijk_and_planes():
    (c,) = motions("G2 I5 F100\n")
    assert c.end == c.start and c.sweep == pytest.approx(-2 * math.pi)
    assert c.length == pytest.approx(2 * math.pi * 0.005)
    (z,) = motions("G18 G3 X10 Z0 K0 I5 F100\n")  # ZX plane, half circle over +-Z
    assert z.plane == "ZX" and z.center == pytest.approx((0.005, 0, 0)) and abs(z.sweep) == pytest.approx(math.pi)
    (h,) = motions("G17 G3 X0 Y0 Z-2 I5 F100\n")  # helix: one turn, 2 mm down
    assert h.length == pytest.approx(math.hypot(2 * math.pi * 0.005, 0.002))


def test_spindle_tool_coolant_dwell_blocks():
    prog = "T3 M6\nS1200 M3\nM8\nG4 P1500\nG4 X0.5\nG4 P1.5\nS2000\nM4\nM5\nM9\nM2\n"
    b = interpret(prog).blocks
    assert b[0] == ToolChange(1, 3, at_rest=True)
    assert b[1] == SpindleSpeed(2, pytest.approx(1200 * 2 * math.pi / 60), 1, 2)
    assert b[2] == Coolant(3, True)
    assert [x.seconds for x in b[3:6]] == [pytest.approx(1.5), pytest.approx(0.5), pytest.approx(1.5)]
    assert isinstance(b[3], Dwell)
    assert b[6].direction == 1 and b[6].speed_line == 7
    assert b[7].direction == -1 and b[7].speed_line == 7
    assert b[8] == SpindleStop(9) and b[9] == Coolant(10, False) and b[10] == ProgramEnd(11, "M2")


def test_end_of_file_and_lines_after_m30():
    assert interpret("G0 X1\n").blocks[-1] == ProgramEnd(1, "end of file")
    blocks = interpret("G0 X1\nM30\nG95 THIS IS NOT READ\n").blocks
    assert blocks[-1] == ProgramEnd(2, "M30")


def test_block_delete():
    on = interpret("G0 X1\n/G0 X2\n", settings=InterpreterSettings(block_delete=True)).blocks
    off = interpret("G0 X1\n/G0 X2\n").blocks
    assert len(on) == 2 and len(off) == 3


@pytest.mark.parametrize(
    "text, line, word, fragment",
    [
        ("G0 X0\nG1 X10 F100\nG2 X20 Y0 R0.5\n", 3, "R0.5", "smaller than half the chord"),
        ("G0 X0\nG1 X10\n", 2, "G1", "no feed rate"),
        ("G0 X0\n\nG95 G1 X1 F1\n", 3, "G1", "feed per revolution G95 G1 feed move while the spindle is stopped"),
        ("G41 D1 X1\n", 1, "D1", "tool radius offset number D1 does not exist"),
        ("G0 X0\nG7 X1\n", 2, "G7", "not supported"),
        ("M99\n", 1, "M99", "M99 in the main program"),
        ("G0 G1 X1 F1\n", 1, "G1", "modal group"),
        ("G0 X1.2.3\n", 1, "X1.2.3", "malformed number"),
        ("G0 X\n", 1, "X", "no value"),
        ("G1 X1 F100\nG2 X20 Y0 I5 J0\n", 2, "G2", "from the centre"),
        ("G43 H7 Z1\n", 1, "H7", "does not exist"),
        ("G0 X1 X2\n", 1, "X2", "twice"),
        ("G0 A10\n", 1, "A10", "not supported"),
        ("G1 X1 F100 (open comment\n", 1, "(", "not closed"),
        ("M6\n", 1, "M6", "no tool"),
        ("G2 I0 J0 F100\n", 1, "G2", "centre coincides"),
    ],
)
def test_errors_name_file_line_word(text, line, word, fragment):
    with pytest.raises(GCodeError) as info:
        interpret(text, "part.nc", InterpreterSettings(tool_lengths=[0.0, 0.0]))
    err = info.value
    assert isinstance(err, CncTwinError)
    assert err.file == "part.nc" and err.line == line and err.word == word
    assert fragment in str(err) and str(err).startswith(f"part.nc:{line}: ")
    assert "expected" in str(err)


def test_error_message_of_small_radius_matches_house_style():
    with pytest.raises(GCodeError) as info:
        interpret("G1 X0 F100\nX0\nX0\nX0\nX0\nX0\nX0\nX0\nX0\nX0\nX0\nG2 X10 R0.5\n", "part.nc")
    assert str(info.value) == ("part.nc:12: 'G2 X10 R0.5': arc radius 0.5 mm is smaller than half the chord "
                               "(5 mm); expected R >= 5")


def test_ijk_radius_tolerance_like_ps0020():
    # end radius 10.0015 mm vs start 10 mm: within 0.002 mm -> accepted, spiral arc ends exactly at the end point
    (a,) = motions("G3 X-10.0015 Y0 I-10 J0 F100\n", initial=(0.01, 0.0, 0.0))
    assert a.end == pytest.approx((-0.0100015, 0.0, 0.0))
    with pytest.raises(GCodeError):
        motions("G3 X-10.0025 Y0 I-10 J0 F100\n", initial=(0.01, 0.0, 0.0))


def test_parses_a_100000_line_program():
    rng = np.random.default_rng(1)
    xs = rng.uniform(0, 100, 100_000)
    body = "\n".join(f"N{i} G1 X{x:.3f} Y{(i % 50):d}. F{500 + i % 7}" for i, x in enumerate(xs))
    prog = interpret("G90 G21\n" + body + "\nM30\n")
    assert len(prog.blocks) == 100_001
    assert prog.blocks[-2].line == 100_001
    assert prog.blocks[-2].end[0] == pytest.approx(round(xs[-1], 3) * MM)
