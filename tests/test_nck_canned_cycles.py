"""Canned cycles G73 G81 G82 G83 G85 G86 G89, G98/G99, K repeats, G80; safe-line cancel codes; the errors of
tapping G84/G74 and boring G76/G87/G88 (their moves and times: tests/test_nck_tapping_boring.py).

Every expected move is written out by hand from the FANUC 0i-MF / 31i-B definition of the cycle:
(1) X/Y positioning at the current level, (2) rapid to R, (3) machining, (4) bottom operation,
(5-6) retract to the initial level (G98) or to R (G99). All numbers in mm unless stated.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.nck import (
    Dwell, GCodeError, InterpreterSettings, Linear, NCKernel, Rapid, SpindleSpeed, SpindleStop, interpret,
)
from fmus_src.nck.cycles import CycleMachine
from fmus_src.nck.overrides import resolve_values

MM = 1e-3
MPM = 1e-3 / 60.0


def mm(p):
    return tuple(round(v / MM, 9) for v in p)


def trace(text: str, **kw):
    """[(kind, line, start mm, end mm)] of the moves, dwells as ("D", line, seconds)."""
    out = []
    for b in interpret(text, "c.nc", InterpreterSettings(**kw) if kw else None).blocks:
        if isinstance(b, Rapid):
            out.append(("G0", b.line, mm(b.start), mm(b.end)))
        elif isinstance(b, Linear):
            out.append(("G1", b.line, mm(b.start), mm(b.end)))
        elif isinstance(b, Dwell):
            out.append(("D", b.line, b.seconds))
        elif isinstance(b, (SpindleStop, SpindleSpeed)):
            out.append((type(b).__name__, b.line))
    return out


def ends(tr):
    return [(t[0], t[3]) if t[0] in ("G0", "G1") else t for t in tr]


START = "G90 G0 X0 Y0 Z10\n"  # line 1: initial level Z10


def test_g81_one_hole_g98():
    tr = trace(START + "G81 X5 Y6 Z-3 R1 F100\n")
    assert ends(tr[1:]) == [
        ("G0", (5, 6, 10)),  # (1) positioning at the initial level
        ("G0", (5, 6, 1)),  # (2) rapid to R
        ("G1", (5, 6, -3)),  # (3) feed to Z
        ("G0", (5, 6, 10)),  # (5-6) rapid back to the initial level (G98)
    ]
    assert {t[1] for t in tr[1:]} == {2}


def test_g99_returns_to_r_and_the_next_hole_positions_at_r():
    tr = trace(START + "G99 G81 X5 Y0 Z-3 R1 F100\nX15\nG98 X25\n")
    assert ends(tr[1:]) == [
        ("G0", (5, 0, 10)), ("G0", (5, 0, 1)), ("G1", (5, 0, -3)), ("G0", (5, 0, 1)),  # G99: back to R
        ("G0", (15, 0, 1)), ("G1", (15, 0, -3)), ("G0", (15, 0, 1)),  # already at R: no rapid to R
        ("G0", (25, 0, 1)), ("G1", (25, 0, -3)), ("G0", (25, 0, 10)),  # G98: initial level Z10
    ]
    assert [t[1] for t in tr[1:]] == [2] * 4 + [3] * 3 + [4] * 3


def test_g83_pecks_with_full_retract_and_clearance():
    # Z-10 R2 Q3: peck bottoms R-3 = -1, -4, -7, then Z = -10. d = 0.5 mm (No. 5115)
    tr = trace(START + "G83 X0 Y0 Z-10 R2 Q3 F100\n", cycles=CycleMachine(0.2e-3, 0.5e-3))
    assert ends(tr[1:]) == [
        ("G0", (0, 0, 2)),
        ("G1", (0, 0, -1)), ("G0", (0, 0, 2)), ("G0", (0, 0, -0.5)),
        ("G1", (0, 0, -4)), ("G0", (0, 0, 2)), ("G0", (0, 0, -3.5)),
        ("G1", (0, 0, -7)), ("G0", (0, 0, 2)), ("G0", (0, 0, -6.5)),
        ("G1", (0, 0, -10)), ("G0", (0, 0, 10)),
    ]


def test_g73_high_speed_pecks_retract_d():
    # d = 0.2 mm (No. 5114): feed 2 -> -1, back to -0.8, feed to -4, back to -3.8, ..., feed to -10
    tr = trace(START + "G73 Z-10 R2 Q3 F100\n", cycles=CycleMachine(0.2e-3, 0.5e-3))
    assert ends(tr[1:]) == [
        ("G0", (0, 0, 2)),
        ("G1", (0, 0, -1)), ("G0", (0, 0, -0.8)),
        ("G1", (0, 0, -4)), ("G0", (0, 0, -3.8)),
        ("G1", (0, 0, -7)), ("G0", (0, 0, -6.8)),
        ("G1", (0, 0, -10)), ("G0", (0, 0, 10)),
    ]
    feeds = [t for t in tr if t[0] == "G1"]
    assert feeds[1][2] == (0, 0, -0.8)  # each peck restarts d above the previous bottom


def test_g82_dwell_and_g89_g85_feed_out():
    tr = trace(START + "G82 X1 Z-2 R1 P500 F100\nG85 X2 Z-2 R1\nG89 X3 Z-2 R1 P1.5\n")
    assert ends(tr[1:]) == [
        ("G0", (1, 0, 10)), ("G0", (1, 0, 1)), ("G1", (1, 0, -2)), ("D", 2, 0.5), ("G0", (1, 0, 10)),
        ("G0", (2, 0, 10)), ("G0", (2, 0, 1)), ("G1", (2, 0, -2)), ("G1", (2, 0, 1)), ("G0", (2, 0, 10)),
        ("G0", (3, 0, 10)), ("G0", (3, 0, 1)), ("G1", (3, 0, -2)), ("D", 4, 1.5), ("G1", (3, 0, 1)),
        ("G0", (3, 0, 10)),
    ]


def test_g86_stops_the_spindle_at_the_bottom_and_restarts_it():
    prog = START + "S2000 M4\nG99 G86 X1 Z-2 R1 F100\n"
    blocks = interpret(prog).blocks
    i = next(k for k, b in enumerate(blocks) if isinstance(b, Linear))
    stop, retract, restart = blocks[i + 1: i + 4]
    assert isinstance(stop, SpindleStop) and isinstance(retract, Rapid) and retract.end[2] == pytest.approx(1 * MM)
    assert isinstance(restart, SpindleSpeed) and restart.direction == -1
    assert restart.speed == pytest.approx(2000 * 2 * math.pi / 60) and restart.speed_line == 2


def test_g91_r_from_initial_z_from_r_and_k_repeats():
    # initial 10; G91 R-8 -> R at 2; Z-5 -> bottom at -3; K3 X10 -> holes at X 10, 20, 30
    tr = trace(START + "G91 G81 X10 Z-5 R-8 K3 F100\n")
    feeds = [t for t in tr if t[0] == "G1"]
    assert [f[2:] for f in feeds] == [((x, 0, 2), (x, 0, -3)) for x in (10, 20, 30)]
    assert tr[-1][3] == (30, 0, 10)


def test_g91_r_and_z_stay_modal_as_increments_and_a_new_r_moves_the_bottom():
    # FANUC G91: R from the initial level (10), Z from the R point. Line 2: R 10-3 = 7, bottom 7-5 = 2, K3 holes
    # at X 10, 20, 30 (G98: back to 10). Line 3 gives R-2 only: R 8 and the modal Z-5 counts from it: bottom 3.
    tr = trace(START + "G91 G81 X10. R-3. Z-5. K3 F100\nX10. R-2.\n")
    hole = [("G0", (10, 0, 10)), ("G0", (10, 0, 7)), ("G1", (10, 0, 2)), ("G0", (10, 0, 10))]
    expected = [(k, (x, 0, z)) for x in (10, 20, 30) for k, (_, _, z) in hole]
    expected += [("G0", (40, 0, 10)), ("G0", (40, 0, 8)), ("G1", (40, 0, 3)), ("G0", (40, 0, 10))]
    assert ends(tr[1:]) == expected
    assert [t[1] for t in tr[1:]] == [2] * 12 + [3] * 4


def test_g91_g99_repeats_stay_at_r_and_measure_from_the_initial_level():
    # R 7, bottom 2 for both holes (the levels count from the initial level 10, not from the tool at R);
    # hole 2 starts at R so its rapid to R is left out; G98 on line 3 returns to the initial level 10.
    tr = trace(START + "G91 G99 G81 X10. R-3. Z-5. K2 F100\nG98 X10.\n")
    assert ends(tr[1:]) == [
        ("G0", (10, 0, 10)), ("G0", (10, 0, 7)), ("G1", (10, 0, 2)), ("G0", (10, 0, 7)),
        ("G0", (20, 0, 7)), ("G1", (20, 0, 2)), ("G0", (20, 0, 7)),
        ("G0", (30, 0, 7)), ("G1", (30, 0, 2)), ("G0", (30, 0, 10)),
    ]


def test_g90_g91_switching_while_the_cycle_is_modal_keeps_each_word_in_its_mode():
    # line 2 (G90): R 2, bottom -5. Line 3 (G91 X10.): both kept as levels -> X10, R 2, bottom -5.
    # Line 4 (G91 Z-3.): bottom 3 below R -> -1. Line 5 (G91 R-4.): R 10-4 = 6, bottom 6-3 = 3.
    # Line 6 (G90 X50. R1.): R 1, Z still the G91 -3 -> bottom -2.
    tr = trace(START + "G99 G81 X0 Y0 R2. Z-5. F100\nG91 X10.\nX10. Z-3.\nR-4.\nG90 X50. R1.\n")
    bottoms = [(t[1], t[3]) for t in tr if t[0] == "G1"]
    assert bottoms == [(2, (0, 0, -5)), (3, (10, 0, -5)), (4, (20, 0, -1)), (5, (20, 0, 3)), (6, (50, 0, -2))]
    retracts = [tr[k + 1][3][2] for k, t in enumerate(tr) if t[0] == "G1"]
    assert retracts == [2, 2, 2, 6, 1]  # G99: each retract ends at that hole's R point


def test_initial_level_is_the_z_where_the_cycle_mode_starts_also_under_g91():
    # G91 Z5. lifts to 15 before the cycle: R 15-5 = 10, bottom 5, G98 back to 15. After G80 and G91 Z-10.
    # (Z 5) a new cycle mode starts at 5: R 4, bottom 2, back to 5.
    tr = trace(START + "G91 G0 Z5.\nG81 X1. R-5. Z-5. F100\nG80\nG0 Z-10.\nG81 X1. R-1. Z-2.\n")
    assert [(t[1], t[3]) for t in tr if t[1] in (3, 6)] == [
        (3, (1, 0, 15)), (3, (1, 0, 10)), (3, (1, 0, 5)), (3, (1, 0, 15)),
        (6, (2, 0, 5)), (6, (2, 0, 4)), (6, (2, 0, 2)), (6, (2, 0, 5)),
    ]


def test_g91_levels_include_work_offset_and_tool_length():
    # G54 Z = -100 mm, H1 = 50 mm; initial work Z 10 -> R 10-8 = 2, bottom 2-5 = -3 (work) -> machine -50 offset
    tr = trace("G54 G43 H1 G0 X0 Y0 Z10\nG91 G81 R-8. Z-5. X0 F100\n", work_offsets={54: (0.0, 0.0, -0.1)},
               tool_lengths=[0.05])
    assert ends(tr[1:]) == [("G0", (0, 0, -48)), ("G1", (0, 0, -53)), ("G0", (0, 0, -40))]


def test_g90_k_repeats_the_same_hole_and_k0_stores_only():
    tr = trace(START + "G81 X5 Z-1 R1 K2 F100\n")
    assert [t[3] for t in tr if t[0] == "G1"] == [(5, 0, -1), (5, 0, -1)]
    tr0 = trace(START + "G81 X5 Z-1 R1 K0 F100\nX7\n")
    assert [t[1] for t in tr0[1:]] == [3, 3, 3, 3]  # K0 drilled nothing; line 3 uses the stored data


def test_cycle_is_modal_until_g80_or_a_group_01_code():
    tr = trace(START + "G81 X1 Z-1 R1 F100\nF200\nX2\nG80 X3\nG81 X4 Z-1 R1\nG1 X5\n")
    assert [t[1] for t in tr if t[0] == "G1"] == [2, 4, 6, 7]  # line 3 (F only) drills nothing
    assert ("G0", 5, (2, 0, 10), (3, 0, 10)) in tr  # G80: a plain rapid in G0 mode
    assert tr[-1] == ("G1", 7, (4, 0, 10), (5, 0, 10))


def test_levels_include_work_offset_and_tool_length():
    # G54 Z = -100 mm, H1 = 50 mm: machine Z = programmed - 100 + 50
    tr = trace("G54 G43 H1 G0 X0 Y0 Z10\nG81 Z-3 R1 F100\n", work_offsets={54: (0.0, 0.0, -0.1)},
               tool_lengths=[0.05])
    assert ends(tr[1:]) == [("G0", (0, 0, -49)), ("G1", (0, 0, -53)), ("G0", (0, 0, -40))]


def test_initial_level_is_kept_while_in_cycle_mode():
    # the cycle starts at Z10; a later G98 hole returns to Z10 even after G99 holes
    tr = trace(START + "G99 G81 X1 Z-1 R1 F100\nG98 G83 X2 Z-4 R1 Q10\n")
    assert tr[-1][3] == (2, 0, 10)


def test_feed_blocks_are_exact_stops_with_the_cycle_line_and_its_feed_override():
    prog = START + "G81 X1 Z-1 R1 F100\nX2\nX3\nG80\n"
    blocks = interpret(prog).blocks
    lin = [b for b in blocks if isinstance(b, Linear)]
    assert all(b.exact_stop for b in lin) and [b.line for b in lin] == [2, 3, 4]
    assert {b.feed_line for b in lin} == {2}
    feeds, _ = resolve_values(blocks, 1, feed={3: 250 * MPM})
    got = {b.line: feeds[0, i] for i, b in enumerate(blocks) if isinstance(b, Linear)}
    assert got == pytest.approx({2: 100 * MPM, 3: 250 * MPM, 4: 250 * MPM})  # modal from line 3 on


def test_g82_pattern_time_bounds_and_dwell_total():
    # 3 holes, each 4 mm of feed (R1 -> Z-3) at 120 mm/min (2 mm/s): 2 s of feed per hole + 0.5 s dwell
    prog = START + "G82 X5 Z-3 R1 P500 F120\nX10\nX15\nG80\nM30\n"
    k = NCKernel(program_text=prog)
    k.setup(0.0)
    assert sum(b.seconds for b in k.program_.blocks if isinstance(b, Dwell)) == pytest.approx(1.5)
    lower = 3 * (4.0 / 2.0 + 0.5)
    assert k.duration_[0] >= lower
    assert k.duration_[0] <= lower + 3.0  # rapids (a few tens of mm at >= 30 m/min) and acc/dec add < 1 s per hole
    # the executing line during a hole is the hole's line
    lines = k.plan_.line[0]
    assert set(np.unique(lines)) <= {1, 2, 3, 4, 6}
    z = k.plan_.position[0, :, 2]
    assert set(np.unique(lines[z < 0.0])) == {2, 3, 4}


def test_g81_pattern_time_is_at_least_the_feed_time():
    prog = START + "G81 X5 Z-5 R2 F300\nX10\nX15\nX20\nG80\nM30\n"
    k = NCKernel(program_text=prog)
    k.setup(0.0)
    assert k.duration_[0] >= 4 * (7.0 / 5.0)  # 7 mm at 300 mm/min = 5 mm/s per hole


@pytest.mark.parametrize("text, word, fragment", [
    ("G84 X0 Z-5 R1 F100\n", "G84", "spindle stopped"),  # conventional G84 needs M3
    ("S100 M4\nG84 X0 Z-5 R1 F100\n", "G84", "M4 (counter-clockwise)"),
    ("S100 M3\nG74 X0 Z-5 R1 F100\n", "G74", "M3 (clockwise)"),
    ("S100 M3\nG84 X0 Z-5 R1 Q1 F100\n", "Q1", "peck tapping"),
    ("S0 M3\nG84 X0 Z-5 R1 F100\n", "G84", "S0"),
    ("M29\n", "M29", "without a spindle speed"),
    ("M29 S100 M3\n", "M3", "M29 and M3 in one block"),
    ("M29 S100\nG81 X0 Z-5 R1 F100\n", "G81", "after M29"),
    ("M29 S100\nG80\n", "G80", "after M29"),
    ("G76 X0 Z-5 R1 F100\n", "G76", "without a shift amount Q"),
    ("G76 X0 Z-5 R1 Q1 F100\n", "G76", "without the spindle turning clockwise"),
    ("S100 M3\nG87 X0 Z-5 R1 Q1 F100\n", "Z-5", "not above the R point"),
    ("S100 M3\nG99 G87 X0 Z-5 R-9 Q1 F100\n", "G87", "under G99"),
    ("G88 X0 Z-5 R1 F100\n", "G88", "manual operation"),
    ("G83 X0 Z-5 R1 F100\n", "G83", "without a peck depth Q"),
    ("G81 X0 Z2 R1 F100\n", "Z2", "not below the R point"),
    ("G81 X0 Z-2 F100\n", "G81", "without an R point"),
    ("G81 X0 R1 F100\n", "G81", "without a hole bottom Z"),
    ("G91 G81 X0 Z-2 F100\n", "G81", "without an R point"),
    ("G91 G81 X0 R-1 Z1 F100\n", "Z1", "under G91 R counts from the initial level"),
    ("G81 X0 Z-2 R1\n", "G81", "no feed rate"),
    ("G81 X0 Z-2 R1 F100 K1.5\n", "K1.5", "repeat count"),
    ("G83 X0 Z-2 R1 Q0 F100\n", "Q0", "not positive"),
    ("G83 X0 Z-99999 R1 Q.001 F100\n", "Q.001", "moves"),
    ("G81 X0 Z-2 R1 I1 F100\n", "I1", "word I"),
    ("G0 G81 X0 Z-2 R1 F100\n", "G0", "in one block"),
    ("G1 X1 Q2 F100\n", "Q2", "outside"),
])
def test_cycle_errors_name_the_word(text, word, fragment):
    with pytest.raises(GCodeError) as info:
        interpret("G0 Z10\n" + text, "p.nc")
    err = info.value
    assert err.line == text.count("\n") + 1 and err.word == word and fragment in str(err) and "expected" in str(err)


# ------------------------------------------------------------------ safe-line cancel codes
def test_safe_line_cancel_codes_are_no_ops():
    safe = "G90 G17 G15 G50 G50.1 G69 G67 G13.1 G80 G40 G49 G98\nG99\nG98\n"
    body = "G0 X1 Y2 Z3\nG1 X5 F100\n"
    assert trace(safe + body) == [t[:1] + (t[1] + 3,) + t[2:] for t in trace(body)]


@pytest.mark.parametrize("code, fragment", [  # G16, G51, G51.1, G68: tests/test_nck_transforms.py
    ("G66", "only its cancel G67"), ("G12.1", "only its cancel G13.1"), ("G50.15", "not supported"),
])
def test_codes_switching_features_on_are_rejected(code, fragment):
    with pytest.raises(GCodeError) as info:
        interpret(f"G0 X0\n{code}\n", "p.nc")
    assert info.value.line == 2 and info.value.word == code and fragment in str(info.value)


def test_lathe_g50_with_words_is_rejected():
    with pytest.raises(GCodeError) as info:
        interpret("G50 S3000\n", "p.nc")
    assert info.value.word == "S3000" and "lathe" in str(info.value)
