"""Optional chamfer ,C and corner R ,R between G1 blocks (FANUC), their errors, and the writer round trip.

Expected numbers are plane geometry: a corner R of radius r at a change of direction theta has its tangent points
r tan(theta/2) from the corner, its centre r / cos(theta/2) from it and the length r theta; a chamfer c takes c
off both blocks and adds the chord 2 c cos(theta/2).
"""
from __future__ import annotations

import math

import pytest

from fmus_src.nck import Arc, GCodeError, InterpreterSettings, Linear, Rapid, interpret, rewrite_program
from fmus_src.nck.component import NCKernel

MM = 1e-3


def moves(text: str, **kw) -> list:
    blocks = interpret(text, "corner.nc", InterpreterSettings(**kw) if kw else None).blocks
    return [b for b in blocks if isinstance(b, (Rapid, Linear, Arc))]


def feed_length(ms: list) -> float:
    """Path length of the feed moves, mm."""
    total = 0.0
    for b in ms:
        if isinstance(b, Linear):
            total += math.dist(b.start, b.end)
        elif isinstance(b, Arc):
            total += b.length
    return total / MM


def mm(p) -> tuple[float, ...]:
    return tuple(v / MM for v in p)


def error(text: str, **kw) -> GCodeError:
    with pytest.raises(GCodeError) as info:
        interpret(text, "corner.nc", InterpreterSettings(**kw) if kw else None)
    assert str(info.value).startswith(f"corner.nc:{info.value.line}:")
    return info.value


def test_corner_r_at_a_right_angle():
    ms = moves("G0 X0 Y0\nG1 X20 F600 ,R2\nY30\nM30\n")
    a, arc, b = ms[1:]
    assert isinstance(arc, Arc) and not arc.clockwise and arc.plane == "XY"  # a left turn: G3
    assert arc.radius_start / MM == pytest.approx(2.0) and arc.radius_end / MM == pytest.approx(2.0)
    assert mm(a.end) == pytest.approx((18.0, 0.0, 0.0)) and mm(arc.start) == pytest.approx((18.0, 0.0, 0.0))
    assert mm(arc.end) == pytest.approx((20.0, 2.0, 0.0)) and mm(b.start) == pytest.approx((20.0, 2.0, 0.0))
    assert mm(arc.center) == pytest.approx((18.0, 2.0, 0.0))
    assert feed_length(ms) == pytest.approx(20 + 30 - 4 + math.pi)
    assert (arc.line, arc.feed, arc.feed_line) == (2, a.feed, 2) and a.feed == pytest.approx(600 * MM / 60)


def test_chamfer_at_a_right_angle():
    ms = moves("G0 X0 Y0\nG1 X20 F600 ,C1.\nY30\nM30\n")
    a, ch, b = ms[1:]
    assert isinstance(ch, Linear) and ch.line == 2
    assert mm(ch.start) == pytest.approx((19.0, 0.0, 0.0)) and mm(ch.end) == pytest.approx((20.0, 1.0, 0.0))
    assert a.end == ch.start and b.start == ch.end
    assert feed_length(ms) == pytest.approx(20 + 30 - 2 + math.sqrt(2))


@pytest.mark.parametrize("turn_deg", [30.0, 60.0, 135.0, -60.0])
def test_corner_r_at_any_angle(turn_deg):
    r, theta = 3.0, math.radians(abs(turn_deg))
    dx, dy = 25 * math.cos(math.radians(turn_deg)), 25 * math.sin(math.radians(turn_deg))
    ms = moves(f"G0 X0 Y0\nG1 X40 F300 ,R{r}\nG91 X{dx:.9f} Y{dy:.9f}\nM30\n")
    a, arc, b = ms[1:]
    t = r * math.tan(theta / 2)
    assert mm(a.end)[0] == pytest.approx(40 - t)
    assert math.dist(mm(b.start)[:2], (40.0, 0.0)) == pytest.approx(t)
    assert math.dist(mm(arc.center)[:2], (40.0, 0.0)) == pytest.approx(r / math.cos(theta / 2))
    assert arc.clockwise == (turn_deg < 0)
    assert abs(arc.sweep) == pytest.approx(theta)
    assert feed_length(ms) == pytest.approx(40 + 25 - 2 * t + r * theta)


def test_chamfer_at_any_angle_and_in_the_zx_plane():
    theta = math.radians(60)
    ms = moves("G18 G0 X0 Z0\nG1 Z-20 F300 ,C2\nG91 X17.320508076 Z-10\nM30\n")
    # Z-20, then 20 mm in a direction 60 deg away: the chamfer is the chord 2 c cos(theta/2)
    ch = ms[2]
    assert math.dist(ch.start, ch.end) / MM == pytest.approx(2 * 2 * math.cos(theta / 2))
    assert mm(ch.start) == pytest.approx((0.0, 0.0, -18.0))
    assert feed_length(ms) == pytest.approx(20 + 20 - 4 + 2 * 2 * math.cos(theta / 2), abs=1e-6)


def test_rounded_square_chains_corners_and_closes():
    # every corner of a 40 mm square rounded by R5 (the last one onto the first side is not: no block after)
    text = ("G0 X0 Y0\nG1 X40 F500 ,R5\nY40 ,R5\nX0 ,R5\nY0\nM30\n")
    ms = moves(text)
    arcs = [b for b in ms if isinstance(b, Arc)]
    assert [a.line for a in arcs] == [2, 3, 4]
    assert feed_length(ms) == pytest.approx(4 * 40 - 3 * 2 * 5 + 3 * 5 * math.pi / 2)
    for prev, nxt in zip(ms[1:], ms[2:]):
        assert prev.end == nxt.start  # a continuous path


def test_inch_values_and_straight_continuation():
    ms = moves("G20 G0 X0 Y0\nG1 X1. F10 ,R.1\nY1.\nM30\n")
    assert ms[2].radius_start / MM == pytest.approx(2.54)
    ms = moves("G0 X0 Y0\nG1 X10 F100 ,R2\nX20\nM30\n")  # no corner: nothing inserted
    assert len(ms) == 3 and feed_length(ms) == pytest.approx(20.0)


def test_corner_r_under_cutter_compensation_is_offset_with_the_contour():
    # a square run clockwise with G41 (tool on the left = outside), D1 = 3 mm: the outer ,R2 corners become
    # arcs of radius 2 + 3 = 5 about the same centres (2, 18) and (18, 18)
    text = ("G0 X-10 Y-10\nG41 D1 G1 X0 Y0 F600\nY20 ,R2\nX20 ,R2\nY0\nG40 G0 X30 Y-10\nM30\n")
    arcs = [b for b in moves(text, tool_radii=(3 * MM,)) if isinstance(b, Arc)]
    assert len(arcs) == 2 and all(a.clockwise for a in arcs)
    assert [a.radius_start / MM for a in arcs] == pytest.approx([5.0, 5.0])
    assert [mm(a.center)[:2] for a in arcs] == [pytest.approx((2.0, 18.0)), pytest.approx((18.0, 18.0))]


def test_planned_path_ends_where_the_program_does():
    text = "G0 X0 Y0\nG1 X20 F1200 ,R2\nY20 ,C1\nX0\nM30\n"
    kernel = NCKernel("nck", program_text=text)
    kernel.setup(0.0)
    assert kernel.plan_.position[0, -1] == pytest.approx([0.0, 0.020, 0.0], abs=1e-9)
    assert set(kernel.plan_.line[0].tolist()) >= {2, 3, 4}


@pytest.mark.parametrize("text, line, word, fragment", [
    ("G0 X0 Y0\nG1 X20 F100 ,R2\nM8\nY20\nM30\n", 2, ",R2", "PS0051"),
    ("G0 X0 Y0\nG1 X20 F100 ,R2\nG0 Y20\nM30\n", 2, ",R2", "PS0052"),
    ("G0 X0 Y0\nG1 X20 F100 ,C1\nG3 X30 Y10 R10\nM30\n", 2, ",C1", "G2/G3"),
    ("G0 X0 Y0\nG1 X20 F100 ,C1\nM30\n", 2, ",C1", "PS0051"),
    ("G0 X0 Y0\nG1 X20 F100 ,C1\n", 2, ",C1", "program ends"),
    ("G0 X0 Y0\nG1 X20 F100 ,R15\nY10\nM30\n", 2, ",R15", "PS0055"),
    ("G0 X0 Y0\nG1 X20 F100 ,C3\nY2\nM30\n", 2, ",C3", "PS0055"),
    ("G0 X0 Y0\nG1 X20 F100 ,C1 ,R1\nY10\nM30\n", 2, ",R1", "one block"),
    ("G0 X0 Y0 ,C1\nG1 X20 F100\nM30\n", 1, ",C1", "not a G1 move"),
    ("G0 X0 Y0\nG1 X20 F100\nG2 X30 Y10 R10 ,R1\nG1 Y20\nM30\n", 3, ",R1", "not supported"),
    ("G0 X0 Y0\nG1 X20 Z-1 F100 ,C1\nY10\nM30\n", 2, ",C1", "normal"),
    ("G0 X0 Y0\nG1 X20 F100 ,C1\nY10 Z-1\nM30\n", 2, ",C1", "normal"),
    ("G0 X0 Y0\nG1 X20 F100 ,C1\nG18 Z-10\nM30\n", 2, ",C1", "plane"),
    ("G0 X0 Y0\nG1 X20 F100 ,C0\nY10\nM30\n", 2, ",C0", "not positive"),
    ("G0 X0 Y0\nG1 X20 F100 ,C1 M30\n", 2, ",C1", "M30"),
    ("G0 X0 Y0\nG1 X20 F100 ,R2\nX0\nM30\n", 2, ",R2", "reverses"),
    ("G0 X0 Y0\nG1 X20 F100 ,A30\nY10\nM30\n", 2, ",A30", "not supported"),
    ("G0 X0 Y0\nG41 D1 G1 X20 F100 ,R1\nG40 Y10\nM30\n", 2, ",R1", "compensation"),
    ("G0 X0 Y0\nG81 X5 Y5 Z-1 R1 F100 ,C1\nG80\nM30\n", 2, ",C1", "not a G1 move"),
])
def test_errors_name_the_line_and_word(text, line, word, fragment):
    exc = error(text, tool_radii=(1 * MM,))
    assert (exc.line, exc.word) == (line, word)
    assert fragment in str(exc)


def test_writer_keeps_comma_words_byte_for_byte():
    text = "G0 X0 Y0\r\nG1 X20 F600 ,R2. (round)\r\nY20,C1.5\r\nX0 , r 1\r\nY0\r\nM30\r\n"
    assert rewrite_program(text, {}, {}) == text
    out = rewrite_program(text, feed_by_line={2: 300, 3: 450, 4: 500})
    assert out == ("G0 X0 Y0\r\nG1 X20 F300 ,R2. (round)\r\nY20,C1.5 F450\r\nX0 , r 1 F500\r\nY0\r\nM30\r\n")
    # the inserted corner blocks run at the feed written on their line
    feeds = {b.line: b.feed for b in moves(out) if not isinstance(b, Rapid)}
    assert feeds[2] == pytest.approx(300 * MM / 60) and feeds[3] == pytest.approx(450 * MM / 60)


def test_feed_override_of_the_corner_line_equals_rewriting_its_f_word():
    from fmus_src.nck.overrides import apply_overrides

    text = "G0 X0 Y0\nG1 X20 F600 ,R2\nY20 ,C1 F900\nX0\nM30\n"
    new = {2: 300.0, 3: 450.0}  # mm/min
    blocks, feeds, _ = apply_overrides(interpret(text), 2, feed={k: v * MM / 60 for k, v in new.items()})
    rewritten = interpret(rewrite_program(text, feed_by_line=new)).blocks
    expected = [b.feed if isinstance(b, (Linear, Arc)) else math.nan for b in rewritten]
    assert len(blocks) == len(rewritten) == 7
    assert feeds[1] == pytest.approx(expected, nan_ok=True)
