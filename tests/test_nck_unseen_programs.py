"""Programs written the way CAM post-processors and machinists write them, checked against hand-derived numbers.

Each program is a realistic sample of one source (Autodesk Fusion FANUC post, Mastercam generic FANUC, NX /
SolidCAM style with canned cycles and incremental blocks, a hand-written shop program, an inch program). The
expected end points, arc centres, dwell times and feed times are derived by hand in the comments, not pasted
from the twin's output. The last part covers the messages of programs the twin cannot run: each names the file,
the line and what was expected.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.nck import (
    Arc, Dwell, GCodeError, InterpreterSettings, Linear, NCKernel, ProgramEnd, Rapid, interpret, read_program,
)

MM = 1e-3
INCH = 25.4e-3
#: 20 zero H and D registers, as the NCKernel component and ``cnctwin simulate`` have them.
REGISTERS = InterpreterSettings(tool_lengths=[0.0] * 20, tool_radii=[0.0] * 20)
#: G28 reference position of the default machine, mm (machine coordinates).
REFERENCE_MM = (380.0, 225.0, 300.0)


def _mm(v) -> tuple[float, ...]:
    return tuple(round(c / MM, 6) + 0.0 for c in v)


def _moves(program, line: int | None = None) -> list:
    return [b for b in program.blocks if isinstance(b, (Rapid, Linear, Arc)) and (line is None or b.line == line)]


# ----------------------------------------------------------------------------- Autodesk Fusion FANUC post
FUSION = """%
O1001 (POCKET)
(T1 D=6. CR=0. - ZMIN=-2. - FLAT END MILL)
N10 G90 G94 G17 G49 G40 G80
N15 G21
N20 G28 G91 Z0.
N25 G90

(2D POCKET1)
N30 T1 M6
N35 (FLAT END MILL)
N40 S6000 M3
N45 G54
N50 M8
N55 G0 X10. Y10.
N60 G43 Z15. H1
N65 Z5.
N70 G1 Z1. F1000.
N75 G3 X11. Y10. Z0.5 I0.5 J0.
N80 X10. Y10. Z0. I-0.5 J0.
N85 G1 X20. F800.
N90 G17 G2 X30. Y20. I0. J10.
N95 G1 Y40.
N100 G3 X20. Y50. I-10. J0.
N105 X10. Y40. R10.
N110 G1 Y10.
N115 G0 Z15.
N120 M9
N125 G28 G91 Z0.
N130 G90
N135 G28 G91 X0. Y0.
N140 M30
%
"""


def test_fusion_post_program_geometry():
    program = interpret(FUSION, "1001.nc", REGISTERS)
    # the file's line numbers (the % line is line 1), not the N numbers
    assert _mm(_moves(program, 6)[0].end) == (0.0, 0.0, 300.0)  # G28 G91 Z0.: straight up to the reference Z
    assert _mm(_moves(program, 16)[0].end) == (10.0, 10.0, 15.0)  # G43 Z15. H1 with H1 = 0
    # helical ramp: two half turns of radius 0.5 about (10.5, 10), 0.5 mm down each
    first, second = _moves(program, 19)[0], _moves(program, 20)[0]
    assert _mm(first.center)[:2] == (10.5, 10.0) and _mm(first.end) == (11.0, 10.0, 0.5)
    assert _mm(second.center)[:2] == (10.5, 10.0) and _mm(second.end) == (10.0, 10.0, 0.0)
    assert first.sweep == pytest.approx(math.pi) and second.sweep == pytest.approx(math.pi)  # G3: CCW
    # G2 from (20, 10) about (20, 20) to (30, 20): from straight below the centre clockwise to its right: 270 deg
    arc = _moves(program, 22)[0]
    assert _mm(arc.center)[:2] == (20.0, 20.0) and arc.sweep == pytest.approx(-1.5 * math.pi)
    # G3 R10. from (20, 50) to (10, 40): the 90 deg arc about (20, 40), the same centre as the I/J arc before it
    assert _mm(_moves(program, 25)[0].center)[:2] == (20.0, 40.0)
    assert _mm(_moves(program, 31)[0].end) == REFERENCE_MM  # G28 G91 X0. Y0. at Z300
    assert isinstance(program.blocks[-1], ProgramEnd) and program.blocks[-1].line == 32


def test_fusion_post_program_line_times():
    # the feed blocks after the helix run at 800 mm/min: Y20 -> Y40 is 20 mm, Y40 -> Y10 30 mm, the 270 deg
    # arc of R10 is 15 pi mm; each ends at a corner or an arc junction, so it takes at least L/F and at most
    # L/F + one acc/dec (v/a + change time + after-interpolation T = 0.0067 + 0.032 + 0.016 s). Line 26 is
    # followed by the rapid G0 Z15.: it also holds the in-position check before the rapid, at most the filter's
    # T = 0.016 s for the reference to arrive plus the decay of a lag of at most v/Kv = 0.267 mm into the 20 um
    # width, ln(0.267 / 0.02) / 50 = 0.052 s
    kernel = NCKernel(program_text=FUSION)
    kernel.setup(0.0)
    plan = kernel.plan_
    line = plan.line[0] if plan.line.ndim == 2 else plan.line
    period = plan.period
    settle = 0.016 + math.log(800 / 60e3 / 50.0 / 0.02e-3) / 50.0
    for number, length, wait in ((23, 20.0, 0.0), (26, 30.0, settle), (22, 15 * math.pi, 0.0)):
        seconds = float((line == number).sum()) * period
        assert length / 800 * 60 <= seconds <= length / 800 * 60 + 0.06 + wait, number


# ----------------------------------------------------------------------------- Mastercam generic FANUC
MASTERCAM = """%
O0000(MCAM PART)
(DATE=DD-MM-YY - 28-11-26 TIME=HH:MM - 15:20)
( T2 |  10. FLAT ENDMILL | H2 )
N100 G21
N102 G0 G17 G40 G49 G80 G90
N104 T2 M6
N106 G0 G90 G54 X-5. Y-5. A0. S5000 M3
N108 G43 H2 Z25.
N110 M30
%
"""


def test_mastercam_fourth_axis_word_turning_the_axis_is_a_clear_error():
    with pytest.raises(GCodeError) as info:
        interpret(MASTERCAM.replace(" A0.", " A90."), "mcam.nc", REGISTERS)
    err = info.value
    assert (err.file, err.line, err.word) == ("mcam.nc", 8, "A90.")
    assert "A is a rotary axis about X" in str(err) and "only X, Y and Z" in str(err)
    assert "A0 is accepted" in str(err)
    assert str(err).startswith("mcam.nc:8: 'N106 G0 G90 G54 X-5. Y-5. A90. S5000 M3':")


def test_mastercam_rotary_word_at_zero_runs_as_without_it():
    """``A0.`` keeps the (absent) rotary table at its home: the blocks are those of the program without it."""
    program = interpret(MASTERCAM, "mcam.nc", REGISTERS)
    assert program.blocks == interpret(MASTERCAM.replace(" A0.", ""), "mcam.nc", REGISTERS).blocks
    assert _mm(_moves(program, 8)[0].end) == (-5.0, -5.0, 0.0)
    assert _mm(_moves(program, 9)[0].end) == (-5.0, -5.0, 25.0)


# ----------------------------------------------------------------------------- NX / SolidCAM style
NX = """%
O2000
N0010 G40 G17 G90 G21 G94
N0020 G91 G28 Z0.0
N0030 T03 M06
N0040 G90 G54 G00 X0.0 Y0.0 S1200 M03
N0050 G43 Z50. H03 M08
N0060 G98 G81 X10. Y10. Z-5. R2. F100.
N0070 X20.
N0080 G99 G82 X30. Z-6. R1. P200
N0090 G83 X40. Z-10. R2. Q3. F80.
N0100 G73 X50. Z-4. R2. Q1.5
N0110 G80
N0120 G00 Z50.
N0130 G91 G01 X10. Y5. F200.
N0140 X-10. Y-5.
N0150 G02 X20. Y0. R10.
N0160 G03 X-20. Y0. I-10. J0.
N0170 G90
N0180 G91 G81 X10. Y0. Z-5. R-48. K3 F100.
N0190 G80 G90
N0200 M30
%
"""


def test_nx_style_canned_cycles_and_incremental_blocks():
    program = interpret(NX, "2000.nc", REGISTERS)
    # G98 G81 from the initial level Z50: rapid to R2, feed to Z-5, back to Z50 (G98)
    assert [_mm(b.end)[2] for b in _moves(program, 8)] == [50.0, 2.0, -5.0, 50.0]
    # G99 G82 P200: to R1, feed to Z-6, dwell 0.2 s, back to R1 (G99)
    assert [_mm(b.end)[2] for b in _moves(program, 10)] == [50.0, 1.0, -6.0, 1.0]
    assert [b.seconds for b in program.blocks if isinstance(b, Dwell) and b.line == 10] == [pytest.approx(0.2)]
    # G83 Q3 to Z-10 from R2: pecks to -1, -4, -7, -10, back to R after each, down again to 0.5 mm above
    feeds = [_mm(b.end)[2] for b in _moves(program, 11) if isinstance(b, Linear)]
    assert feeds == [-1.0, -4.0, -7.0, -10.0]
    rapids = [_mm(b.end)[2] for b in _moves(program, 11) if isinstance(b, Rapid)]
    assert rapids == [1.0, 2.0, 2.0, -0.5, 2.0, -3.5, 2.0, -6.5, 2.0]  # the first: X40 at the R1 of line 10
    # G73 Q1.5 to Z-4 from R2: pecks to 0.5, -1, -2.5, -4 with 0.2 mm retracts (No. 5114)
    g73 = [_mm(b.end)[2] for b in _moves(program, 12)]
    assert g73 == [2.0, 0.5, 0.7, -1.0, -0.8, -2.5, -2.3, -4.0, 2.0]
    # incremental lines and arcs from (50, 10, 50)
    assert _mm(_moves(program, 15)[0].end) == (60.0, 15.0, 50.0)
    assert _mm(_moves(program, 16)[0].end) == (50.0, 10.0, 50.0)
    r_arc, ij_arc = _moves(program, 17)[0], _moves(program, 18)[0]
    assert _mm(r_arc.end) == (70.0, 10.0, 50.0) and _mm(r_arc.center)[:2] == (60.0, 10.0)
    assert _mm(ij_arc.end) == (50.0, 10.0, 50.0) and _mm(ij_arc.center)[:2] == (60.0, 10.0)
    # G91 G81 K3 from Z50: R = 50 - 48 = 2, bottom 2 - 5 = -3, X steps of 10 from X50, return to R (G99 modal)
    holes = [_mm(b.end) for b in _moves(program, 20) if isinstance(b, Linear)]
    assert holes == [(60.0, 10.0, -3.0), (70.0, 10.0, -3.0), (80.0, 10.0, -3.0)]
    assert _mm(_moves(program, 20)[-1].end) == (80.0, 10.0, 2.0)


# ----------------------------------------------------------------------------- hand-written shop program
SHOP = """%
o1234 (shop program)
g21 g90 g17 g40 g49 g80
g 91 g 28 z 0
t 2 m 6
s 1500 m 03
g 90 g 54 g 00 x 0 y 0
g 43 h 2 z 10 ; approach
/m08
g 01 z-2 f 100
x 40. f 300 (no decimal point on z above)
y 30
g04 p500
g4 x0.5
g0 z10
m98 p1000 l3
#100 = 5
#101 = 0
while [#101 lt 3] do1
g1 x[#101 * #100] y-5 f200
#101 = #101 + 1
end1
if [#101 eq 3] goto 50
g0 x999
n50 g0 z50
m30
o1000
g91 g1 x1. f100
g90
m99
%
"""


def test_hand_written_shop_program():
    program = interpret(SHOP, "shop.nc", REGISTERS)
    assert _mm(_moves(program, 10)[0].end) == (0.0, 0.0, -2.0)  # z-2 without a point: 2 mm (calculator input)
    assert _mm(_moves(program, 11)[0].end) == (40.0, 0.0, -2.0)
    # P500 without a point is 500 ms; X0.5 is 0.5 s
    assert [b.seconds for b in program.blocks if isinstance(b, Dwell)] == [pytest.approx(0.5), pytest.approx(0.5)]
    # M98 P1000 L3: three incremental 1 mm steps on line 28 from X40
    assert [_mm(b.end)[0] for b in _moves(program, 28)] == [41.0, 42.0, 43.0]
    # the WHILE loop: X = 0, 5, 10 at Y-5; the IF jumps over x999
    assert [_mm(b.end)[:2] for b in _moves(program, 20)] == [(0.0, -5.0), (5.0, -5.0), (10.0, -5.0)]
    assert not _moves(program, 24) and _mm(_moves(program, 25)[0].end) == (10.0, -5.0, 50.0)


# ----------------------------------------------------------------------------- inch program
def test_inch_program_arcs_and_cycle_in_mm():
    text = ("%\nO3000 (INCH)\nG20 G90 G17 G40 G49 G80 G94\nG54 G0 X0. Y0. Z1.\nG1 Z-.1 F10.\nX2. F20.\n"
            "G2 X3. Y1. R1.\nG3 X2. Y2. I-1.\nG99 G81 X1. Y1. Z-.5 R.1 F5.\nG80\nM30\n%\n")
    program = interpret(text, "inch.nc", REGISTERS)
    r_arc, ij_arc = _moves(program, 7)[0], _moves(program, 8)[0]
    # G2 R1. from (2, 0) to (3, 1): the short arc about (3, 0); G3 I-1. from (3, 1) about (2, 1)
    assert r_arc.center[:2] == pytest.approx((3 * INCH, 0.0)) and r_arc.sweep == pytest.approx(-math.pi / 2)
    assert ij_arc.center[:2] == pytest.approx((2 * INCH, 1 * INCH)) and ij_arc.end[:2] == pytest.approx(
        (2 * INCH, 2 * INCH))
    assert _moves(program, 6)[0].feed == pytest.approx(20 * INCH / 60)  # 20 in/min in m/s
    drill = [b for b in _moves(program, 9) if isinstance(b, Linear)][0]
    assert drill.end[2] == pytest.approx(-0.5 * INCH) and drill.feed == pytest.approx(5 * INCH / 60)


# ----------------------------------------------------------------------------- messages
def test_h_register_without_tool_lengths_says_none_are_set():
    with pytest.raises(GCodeError) as info:
        interpret("G90 G0 X0 Y0\nG43 Z15. H1\n", "a.nc")
    message = str(info.value)
    assert info.value.line == 2 and info.value.word == "H1"
    assert "no tool length offsets are set" in message and "InterpreterSettings.tool_lengths" in message
    assert "H0..H0" not in message
    # with registers, the range is named
    with pytest.raises(GCodeError, match=r"expected H0\.\.H20 \(integers\)"):
        interpret("G43 Z15. H21\n", "a.nc", REGISTERS)


def test_g43_without_h_and_without_registers_names_the_setting():
    with pytest.raises(GCodeError, match=r"G43 H<n>, with the tool lengths given in InterpreterSettings"):
        interpret("G43 Z15.\n", "a.nc")


def test_d_register_without_tool_radii_says_none_are_set():
    with pytest.raises(GCodeError, match="no tool radius offsets are set") as info:
        interpret("G0 X0 Y0\nG41 D1 G1 X10. F100\n", "a.nc")
    assert info.value.line == 2 and "D0..D0" not in str(info.value)


@pytest.mark.parametrize("block", ["G91 G81 X1. Z-1. R-1. K99999999 F100", "G81 X1. Z-1. R1. K100000 F100"])
def test_canned_cycle_repeat_count_is_not_range_checked_as_a_coordinate(block):
    with pytest.raises(GCodeError) as info:
        interpret(f"G0 X0 Y0 Z10.\n{block}\n", "a.nc")
    assert info.value.line == 2 and "repeat count" in str(info.value) and "K9999" in str(info.value)
    assert "input range" not in str(info.value)


def test_canned_cycle_repeat_count_in_a_modal_cycle_block_and_arc_k_keep_their_checks():
    with pytest.raises(GCodeError, match="repeat count K99999999"):
        interpret("G0 X0 Y0 Z10.\nG81 X1. Z-1. R1. F100\nX2. K99999999\n", "a.nc")
    with pytest.raises(GCodeError, match="beyond the input range"):  # K of an arc is a length
        interpret("G0 X0 Y0 Z0\nG18 G2 X1. Z0 K999999. F100\n", "a.nc")
    with pytest.raises(GCodeError, match="K50000 is beyond the input range of 9999.9999 in"):
        interpret("G20\nG0 X0 Y0 Z0\nG18 G2 X1. Z0 K50000 F10\n", "a.nc")


@pytest.mark.parametrize("radius", [0.1, 0.7, 2.3, 4.9])
def test_arc_radius_equal_to_the_tool_radius_prints_no_float_noise(radius):
    # G41 on a G3 arc puts the tool inside it: R - D = 0 exactly, printed as 0 (was e.g. -1.35525e-17 mm)
    text = f"G0 X-10. Y0\nG41 D1 G1 X0.3 Y0 F100\nG3 X{0.3 + 2 * radius:.4f} Y0 R{radius}\nG1 X30.\nG40 X40.\n"
    with pytest.raises(GCodeError) as info:
        interpret(text, "a.nc", InterpreterSettings(tool_radii=[radius * MM]))
    message = str(info.value)
    assert info.value.line == 3 and "tool-centre arc radius of 0 mm" in message and "e-" not in message


@pytest.mark.parametrize("raw, shown", [
    ("G1\x07X1 F100", r"G1\x07X1 F100"),  # BEL
    ("G1 X1\x1b[31m F100", r"G1 X1\x1b[31m F100"),  # a terminal colour escape sequence
    ("G1\tX1\x0cY2", r"G1\tX1\x0cY2"),  # tab and form feed
])
def test_control_characters_in_quoted_blocks_are_escaped(raw, shown):
    with pytest.raises(GCodeError) as info:
        interpret(f"G0 X0\n{raw}\n", "a.nc")
    message = str(info.value)
    assert message.startswith(f"a.nc:2: '{shown}':")
    assert message.isprintable()
    assert info.value.block == raw.strip()  # the attribute keeps the text as it is


def test_work_offset_system_variable_reports_the_code_as_written():
    # #4014 of G54, G54.1 P3, G154 P3, G112, G54 P2 (= G54.1 P2) and G55, written to X/Y/Z as numbers
    text = ("G0 X0\n#100=#4014\nG54.1 P3\n#101=#4014\nG154 P3\n#102=#4014\nG112\n#103=#4014\n"
            "G54 P2\n#104=#4014\nG55\n#105=#4014\nG1 X#100 Y#101 Z#102 F100\nX#103 Y#104 Z#105\n")
    ends = [_mm(b.end) for b in interpret(text).blocks if isinstance(b, Linear)]
    assert ends == [(54.0, 54.1, 154.0), (112.0, 54.1, 55.0)]


@pytest.mark.parametrize("data, line, offset", [
    (b"%\nO1000 (\xd86 ENDMILL)\nG0 X1.\nM30\n%\n", 2, 9),  # Windows-1252 diameter sign in a tool comment
    (b"G0 X1. ; \xc8\xb2\xbb\xe8\r\nM30\r\n", 1, 11),  # a CP949 (Hangul) comment after ';', CRLF lines
])
def test_program_in_a_windows_code_page_names_the_comment_and_the_encoding(tmp_path, data, line, offset):
    path = tmp_path / "part.nc"
    path.write_bytes(data)
    with pytest.raises(GCodeError) as info:
        read_program(path)
    assert info.value.line == line and f"byte offset {offset}, inside a comment" in str(info.value)
    assert "saved as UTF-8 or ASCII" in str(info.value) and "binary" not in str(info.value)


# ----------------------------------------------------------------------------- short CAM segments (planner)
TS = 1e-3


def _motion_end(kernel: NCKernel) -> int:
    """Sample index from which the reference no longer changes."""
    pos = kernel.plan_.position[0]
    moving = np.nonzero(np.any(np.diff(pos, axis=0) != 0.0, axis=1))[0]
    return int(moving[-1]) + 1


def _segments(step_mm: float, length_mm: float, feed: float) -> str:
    n = int(round(length_mm / step_mm))
    return f"G90 G0 X0 Y0\nG1 F{feed:g}\n" + "".join(f"X{step_mm * k:.3f}\n" for k in range(1, n + 1)) + "M30\n"


@pytest.mark.parametrize("step_mm", [0.1, 0.2])
def test_short_collinear_segments_run_like_one_line(step_mm):
    # 50 mm at F3000 (v = 0.05 m/s) cut into 0.1 or 0.2 mm blocks, as a CAM post linearises a surface path.
    # Bell-shaped acc/dec before interpolation, a = 2 m/s2, tc = 32 ms: v < a tc, so each speed change takes
    # 2 sqrt(v tc / a) = 56.6 ms and T = L/v + 2 sqrt(v tc / a) = 1.0566 s, plus the 16 ms linear filter after
    # interpolation: the time of the single 50 mm block. The 40-block window (3.9 mm) is longer than the
    # 1.43 mm stop from 0.05 m/s, so it does not bind. (Planned block by block, every speed change had to
    # fit in one block: 2.04 s with 0.1 mm blocks.)
    kernel = NCKernel(program_text=_segments(step_mm, 50.0, 3000))
    kernel.setup(0.0)
    v = 0.05
    expected = math.ceil((0.05 / v + 2 * math.sqrt(v * 0.032 / 2.0)) / TS - 1e-9) + 16
    assert abs(_motion_end(kernel) - expected) <= 1
    assert kernel.plan_.position[0, -1, 0] == pytest.approx(0.05, abs=1e-12)


def test_short_segments_keep_their_lines_at_cruise():
    # 0.1 mm blocks at 0.05 m/s take 2 ms = 2 samples each: at cruise every line runs for 2 samples
    kernel = NCKernel(program_text=_segments(0.1, 50.0, 3000))
    kernel.setup(0.0)
    line = kernel.plan_.line[0]
    counts = [int((line == n).sum()) for n in range(200, 300)]  # blocks 18-28 mm into the path: cruise
    assert set(counts) <= {1, 2, 3} and sum(counts) == 200


def test_a_corner_between_short_segments_still_slows_the_path():
    # 25 mm of 0.1 mm blocks along X, then 25 mm along Y at F3000: the 90 deg corner changes both axis
    # velocities by the full speed, so it is passed at the allowable velocity difference 400 mm/min
    text = ("G90 G0 X0 Y0\nG1 F3000\n" + "".join(f"X{0.1 * k:.1f}\n" for k in range(1, 251))
            + "".join(f"Y{0.1 * k:.1f}\n" for k in range(1, 251)) + "M30\n")
    kernel = NCKernel(program_text=text, cutting_time_constant=0.0)
    kernel.setup(0.0)
    pos, feed = kernel.plan_.position[0], kernel.plan_.feed[0]
    at_corner = int(np.argmin(np.hypot(pos[:, 0] - 0.025, pos[:, 1])))
    assert feed[at_corner] == pytest.approx(400 / 60e3, rel=0.05)
    assert feed.max() == pytest.approx(0.05, rel=1e-9)


@pytest.mark.parametrize("tail", ["\x1a", "\x1a\r\n", "\r\n\x1a\x1a\r\n  \r\n"])
def test_dos_end_of_file_mark_ends_the_program(tail):
    # old DOS editors and DNC programs append Ctrl-Z; the program ends at the end of file as without it
    text = "G21 G90\r\nG0 X10. Y5.\r\n" + tail
    program = interpret(text, "dos.nc")
    assert [_mm(b.end) for b in _moves(program)] == [(10.0, 5.0, 0.0)]
    assert program.blocks[-1].reason == "end of file"


def test_ctrl_z_inside_the_program_is_still_an_unexpected_character():
    with pytest.raises(GCodeError, match=r"unexpected character '\\x1a'") as info:
        interpret("G0 X1.\n\x1aG0 X2.\n", "dos.nc")
    assert info.value.line == 2


def test_inch_arc_with_four_decimal_rounding_is_accepted():
    # an inch post rounds end point and centre to 0.0001 in: from (0, 0) with I.3334 the start radius is
    # .3334 in and the end (.3334, .3333) lies .3333 in from the centre (.3334, 0): 0.0001 in = 0.00254 mm apart,
    # more than 0.002 mm but within FANUC's No. 3410 tolerance, which is in the input unit (0.002 in here)
    program = interpret("G20 G90 G17\nG0 X0 Y0\nG3 X.3334 Y.3333 I.3334 J0 F10.\nM30\n", "inch.nc")
    arc = _moves(program, 3)[0]
    assert arc.center[:2] == pytest.approx((0.3334 * INCH, 0.0))
    assert arc.end[:2] == pytest.approx((0.3334 * INCH, 0.3333 * INCH))
    with pytest.raises(GCodeError, match=r"radii equal within 0\.002 in") as info:  # 0.003 in apart
        interpret("G20 G90 G17\nG0 X0 Y0\nG3 X.3334 Y.3304 I.3334 J0 F10.\nM30\n", "inch.nc")
    assert info.value.line == 3
    with pytest.raises(GCodeError, match=r"radii equal within 0\.002 mm"):  # 0.0025 mm apart under G21
        interpret("G21 G90 G17\nG0 X0 Y0\nG3 X10. Y9.9975 I10. J0 F100.\nM30\n", "mm.nc")


@pytest.mark.parametrize("text", [
    "G0 X0 Y0 Z10.\nG91 G81 X10. Z-5. R-3. L3 F100.\n",  # Haas (and the older FANUC form): L is the repeat count
    "G0 X0 Y0 Z10.\nG81 X1. Z-1. R1. F100.\nX2. L3\n",  # in a modal cycle block
    "G0 X0 Y0 Z10.\nG81 X1. Z-1. R1. F100. L0\nX2.\n",  # L0: the cycle is stored, no hole at X1
])
def test_canned_cycle_repeat_count_written_as_l_reads_as_k(text):
    """A Haas reads L in a canned-cycle block as the repeat count (Haas mill manual, G81: L = number of repeats):
    the blocks are those of the same program with K."""
    assert interpret(text, "a.nc").blocks == interpret(text.replace(" L", " K"), "a.nc").blocks


def test_canned_cycle_with_both_k_and_l_and_l_elsewhere_are_errors():
    with pytest.raises(GCodeError, match=r"words K and L in one canned-cycle block") as info:
        interpret("G0 X0 Y0 Z10.\nG81 X1. Z-1. R1. F100. K2 L3\n", "a.nc")
    assert info.value.line == 2 and info.value.word == "L3"
    with pytest.raises(GCodeError, match=r"word L outside an M98 block"):  # elsewhere the message is unchanged
        interpret("G0 X0 Y0 Z10.\nG81 X1. Z-1. R1. F100.\nG80 L3\n", "a.nc")
