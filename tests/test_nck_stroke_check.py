"""Stored stroke check 1 (FANUC No. 1320/1321, alarms OT0500/OT0501) on the planned path, before the program runs.

The default machine's limits follow from its travels and its machine zero, the G28 reference position at the +
ends of the travels (default.toml): X 762 mm -> [-762, 0] mm, Y 450 mm -> [-450, 0] mm, Z 510 mm -> [-510, 0] mm
in machine coordinates, which are the axis frame (the work coordinates of the default G54 = (-380, -225, -300) mm)
minus machine zero (380, 225, 300) mm. Every expected position below is machine = programmed + work offset (+ tool
length on Z), or an arc's centre +- radius - machine zero.
"""
from __future__ import annotations

import math

import pytest

from fmus_src.nck import Arc, GCodeError, NCKernel, NCParameterError
from fmus_src.nck.stroke import StrokeLimits, arc_extremes
from orchestrator.machine import MachineFileError, load_machine
from orchestrator.twin import nck_parameters

MM = 1e-3


def kernel(text: str, machine=None, **extra) -> NCKernel:
    params = nck_parameters(machine or load_machine("default"))
    return NCKernel(program_text=text, **{**params, **extra})


def overtravel(text: str, **extra) -> GCodeError:
    with pytest.raises(GCodeError) as info:
        kernel(text, **extra).planning_inputs()
    return info.value


def test_default_limits_come_from_the_travels_and_the_reference_position():
    machine = load_machine("default")
    limits = machine.stroke_limits()
    nck = machine.values["nck"]
    travel = {"x": 762.0, "y": 450.0, "z": 510.0}
    for a in "xyz":
        lo, hi = limits[a]
        assert hi * 1e3 == pytest.approx(nck[f"reference_{a}_mm"])  # the + end at the reference position
        assert hi == 0.0  # ... which is machine zero (FANUC No. 1240 = 0)
        assert (hi - lo) * 1e3 == pytest.approx(travel[a])


def test_rapid_beyond_plus_x_names_file_line_axis_position_and_limit():
    # G54 X -280 mm (100 mm right of the default -380): programmed X 290 is machine X 10, beyond the + limit 0
    exc = overtravel("G90 G54 G0 X0 Y0 Z10.\nG0 X290.\nM30\n", g54_x=-0.28)
    assert exc.line == 2 and exc.word == "X"
    assert "OT0500 + OVERTRAVEL" in str(exc) and "takes X to 10 mm" in str(exc) and "limit 0 mm" in str(exc)
    assert "[-762, 0] mm" in str(exc)
    assert "'G0 X290.'" in str(exc) and "[axis.x] stroke_max_mm" in str(exc)


def test_exactly_at_the_limit_is_inside_and_the_reference_return_is_allowed():
    k = kernel("G90 G54 G0 X0 Y0 Z10.\nG0 X280.\nG28 G91 Z0.\nG28 X0. Y0.\nG90\nM30\n", g54_x=-0.28)
    k.planning_inputs()  # machine X 0 = the + limit, and G28 goes to machine (0, 0, 0): all on the limits


def test_full_circle_whose_end_points_are_inside_reaches_beyond_at_its_quarter_point():
    # from X 350 around the centre X 350 + I: the arc's + X extreme is 350 + 2 I
    inside = "G90 G0 X350. Y0 Z10.\nG2 X350. Y0 I15. J0 F500.\nM30\n"   # 380 - 380 = machine 0: on the limit
    kernel(inside).planning_inputs()
    exc = overtravel(inside.replace("I15.", "I15.5"))                  # machine 381 - 380 = 1: beyond
    assert exc.line == 2 and exc.word == "X" and "the arc takes X to 1 mm" in str(exc)


def test_tool_length_and_work_offset_take_z_beyond_its_limits():
    # G43 H1 with 100 mm: programmed Z 250 is machine Z 250 + 100 - 300 = 50 > 0 (OT0500)
    exc = overtravel("G90 G0 X0 Y0\nG43 H1 Z250.\nM30\n", tool_length_1=0.1)
    assert exc.line == 2 and exc.word == "Z" and "to 50 mm" in str(exc) and "OT0500" in str(exc)
    # G54 Z -450 mm: a feed to Z -70 is machine Z -520 < -510 (OT0501)
    exc = overtravel("G90 G54 G0 X0 Y0 Z10.\nG1 Z-70. F100.\nM30\n", g54_z=-0.45)
    assert exc.line == 2 and exc.word == "Z" and "OT0501 - OVERTRAVEL" in str(exc) and "-520 mm" in str(exc)


def test_canned_cycle_bottom_and_g53_are_checked_on_their_lines():
    # G54 Z -500 mm: the hole bottom Z -15 is machine Z -515
    exc = overtravel("G90 G54 G0 X0 Y0 Z10.\nG99 G81 X5. Y5. Z-15. R2. F100.\nG80\nM30\n", g54_z=-0.5)
    assert exc.line == 2 and exc.word == "Z" and "-515 mm" in str(exc)
    exc = overtravel("G90 G0 X0 Y0 Z10.\nG53 Y-460.\nM30\n")
    assert exc.line == 2 and exc.word == "Y" and "OT0501" in str(exc) and "-460 mm" in str(exc)


def test_start_position_outside_the_travel_is_reported_without_a_line():
    exc = overtravel("G90 G0 X0\nM30\n", z_initial=0.35)
    assert exc.line == 0 and "before the program" in str(exc)


def test_a_machine_file_without_limits_does_not_check(tmp_path):
    text = load_machine("default").path.read_text()
    path = tmp_path / "no_limits.toml"
    path.write_text("\n".join(l for l in text.splitlines() if not l.startswith("stroke_")))
    machine = load_machine(path)
    assert machine.stroke_limits() == {}
    kernel("G90 G0 X0 Y0 Z10.\nG0 X500.\nM30\n", machine).planning_inputs()  # no check: it plans
    assert NCKernel(program_text="G0 X5000.\nM30\n").planning_inputs()  # the component's default: off


def test_one_axis_without_limits_is_not_checked(tmp_path):
    text = load_machine("default").path.read_text()
    lines = text.splitlines()
    start = lines.index("[axis.y]")
    end = lines.index("[axis.z]")
    kept = [l for i, l in enumerate(lines) if not (start < i < end and l.startswith("stroke_"))]
    path = tmp_path / "no_y.toml"
    path.write_text("\n".join(kept))
    machine = load_machine(path)
    assert set(machine.stroke_limits()) == {"x", "z"}
    kernel("G90 G0 X0 Y0 Z10.\nG0 Y400.\nM30\n", machine).planning_inputs()
    with pytest.raises(GCodeError, match="OT0500"):
        kernel("G90 G0 X0 Y0 Z10.\nG0 X400.\nM30\n", machine).planning_inputs()


@pytest.mark.parametrize("edit, fragment", [
    (("stroke_max_mm = { value = 0.0", "stroke_mx = { value = 0.0"), "unknown key 'stroke_mx'"),
    (("stroke_max_mm = { value = 0.0", "stroke_max_mm = { value = -800.0"), "must be less than stroke_max_mm"),
    (("reference_z_mm = { value = 0.0", "reference_z_mm = { value = 10.0"), "reference_z_mm = 10.0 is outside"),
])
def test_bad_limits_name_the_file_and_line(tmp_path, edit, fragment):
    text = load_machine("default").path.read_text()
    assert edit[0] in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(*edit, 1))
    with pytest.raises(MachineFileError, match=fragment) as info:
        load_machine(path)
    assert str(path) in str(info.value)


def test_only_one_limit_of_an_axis_is_an_error(tmp_path):
    text = load_machine("default").path.read_text()
    path = tmp_path / "half.toml"
    path.write_text("\n".join(l for l in text.splitlines() if not l.startswith("stroke_min_mm = { value = -762")))
    with pytest.raises(MachineFileError, match=r"\[axis.x\] stroke_max_mm without stroke_min_mm"):
        load_machine(path)


def test_limits_must_be_ordered():
    with pytest.raises(NCParameterError):
        StrokeLimits(x=(0.1, -0.1))


def _arc(start, end, center, clockwise):
    return Arc(1, start, end, center, "XY", clockwise, 0.01, 1)


def test_arc_extremes_are_the_quarter_points_inside_the_sweep():
    # counter-clockwise quarter from angle 0 to 90 deg about the origin, r = 1: the points at 0 and 90 deg
    pts = arc_extremes(_arc((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 0.0), False))
    assert sorted((round(x, 12), round(y, 12)) for x, y, _ in pts) == [(0.0, 1.0), (1.0, 0.0)]
    # clockwise from 0 to -90 deg: the points at 0 and 270 deg, not 90 or 180
    pts = arc_extremes(_arc((1.0, 0.0, 0.0), (0.0, -1.0, 0.0), (0.0, 0.0, 0.0), True))
    assert sorted((round(x, 12), round(y, 12)) for x, y, _ in pts) == [(0.0, -1.0), (1.0, 0.0)]
    # a half circle from 45 to 225 deg counter-clockwise passes 90 and 180 deg
    c = math.sqrt(0.5)
    pts = arc_extremes(_arc((c, c, 0.0), (-c, -c, 0.0), (0.0, 0.0, 0.0), False))
    assert sorted((round(x, 12), round(y, 12)) for x, y, _ in pts) == [(-1.0, 0.0), (0.0, 1.0)]


def test_helix_extreme_has_the_z_of_its_angle():
    # a full helical turn from Z 0 to Z 4 mm: the quarter point at 90 deg (a quarter of the sweep) is at Z 1 mm
    arc = Arc(1, (1.0, 0.0, 0.0), (1.0, 0.0, 4 * MM), (0.0, 0.0, 0.0), "XY", False, 0.01, 1)
    z_at = {(round(x, 9), round(y, 9)): z for x, y, z in arc_extremes(arc)}
    assert z_at[(0.0, 1.0)] == pytest.approx(1 * MM, abs=1e-15)
    assert z_at[(-1.0, 0.0)] == pytest.approx(2 * MM, abs=1e-15)
