"""More programs in the styles of CAM posts and shop floors, with features the other program tests do not cover.

Fusion 360 helical ramps (full-circle helices) and a drill cycle with T pre-staging, Mastercam rigid tapping and
``G91 G28 Z0.`` / ``G28 X0. Y0.`` in G91, SolidCAM subprograms that step Z with G91 and repeat with L, a
hand-written macro program (bolt circle with IF/GOTO, G10 L2, G52 + M98, ``#3006`` stop with message), an inch
program with ``,C``/``,R`` and a subprogram under mirror image and rotation. Expected numbers are derived by hand
in the comments; every program also plans on the default machine with its stroke limits on.
"""
from __future__ import annotations

import math

import pytest

from fmus_src.nck import Arc, InterpreterSettings, Linear, NCKernel, ProgramStop, Rapid, ToolChange, interpret
from orchestrator.machine import load_machine
from orchestrator.twin import nck_parameters

MM = 1e-3
INCH = 25.4e-3
REGISTERS = InterpreterSettings(tool_lengths=[0.0] * 20, tool_radii=[0.0] * 20)


def line_of(text: str, start: str) -> int:
    """1-based number of the only line of ``text`` starting with ``start``."""
    found = [i + 1 for i, line in enumerate(text.splitlines()) if line.startswith(start)]
    assert len(found) == 1, found
    return found[0]

FUSION_HELIX = """%
O01001 (ADAPTIVE + DRILL)
(T1  D=10. CR=0. - ZMIN=-1. - FLAT END MILL)
(T2  D=6.8 CR=0. TAPER=118DEG - ZMIN=-15. - DRILL)
N10 G90 G94 G17 G49 G40 G80
N15 G21
N20 G28 G91 Z0.
N25 G90
N30 T1 M06
N35 T2
N40 S8000 M03
N45 G54
N50 M08
N55 G00 X-12.5 Y-3.
N60 G43 Z15. H01
N65 G00 Z5.
N70 G01 Z1.5 F1000.
N75 G03 X-12.5 Y-3. Z0.5 I0.5 J0. F600.
N80 X-12.5 Y-3. Z-0.5 I0.5 J0.
N85 X-12.5 Y-3. Z-1. I0.5 J0.
N90 G01 X25. F1200.
N95 G00 Z15.
N100 M09
N105 G28 G91 Z0.
N110 G90
N115 G49
N120 M01
N125 T02 M06
N130 T01
N135 S2500 M03
N140 G54
N145 G00 X5. Y5.
N150 G43 Z15. H02
N155 G00 Z5.
N160 G98 G83 X5. Y5. Z-15. R5. Q6. F250.
N165 X20.
N170 G80
N175 G28 G91 Z0.
N180 G90
N185 G28 G91 X0. Y0.
N190 G90
N195 M05
N200 M30
%
"""


def test_fusion_full_circle_helices_ramp_down_by_their_z_words():
    program = interpret(FUSION_HELIX, "fusion.nc", REGISTERS)
    helices = [b for b in program.blocks if isinstance(b, Arc)]
    # three full circles about (-12, -3), r 0.5 mm, from Z 1.5 to 0.5, -0.5 and -1
    assert [b.line for b in helices] == [line_of(FUSION_HELIX, n) for n in ("N75", "N80", "N85")]
    for b, (z0, z1) in zip(helices, [(1.5, 0.5), (0.5, -0.5), (-0.5, -1.0)]):
        assert b.center[:2] == pytest.approx((-12 * MM, -3 * MM))
        assert abs(b.sweep) == pytest.approx(2 * math.pi)
        assert (b.start[2], b.end[2]) == pytest.approx((z0 * MM, z1 * MM))
        assert b.length == pytest.approx(math.hypot(2 * math.pi * 0.5, z1 - z0) * MM)
    # T2 after T1 M06 only pre-stages: the tool changes are T1 then T2 (the T01 after it is staged again)
    assert [b.tool for b in program.blocks if isinstance(b, ToolChange)] == [1, 2]
    # G83 Q6 to Z-15 from R5: pecks end at -1, -7, -13, -15 (Q steps from R), twice (X5 and X20)
    cycle = line_of(FUSION_HELIX, "N160")
    bottoms = [round(b.end[2] / MM, 6) for b in program.blocks if isinstance(b, Linear) and b.line == cycle]
    assert bottoms == [-1.0, -7.0, -13.0, -15.0]


MASTERCAM_TAP = """%
O0100(MCAM PART)
( T3 |  M8 X 1.25 TAP | H3 )
N100 G21
N102 G0 G17 G40 G49 G80 G90
N104 T1 M6
N106 G0 G90 G54 X-8. Y-8. S6000 M3
N108 G43 H1 Z25.
N110 Z5.
N112 G1 Z-2. F300.
N114 X38. F900.
N116 G0 Z25.
N118 M5
N120 G91 G28 Z0.
N122 G28 X0. Y0.
N124 M01
N126 T3 M6
N128 G0 G90 G54 X5. Y5. S500 M3
N130 G43 H3 Z25.
N132 M29 S500
N134 G99 G84 Z-12. R5. F625.
N136 X25.
N138 G80
N140 M5
N142 G91 G28 Z0.
N144 G28 X0. Y0.
N146 M30
%
"""


def test_mastercam_g28_in_g91_and_rigid_tapping():
    program = interpret(MASTERCAM_TAP, "mcam.nc", REGISTERS)
    # G28 X0. Y0. in G91 (modal from the line before): the intermediate point is the current position, so X and Y
    # go straight to the reference (380, 225); Z stays at the reference 300 of the G91 G28 Z0. before
    g28 = [b for b in program.blocks if isinstance(b, Rapid) and b.line == line_of(MASTERCAM_TAP, "N122")]
    assert len(g28) == 1 and g28[0].start[:2] == pytest.approx((38 * MM, -8 * MM))
    assert g28[0].end == pytest.approx((380 * MM, 225 * MM, 300 * MM))
    # rigid tapping at S500, F625: pitch 625 / 500 = 1.25 mm, in (+1) and out (-1) at X5 and X25
    taps = [b for b in program.blocks if isinstance(b, Linear) and b.rigid_tap]
    assert [(round(b.end[0] / MM, 6), b.rigid_tap) for b in taps] == [(5.0, 1), (5.0, -1), (25.0, 1), (25.0, -1)]
    assert [b.tap_pitch for b in taps] == pytest.approx([1.25 * MM] * 4)
    assert [round(b.end[2] / MM, 6) for b in taps] == [-12.0, 5.0, -12.0, 5.0]  # G99: back to R between holes


SOLIDCAM_SUBS = """%
O5000 (SOLIDCAM POCKET)
(SUBROUTINES: O1 .. O2)
N1 G90 G17 G40 G80 G49 G21
N2 G91 G28 Z0
N3 G90
N4 T1 M6
N5 G90 G54 G0 X10. Y5. S7000 M3
N6 G43 H1 Z50.
N7 Z2.
N8 G1 Z0. F300
N9 M98 P1 L3
N10 G90 G0 Z50.
N11 M5
N12 G91 G28 Z0
N13 G90
N14 M30
O1 (POCKET STEP)
N100 G91 G1 Z-1. F200
N101 G90 X20. F900
N102 Y15.
N103 X10.
N104 Y5.
N105 M99
%
"""


def test_solidcam_incremental_step_down_repeats_with_l():
    program = interpret(SOLIDCAM_SUBS, "solidcam.nc", REGISTERS)
    step, last = line_of(SOLIDCAM_SUBS, "N100"), line_of(SOLIDCAM_SUBS, "N104")
    steps = [round(b.end[2] / MM, 6) for b in program.blocks if isinstance(b, Linear) and b.line == step]
    assert steps == [-1.0, -2.0, -3.0]  # G91 Z-1. from Z0, three passes
    square = [(round(b.end[0] / MM, 6), round(b.end[1] / MM, 6)) for b in program.blocks
              if isinstance(b, Linear) and step < b.line <= last]
    assert square == [(20.0, 5.0), (20.0, 15.0), (10.0, 15.0), (10.0, 5.0)] * 3


SHOP_MACRO = """%
O2000 (SHOP - BOLT CIRCLE AND POCKETS)
G17 G21 G40 G49 G80 G90
G10 L2 P2 X-330. Y-225. Z-300.
#100=6 (HOLES)
#101=25. (BC RADIUS)
T5 M6
S3000 M3
G55 G0 X0 Y0
G43 H5 Z20. M8
#1=0
WHILE[#1LT#100]DO1
#2=#1*360/#100
X[#101*COS[#2]] Y[#101*SIN[#2]]
IF[#1NE0]GOTO10
G98 G81 Z-8. R2. F120
GOTO20
N10 G81 Z-8. R2. F120
N20 G80
#1=#1+1
END1
G0 Z20.
#3006=1(TURN THE CLAMP)
G52 X-10. Y-10.
M98 P2100
G52 X10. Y-10.
M98 P2100
G52 X0 Y0
G0 Z50.
M30
O2100 (SQUARE POCKET 6 X 6)
G0 X0 Y0
Z2.
G1 Z-2. F100
G91 X3. F300
Y3.
X-6.
Y-6.
X6.
Y3.
G90 G0 Z20.
M99
%
"""


def test_hand_written_macro_program_bolt_circle_local_shifts_and_stop_with_message():
    # the default machine's frame: machine zero at axis (380, 225, 300) mm, so G55 = machine (-330, -225, -300) mm
    # is axis (50, 0, 0) mm
    frame = InterpreterSettings(tool_lengths=[0.0] * 20, tool_radii=[0.0] * 20, machine_zero=(0.38, 0.225, 0.3))
    program = interpret(SHOP_MACRO, "shop.nc", frame)
    holes = [(round(b.end[0] / MM, 3), round(b.end[1] / MM, 3)) for b in program.blocks
             if isinstance(b, Linear) and b.end[2] == pytest.approx(-8 * MM)]
    # G55 = axis X 50 (G10 L2 P2): holes at 50 + 25 cos(60 k), 25 sin(60 k)
    expected = [(round(50 + 25 * math.cos(math.radians(60 * k)), 3), round(25 * math.sin(math.radians(60 * k)), 3))
                for k in range(6)]
    assert holes == expected
    # #3006 = 1 (MESSAGE) stops as M00 on its line
    stops = [b for b in program.blocks if isinstance(b, ProgramStop)]
    assert [(b.line, b.code) for b in stops] == [(line_of(SHOP_MACRO, "#3006"), "M0")]
    # the pocket at the two G52 origins: G55 (50, 0) + (-10, -10) and + (10, -10); first corner X +3
    starts = [(round(b.end[0] / MM, 6), round(b.end[1] / MM, 6)) for b in program.blocks
              if isinstance(b, Linear) and b.line == line_of(SHOP_MACRO, "G91 X3.")]
    assert starts == [(43.0, -10.0), (63.0, -10.0)]


INCH_CORNERS = """%
O00010 (INCH FACE AND CHAMFER)
G20
G0 G17 G40 G49 G80 G90
T1 M6
G0 G90 G54 X-0.6 Y0.5 S5000 M3
G43 H1 Z1.
G1 Z-0.02 F20.
G1 X0.25 Y1. ,C0.05
X2. ,R0.1
Y1.5
G0 Z1.
G4 P500
M5
G28 G91 Z0.
G90
M30
%
"""


def test_inch_chamfer_and_corner_round_between_g1_blocks():
    program = interpret(INCH_CORNERS, "inch.nc", REGISTERS)
    first_line = line_of(INCH_CORNERS, "G1 X0.25")
    cuts = [b for b in program.blocks if isinstance(b, (Linear, Arc)) and first_line <= b.line <= first_line + 2]
    # ,C0.05: the chamfer starts 0.05 in before the corner (0.25, 1) along the line from (-0.6, 0.5)
    d = math.hypot(0.85, 0.5)
    first = (0.25 - 0.05 * 0.85 / d, 1.0 - 0.05 * 0.5 / d)
    assert cuts[0].end[:2] == pytest.approx((first[0] * INCH, first[1] * INCH))
    assert cuts[1].end[:2] == pytest.approx((0.30 * INCH, 1.0 * INCH))  # 0.05 in along X after the corner
    # ,R0.1 at (2, 1) between +X and +Y: tangent points (1.9, 1) and (2, 1.1), centre (1.9, 1.1), counter-clockwise
    assert cuts[2].end[:2] == pytest.approx((1.9 * INCH, 1.0 * INCH))
    arc = cuts[3]
    assert isinstance(arc, Arc) and not arc.clockwise
    assert arc.center[:2] == pytest.approx((1.9 * INCH, 1.1 * INCH))
    assert arc.end[:2] == pytest.approx((2.0 * INCH, 1.1 * INCH))


TRANSFORMED_SUB = """%
O3000 (MIRROR AND ROTATION OF ONE SLOT)
G21 G17 G40 G49 G80 G90
T2 M6
S5000 M3
G54 G0 X0 Y0 Z10.
M98 P3100
G51.1 X0
M98 P3100
G50.1 X0
G68 X0 Y0 R90.
M98 P3100
G69
G0 Z50.
M5
M30
O3100
G0 X10. Y5.
G1 Z-1. F150
X25. F500
G2 X30. Y10. R5.
G0 Z10.
M99
%
"""


def test_subprogram_under_mirror_and_rotation():
    program = interpret(TRANSFORMED_SUB, "xf.nc", REGISTERS)
    arcs = [b for b in program.blocks if isinstance(b, Arc)]
    # as written: G2 R5 from (25, 5) to (30, 10): the quarter clockwise about (30, 5) (about (25, 10) it would be
    # 270 deg, which R > 0 excludes); mirrored about X0: G3 to (-30, 10) about (-30, 5); rotated 90 deg about the
    # origin, (x, y) -> (-y, x): G2 to (-10, 30) about (-5, 30)
    got = [(round(b.end[0] / MM, 6), round(b.end[1] / MM, 6), round(b.center[0] / MM, 6),
            round(b.center[1] / MM, 6), b.clockwise) for b in arcs]
    assert got == [(30.0, 10.0, 30.0, 5.0, True), (-30.0, 10.0, -30.0, 5.0, False),
                   (-10.0, 30.0, -5.0, 30.0, True)]


@pytest.mark.parametrize("text", [FUSION_HELIX, MASTERCAM_TAP, SOLIDCAM_SUBS, SHOP_MACRO, INCH_CORNERS,
                                  TRANSFORMED_SUB])
def test_every_program_plans_on_the_default_machine_inside_its_travel(text):
    # the default machine: stroke limits on, the twin's start height Z 50 mm
    kernel = NCKernel(program_text=text, **{**nck_parameters(load_machine("default")), "z_initial": 0.05})
    kernel.setup(0.0)
    assert kernel.duration_[0] > 0.0


def test_iso_colon_program_numbers_are_o_numbers():
    # FANUC ISO code: ":2000" is the program number O2000, so M98 P2000 finds the subprogram written ":2000"
    text = "%\n:1000 (MAIN)\nG90 G0 X1.\nM98 P2000\nM30\n:2000\nG1 X2. F100\nM99\n%\n"
    with_o = text.replace(":1000", "O1000").replace(":2000", "O2000")
    assert interpret(text, "colon.nc").blocks == interpret(with_o, "o.nc").blocks
    ends = [round(b.end[0] / MM, 6) for b in interpret(text).blocks if isinstance(b, (Rapid, Linear))]
    assert ends == [1.0, 2.0]
