"""Cutter radius compensation C with a nonzero radius (FANUC 0i-MF/31i-B, G17): the tool-centre path.

Every expected point below is derived by hand from the geometry (offset lines x = const / y = const, circles
of radius R +- r about the programmed centre, intersections of those), not read back from the code:

* G41 puts the tool centre r to the LEFT of the direction of travel, G42 to the right.
* Inner corners and outer corners with an angle alpha >= 90 deg between the blocks: the intersection of the
  two offset elements; alpha < 90 deg (outer): FANUC type C, the offset of the first block extended by r
  along its end tangent (V1), the offset of the second one back by r along its start tangent (V2), V1-V2
  joined by a straight line.
* Start-up (type A): from the programmed start point (no offset) to the intersection (inner corner) or to
  the point r perpendicular to the next block (outer); cancel: from the intersection (inner) or the point r
  perpendicular to the last block (outer), to the programmed end point.
"""
from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from fmus_src.nck import Arc, GCodeError, InterpreterSettings, Linear, NCKernel, Rapid, interpret, rewrite_program
from fmus_src.nck.component import N_TOOL_LENGTHS, N_TOOL_RADII

MM = 1e-3
R3 = 3.0  # tool radius of the tests, mm
S2 = math.sqrt(2.0)


def _settings(**radii_mm: float) -> InterpreterSettings:
    r = [0.0] * N_TOOL_RADII
    for key, value in radii_mm.items():
        r[int(key[1:]) - 1] = value * MM
    return InterpreterSettings(tool_lengths=[0.0] * N_TOOL_LENGTHS, tool_radii=r)


def _moves(program) -> list:
    return [b for b in program.blocks if isinstance(b, (Rapid, Linear, Arc))]


def _xy(p) -> tuple[float, float]:
    return (p[0] / MM, p[1] / MM)


def _path(program, first_line: int = 2) -> list[tuple[float, float]]:
    """XY points (mm) of the moves from ``first_line`` on: the start of the first, then every end point."""
    moves = [b for b in _moves(program) if b.line >= first_line]
    return [_xy(moves[0].start)] + [_xy(b.end) for b in moves]


#: The 20 x 20 mm square (0,0)-(20,20) milled clockwise around the part with G41 (tool on the left = outside:
#: climb milling), lead-in from (-10,-10) on the diagonal, exact stop on every block (G61).
SQUARE = ("G0 X-10. Y-10.\nG61\nG41 D1 G1 X0. Y0. F600.\nY20.\nX20.\nY0.\nX0.\nG40 X-10. Y-10.\nM30\n")
#: Tool-centre corners for r = 3: offset lines x = -3, y = 23, x = 23, y = -3 (alpha = 90 deg: intersections).
#: Start-up (inner corner, left turn under G41): the lead-in's offset line y = x + 3*sqrt(2) meets x = -3 at
#: y = 3*(sqrt(2) - 1); the cancel meets y = -3 at x = 3*(sqrt(2) - 1) by symmetry.
K = 3.0 * (S2 - 1.0)
SQUARE_CENTRE = [(-10, -10), (-3, K), (-3, 23), (23, 23), (23, -3), (K, -3), (-10, -10)]


def _close(actual, expected, atol: float = 1e-9) -> None:
    """Point lists (mm) equal within ``atol`` mm."""
    np.testing.assert_allclose(np.asarray(actual, dtype=float), np.asarray(expected, dtype=float), rtol=0, atol=atol)


def _length(points) -> float:
    return sum(math.dist(p, q) for p, q in zip(points, points[1:]))


def test_square_contour_g41_climb_gives_the_square_offset_by_the_radius():
    p = interpret(SQUARE, "square.nc", _settings(D1=R3))
    _close(_path(p, 3), SQUARE_CENTRE)
    moves = _moves(p)
    assert [b.line for b in moves] == [1, 3, 4, 5, 6, 7, 8]  # no extra block, every block keeps its line
    assert all(b.exact_stop for b in moves[1:]) and all(b.feed == pytest.approx(600 * MM / 60) for b in moves[1:])
    # the tool-centre square: sides of 20 + 2*3 = 26 mm (perimeter 104, FANUC's corner rule at 90 deg)
    assert [math.dist(a, b) for a, b in zip(SQUARE_CENTRE[2:4], SQUARE_CENTRE[3:5])] == pytest.approx([26, 26])


def test_time_through_the_twin_grows_by_the_extra_path_length_over_the_feed():
    """G61: every block runs alone from rest to rest at 10 mm/s, so the time grows by (L_centre - L_programmed)/F."""
    programmed = [(-10, -10), (0, 0), (0, 20), (20, 20), (20, 0), (0, 0), (-10, -10)]
    extra_mm = _length(SQUARE_CENTRE) - _length(programmed)
    assert extra_mm == pytest.approx(2 * (math.hypot(7, 10 + K) - 10 * S2) + 2 * (23 - K) + 2 * 26 - 80)
    durations = []
    for radius in (0.0, R3 * MM):
        k = NCKernel(program_text=SQUARE, tool_radius_1=radius)
        k.setup(0.0)
        durations.append(float(k.duration_[0]))
    period = float(k.values["interpolation_period"][0])
    assert durations[1] - durations[0] == pytest.approx(extra_mm / 10.0, abs=6 * period)


def test_circle_g2_i_with_g41_and_g42_has_radius_r_plus_and_minus_the_tool_radius():
    text = "G0 X20. Y0.\nG4{side} D1 G1 X10. F600.\nG2 I-10.\nG40 G1 X20.\n"
    # G41 on a clockwise circle: the tool is outside, radius 13. Start-up along -X to (10,0) turns left into
    # the circle (inner corner under G41): y = -3 meets the circle of radius 13 at x = sqrt(13^2 - 3^2);
    # the cancel along +X: y = +3 meets it at the same x.
    p = interpret(text.format(side=1), "c.nc", _settings(D1=R3))
    arc = [b for b in p.blocks if isinstance(b, Arc)][0]
    x = math.sqrt(13 ** 2 - 3 ** 2)
    assert _xy(arc.center) == pytest.approx((0, 0)) and arc.radius_start == pytest.approx(13 * MM)
    assert _xy(arc.start) == pytest.approx((x, -3)) and _xy(arc.end) == pytest.approx((x, 3))
    assert arc.sweep == pytest.approx(-(2 * math.pi - 2 * math.asin(3 / 13)))
    # G42: inside, radius 7; start-up and cancel are outer corners: the point r perpendicular, (7, 0)
    p = interpret(text.format(side=2), "c.nc", _settings(D1=R3))
    arc = [b for b in p.blocks if isinstance(b, Arc)][0]
    assert arc.radius_start == pytest.approx(7 * MM) and arc.radius_end == pytest.approx(7 * MM)
    assert _xy(arc.start) == pytest.approx((7, 0)) and _xy(arc.end) == pytest.approx((7, 0))
    assert arc.sweep == pytest.approx(-2 * math.pi)
    _close(_path(p), [(20, 0), (7, 0), (7, 0), (20, 0)])


def test_inside_corner_is_the_intersection_of_the_offset_lines():
    # G41 (left) along +X then +Y turns left: inner corner, y = 3 meets x = 17 at (17, 3); the cancel goes on
    # along +Y (tangent): from (17, 20), 3 mm left of the end (20, 20), to (20, 30)
    p = interpret("G0 X-10. Y0.\nG41 D1 G1 X0. F600.\nX20.\nY20.\nG40 X20. Y30.\n", "in.nc", _settings(D1=R3))
    _close(_path(p), [(-10, 0), (0, 3), (17, 3), (17, 20), (20, 30)])


def test_line_to_tangent_arc_adds_no_move():
    # +X line to (10,0), then G3 about (10,10): tangent. G41 is towards the centre: y = 3, then radius 10 - 3.
    text = "G0 X-10. Y0.\nG41 D1 G1 X0. Y0. F600.\nX10.\nG3 X20. Y10. R10.\nG40 G1 Y20.\n"
    p = interpret(text, "t.nc", _settings(D1=R3))
    assert len(p.blocks) == len(interpret(text, "t.nc", _settings()).blocks)
    arc = [b for b in p.blocks if isinstance(b, Arc)][0]
    assert _xy(arc.start) == pytest.approx((10, 3)) and _xy(arc.end) == pytest.approx((17, 10))
    assert arc.radius_start == pytest.approx(7 * MM) and _xy(arc.center) == pytest.approx((10, 10))
    # the arc ends going +Y and the cancel goes +Y: tangent again, the cancel runs from (17, 10) to (20, 20)
    _close(_path(p), [(-10, 0), (0, 3), (10, 3), (17, 10), (20, 20)])


def test_acute_outside_corner_is_fanucs_type_c():
    # G42 (right): +X to (10,0), then towards (0,5): a left turn (outer under G42) of 153.4 deg, alpha < 90.
    # V1 = (10,0) + 3*(0,-1) + 3*(1,0) = (13,-3); the second line has t = (-2,1)/sqrt5 and right normal
    # (1,2)/sqrt5: V2 = (10,0) + 3*(1,2)/sqrt5 - 3*(-2,1)/sqrt5 = (10 + 9/sqrt5, 3/sqrt5).
    text = "G0 X-10. Y0.\nG42 D1 G1 X0. F600.\nX10.\nX0. Y5.\nG40 X-10.\n"
    p = interpret(text, "a.nc", _settings(D1=R3))
    r5 = math.sqrt(5.0)
    moves = _moves(p)
    assert [b.line for b in moves] == [1, 2, 3, 3, 4, 5]  # the corner move carries the line before the corner
    assert _xy(moves[2].end) == pytest.approx((13, -3)) and _xy(moves[3].end) == pytest.approx((10 + 9 / r5, 3 / r5))
    assert isinstance(moves[3], Linear) and moves[3].feed == moves[2].feed and moves[3].feed_line == 2


def test_g42_mirrors_g41():
    """The program mirrored in X (Y -> -Y, G2 <-> G3, G41 <-> G42) gives the mirrored tool-centre path."""
    left = "G0 X-10. Y0.\nG41 D1 G1 X0. Y0. F600.\nX10.\nG3 X20. Y10. R10.\nG1 X25. Y0.\nG40 G1 X35. Y0.\n"
    right = "G0 X-10. Y0.\nG42 D1 G1 X0. Y0. F600.\nX10.\nG2 X20. Y-10. R10.\nG1 X25. Y0.\nG40 G1 X35. Y0.\n"
    a, b = (_moves(interpret(t, "m.nc", _settings(D1=R3))) for t in (left, right))
    assert len(a) == len(b) == 8  # the arc -> line corner is acute (outer): 2 extra moves
    for u, v in zip(a, b):
        assert type(u) is type(v) and u.line == v.line
        assert (u.start[0], -u.start[1]) == pytest.approx(v.start[:2], abs=1e-15)
        assert (u.end[0], -u.end[1]) == pytest.approx(v.end[:2], abs=1e-15)
        if isinstance(u, Arc):
            assert u.clockwise != v.clockwise and u.sweep == pytest.approx(-v.sweep)


def test_z_only_cancel_moves_back_to_the_programmed_point_while_retracting():
    text = "G0 X-10. Y0. Z5.\nG41 D1 G1 X0. F600.\nZ-2.\nX20.\nG0 G40 Z5.\n"
    p = interpret(text, "z.nc", _settings(D1=R3))
    moves = _moves(p)
    # the start-up (+X, then +X after the Z move: tangent) ends at (0, 3); the plunge runs there
    assert _xy(moves[1].end) == pytest.approx((0, 3)) and _xy(moves[2].start) == pytest.approx((0, 3))
    assert _xy(moves[2].end) == pytest.approx((0, 3))
    # the last line ends r perpendicular: (20, 3); the Z-only cancel goes from there back to (20, 0)
    assert _xy(moves[3].end) == pytest.approx((20, 3))
    assert isinstance(moves[4], Rapid) and _xy(moves[4].start) == pytest.approx((20, 3))
    assert moves[4].end == pytest.approx((20 * MM, 0.0, 5 * MM))


def test_up_to_three_blocks_without_xy_motion_are_looked_through_and_four_keep_the_vector():
    base = "G0 X-10. Y0.\nG41 D1 G1 X0. F600.\nX20.\n{gap}Y20.\nG40 Y30.\n"
    three = interpret(base.format(gap="Z-1.\nM8\nG4 P100\n"), "g.nc", _settings(D1=R3))
    _close(_path(three), [(-10, 0), (0, 3), (17, 3), (17, 3), (17, 20), (20, 30)])
    four = interpret(base.format(gap="Z-1.\nM8\nG4 P100\nM9\n"), "g.nc", _settings(D1=R3))
    # FANUC keeps the vector perpendicular to the +X line: (20, 3); the +Y line then runs to its end vector
    _close(_path(four), [(-10, 0), (0, 3), (20, 3), (20, 3), (17, 20), (20, 30)])


def test_d_change_in_offset_mode_applies_to_the_end_of_the_next_move():
    # G42, D1 = 0 at the start-up (ends at (10, 0)), D3 = 2 from the next block: its end vector is 2 mm to
    # the right of +Y and of -X: x = 12, y = 12; the cancel (outer corner) starts 2 mm right of -X at (0, 12)
    text = "G0 X0 Y0\nG42 D1 G1 X10 F500\nD3 Y10\nX0\nG40 Y0\n"
    p = interpret(text, "d.nc", _settings(D3=2.0))
    _close(_path(p), [(0, 0), (10, 0), (12, 12), (0, 12), (0, 0)])


def test_g10_l12_in_the_program_and_l13_wear_set_the_radius():
    body = "G0 X-10. Y-10.\nG61\nG41 D1 G1 X0. Y0. F600.\nY20.\nX20.\nY0.\nX0.\nG40 X-10. Y-10.\nM30\n"
    p = interpret("G10 L12 P1 R3.2\nG10 L13 P1 R-0.2\n" + body, "g10.nc", _settings())
    _close(_path(p, 5), SQUARE_CENTRE)


def test_negative_radius_swaps_g41_and_g42():
    p = interpret("G0 X-10. Y0.\nG41 D1 G1 X0. F600.\nX20.\nY20.\nG40 Y30.\n", "n.nc", _settings(D1=-R3))
    q = interpret("G0 X-10. Y0.\nG42 D1 G1 X0. F600.\nX20.\nY20.\nG40 Y30.\n", "n.nc", _settings(D1=R3))
    _close(_path(p), _path(q))


def test_arc_too_small_for_the_tool_is_an_error_naming_file_and_line():
    text = "G0 X-10. Y0.\nG41 D1 G1 X0. F600.\nX10.\nG3 X12. Y2. R2.\nG40 G1 X30.\n"
    with pytest.raises(GCodeError) as info:
        interpret(text, "small.nc", _settings(D1=R3))
    err = info.value
    assert (err.file, err.line, err.word) == ("small.nc", 4, "G3")
    assert str(err).startswith("small.nc:4: 'G3 X12. Y2. R2.': arc radius 2 mm with the tool radius offset D1 = 3 mm")
    assert "radius of -1 mm" in str(err) and "PS0041" in str(err)
    # the same arc with G42 (tool outside the counter-clockwise arc) is fine: radius 5
    arc = [b for b in interpret(text.replace("G41", "G42"), "small.nc", _settings(D1=R3)).blocks
           if isinstance(b, Arc)][0]
    assert arc.radius_start == pytest.approx(5 * MM)


def test_step_smaller_than_the_radius_is_an_interference_error():
    # a 2 mm wide slot step under G41 (inner corners both sides): the offset of the 2 mm line runs backwards
    text = "G0 X-10. Y0.\nG41 D1 G1 X0. F600.\nX10.\nY2.\nX0.\nG40 Y-10.\n"
    with pytest.raises(GCodeError) as info:
        interpret(text, "step.nc", _settings(D1=R3))
    assert info.value.line == 4 and "PS0041" in str(info.value) and "against the programmed direction" in str(
        info.value)


@pytest.mark.parametrize("text, line, word, fragment", [
    ("G0 X0 Y0\nG41 D1\nG1 Z-1 F100\nG2 X10 Y0 R5\n", 4, "G2", "PS0034"),  # the first XY move is the start-up
    ("G18 G0 X0 Z0\nG41 D1 G1 X10 F100\n", 2, "D1", "in the ZX plane is not simulated"),
    ("G0 X0 Y0\nG41 D1 G1 X10 F100\nG42 Y10\n", 3, "G42", "switches the offset side"),
    ("G0 X0 Y0\nG41 D1 G1 X10 F100\nG28 G91 Z0\n", 3, "G28", "G28 while cutter compensation G41"),
    ("G0 X0 Y0 Z5\nG41 D1 G1 X10 F100\nG81 X20 Z-5 R2\n", 3, "G81", "G81 while cutter compensation"),
    # an outer corner of 80 deg into a G3 of radius 4 about (13.939, 0.695): its offset circle (radius 1) stays
    # below the offset line y = 3 of the +X line: no intersection
    ("G0 X-10 Y0\nG41 D1 G1 X0 F100\nX10\nG3 X17.87846 Y1.38919 I3.93923 J0.69459\n", 3, "D1", "PS0033"),
])
def test_what_a_nonzero_radius_does_not_simulate_is_an_error(text, line, word, fragment):
    with pytest.raises(GCodeError) as info:
        interpret(text, "e.nc", _settings(D1=R3))
    assert (info.value.line, info.value.word) == (line, word) and fragment in str(info.value)


def test_zero_radius_logs_once_that_the_program_is_the_tool_centre_path(caplog):
    text = "G0 X0 Y0\nG41 D1 G1 X10 F100\nG40 X20\nG42 D1 X30\nG40 X40\n"
    with caplog.at_level(logging.INFO, logger="fmus_src.nck.radius_offset"):
        interpret(text, "wear.nc", _settings())
    msgs = [r for r in caplog.records if r.name == "fmus_src.nck.radius_offset"]
    assert len(msgs) == 1 and msgs[0].levelno == logging.INFO
    assert "wear.nc:2" in msgs[0].getMessage() and "tool-centre path" in msgs[0].getMessage()
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="fmus_src.nck.radius_offset"):
        interpret(text, "wear.nc", _settings(D1=R3))
    assert not [r for r in caplog.records if r.name == "fmus_src.nck.radius_offset"]


def test_rewriting_f_and_s_keeps_the_compensated_path_and_overrides_match_the_rewrite():
    text = SQUARE.replace("G61\n", "G61 S6000 M3\n")
    new = rewrite_program(text, {5: 300.0}, {2: 5000.0})
    assert [ln for ln in new.splitlines() if ln not in text.splitlines()] == ["G61 S5000 M3", "X20. F300"]
    a, b = (interpret(t, "r.nc", _settings(D1=R3)) for t in (text, new))
    assert [(u.start, u.end) for u in _moves(a)] == [(v.start, v.end) for v in _moves(b)]
    assert [round(v.feed / (MM / 60), 9) for v in _moves(b)[1:]] == [600, 600, 300, 300, 300, 300]
    # a per-line feed override of the NC kernel gives the rewritten program's plan
    k = NCKernel(program_text=text, tool_radius_1=R3 * MM)
    k.set_overrides(feed={5: 300.0 * MM / 60})
    k.setup(0.0)
    single = NCKernel(program_text=rewrite_program(text, {5: 300.0}), tool_radius_1=R3 * MM)
    single.setup(0.0)
    assert single.duration_[0] == k.duration_[0]
    np.testing.assert_array_equal(single.plan_.position[0], k.plan_.position[0])


def test_compensated_subprogram_keeps_runs_and_lines():
    # the acute-corner contour in O100, called twice: each run has the extra corner move
    text = ("G0 X-10. Y0.\nM98 P100 L2\nM30\nO100\nG42 D1 G1 X0. F600.\nX10.\nX0. Y5.\nG40 X-10. Y0.\nM99\n")
    p = interpret(text, "s.nc", _settings(D1=R3))
    assert sum(p.segment_blocks) == len(p.blocks) and len(p.segment_blocks) == len(p.segments)
    corner = [b for b in _moves(p) if b.line == 6]
    assert len(corner) == 4 and _xy(corner[1].start) == pytest.approx((13, -3))
    k = NCKernel(program_text=text, tool_radius_1=R3 * MM)  # per-line overrides walk these runs
    k.set_overrides(feed={5: 300.0 * MM / 60})
    k.setup(0.0)
    assert k.duration_[0] > 0.0
