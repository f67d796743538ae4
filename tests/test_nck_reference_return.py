"""G28 reference position return and G53 machine coordinates (FANUC 0i-MF / 31i-B semantics).

Expected positions follow from the FANUC definitions: machine = programmed + work offset (+ tool length on
Z); G28 goes via the intermediate point (programmed like a G0 end point in G90/G91) to the reference
position, a machine position without offsets; G53 positions in machine coordinates at rapid.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck import GCodeError, InterpreterSettings, Linear, NCKernel, Rapid, interpret
from orchestrator import simulate
from orchestrator.machine import load_machine

MM = 1e-3
PAPER_CASE = Path(__file__).resolve().parent.parent / "models" / "examples" / "paper_part"
REF = (0.5, 0.4, 0.3)  # a reference position unlike the default one, m

CAM_POST = """%
O1001 (PART)
N10 G90 G94 G17 G49 G40 G80
N15 G21
N20 G28 G91 Z0.
N25 G90
N30 T1 M6
N35 S5000 M3
N40 G54
N45 M8
N50 G0 X-5. Y6.
N55 G43 Z15. H1
N60 G0 Z5.
N65 G1 Z-1. F1000.
N70 X35. F300.
N75 G0 Z15.
N80 M9
N85 M5
N90 G28 G91 Z0.
N95 G90
N100 G49
N105 G28 G91 X0. Y0.
N110 G90
N115 M01
N120 M30
%
"""


def moves(text: str, **kw):
    settings = InterpreterSettings(**{"reference": REF, **kw})
    return [b for b in interpret(text, "t.nc", settings).blocks if isinstance(b, (Rapid, Linear))]


def test_g28_g91_z0_goes_straight_up_to_the_reference_z():
    # G91 Z0: the intermediate point is the current position, so one rapid straight to reference Z
    ms = moves("G0 X10 Y20 Z5\nG28 G91 Z0.\n")
    assert len(ms) == 2
    assert isinstance(ms[1], Rapid) and ms[1].line == 2
    assert ms[1].start == pytest.approx((0.010, 0.020, 0.005))
    assert ms[1].end == pytest.approx((0.010, 0.020, REF[2]))  # X, Y not named: they stay


def test_g28_g90_goes_via_the_work_coordinate_intermediate_point():
    # G54 = (100, 50, -200) mm. G90 X0 Y0 intermediate = work (0, 0) = machine (0.1, 0.05); then reference X, Y
    ms = moves("G54 G0 X10 Y20 Z5\nG28 G90 X0 Y0\n", work_offsets={54: (0.1, 0.05, -0.2)})
    mid, ref = ms[1], ms[2]
    assert mid.end == pytest.approx((0.100, 0.050, -0.195))
    assert ref.start == mid.end and ref.end == pytest.approx((REF[0], REF[1], -0.195))
    assert {m.line for m in ms[1:]} == {2}


def test_after_g28_the_programmed_position_is_reference_minus_work_offset():
    # work Z offset -200 mm: after G28 Z the programmed Z is 300 - (-200) = 500 mm;
    # G91 Z-10 then goes to machine 290 mm, G90 Z5 to machine 5 - 200 = -195 mm
    ms = moves("G28 G91 Z0\nG91 G0 Z-10\nG90 Z5\n", work_offsets={54: (0.0, 0.0, -0.2)})
    assert ms[-2].end[2] == pytest.approx(REF[2] - 0.010)
    assert ms[-1].end[2] == pytest.approx(-0.195)


def test_tool_length_is_not_added_to_the_reference_and_is_reapplied_by_the_next_z_move():
    L = 0.08  # H1
    ms = moves("G43 H1 G0 Z15\nG28 G91 Z0\nG90 G0 Z15\nG28 G91 Z0\nG91 G0 Z-10\n", tool_lengths=[L])
    assert ms[0].end[2] == pytest.approx(0.015 + L)
    assert ms[1].end[2] == pytest.approx(REF[2])  # a machine position: no tool length
    assert ms[2].end[2] == pytest.approx(0.015 + L)  # G43 still active
    assert ms[3].end[2] == pytest.approx(REF[2])
    # G91 Z-10 after G28: programmed Z = REF - 0 (no tool length in the position) - 10, machine = that + L
    assert ms[4].end[2] == pytest.approx(REF[2] - 0.010 + L)


def test_g28_g90_intermediate_point_applies_the_tool_length_like_g0():
    ms = moves("G43 H1 G0 Z15\nG28 G90 Z40\n", tool_lengths=[0.05])
    assert ms[1].end[2] == pytest.approx(0.040 + 0.05)
    assert ms[2].end[2] == pytest.approx(REF[2])


def test_g28_is_non_modal_and_keeps_the_motion_mode():
    ms = moves("G1 X1 F100\nG28 G91 Z0\nG90 X5\n")
    assert isinstance(ms[1], Rapid)  # G28 moves at rapid even in G1 mode
    assert isinstance(ms[2], Linear) and ms[2].end == pytest.approx((0.005, 0.0, REF[2]))


REF2, REF3, REF4 = (0.45, 0.35, 0.25), (0.1, 0.2, 0.35), (-0.05, 0.15, 0.32)  # m, distinct from REF and each other


def test_g30_without_p_is_the_2nd_reference_and_only_named_axes_move():
    ms = moves("G0 X10 Y20 Z5\nG30 G91 Z0.\n", reference2=REF2, reference3=REF3, reference4=REF4)
    assert len(ms) == 2 and isinstance(ms[1], Rapid) and ms[1].line == 2
    assert ms[1].end == pytest.approx((0.010, 0.020, REF2[2]))


@pytest.mark.parametrize("p, ref", [(2, REF2), (3, REF3), (4, REF4)])
def test_g30_p_goes_via_the_work_intermediate_point_to_its_reference(p, ref):
    # as G28: G54 = (100, 50, -200) mm, G90 X0 Y0 -> machine (0.1, 0.05) first, then reference p X, Y; Z stays
    ms = moves(f"G54 G0 X10 Y20 Z5\nG30 P{p} G90 X0 Y0\n", work_offsets={54: (0.1, 0.05, -0.2)},
               reference2=REF2, reference3=REF3, reference4=REF4)
    mid, end = ms[1], ms[2]
    assert isinstance(mid, Rapid) and isinstance(end, Rapid)
    assert mid.end == pytest.approx((0.100, 0.050, -0.195))
    assert end.start == mid.end and end.end == pytest.approx((ref[0], ref[1], -0.195))


def test_g30_keeps_the_tool_length_out_and_the_programmed_position_consistent():
    # as after G28 Z: machine Z = REF3 Z (no tool length in it); work Z offset -200 mm, H1 = 80 mm:
    # G91 Z-10 -> programmed REF3 + 200 - 10 mm, machine = programmed - 200 + 80 mm
    ms = moves("G43 H1 G0 Z15\nG30 P3 G91 Z0\nG91 G0 Z-10\n", tool_lengths=[0.08], reference3=REF3,
               work_offsets={54: (0.0, 0.0, -0.2)})
    assert ms[1].end[2] == pytest.approx(REF3[2])
    assert ms[2].end[2] == pytest.approx(REF3[2] - 0.010 + 0.08)


def test_g30_with_unset_2nd_to_4th_references_goes_to_the_1st():
    for p in (2, 3, 4):
        assert moves(f"G0 Z5\nG30 P{p} G91 Z0\n")[-1].end[2] == pytest.approx(REF[2])


def test_kernel_parameters_and_machine_file_mapping_of_the_2nd_reference(tmp_path: Path):
    from orchestrator.twin import nck_parameters

    k = NCKernel(program_text="G0 X10 Y10 Z5\nG30 G91 Z0\nG30 P4 G91 X0 Y0\nM30\n",
                 reference2_x=0.2, reference2_y=0.1, reference2_z=0.15, reference4_x=0.05, reference4_y=0.06)
    k.setup(0.0)
    # Z to the 2nd reference Z (0.15), then X, Y to the 4th reference X, Y (4th Z is left at its default)
    np.testing.assert_allclose(k.plan_.position[0, -1], (0.05, 0.06, 0.15), atol=1e-12)
    # an older machine file without reference2..4 keys but with its own 1st reference: G30 goes there
    machine = load_machine("default")
    text = "\n".join(l for l in machine.path.read_text().splitlines() if not l.startswith(("reference2", "reference3",
                                                                                          "reference4")))
    text = text.replace("reference_z_mm = { value = 0.0", "reference_z_mm = { value = -20.0")
    path = tmp_path / "older.toml"
    path.write_text(text)
    params = nck_parameters(load_machine(path))
    assert [params[f"reference{n}_z"] for n in (2, 3, 4)] == pytest.approx([-0.02] * 3)
    assert params["reference2_x"] == 0.0


def test_g53_moves_in_machine_coordinates_at_rapid():
    # G55 = (10, 20, 30) mm and H1 = 50 mm must not enter a G53 position; G1 stays modal afterwards
    ms = moves("G55 G43 H1 G1 X1 Y1 Z1 F100\nG90 G53 X-100 Z-20\nY2\n",
               work_offsets={55: (0.01, 0.02, 0.03)}, tool_lengths=[0.05])
    g53 = ms[1]
    assert isinstance(g53, Rapid)
    assert g53.end == pytest.approx((-0.100, 0.021, -0.020))
    assert isinstance(ms[2], Linear) and ms[2].end == pytest.approx((-0.100, 0.022, -0.020))


def test_g53_then_absolute_move_is_consistent():
    ms = moves("G54 G90 G53 X0 Y0 Z0\nG0 X10 Z5\n", work_offsets={54: (0.1, 0.0, -0.2)})
    assert ms[0].end == pytest.approx((0.0, 0.0, 0.0))
    assert ms[1].end == pytest.approx((0.110, 0.0, -0.195))


@pytest.mark.parametrize("text, word, fragment", [
    ("G91 G53 Z0\n", "G53", "incremental"),
    ("G28\n", "G28", "without an axis word"),
    ("G28 G91 Z0 R5\n", "R5", "word R"),
    ("G30 P1 G91 Z0\n", "P1", "not a reference position number"),
    ("G30 P5 G91 Z0\n", "P5", "not a reference position number"),
    ("G30 P2.5 G91 Z0\n", "P2.5", "not a reference position number"),
    ("G30 P2\n", "G30", "without an axis word"),
    ("G30 G91 Z0 R5\n", "R5", "word R"),
    ("G0 Z10\nG81 X0 Z-1 R1 F100\nG30 G91 Z0\n", "G30", "canned-cycle mode"),
    ("G29 X0\n", "G29", "G29 is not supported"),
    ("G0 Z10\nG81 X0 Z-1 R1 F100\nG28 G91 Z0\n", "G28", "canned-cycle mode"),
])
def test_errors_name_the_word(text, word, fragment):
    with pytest.raises(GCodeError) as info:
        interpret(text, "p.nc")
    assert info.value.word == word and fragment in str(info.value)
    assert "expected" in str(info.value)


def test_default_reference_is_the_machine_files_and_well_above_the_work():
    nck = load_machine("default").si("nck")
    k = NCKernel()  # machine zero at the axis-frame origin: the reference parameter is the axis-frame position
    for a in "xyz":
        assert k.values[f"reference_{a}"][0] == pytest.approx(nck[f"machine_zero_{a}"] + nck[f"reference_{a}"])
    # default work offsets (-machine zero) and tool lengths 0: reference Z is the tool tip height above work Z0
    assert nck["machine_zero_z"] + nck["reference_z"] >= 0.1


def test_planned_reference_ends_at_the_reference_position():
    k = NCKernel(program_text="G0 X10 Y10 Z5\nG28 G91 Z0\nG28 G91 X0 Y0\nM30\n",
                 reference_x=0.2, reference_y=0.1, reference_z=0.15)
    k.setup(0.0)
    np.testing.assert_allclose(k.plan_.position[0, -1], (0.2, 0.1, 0.15), atol=1e-12)
    # Z rose first (line 2) with X, Y at 10 mm
    line = k.plan_.line[0]
    pos = k.plan_.position[0]
    at_line3 = int(np.argmax(line == 3))
    assert pos[at_line3] == pytest.approx((0.01, 0.01, 0.15), abs=0.02e-3)  # in position (20 um)


def test_cam_post_program_air_cut_ends_at_reference(tmp_path: Path):
    program = tmp_path / "cam.nc"
    program.write_text(CAM_POST)
    result = simulate(program, out=tmp_path / "out", plot=False)
    assert result.success, result.message
    nck = load_machine("default").si("nck")
    frame = result.recording.member(0)
    end = [frame[f"{a}_ref_mm"][-1] for a in "xyz"]  # the axis frame: machine zero + the reference position
    assert end == pytest.approx([(nck[f"machine_zero_{a}"] + nck[f"reference_{a}"]) * 1e3 for a in "xyz"], abs=1e-9)
    assert frame["z_mm"][-1] == pytest.approx((nck["machine_zero_z"] + nck["reference_z"]) * 1e3, abs=0.02)
    # the slot at Z-1 (line 14/15) is cut: the reference went down to Z -1 mm
    assert min(frame["z_ref_mm"]) == pytest.approx(-1.0, abs=1e-9)


def test_cam_post_program_on_the_paper_part_case(tmp_path: Path):
    program = tmp_path / "cam.nc"
    program.write_text(CAM_POST)
    result = simulate(program, case=PAPER_CASE, out=tmp_path / "out", plot=False)
    assert result.success, result.message
    frame = result.recording.member(0)
    nck = load_machine("default").si("nck")
    assert frame["z_ref_mm"][-1] == pytest.approx((nck["machine_zero_z"] + nck["reference_z"]) * 1e3, abs=1e-9)
