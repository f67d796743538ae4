"""Haas words the Autodesk Fusion / HSMWorks Haas posts write: G187, G103, G154 Pn and G110-G129.

What the posts write (Autodesk ``haas next generation.cps``, 2023): ``G187 P<level>`` (smoothing, property
"Use G187") before the first move of an operation and ``G187`` to cancel, ``G154 P<n>`` for work offsets past
G59 (``wcsDefinitions``: "G154 P", 1..99), ``G103 P1 (LOOKAHEAD OFF)`` / ``G103 P0 (LOOKAHEAD ON)`` around
surface-inspection moves, ``G90 G53 G0 Z0.`` retracts. Every expected number is derived by hand in the test.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.nck import NCKernel
from fmus_src.nck.blocks import Linear, Rapid
from fmus_src.nck.errors import GCodeError
from fmus_src.nck.interpreter import InterpreterSettings, additional_offset_key, interpret
from fmus_src.nck.lookahead import block_windows, plan_chain_speeds
from fmus_src.nck.planner import build_schedule
from fmus_src.nck.profiles import SpeedChange
from fmus_src.nck.settings import g154_offset_key

MM = 1e-3
TS = 1e-3


def _ends(text: str, settings: InterpreterSettings | None = None) -> list[tuple[float, float, float]]:
    """End points (m, machine) of the moves of a program."""
    return [b.end for b in interpret(text, "haas.nc", settings).blocks if isinstance(b, (Rapid, Linear))]


def _error(text: str) -> GCodeError:
    with pytest.raises(GCodeError) as info:
        interpret(text, "haas.nc", InterpreterSettings(tool_lengths=[0.1]))
    return info.value


def _plan(text: str, **params) -> NCKernel:
    k = NCKernel(program_text=text, **params)
    k.setup(0.0)
    return k


def _junctions(text: str, accel: float = 2.0, change_time: float = 0.0, window: int = 40) -> np.ndarray:
    """Junction speeds (m/s) of the single feed chain of a program, planned with each block's own window."""
    program = interpret(text, "haas.nc")
    chains = [it for it in build_schedule(program.blocks, program.initial).items if it.kind == "chain"]
    assert len(chains) == 1
    blocks = [program.blocks[i] for i in chains[0].blocks]
    windows = block_windows([b.lookahead_limit for b in blocks], window)
    sp = plan_chain_speeds(chains[0].geometry, np.array([b.feed for b in blocks]), SpeedChange(accel, change_time),
                           max_cutting_feed=1.0, arc_accel=1.0, corner_velocity_difference=1.0,
                           lookahead_blocks=windows)
    return sp.junction


# ---------------------------------------------------------------------------- G187 accuracy control
@pytest.mark.parametrize("word", ["G187", "G187 P1", "G187 P2", "G187 P3", "G187 E0.01", "G187 P3 E0.01",
                                  "N45 G187 P1 E.05", "G187 E0"])
def test_g187_is_accepted_and_changes_nothing_in_the_plan(word):
    # G187 only overrides Haas settings 191/85 (smoothness, corner rounding): the twin keeps the programmed
    # path with its own look-ahead, so the plan is the one without the G187 line, sample for sample
    body = "G0 X0 Y0\nG1 X10. F3000.\nY10.\nG2 X20. Y0. R10.\nG0 Z5.\nM30\n"
    with_g187 = _plan(f"{word}\n" + body.replace("Y10.\n", f"Y10.\n{word}\n"))
    without = _plan(body)
    np.testing.assert_array_equal(with_g187.plan_.position, without.plan_.position)
    assert [type(b) for b in interpret(word + "\nM30\n").blocks] == [type(interpret("M30\n").blocks[0])]


@pytest.mark.parametrize("text,word,fragment", [
    ("G187 P0\n", "P0", "not a smoothness level"),
    ("G187 P4\n", "P4", "not a smoothness level"),
    ("G187 P2.\n", "P2.", "not a smoothness level"),
    ("G187 P1.5\n", "P1.5", "not a smoothness level"),
    ("G187 E-0.01\n", "E-0.01", "negative"),
    ("G187 P1 X10.\n", "X10.", "X10. in the G187 block"),
    ("G1 G187 P1 X10. F100.\n", "G1", "G1 in the G187 block"),
    ("G187 Q1\n", "Q1", "Q1 in the G187 block"),
    ("G5.1 Q1 G187\n", "G187", "G187 in the G5.1 block"),
    ("G187 P1 P2\n", "P2", "appears twice"),
    ("G1 X1. E5. F100.\n", "E5.", "address E is not supported"),  # E only in a G187 block
])
def test_g187_errors_name_the_line_and_word(text, word, fragment):
    err = _error("G0 X0\n" + text)
    assert (err.file, err.line, err.word) == ("haas.nc", 2, word)
    assert fragment in str(err) and str(err).startswith("haas.nc:2: ")


# ---------------------------------------------------------------------------- G103 limit block buffering
def test_g103_p1_junction_is_the_stop_within_the_next_block_and_p0_restores_the_plan():
    # 20 collinear 1 mm blocks at F6000 (0.1 m/s), trapezoidal acc/dec a = 2 m/s2 (reach sqrt(v^2 + 2 a L)).
    a, L, n = 2.0, 1e-3, 20
    body = "G91 G1 F6000.\n" + "X1.\n" * n + "M30\n"
    # full window (40 > 20 blocks): junction k (after k blocks) = min(F, sqrt(2 a k L), sqrt(2 a (n - k) L))
    full = [min(0.1, math.sqrt(2 * a * k * L), math.sqrt(2 * a * (n - k) * L)) for k in range(n + 1)]
    np.testing.assert_allclose(_junctions(body), full, rtol=1e-12, atol=1e-15)
    assert max(full) == 0.1  # the middle of the chain never slows
    # G103 P1: window 2, the tool must stop at the end of the next block: every inner junction sqrt(2 a L)
    p1 = _junctions("G103 P1\n" + body)
    np.testing.assert_allclose(p1[1:-1], math.sqrt(2 * a * L), rtol=1e-12)
    assert p1[0] == p1[-1] == 0.0
    # G103 P2: window 3, stop within two blocks: sqrt(2 a 2L) = 0.0894 m/s < F
    np.testing.assert_allclose(_junctions("G103 P2\n" + body)[2:-2], math.sqrt(4 * a * L), rtol=1e-12)
    # G103 / G103 P0 / a limit beyond the machine window (P15 + 1 > 5) give the unlimited plan, bit for bit
    np.testing.assert_array_equal(_junctions("G103 P1\nG103\n" + body), _junctions(body))
    np.testing.assert_array_equal(_junctions("G103 P1\nG103 P0\n" + body), _junctions(body))
    np.testing.assert_array_equal(_junctions("G103 P15\n" + body, window=5), _junctions(body, window=5))


def test_g103_p1_with_bell_shaped_acc_dec_uses_the_jerk_limited_stop_distance():
    # a = 2 m/s2, tc = 32 ms (jerk a/tc): stopping from v < a tc takes 2 sqrt(v tc / a) and covers
    # v sqrt(v tc / a) = L, so the junction speed is v = (a L^2 / tc)^(1/3) = 0.039685 m/s (< a tc = 0.064)
    a, tc, L = 2.0, 0.032, 1e-3
    v = (a * L * L / tc) ** (1.0 / 3.0)
    assert v < a * tc
    j = _junctions("G103 P1\nG91 G1 F6000.\n" + "X1.\n" * 10 + "M30\n", accel=a, change_time=tc)
    np.testing.assert_allclose(j[1:-1], v, rtol=1e-9)


def test_g103_applies_to_the_blocks_read_after_it():
    # 10 blocks unlimited, then G103 P1 and 10 more (one chain: G103 is no block). Block 11 (the first read
    # after G103 P1) must be enterable at a speed from which the tool stops at the end of block 12:
    # sqrt(2 a 2L); the junctions after it are sqrt(2 a L); the ones before it stay at F where reachable
    # (from 0.1 m/s down to sqrt(4 a L) = 0.0894 m/s needs (0.01 - 0.008) / 4 = 0.5 mm < L).
    a, L = 2.0, 1e-3
    j = _junctions("G91 G1 F6000.\n" + "X1.\n" * 10 + "G103 P1 (LOOKAHEAD OFF)\n" + "X1.\n" * 10 + "M30\n")
    assert j[9] == pytest.approx(0.1, rel=1e-12)
    assert j[10] == pytest.approx(math.sqrt(4 * a * L), rel=1e-12)
    np.testing.assert_allclose(j[11:-1], math.sqrt(2 * a * L), rtol=1e-12)
    blocks = interpret("G1 X1. F100.\nG103 P3\nX2.\nG103\nX3.\nM30\n").blocks
    assert [b.lookahead_limit for b in blocks if isinstance(b, Linear)] == [0, 3, 0]


def test_g103_p1_slows_the_planned_path_to_sqrt_2_a_l():
    # G103 P1: the tool must be able to stop at the end of the next block, so it runs across the blocks at the
    # window-limited speed sqrt(2 a l) (one acc/dec span, .spans); only the last two blocks, whose window
    # reaches the chain end, may rise above it, to at most sqrt(3 a l) (from sqrt(2 a l) to rest in 2 l).
    # The machine window alone: F.
    a, l = 2.0, 1e-3
    body = "G91 G1 F6000.\n" + "X1.\n" * 20 + "M30\n"
    fast = _plan(body, accel_change_time_before_interp=0.0, cutting_time_constant=0.0)
    slow = _plan("G103 P1\n" + body, accel_change_time_before_interp=0.0, cutting_time_constant=0.0)
    assert fast.plan_.feed[0].max() == pytest.approx(0.1, rel=1e-9)
    feed = slow.plan_.feed[0]
    v = math.sqrt(2 * a * l)
    np.testing.assert_allclose(feed[len(feed) // 4: len(feed) // 2], v, rtol=1e-9)
    assert feed.max() <= math.sqrt(3 * a * l) * (1 + 1e-9)
    same = _plan("G103 P1\nG103 P0\n" + body, accel_change_time_before_interp=0.0, cutting_time_constant=0.0)
    np.testing.assert_array_equal(same.plan_.position, fast.plan_.position)


@pytest.mark.parametrize("text,word,fragment", [
    ("G103 P16\n", "P16", "not a number of blocks 0..15"),
    ("G103 P-1\n", "P-1", "not a number of blocks"),
    ("G103 P1.\n", "P1.", "not a number of blocks"),
    ("G103 P1.5\n", "P1.5", "not a number of blocks"),
    ("G103 P1 X5.\n", "X5.", "X5. in the G103 block"),
    ("G103 Q1\n", "Q1", "Q1 in the G103 block"),
    ("G103 P1 G187\n", "G103", "G103 in the G187 block"),
])
def test_g103_errors_name_the_line_and_word(text, word, fragment):
    err = _error("G0 X0\n" + text)
    assert (err.file, err.line, err.word) == ("haas.nc", 2, word)
    assert fragment in str(err)


# ---------------------------------------------------------------------------- G154 Pn / G110-G129
def test_g10_l20_then_g154_moves_to_the_offsets_machine_position():
    # G10 L20 P7 X100. Y-50. Z-20.: G154 P7 G0 X0 Y0 goes to machine (100, -50) mm; Z not programmed
    ends = _ends("G10 L20 P7 X100. Y-50. Z-20.\nG154 P7 G0 X0 Y0\nZ5.\nM30\n")
    assert ends[0] == pytest.approx((0.100, -0.050, 0.0), abs=1e-15)
    assert ends[1] == pytest.approx((0.100, -0.050, -0.015), abs=1e-15)
    # P60 exists only on the Haas form (G54.1 stops at 48); G10 L20 sets it
    assert _ends("G10 L20 P60 X1.\nG154 P60 G0 X2.\nM30\n")[0][0] == pytest.approx(0.003, abs=1e-15)


def test_g110_is_g154_p1_and_g154_pn_is_g54_1_pn():
    s = InterpreterSettings(work_offsets={additional_offset_key(1): (0.01, 0.02, 0.0),
                                          g154_offset_key(20): (0.3, 0.0, 0.0),
                                          g154_offset_key(99): (0.0, 0.4, 0.0)})
    ends = _ends("G110 G0 X1. Y1.\nG154 P1 X2.\nG54.1 P1 X3.\nG129 X0\nG154 P20 X1.\nG154 P99 X0 Y0\nM30\n", s)
    expected = [(0.011, 0.021), (0.012, 0.021), (0.013, 0.021), (0.3, 0.021), (0.301, 0.021), (0.0, 0.4)]
    np.testing.assert_allclose([e[:2] for e in ends], expected, rtol=0, atol=1e-15)
    assert [g154_offset_key(n) for n in (1, 48, 99)] == [1001, 1048, 1099]
    with pytest.raises(ValueError):
        g154_offset_key(100)


def test_g154_change_shifts_the_programmed_position_like_g54_1():
    # at machine X 10 in G54 (offset 0), G154 P2 with offset X 4 mm: the current point is work X 6; G91 X1.
    # moves 1 mm (machine 11), G90 X0 goes to machine 4
    ends = _ends("G0 X10.\nG10 L20 P2 X4.\nG154 P2\nG91 G0 X1.\nG90 X0\nM30\n")
    assert [e[0] for e in ends] == pytest.approx([0.010, 0.011, 0.004], abs=1e-15)


@pytest.mark.parametrize("text,line,word,fragment", [
    ("G0 X0\nG154 X1.\n", 2, "G154", "G154 without P"),
    ("G154 P100\n", 1, "P100", "P100 does not exist"),
    ("G154 P0\n", 1, "P0", "does not exist"),
    ("G154 P7.\n", 1, "P7.", "does not exist"),
    ("G154 P1.5\n", 1, "P1.5", "does not exist"),
    ("G0 X0\nG54.1 P49\n", 2, "P49", "P49 does not exist"),  # FANUC's form keeps its 48
    ("G154 P2 G4 X1.\n", 1, "G154", "G154 and G4 in one block"),
    ("G154 P2 G10 L20 P3 X0\n", 1, "P3", "twice"),
    ("G154 M97 P10\nM30\nN10 M99\n", 1, "G154", "G154 and M97 in one block"),
    ("G0 X0 Z5\nG81 X0 Z-1 R1 F100\nG154 P2 X5\n", 3, "G154", "canned-cycle mode G81"),
    ("G110 P5\n", 1, "P5", "word P outside"),
    ("G110 G154 P1\n", 1, "G154", "modal group 'work offset'"),
])
def test_g154_errors_name_file_line_and_word(text, line, word, fragment):
    err = _error(text)
    assert (err.file, err.line, err.word) == ("haas.nc", line, word)
    assert fragment in str(err) and str(err).startswith(f"haas.nc:{line}: ")


# ---------------------------------------------------------------------------- Haas-post programs end to end
#: Autodesk "haas next generation.cps" with "Use G187" = Finish/Rough and a second WCS (G154 P1): header,
#: tool change, G187, G54 / G154, high-feed G1 positioning, G43 H, cuts, G187 cancel, G53 G0 Z0., M30.
FUSION_NGC = """%
O01001 (HAAS NGC POST - CONTOUR AND FACE)
(Using high feed G1 F5000. instead of G0.)
(T1 D=6. CR=0. - ZMIN=-2. - flat end mill)
N10 G90 G94 G17
N15 G21

(2D Contour1)
N20 T1 M6
N25 S2000 M3
N30 G17 G90 G94
N35 G54
N40 M8
N45 G187 P3
N50 G90 G1 X-4. Y0. F5000.
N55 G0 G43 Z15. H1
N60 G0 Z3.
N65 G1 Z-2. F1200.
N70 G41 X0. Y0. D1
N75 Y20.
N80 G2 X5. Y25. I5. J0.
N85 G1 X20.
N90 Y0.
N95 X0.
N100 G40 X-4.
N105 G0 Z15.
N110 G187
N115 G90 G53 G0 Z0.

(Face1)
N120 G154 P1
N125 G187 P1 E0.05
N130 G90 G1 X-4. Y0. F5000.
N135 G0 G43 Z15. H1
N140 G0 Z3.
N145 G1 Z-0.5 F1200.
N150 X24. F3000.
N155 G0 Z15.
N160 G187
N165 M9
N170 M5
N175 G90 G53 G0 Z0.
N180 G90 G53 G0 X0. Y0.
N185 M30
%
"""
#: A Haas-style hand program: G10 L20 + G110, G187 E, G103 P1 around an M97 local subprogram, G28 G91 Z0.
HAAS_HAND = """%
O02002 (HAAS HAND PROGRAM - G110 G103 M97)
G00 G17 G40 G49 G80 G90
G21
T1 M06
G10 L20 P1 X-370. Y-220. Z-300.
G110
S2500 M03
G187 E0.01
G00 X0. Y0.
G43 H01 Z10.
M08
G01 Z-1. F600.
G103 P1 (LOOKAHEAD LIMITED)
M97 P100 L2
G103
G187
G00 Z10.
M09
M05
G28 G91 Z0.
G90
M30
N100 G91 G01 X2. F1500.
Y2.
X-2.
Y-2.
G90
M99
%
"""
#: HSMWorks/Fusion classic "haas.cps" drilling: "G187" (reset for drilling), G154 P7 set by G10 L20, G83.
HAAS_DRILL = """%
O03003 (HAAS CLASSIC POST - DRILL G154 P7)
(T3 D=5. CR=0. TAPER=118deg - drill)
N10 G90 G17
N15 G21
N20 G53 G00 Z0.
N25 G10 L20 P7 X-360. Y-215. Z-300.
(Drill1)
N30 T3 M06
N35 S2000 M03
N40 G154 P7
N45 G187
N50 G00 X5. Y5.
N55 G43 Z15. H03 M08
N60 G00 Z5.
N65 G98 G83 X5. Y5. Z-6. R2. Q2. F300.
N70 X15.
N75 G80
N80 G00 Z15.
N85 M09
N90 M05
N95 G53 G00 Z0.
N100 G53 G00 X0. Y0.
N105 M30
%
"""


def _line(text: str, prefix: str) -> int:
    """1-based file line of the block starting with ``prefix``."""
    return next(i for i, row in enumerate(text.splitlines(), 1) if row.startswith(prefix))


@pytest.fixture(scope="module")
def haas_runs(tmp_path_factory):
    from orchestrator.simulate import simulate

    folder = tmp_path_factory.mktemp("haas")
    runs = {}
    for name, text in (("fusion_ngc", FUSION_NGC), ("hand", HAAS_HAND), ("drill", HAAS_DRILL)):
        path = folder / f"{name}.nc"
        path.write_text(text)
        runs[name] = simulate(path, plot=False)  # air cut on the default machine
    return runs


def test_fusion_ngc_post_program_runs_end_to_end(haas_runs):
    result = haas_runs["fusion_ngc"]
    assert result.success, result.message
    rec = result.recording
    # G154 P1 (unset: zero) and G54 (zero on the default machine): the face pass N150 ends at machine X 24 mm,
    # where the filtered reference arrives during the Z retract N155
    face = np.isin(rec["line"], [_line(FUSION_NGC, "N150 "), _line(FUSION_NGC, "N155 ")])
    assert rec["x_ref_mm"][face].max() == pytest.approx(24.0, abs=1e-9)
    assert _line(FUSION_NGC, "N180 ") in set(rec["line"].tolist())  # ran to the G53 home move


def test_haas_hand_program_with_g110_and_g103_runs_end_to_end(haas_runs):
    result = haas_runs["hand"]
    assert result.success, result.message
    rec = result.recording
    # the M97 square (2 mm, G91) starts at work X0 Y0 of G110 = G154 P1, set by G10 L20 to machine (-370, -220) mm:
    # axis frame (recording) (10, 5) mm with the default machine's machine zero at (380, 225, 300) mm
    first = _line(HAAS_HAND, "N100 ")
    square = (rec["line"] >= first) & (rec["line"] <= first + 3)
    assert [rec["x_ref_mm"][square].min(), rec["x_ref_mm"][square].max()] == pytest.approx([10.0, 12.0], abs=1e-9)
    assert [rec["y_ref_mm"][square].min(), rec["y_ref_mm"][square].max()] == pytest.approx([5.0, 7.0], abs=1e-9)


def test_haas_drill_program_with_g154_p7_runs_end_to_end(haas_runs):
    result = haas_runs["drill"]
    assert result.success, result.message
    rec = result.recording
    # holes at work (5, 5) and (15, 5) of G154 P7 = machine (-360, -215, -300) mm = axis frame (20, 10, 0) mm:
    # axis (25, 15) and (35, 15), bottom Z-6
    for prefix, x in (("N65 ", 25.0), ("N70 ", 35.0)):
        hole = rec["line"] == _line(HAAS_DRILL, prefix)
        k = int(np.argmin(np.where(hole, rec["z_ref_mm"], np.inf)))
        assert (rec["x_ref_mm"][k], rec["y_ref_mm"][k]) == pytest.approx((x, 15.0), abs=1e-9)
        assert rec["z_ref_mm"][k] == pytest.approx(-6.0, abs=0.02)  # sampled near the bottom of the feed
