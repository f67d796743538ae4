"""The machine coordinate frame: machine zero at the G28 reference position, as on a FANUC/Haas VMC.

The default machine (default.toml) puts machine zero at axis (380, 225, 300) mm, the + ends of its 762/450/510 mm
travels; the default work offsets are -machine zero, so work coordinates are the twin's axis frame (recordings,
stock). Expected positions below are axis = machine coordinate + machine zero, and work = machine - work offset.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck import GCodeError, NCKernel, Rapid
from orchestrator.fmu.build import _nck_parameters, machine_parameters
from orchestrator.machine import MachineFileError, load_machine
from orchestrator.twin import nck_parameters

MM = 1e-3
ZERO_MM = (380.0, 225.0, 300.0)  # machine zero in the axis frame (default.toml machine_zero_*_mm)

#: A Fusion 360 Haas-style post: G28 G91 Z0. first, the G53 safe retract and the G53 X/Y park at the end.
FUSION_HAAS = """%
O1001 (FUSION 360 HAAS-STYLE POST)
G90 G94 G17 G40 G49 G80
G21
G28 G91 Z0.
G90
T1 M6
S6000 M3
G54 G0 X10. Y10.
G43 H1 Z15.
G1 Z-1. F300.
X40. F600.
G0 Z15.
G53 G0 Z0.
G53 G0 X0. Y0.
M30
%
"""
RETRACT_LINE = 14  # G53 G0 Z0.
PARK_LINE = 15  # G53 G0 X0. Y0.


def kernel(text: str, machine=None, **extra) -> NCKernel:
    params = nck_parameters(machine or load_machine("default"))
    return NCKernel(program_text=text, **{**params, "z_initial": 0.05, **extra})


def planned(text: str, machine=None, **extra) -> NCKernel:
    k = kernel(text, machine, **extra)
    k.setup(0.0)
    return k


def ends(k: NCKernel, line: int) -> list[tuple[float, float, float]]:
    return [tuple(b.end) for b in k.program_.blocks if isinstance(b, Rapid) and b.line == line]


def test_default_machine_places_machine_zero_at_the_reference_position_and_work_zero_at_the_axis_origin():
    m = load_machine("default")
    nck = m.values["nck"]
    assert tuple(nck[f"machine_zero_{a}_mm"] for a in "xyz") == ZERO_MM
    assert all(nck[f"reference{n}_{a}_mm"] == 0.0 for n in ("", "2", "3", "4") for a in "xyz")
    params = nck_parameters(m)
    for i, a in enumerate("xyz"):
        for g in range(54, 60):  # default work offsets: machine coordinates of the axis-frame origin
            assert params[f"g{g}_{a}"] == -ZERO_MM[i] * MM
        lo, hi = m.stroke_limits()[a]
        assert hi == 0.0  # the + end of the travel is machine zero
    # the NCK FMU's start values, and the FMU build's own mapping (used when orchestrator.twin does not import),
    # carry the same frame
    starts = machine_parameters("NCKernel", m, NCKernel)
    fmu = _nck_parameters(m, NCKernel)
    for key in ("machine_zero_x", "machine_zero_z", "g54_x", "g59_z", "reference_z", "reference2_z", "reference4_x"):
        assert starts[key] == params[key] and fmu[key] == params[key], key
    assert starts["machine_zero_z"] == 0.3 and starts["g54_z"] == -0.3


def test_fusion_haas_safe_retract_goes_to_the_top_of_the_travel_and_parks_at_the_reference_xy():
    k = planned(FUSION_HAAS)
    # G53 Z0 = machine Z 0 = axis (= work, default offsets) Z 300 mm, the top of the 510 mm travel
    (retract,) = ends(k, RETRACT_LINE)
    assert retract == pytest.approx((40 * MM, 10 * MM, 300 * MM), abs=1e-15)
    (park,) = ends(k, PARK_LINE)
    assert park == pytest.approx((380 * MM, 225 * MM, 300 * MM), abs=1e-15)  # the G28 reference X/Y
    end = k.plan_.member(0).position[-1]
    np.testing.assert_allclose(end, (0.380, 0.225, 0.300), atol=1e-15)


def test_the_retract_takes_the_rapid_profile_time():
    # Z rapid 30 m/min, bell-shaped rapid acc/dec after interpolation of 60 ms (default.toml): from Z 15 mm to
    # Z 300 mm, the filtered reference arrives (300 - 15) mm / 500 mm/s + 60 ms = 0.63 s after the block starts
    m = load_machine("default")
    v = m.values["axis"]["z"]["rapid_feed_mm_per_min"] / 60.0
    t_filter = m.values["nck"]["rapid_time_constant_ms"] * 1e-3
    expected = (300.0 - 15.0) / v + t_filter
    plan = planned(FUSION_HAAS, m).plan_.member(0)
    ts = m.values["nck"]["interpolation_period_ms"] * 1e-3
    start = int(np.argmax(plan.line == RETRACT_LINE))
    arrive = start + int(np.argmax(np.abs(plan.position[start:, 2] - 0.300) < 1e-12))  # (G28 was there before)
    assert (arrive - start) * ts == pytest.approx(expected, abs=2 * ts)
    # the same arithmetic alone, from the twin's start height Z 50 mm: 250 mm / 500 mm/s + 60 ms
    alone = planned("G90 G53 G0 Z0.\nM30\n", m).plan_.member(0)
    arrive = int(np.argmax(np.abs(alone.position[:, 2] - 0.300) < 1e-12))
    assert arrive * ts == pytest.approx((300.0 - 50.0) / v + t_filter, abs=2 * ts)


def test_g53_plans_bit_for_bit_as_the_same_positions_written_in_work_coordinates():
    # work coordinates of the default offsets are the axis frame: G53 Z0 = G0 Z300 (without tool length)
    written = (FUSION_HAAS.replace("G53 G0 Z0.", "G49 G0 Z300.").replace("G53 G0 X0. Y0.", "G0 X380. Y225."))
    a, b = planned(FUSION_HAAS), planned(written)
    assert a.duration_[0] == b.duration_[0]
    pa, pb = a.plan_.member(0).position, b.plan_.member(0).position
    assert pa.shape == pb.shape and (pa == pb).all()


@pytest.mark.parametrize("block, word, alarm, where", [
    ("G53 G0 Z10.", "Z", "OT0500 + OVERTRAVEL", "takes Z to 10 mm in machine coordinates"),
    ("G53 G0 X-770.", "X", "OT0501 - OVERTRAVEL", "takes X to -770 mm in machine coordinates"),
])
def test_g53_beyond_the_travel_is_an_overtravel_named_in_machine_coordinates(block, word, alarm, where):
    with pytest.raises(GCodeError) as info:
        kernel(f"G90 G0 X0 Y0 Z10.\n{block}\nM30\n").planning_inputs()
    exc = info.value
    assert exc.line == 2 and exc.word == word
    assert alarm in str(exc) and where in str(exc)
    limits = {"X": "[-762, 0] mm", "Z": "[-510, 0] mm"}
    assert limits[word] in str(exc)


def test_a_program_setting_its_own_g54_in_machine_coordinates():
    # G10 L2 P1 X-400 Y-250 Z-450: work zero at machine (-400, -250, -450) = axis (-20, -25, -150) mm; Z stays at
    # the start height 50 mm until the first Z word
    text = ("G90 G10 L2 P1 X-400. Y-250. Z-450.\nG54 G0 X10. Y20.\nZ5.\nG1 Z-20. F300.\n"
            "G91 G10 L2 P1 X5.\nG90 G0 X10.\nM30\n")
    k = planned(text)
    pts = [tuple(round(v / MM, 9) for v in b.end) for b in k.program_.blocks if hasattr(b, "end") and b.line > 1]
    assert pts == [(-10.0, -5.0, 50.0), (-10.0, -5.0, -145.0), (-10.0, -5.0, -170.0), (-5.0, -5.0, -170.0)]
    # the recording's axes show the same axis-frame positions (work coordinates of the default offsets)
    assert k.plan_.member(0).position[-1] == pytest.approx((-5 * MM, -5 * MM, -170 * MM), abs=1e-12)
    # the stroke check sees machine Z = -450 + (-70) = -520 mm < -510 mm
    with pytest.raises(GCodeError) as info:
        kernel(text.replace("Z-20.", "Z-70.")).planning_inputs()
    assert info.value.line == 4 and "OT0501" in str(info.value) and "takes Z to -520 mm" in str(info.value)


def test_unset_additional_offsets_are_the_default_work_zero_and_g10_l20_sets_machine_coordinates():
    k = planned("G90 G54.1 P3 G0 X10. Y20.\nG10 L20 P3 X-370. Y-200.\nG0 X0 Y0\nG154 P60 X1.\nM30\n")
    pts = [tuple(round(v / MM, 9) for v in b.end[:2]) for b in k.program_.blocks if isinstance(b, Rapid)]
    # P3 unset: axis (10, 20); set to machine (-370, -200) = axis (10, 25): X0 Y0 there; G154 P60 unset: X 1
    assert pts == [(10.0, 20.0), (10.0, 25.0), (1.0, 25.0)]


def _old_frame_file(tmp_path: Path) -> Path:
    """default.toml written as before machine_zero_*_mm: machine coordinates = the axis frame."""
    text = load_machine("default").path.read_text()
    text = "\n".join(l for l in text.splitlines() if not l.startswith("machine_zero_"))
    for a, ref in zip("xyz", ZERO_MM):
        text = re.sub(rf"^(reference\d?_{a}_mm = {{ value = )0\.0", rf"\g<1>{ref}", text, flags=re.M)
    lines, axis = [], None
    old = {"x": (-382.0, 380.0), "y": (-225.0, 225.0), "z": (-210.0, 300.0)}
    for line in text.splitlines():
        m = re.match(r"^\[axis\.([xyz])\]$", line)
        axis = m.group(1) if m else (None if line.startswith("[") else axis)
        if axis and line.startswith(("stroke_min_mm", "stroke_max_mm")):
            value = old[axis][0 if line.startswith("stroke_min") else 1]
            line = re.sub(r"value = [-0-9.]+", f"value = {value}", line)
        lines.append(line)
    path = tmp_path / "old_frame.toml"
    path.write_text("\n".join(lines))
    return path


def test_a_machine_file_without_machine_zero_keeps_the_axis_frame_as_machine_coordinates(tmp_path):
    old = load_machine(_old_frame_file(tmp_path))
    assert old.machine_zero() is None and "machine_zero_x" not in nck_parameters(old)
    # G53 Z0 is axis Z 0 there (the part top, as before), G28 Z the reference Z 300
    k = planned("G90 G0 X0 Y0 Z10.\nG53 G0 Z0.\nG28 G91 Z0.\nM30\n", old)
    assert [e[2] for e in ends(k, 2) + ends(k, 3)] == pytest.approx([0.0, 0.3], abs=1e-15)
    # a program without G53/G10 plans bit for bit alike in both frames
    text = ("G90 G54 G0 X10. Y10. Z5.\nG28 G91 Z0.\nG90 G28 X0. Y0.\nG30 G91 Z0.\nG90 G55 G0 X20. Y-30. Z2.\n"
            "G54.1 P2 G1 Z-1. F300.\nX40. F600.\nG28 G91 Z0.\nM30\n")
    a, b = planned(text), planned(text, old)
    pa, pb = a.plan_.member(0).position, b.plan_.member(0).position
    assert a.duration_[0] == b.duration_[0] and pa.shape == pb.shape and (pa == pb).all()


def test_machine_zero_without_references_returns_to_machine_zero(tmp_path):
    text = load_machine("default").path.read_text()
    path = tmp_path / "no_refs.toml"
    path.write_text("\n".join(l for l in text.splitlines() if not l.startswith("reference")))
    k = planned("G90 G0 X0 Y0 Z10.\nG28 G91 Z0.\nG30 G91 X0.\nM30\n", load_machine(path))
    assert ends(k, 2)[-1][2] == pytest.approx(0.3, abs=1e-15) and ends(k, 3)[-1][0] == pytest.approx(0.38, abs=1e-15)


def test_machine_zero_needs_all_three_axes(tmp_path):
    text = load_machine("default").path.read_text()
    path = tmp_path / "half.toml"
    path.write_text("\n".join(l for l in text.splitlines() if not l.startswith("machine_zero_y")))
    with pytest.raises(MachineFileError, match=r"\[nck\] machine_zero_x_mm without machine_zero_y_mm") as info:
        load_machine(path)
    line = 1 + text.splitlines().index(next(l for l in text.splitlines() if l.startswith("machine_zero_x")))
    assert f"{path}:{line}:" in str(info.value)
