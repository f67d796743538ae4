"""FANUC programmable transforms: G68/G69 rotation, G51.1/G50.1 mirror, G51/G50 scaling, G16/G15 polar.

Every expected number is derived by hand from the manual's definition (rotation matrix, reflection, scaling
about a centre, polar -> Cartesian), or is the same program without the transform, transformed here.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck import Arc, GCodeError, InterpreterSettings, Linear, Rapid, interpret
from fmus_src.nck.writer import rewrite_program

PAPER_CASE = Path(__file__).resolve().parent.parent / "models" / "examples" / "paper_part"


def rot(p, c, deg):
    """Point ``p`` rotated by ``deg`` counter-clockwise about ``c`` (mm)."""
    a = math.radians(deg)
    dx, dy = p[0] - c[0], p[1] - c[1]
    return (c[0] + math.cos(a) * dx - math.sin(a) * dy, c[1] + math.sin(a) * dx + math.cos(a) * dy)


def ends(program, kinds=(Linear, Rapid, Arc), line=None):
    """End points (mm, x y z) of the moves of ``program`` (of one source line if given)."""
    return [tuple(v * 1e3 for v in b.end) for b in program.blocks
            if isinstance(b, kinds) and (line is None or b.line == line)]


def xy(points):
    return np.array([p[:2] for p in points])


RECT = "G1 X0 Y0 F300\nX20\nY10\nX0\nY0\n"


# ------------------------------------------------------------------ G68 / G69 rotation
def test_rectangle_rotated_30_deg_about_5_5_is_the_rotation_matrix_applied_by_hand():
    program = interpret("G90 G17 G0 X0 Y0 Z0\nG68 X5 Y5 R30\n" + RECT + "G69\nG0 X0 Y0\nM30\n")
    corners = [(0, 0), (20, 0), (20, 10), (0, 10), (0, 0)]
    expected = [rot(p, (5, 5), 30) for p in corners]
    got = xy(ends(program, Linear))
    assert got == pytest.approx(np.array(expected), abs=1e-9)
    assert ends(program, Rapid)[-1] == pytest.approx((0, 0, 0), abs=1e-12)  # G69: back to the plain system


def test_rotation_follows_the_work_offset_and_r_omitted_is_zero():
    settings = InterpreterSettings(work_offsets={54: (0.1, 0.05, 0.0)})
    program = interpret("G90 G0 X0 Y0\nG68 X5 Y5 R90\nG1 X20 Y0 F100\nG69\nG68 X5 Y5\nG1 X20 Y0\nM30\n",
                        settings=settings)
    first, second = xy(ends(program, Linear))
    assert first == pytest.approx(np.add(rot((20, 0), (5, 5), 90), (100, 50)), abs=1e-9)
    assert second == pytest.approx((120, 50), abs=1e-9)


def test_one_axis_absolute_move_under_g68_moves_both_axes():
    # programmed point (20, 0): Y keeps its programmed value 0 (FANUC), rotated 90 deg about the origin
    program = interpret("G0 X10 Y0\nG68 X0 Y0 R90\nG1 X20 F100\nM30\n")
    assert xy(ends(program, Linear))[0] == pytest.approx((0, 20), abs=1e-9)


def test_incremental_moves_after_g68_start_at_the_tool_position():
    # manual: the centre for incremental commands after G68, before an absolute one, is the tool position
    program = interpret("G0 X10 Y0\nG68 X0 Y0 R90\nG91 G1 X10 F100\nY5\nG90 X0 Y0\nM30\n")
    got = xy(ends(program, Linear))
    assert got == pytest.approx(np.array([(10, 10), (5, 10), (0, 0)]), abs=1e-9)


def test_arc_under_rotation_rotates_its_centre_and_keeps_its_direction():
    program = interpret("G0 X10 Y0\nG68 X0 Y0 R90\nG0 X10 Y0\nG3 X0 Y10 I-10 J0 F100\nM30\n")
    arc = [b for b in program.blocks if isinstance(b, Arc)][0]
    assert not arc.clockwise
    assert np.array(arc.center[:2]) * 1e3 == pytest.approx((0, 0), abs=1e-9)
    assert np.array(arc.end[:2]) * 1e3 == pytest.approx(rot((0, 10), (0, 0), 90), abs=1e-9)


def test_canned_cycle_holes_are_rotated_but_not_their_levels():
    program = interpret("G0 X0 Y0 Z10\nG68 X0 Y0 R45\nG81 X10 Y0 Z-5 R2 F100\nX20\nG80\nM30\n")
    drills = [b for b in program.blocks if isinstance(b, Linear)]
    assert xy(ends(program, Linear)) == pytest.approx(np.array([rot((10, 0), (0, 0), 45),
                                                                 rot((20, 0), (0, 0), 45)]), abs=1e-9)
    assert [d.end[2] * 1e3 for d in drills] == pytest.approx([-5, -5], abs=1e-12)


def test_g41_contour_under_g68_is_the_rotation_of_the_unrotated_compensated_contour():
    body = "G41 D1 G1 X0 Y0 F300\nX20\nY10\nX0\nY0\nG40 G1 X-10 Y-10\n"
    settings = InterpreterSettings(tool_radii=[3e-3])
    plain = interpret("G0 X-10 Y-10\n" + body + "M30\n", settings=settings)
    rotated = interpret("G0 X-10 Y-10\nG68 X5 Y5 R30\nG0 X-10 Y-10\n" + body + "M30\n", settings=settings)
    p = xy(ends(plain, Linear))
    r = xy(ends(rotated, Linear))
    assert len(p) == len(r) and len(p) >= 6
    assert r == pytest.approx(np.array([rot(q, (5, 5), 30) for q in p]), abs=1e-9)
    # G41 on this counter-clockwise contour is the inside: the first corner is (20 - 3, 0 + 3)
    assert p[1] == pytest.approx((17, 3), abs=1e-9)


def test_rotation_survives_a_subprogram_call():
    text = "G0 X0 Y0\nG68 X0 Y0 R90\nM98 P100\nG69\nM30\nO100\nG1 X10 Y0 F100\nM99\n"
    program = interpret(text)
    assert xy(ends(program, Linear))[0] == pytest.approx((0, 10), abs=1e-9)


def test_macro_reads_the_transform_modes():
    program = interpret("G0 X0 Y0\nG68 X0 Y0 R0\n#1 = #4016\nG69\n#2 = #4016\nG1 X#1 Y#2 F100\nM30\n")
    assert xy(ends(program, Linear))[0] == pytest.approx((68, 69), abs=1e-12)


def test_writer_rewrites_feeds_of_a_g68_program_and_the_path_stays():
    text = "G90 G0 X0 Y0\nG68 X5 Y5 R30\nG1 X20 Y0 F300\nY10\nG69\nM30\n"
    new = rewrite_program(text, feed_by_line={3: 600.0})
    before, after = interpret(text), interpret(new)
    assert ends(before) == ends(after)
    feeds = [b.feed for b in after.blocks if isinstance(b, Linear)]
    assert feeds == pytest.approx([600e-3 / 60] * 2, rel=1e-12)
    assert "F600" in new.splitlines()[2]


# ------------------------------------------------------------------ G51.1 / G50.1 mirror
def test_g2_arc_mirrored_in_x_becomes_g3_with_the_mirrored_centre():
    # programmed: G2 from (20, 5) about (30, 5) to (30, 15); mirror about X = 50: x -> 100 - x
    for arc_words in ("I10 J0", "R10"):
        program = interpret(f"G0 X0 Y0\nG51.1 X50\nG0 X20 Y5\nG2 X30 Y15 {arc_words} F100\nG50.1 X0\nM30\n")
        arc = [b for b in program.blocks if isinstance(b, Arc)][0]
        assert not arc.clockwise  # G2 -> G3
        assert np.array(arc.start[:2]) * 1e3 == pytest.approx((80, 5), abs=1e-9)
        assert np.array(arc.center[:2]) * 1e3 == pytest.approx((70, 5), abs=1e-9)
        assert np.array(arc.end[:2]) * 1e3 == pytest.approx((70, 15), abs=1e-9)


def test_mirror_in_both_axes_keeps_the_arc_direction_and_g50_1_cancels():
    program = interpret("G0 X0 Y0\nG51.1 X0 Y0\nG0 X10 Y0\nG2 X0 Y-10 R10 F100\nG50.1\nG0 X10 Y0\nM30\n")
    arc = [b for b in program.blocks if isinstance(b, Arc)][0]
    assert arc.clockwise
    assert np.array(arc.end[:2]) * 1e3 == pytest.approx((0, 10), abs=1e-9)
    assert ends(program, Rapid)[-1][:2] == pytest.approx((10, 0), abs=1e-12)


def test_mirror_exchanges_g41_and_g42():
    # G42 under a mirror in X cuts the mirror image of the G42 path (the offset side follows the mirror)
    body = "G42 D1 G1 X0 Y0 F300\nX20\nY10\nX0\nY0\nG40 G1 X-10 Y-10\n"
    settings = InterpreterSettings(tool_radii=[2e-3])
    plain = xy(ends(interpret("G0 X-10 Y-10\n" + body + "M30\n", settings=settings), Linear))
    mirrored = xy(ends(interpret("G0 X0 Y0\nG51.1 X0\nG0 X-10 Y-10\n" + body + "M30\n", settings=settings),
                       Linear))
    assert mirrored == pytest.approx(plain * np.array([-1.0, 1.0]), abs=1e-9)


def test_rotation_direction_reverses_under_a_mirror():
    # the result is the mirror image of the rotated part: (20, 0) rotated +30 about the origin, then x -> -x
    program = interpret("G0 X0 Y0\nG51.1 X0\nG68 X0 Y0 R30\nG1 X20 Y0 F100\nG69\nG50.1\nM30\n")
    x, y = rot((20, 0), (0, 0), 30)
    assert xy(ends(program, Linear))[0] == pytest.approx((-x, y), abs=1e-9)


def test_centres_are_mapped_through_the_earlier_transforms():
    # mirror about X = 10 of the part rotated 90 deg about (15, 0): (20, 0) -> (15, 5) -> (5, 5)
    mirrored = interpret("G0 X0 Y0\nG51.1 X10\nG68 X15 Y0 R90\nG1 X20 Y0 F100\nM30\n")
    assert xy(ends(mirrored, Linear))[0] == pytest.approx((5, 5), abs=1e-9)
    # the rotation centre is scaled, not the angle: (10, 0) about (5, 0) by 90 deg -> (5, 5), x2 -> (10, 10)
    scaled = interpret("G0 X0 Y0\nG51 X0 Y0 P2000\nG68 X5 Y0 R90\nG1 X10 Y0 F100\nM30\n")
    assert xy(ends(scaled, Linear))[0] == pytest.approx((10, 10), abs=1e-9)


def test_rotation_centre_omitted_is_the_tool_position_and_g28_after_g69_is_allowed():
    program = interpret("G0 X10 Y10\nG68 R90\nG1 X20 Y10 F100\nG69 G91 G28 Z0\nM30\n")
    assert xy(ends(program, Linear))[0] == pytest.approx((10, 20), abs=1e-9)


# ------------------------------------------------------------------ G51 / G50 scaling
def test_g51_p2000_doubles_a_square_about_its_centre():
    program = interpret("G0 X0 Y0\nG51 X10 Y10 P2000\nG1 X5 Y5 F100\nX15\nY15\nX5\nY5\nG50\nG0 X0 Y0\nM30\n")
    got = xy(ends(program, Linear))
    square = [(5, 5), (15, 5), (15, 15), (5, 15), (5, 5)]
    assert got == pytest.approx(np.array([(10 + 2 * (x - 10), 10 + 2 * (y - 10)) for x, y in square]), abs=1e-9)
    side = np.linalg.norm(got[1] - got[0])
    assert side == pytest.approx(20.0, abs=1e-9)


def test_scaling_scales_arc_radius_and_corner_but_not_the_tool_offsets():
    settings = InterpreterSettings(tool_lengths=[0.1])
    program = interpret("G43 H1 G0 X0 Y0 Z0\nG51 X0 Y0 Z0 P500\nG0 X20 Y0 Z10\nG3 X0 Y20 R20 F100\n"
                        "G1 X-20 ,R4\nY0\nG50\nM30\n", settings=settings)
    arc = [b for b in program.blocks if isinstance(b, Arc)]
    assert np.array(arc[0].end[:2]) * 1e3 == pytest.approx((0, 10), abs=1e-9)  # end (0, 20) x 0.5
    assert arc[0].radius_start * 1e3 == pytest.approx(10.0, abs=1e-9)
    assert arc[1].radius_start * 1e3 == pytest.approx(2.0, abs=1e-9)  # ,R4 x 0.5
    assert ends(program, Rapid)[-1][2] == pytest.approx(5.0 + 100.0, abs=1e-9)  # Z10 x 0.5 + H1 (not scaled)


def test_scaled_canned_cycle_scales_position_and_levels():
    program = interpret("G0 X0 Y0 Z10\nG51 X0 Y0 Z0 P2000\nG81 X10 Y5 Z-3 R1 F100\nG80\nG50\nM30\n")
    drill = [b for b in program.blocks if isinstance(b, Linear)][0]
    assert np.array(drill.start) * 1e3 == pytest.approx((20, 10, 2), abs=1e-9)
    assert np.array(drill.end) * 1e3 == pytest.approx((20, 10, -6), abs=1e-9)


def test_per_axis_scaling():
    program = interpret("G0 X0 Y0\nG51 X0 Y0 I2000 J-500\nG1 X10 Y10 F100\nM30\n")
    assert xy(ends(program, Linear))[0] == pytest.approx((20, -5), abs=1e-9)


# ------------------------------------------------------------------ G16 / G15 polar coordinates
def test_bolt_circle_of_six_holes_in_g16():
    absolute = "G0 X0 Y0 Z10\nG16\nG81 X30 Y0 Z-5 R2 F100\nY60\nY120\nY180\nY240\nY300\nG80 G15\nM30\n"
    incremental = "G0 X0 Y0 Z10\nG16\nG81 X30 Y0 Z-5 R2 F100\nG91 Y60 K5\nG80 G15\nM30\n"
    expected = np.array([(30 * math.cos(math.radians(60 * k)), 30 * math.sin(math.radians(60 * k)))
                         for k in range(6)])
    for text in (absolute, incremental):
        assert xy(ends(interpret(text), Linear)) == pytest.approx(expected, abs=1e-9)


def test_g16_radius_from_the_current_position_under_g91_and_g15_cancels():
    # G91: origin = the current position (10, 10), radius 5; angle = 45 deg (the current position about the
    # work origin) + 90
    program = interpret("G0 X10 Y10\nG16\nG91 G1 X5 Y90 F100\nG90 G15\nG1 X1 Y2\nM30\n")
    a = math.radians(135)
    want = [(10 + 5 * math.cos(a), 10 + 5 * math.sin(a)), (1, 2)]
    assert xy(ends(program, Linear)) == pytest.approx(np.array(want), abs=1e-9)


# ------------------------------------------------------------------ errors
@pytest.mark.parametrize("text, word, fragment", [
    ("G17 G68 X0 Z5 R30\n", "Z5", "not an axis of the XY plane"),
    ("G51 X0 Y0 P0\n", "P0", "is zero"),
    ("G51 X0 Y0 P1.5\n", "P1.5", "decimal point"),
    ("G51 X0 Y0\n", "G51", "without a magnification"),
    ("G16\nG1 Y30 F100\n", "Y30", "no radius X"),
    ("G51 X0 Y0 I1000 J2000\nG2 X10 Y0 R5 F100\n", "G2", "different factors"),
    ("G68 X0 Y0 R30\nG28 G91 Z0\n", "G28", "not allowed"),
    ("G68 X0 Y0 R30\nG53 Z0\n", "G53", "not allowed"),
    ("G51.1 X0\nG55\n", "G55", "not allowed"),
    ("G68 X0 Y0 R30\nG18\n", "G18", "changes the plane"),
    ("G68 X0 Y0 R30\nG68 X1 Y1 R10\n", "G68", "G69 before"),
    ("G16\nG68 X0 Y0 R30\n", "G68", "G15 before"),
    ("G68 X0 Y0 R30\nG51.1 X0\n", "G51.1", "G69 before"),
    ("G51 X0 Y0 P2000\nG68 X0 Y0 R30\nG50\n", "G50", "G69 before"),
    ("G68 X0 Y0 R400\n", "R400", "beyond"),
    ("G68 X0 Y0 R30 G1\n", "G1", "in one block"),
    ("G51.1 Z0\nG81 X1 Y1 Z-1 R1 F10\n", "G81", "Z is mirrored"),
    ("G51 X0 Y0 I1000 J2000\nG1 X10 ,C1 F100\n", ",C1", "different factors"),
])
def test_errors_name_file_line_and_word(text, word, fragment):
    with pytest.raises(GCodeError) as info:
        interpret("G0 X0 Y0\n" + text, "p.nc")
    err = info.value
    assert err.file == "p.nc" and err.line == text.count("\n") + 1 and err.word == word
    assert fragment in str(err) and "expected" in str(err)


def test_transform_under_nonzero_cutter_compensation_is_an_error():
    with pytest.raises(GCodeError) as info:
        interpret("G41 D1 G1 X0 Y0 F100\nG68 X0 Y0 R30\n", "p.nc", InterpreterSettings(tool_radii=[3e-3]))
    assert info.value.line == 2 and "G40" in str(info.value)


# ------------------------------------------------------------------ end to end
def test_simulate_rotated_rectangle_on_the_paper_part_passes_the_rotated_corners(tmp_path: Path):
    from orchestrator import simulate

    program = tmp_path / "rot.nc"
    program.write_text("G21 G90 G17 G40 G49 G94\nG54\nS6000 M3\nG0 X10 Y7 Z1\nG68 X15 Y10 R30\nG0 X10 Y7\n"
                       "G1 G61 Z-0.5 F200\nX20 F600\nY13\nX10\nY7\nG0 Z5\nG69\nM5\nM30\n")
    result = simulate(program, case=PAPER_CASE, out=tmp_path / "out", plot=False)
    assert result.success, result.message
    frame = result.recording.member(0)
    # the reference, rotated back by -30 deg about (15, 10), runs along the programmed rectangle's edges
    ref = np.column_stack([frame["x_ref_mm"], frame["y_ref_mm"]])
    back = np.array([rot(p, (15, 10), -30) for p in ref])
    on = back[(frame["line"] >= 8) & (frame["line"] <= 11)]  # the four G1 sides X20, Y13, X10, Y7
    to_edge = np.minimum(np.minimum(np.abs(on[:, 0] - 10), np.abs(on[:, 0] - 20)),
                         np.minimum(np.abs(on[:, 1] - 7), np.abs(on[:, 1] - 13)))
    corners = np.array([(10, 7), (20, 7), (20, 13), (10, 13)])
    dist = np.linalg.norm(on[:, None, :] - corners[None, :, :], axis=2)  # (samples, 4)
    to_corner = np.min(dist, axis=1)
    inside = (on[:, 0] > 10 - 1e-6) & (on[:, 0] < 20 + 1e-6) & (on[:, 1] > 7 - 1e-6) & (on[:, 1] < 13 + 1e-6)
    assert len(on) > 1000 and np.all(inside)
    assert np.max(to_edge[to_corner > 1.0]) < 1e-6  # on the rotated sides away from the corners
    assert np.max(to_edge) < 0.02  # the acc/dec filter rounds the corners by a few um only
    assert np.all(np.min(dist, axis=0) < 0.02)  # G61: every corner is reached
    assert np.max(frame["fc_N"]) > 1.0  # the tool cut the stock
