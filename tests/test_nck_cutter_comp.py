"""Cutter radius compensation G41/G42 as CAM posts write it in "wear" mode (FANUC 0i-MF / 31i-B semantics).

A post in "wear" (or "computer") compensation mode writes the tool-centre path and adds ``G41 D1`` / ``G40`` so the
operator can enter a wear value; with the D register at 0 FANUC executes exactly the programmed path. So the
expected blocks of a program with G41/G42 ... G40 and D = 0 are those of the same program with the G41/G42/G40/D
words deleted (same lines, same numbers), and the end points are the programmed coordinates (written out below).
A nonzero radius (the tool-centre path computed by the NC kernel) is tested in test_nck_radius_offset.py.
"""
from __future__ import annotations

import re

import pytest

from fmus_src.nck import Arc, GCodeError, InterpreterSettings, Linear, NCKernel, Rapid, interpret
from fmus_src.nck.component import N_TOOL_LENGTHS, N_TOOL_RADII

MM = 1e-3
MPM = 1e-3 / 60.0  # 1 mm/min in m/s

#: A Fusion 360 FANUC post, 2D contour with compensation type "Wear": lead-in with G41 ... D1, lead-out with G40.
FUSION_WEAR = """%
O1001 (WEAR MODE CONTOUR)
N10 G90 G94 G17 G49 G40 G80
N15 G21
N20 G28 G91 Z0.
N25 G90
(2D CONTOUR1)
N30 T1 M6
N35 S8000 M3
N40 G54 G0 X-5. Y-5.
N45 G43 Z15. H1
N50 Z5.
N55 G1 Z-2. F300.
N60 G41 X0. Y0. D1 F1000.
N65 Y20.
N70 G2 X10. Y30. I10. J0.
N75 G1 X40.
N80 G2 X50. Y20. R10.
N85 G1 Y0.
N90 X0.
N95 G40 X-5. Y-5.
N100 G0 Z15.
N105 M5
N110 G28 G91 Z0.
N115 G90
N120 M30
%
"""

#: A Mastercam-style post in "wear" mode with G42 (conventional milling, clockwise contour), cancel in the retract.
MASTERCAM_WEAR = """%
O0002
G20 G0 G17 G40 G49 G80 G90
T2 M6
G0 G90 G54 X-0.2 Y-0.2 S6000 M3
G43 H2 Z0.5
G1 Z-0.1 F20.
G1 G42 D2 X0. Y0. F40.
X0. Y1.
G3 X1. Y2. R1.
G1 X2.
Y0.
X0.
G0 G40 Z0.5
M30
%
"""


def _radii(**nonzero: float) -> list[float]:
    """N_TOOL_RADII radius offsets (m), zero except ``D<n>=value``."""
    r = [0.0] * N_TOOL_RADII
    for key, value in nonzero.items():
        r[int(key[1:]) - 1] = value
    return r


def _settings(**nonzero: float) -> InterpreterSettings:
    return InterpreterSettings(tool_lengths=[0.0] * N_TOOL_LENGTHS, tool_radii=_radii(**nonzero))


def _strip_compensation(text: str) -> str:
    """The same program without G40/G41/G42 and D words (line by line, so line numbers are kept)."""
    return "\n".join(re.sub(r"\s*(G4[012](?![0-9.])|D\d+)", "", ln) for ln in text.split("\n"))


def _feed_moves(program) -> list:
    return [b for b in program.blocks if isinstance(b, (Linear, Arc))]


def test_fusion_wear_mode_g41_d0_gives_the_tool_centre_path():
    with_comp = interpret(FUSION_WEAR, "fusion.nc", _settings())
    without = interpret(_strip_compensation(FUSION_WEAR), "fusion.nc", _settings())
    assert "G41" not in _strip_compensation(FUSION_WEAR) and "N10 G90 G94 G17 G49 G80" in _strip_compensation(
        FUSION_WEAR)
    assert with_comp.blocks == without.blocks
    # end points and feeds written out from the program (work offset and tool length zero: machine = program)
    moves = _feed_moves(with_comp)
    ends = [tuple(round(v / MM, 9) for v in b.end) for b in moves]
    assert ends == [(-5, -5, -2), (0, 0, -2), (0, 20, -2), (10, 30, -2), (40, 30, -2), (50, 20, -2), (50, 0, -2),
                    (0, 0, -2), (-5, -5, -2)]
    assert [b.feed / MPM for b in moves] == pytest.approx([300] + [1000] * 8)
    arcs = [b for b in moves if isinstance(b, Arc)]
    assert [tuple(round(v / MM, 9) for v in a.center) for a in arcs] == [(10, 20, -2), (40, 20, -2)]
    assert all(a.clockwise for a in arcs)


def test_mastercam_wear_mode_g42_d0_gives_the_tool_centre_path_in_inch():
    settings = _settings(D5=0.004)  # a nonzero register that is not used must not matter
    with_comp = interpret(MASTERCAM_WEAR, "mc.nc", settings)
    without = interpret(_strip_compensation(MASTERCAM_WEAR), "mc.nc", settings)
    assert with_comp.blocks == without.blocks
    inch = 25.4e-3
    ends = [tuple(round(v / inch, 9) for v in b.end[:2]) for b in _feed_moves(with_comp)]
    assert ends == [(-0.2, -0.2), (0, 0), (0, 1), (1, 2), (2, 2), (2, 0), (0, 0)]
    last_rapid = [b for b in with_comp.blocks if isinstance(b, Rapid)][-1]
    assert last_rapid.line == 14 and last_rapid.end[2] == pytest.approx(0.5 * inch)


@pytest.mark.parametrize("word", ["D201", "D1.5", "D1.", "D-1"])
def test_d_out_of_range_is_an_error(word):
    with pytest.raises(GCodeError) as info:
        interpret(f"G0 X0\nG41 {word} G1 X1 F100\n", "a.nc", _settings())
    assert info.value.line == 2 and info.value.word == word
    assert "does not exist" in str(info.value) and "D0..D200" in str(info.value)


def test_d_with_default_settings_has_only_d0():
    assert interpret("G41 D0 G1 X1 F100\nG40 X2\n").blocks[0].end[0] == pytest.approx(1 * MM)
    with pytest.raises(GCodeError, match=r"no tool radius offsets are set: InterpreterSettings.tool_radii is empty"):
        interpret("G41 D1 G1 X1 F100\n")


@pytest.mark.parametrize("text, line, word, fragment", [
    ("G0 X0 Y0\nG41 D1\nG2 X10 Y0 R5 F100\n", 3, "G2", "start-up after G41/G42 in circular interpolation G2"),
    ("G0 X0 Y0\nG3 G42 D1 X10 Y0 R5 F100\n", 2, "G3", "start-up"),
    ("G0 X0 Y0\nG41 D1 G1 X5 F100\nG40\nG2 X15 R5\n", 4, "G2", "cancel after G40 in circular interpolation"),
    ("G0 X0 Y0\nG41 D1 G1 X5 F100\nG18 X6\n", 3, "G18", "PS0037"),
    ("G0 X0 Y0\nG41 D1 G1 X5 F100\nG40 G19 X6\n", 3, "G19", "changes the plane"),
])
def test_fanuc_alarms_of_compensation_start_up_cancel_and_plane(text, line, word, fragment):
    with pytest.raises(GCodeError) as info:
        interpret(text, "a.nc", _settings())
    assert info.value.line == line and info.value.word == word and fragment in str(info.value)


def test_start_up_and_cancel_in_g0_g1_then_arcs_are_fine():
    text = ("G0 X0 Y0\nG41 D1\nG1 X5 F100\nG2 X15 R5\nG40\nG0 Z10\nG2 X25 R5 F100\n")
    assert interpret(text, "a.nc", _settings()).blocks == interpret(_strip_compensation(text), "a.nc",
                                                                      _settings()).blocks


def test_g41_in_g18_with_zero_radius_is_the_programmed_path():
    text = "G18 G0 X0 Z0\nG41 D1 G1 X10 Z-5 F200\nG2 X20 Z-5 R5\nG40 G1 X30 Z0\n"
    with_comp = interpret(text, "a.nc", _settings())
    assert with_comp.blocks == interpret(_strip_compensation(text), "a.nc", _settings()).blocks
    arc = [b for b in with_comp.blocks if isinstance(b, Arc)][0]
    assert arc.plane == "ZX" and arc.end == pytest.approx((0.020, 0.0, -0.005))


def test_canned_cycle_and_reference_return_under_g41_with_zero_radius_run_as_programmed():
    text = ("G0 X0 Y0 Z20\nG1 G41 D1 X1 F300\nG99 G81 X10 Y10 Z-5 R2 F150\nX20\nG80\nG28 G91 Z0\nG90 G53 Z0\n"
            "G40 G0 X0 Y0\n")
    with_comp = interpret(text, "a.nc", _settings())
    assert with_comp.blocks == interpret(_strip_compensation(text), "a.nc", _settings()).blocks
    drills = [b for b in with_comp.blocks if isinstance(b, Linear) and b.line in (3, 4)]
    assert [tuple(round(v / MM, 9) for v in b.end) for b in drills] == [(10, 10, -5), (20, 10, -5)]


def test_nck_parameters_tool_radius_feed_the_interpreter():
    names = {v.name for v in NCKernel.variables}
    assert {f"tool_radius_{d}" for d in range(1, N_TOOL_RADII + 1)} <= names and N_TOOL_RADII == N_TOOL_LENGTHS
    assert all(v.start == 0.0 and v.unit == "m" for v in NCKernel.variables if v.name.startswith("tool_radius_"))
    prog = "G0 X0 Y0\nG1 G41 D2 X5 F600\nG40 X10\nM30\n"
    k = NCKernel(program_text=prog)
    k.setup(0.0)
    assert k.program_.blocks == interpret(_strip_compensation(prog)).blocks
    # D2 = 4 mm: a straight start-up and cancel; G41 offsets to +Y (left of +X): the start-up ends at (5, 4)
    k = NCKernel(program_text=prog, tool_radius_2=4e-3)
    k.setup(0.0)
    start_up = k.program_.blocks[1]
    assert start_up.line == 2 and start_up.end == pytest.approx((5 * MM, 4 * MM, 0.0), abs=1e-15)
