"""FANUC codes CAM posts write: G54.1 Pn / G54 Pn, G10 data input, look-ahead modes, G95 feed per revolution.

Every expected number is derived in the test from the offsets, feeds and speeds written in the program.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.nck import NCKernel
from fmus_src.nck.blocks import Linear, Rapid
from fmus_src.nck.errors import GCodeError, NCParameterError
from fmus_src.nck.interpreter import (
    EXTERNAL_OFFSET, InterpreterSettings, additional_offset_key, interpret,
)
from fmus_src.nck.writer import per_revolution_lines, rewrite_program

MM = 1e-3
RPM = 2.0 * math.pi / 60.0
TS = 1e-3


def _ends(text: str, settings: InterpreterSettings | None = None) -> list[tuple[float, float, float]]:
    """End points (m, machine) of the moves of a program."""
    return [b.end for b in interpret(text, "part.nc", settings).blocks if isinstance(b, (Rapid, Linear))]


def _error(text: str, settings: InterpreterSettings | None = None) -> GCodeError:
    with pytest.raises(GCodeError) as info:
        interpret(text, "part.nc", settings or InterpreterSettings(tool_lengths=[0.1], tool_radii=[0.0]))
    return info.value


# ---------------------------------------------------------------------------- G54.1 Pn / G54 Pn
def test_g54_1_offset_moves_the_machine_target_by_exactly_the_offset():
    off = (0.125, -0.0375, -0.2)
    s = InterpreterSettings(work_offsets={54: (0.01, 0.02, 0.03), additional_offset_key(2): off})
    ends = _ends("G90 G54 G0 X5 Y6 Z7\nG54.1 P2\nG0 X5 Y6 Z7\nG54 P2 X8\nG54 X8\nM30\n", s)
    assert ends[0] == pytest.approx((0.015, 0.026, 0.037), abs=1e-15)
    # same programmed point in G54.1 P2: machine = programmed + offset
    assert ends[1] == pytest.approx((0.005 + off[0], 0.006 + off[1], 0.007 + off[2]), abs=1e-15)
    # G54 P2 is G54.1 P2; plain G54 goes back to G54's offset (Y, Z not programmed: they do not move)
    assert ends[2][0] == pytest.approx(0.008 + off[0], abs=1e-15)
    assert ends[3] == pytest.approx((0.008 + 0.01, 0.006 + off[1], 0.007 + off[2]), abs=1e-15)


def test_g54_1_keys_are_1000_plus_n_and_missing_ones_are_zero():
    assert [additional_offset_key(n) for n in (1, 48)] == [1001, 1048]
    with pytest.raises(ValueError):
        additional_offset_key(49)
    assert _ends("G54.1 P48 G0 X1\nM30\n")[0] == pytest.approx((0.001, 0.0, 0.0), abs=1e-15)


@pytest.mark.parametrize("text,line,word,fragment", [
    ("G0 X0\nG54.1 X1\n", 2, "G54.1", "G54.1 without P"),
    ("G0 X0\nG54.1 P49\n", 2, "P49", "P49 does not exist"),
    ("G54.1 P0\n", 1, "P0", "does not exist"),
    ("G54.1 P1.5\n", 1, "P1.5", "does not exist"),
    ("G54 P49\n", 1, "P49", "does not exist"),
    ("G54.1 P2 G4 X1.\n", 1, "G54.1", "G54.1 and G4 in one block"),
    ("G54.1 P2 M98 P100\n", 1, "P100", "twice"),
    ("G0 X0 Z5\nG81 X0 Z-1 R1 F100\nG54.1 P2 X5\n", 3, "G54.1", "canned-cycle mode G81"),
])
def test_g54_1_errors_name_file_line_and_word(text, line, word, fragment):
    err = _error(text)
    assert (err.file, err.line, err.word) == ("part.nc", line, word)
    assert fragment in str(err) and str(err).startswith(f"part.nc:{line}: ")


def test_g54_p_in_a_dwell_block_stays_the_dwell():
    blocks = interpret("G54 G4 P1500\nM30\n").blocks
    assert blocks[0].seconds == 1.5


# ---------------------------------------------------------------------------- G10
def test_g10_l2_sets_under_g90_and_adds_under_g91():
    s = InterpreterSettings(work_offsets={54: (0.010, 0.0, 0.0), 55: (0.0, 0.0, -0.1)})
    text = ("G90 G10 L2 P1 X5. Y-2.\nG54 G0 X0 Y0\n"  # G54 becomes (5, -2, 0) mm
            "G91 G10 L2 P1 X5.\nG90 G0 X0\n"  # G54 X: 5 + 5 = 10 mm
            "G91 G10 L2 P2 Z0.5\nG90 G55 G0 Z0\nM30\n")  # G55 Z: -100 + 0.5 mm
    ends = _ends(text, s)
    assert ends[0] == pytest.approx((0.005, -0.002, 0.0), abs=1e-15)
    assert ends[1][0] == pytest.approx(0.010, abs=1e-15)
    assert ends[2][2] == pytest.approx(-0.1 + 0.0005, abs=1e-15)
    # the settings themselves are untouched: a second run starts from them again
    assert s.work_offsets[54] == (0.010, 0.0, 0.0)


def test_g10_l2_p0_external_offset_adds_to_every_work_system_but_not_to_g53():
    s = InterpreterSettings(work_offsets={EXTERNAL_OFFSET: (0.001, 0.0, 0.0), 56: (0.1, 0.0, 0.0),
                                          additional_offset_key(7): (0.2, 0.0, 0.0)})
    ends = _ends("G56 G0 X0\nG54.1 P7 X0\nG10 L2 P0 X3.\nX0\nG53 X0\nM30\n", s)
    assert [e[0] for e in ends] == pytest.approx([0.101, 0.201, 0.203, 0.0], abs=1e-15)


def test_g10_l20_sets_g54_1_and_change_of_the_active_offset_shifts_the_programmed_position():
    # at work X0 of G54.1 P3 (offset 0), G10 L20 P3 X20. makes the current point work X-20:
    # G91 X1 then moves 1 mm, G90 X0 goes to machine 20 mm
    ends = _ends("G54.1 P3 G0 X0\nG10 L20 P3 X20.\nG91 G0 X1.\nG90 G0 X0\nM30\n")
    assert [e[0] for e in ends] == pytest.approx([0.0, 0.001, 0.020], abs=1e-15)


def test_g10_in_inch_is_in_inch():
    ends = _ends("G20 G10 L2 P1 X1.\nG54 G0 X0\nM30\n")
    assert ends[0][0] == pytest.approx(0.0254, abs=1e-15)


def test_g10_tool_length_geometry_and_wear():
    # H1 geometry 100 mm (settings), wear -0.2 mm (L11): Z0 with G43 H1 -> machine 99.8 mm;
    # G91 L10 adds 5 mm to the geometry -> the next Z move applies 104.8 mm
    s = InterpreterSettings(tool_lengths=[0.1])
    ends = _ends("G10 L11 P1 R-0.2\nG43 H1 G0 Z0\nG91 G10 L10 P1 R5.\nG90 G0 Z0\nM30\n", s)
    assert [e[2] for e in ends] == pytest.approx([0.0998, 0.1048], abs=1e-15)


def test_g10_tool_radius_geometry_plus_wear_is_the_radius_of_g41():
    s = InterpreterSettings(tool_radii=[0.0, 0.0])
    # geometry 3 mm and wear -3 mm: radius 0 -> the programmed path
    p = interpret("G10 L12 P1 R3.\nG10 L13 P1 R-3.\nG41 D1 G1 X10 F100\nG40 X20\nM30\n", settings=s)
    assert p.blocks[0].end == pytest.approx((0.010, 0.0, 0.0), abs=1e-15)
    # geometry 3 mm: a start-up to X10 ending the program in offset mode ends 3 mm to the left (+Y) of it
    p = interpret("G10 L12 P2 R3.\nG41 D2 G1 X10 F100\n", settings=s)
    assert p.blocks[0].end == pytest.approx((0.010, 0.003, 0.0), abs=1e-15)


@pytest.mark.parametrize("text,line,word,fragment", [
    ("G10 P1 X0\n", 1, "G10", "without L"),
    ("G10 L3 P1 X0\n", 1, "L3", "G10 L3 is not supported"),
    ("G10 L1 P1 R0\n", 1, "L1", "not supported"),
    ("G10 L2 X0\n", 1, "L2", "without P"),
    ("G10 L2 P7 X0\n", 1, "P7", "does not exist"),
    ("G10 L20 P0 X0\n", 1, "P0", "does not exist"),
    ("G10 L20 P100 X0\n", 1, "P100", "does not exist"),  # P1..P99: G54.1 Pn and Haas G154 Pn
    ("G10 L10 P2 R1\n", 1, "P2", "does not exist"),
    ("G10 L2 P1\n", 1, "L2", "without data"),
    ("G10 L2 P1 R1\n", 1, "R1", "word R in a G10 L2 block"),
    ("G10 L10 P1 Z1\n", 1, "Z1", "word Z in a G10 L10 block"),
    ("G10 G1 L2 P1 X0\n", 1, "G1", "motion G code"),
    ("G0 Z5\nG81 X0 Z-1 R1 F100\nG10 L2 P1 X0\n", 3, "G10", "canned-cycle mode"),
    ("G1 X0 L2\n", 1, "L2", "outside an M98 block"),
])
def test_g10_errors_name_file_line_and_word(text, line, word, fragment):
    err = _error(text)
    assert (err.file, err.line, err.word) == ("part.nc", line, word)
    assert fragment in str(err) and str(err).startswith(f"part.nc:{line}: ")


# ---------------------------------------------------------------------------- look-ahead modes
BODY = "G90 G54 G0 X0 Y0 Z1.\nS3000 M3\nG1 Z-1. F600\nX10. Y5.\nG2 X20. Y5. R5.\nG1 X25. Y0\nG0 Z5.\nM30\n"


@pytest.mark.parametrize("on,off", [("G5.1 Q1", "G5.1 Q0"), ("G05.1 Q1 R5", "G05.1 Q0"), ("G08 P1", "G8 P0"),
                                    ("G5 P10000", "G05 P0"), ("N10 G5.1 Q1.", "N20 G5.1 Q0")])
def test_look_ahead_modes_plan_identically_to_the_program_without_them(on, off):
    head, rest = BODY.split("\n", 1)
    with_mode = head + "\n" + on + "\n" + rest.replace("G0 Z5.", off + "\nG0 Z5.")
    plain = NCKernel(program_text=BODY)
    moded = NCKernel(program_text=with_mode)
    plain.setup(0.0)
    moded.setup(0.0)
    assert moded.duration_[0] == plain.duration_[0]
    np.testing.assert_array_equal(moded.plan_.position, plain.plan_.position)
    np.testing.assert_array_equal(moded.plan_.feed, plain.plan_.feed)


@pytest.mark.parametrize("text,word,fragment", [
    ("G5.1 Q3\n", "Q3", "not a supported mode"),
    ("G5.1 Q2\n", "Q2", "not a supported mode"),
    ("G5.1\n", "G5.1", "without Q"),
    ("G8 P2\n", "P2", "not a supported mode"),
    ("G5 P1\n", "P1", "not a supported mode"),
    ("G5.1 Q1 R11\n", "R11", "1..10"),
    ("G5.1 Q0 R5\n", "R5", "in the G5.1 block"),
    ("G5.1 Q1 G1 X10 F100\n", "G1", "alone in its block"),
    ("G08 P1 X10\n", "X10", "alone in its block"),
])
def test_look_ahead_errors_name_the_word(text, word, fragment):
    err = _error(text)
    assert (err.line, err.word) == (1, word) and fragment in str(err)


# ---------------------------------------------------------------------------- G95 feed per revolution
def test_g95_block_feed_is_f_times_commanded_speed():
    # F0.05 mm/rev x 6000 rev/min = 300 mm/min; in G20 F0.002 in/rev x 2500 rev/min = 5 in/min
    b = [x for x in interpret("S6000 M3\nG95 G1 X30 F0.05\nG94 G1 X40 F200\nM30\n").blocks if isinstance(x, Linear)]
    assert b[0].feed == pytest.approx(300.0 * MM / 60.0, rel=1e-14) and b[0].feed_per_rev == pytest.approx(5e-5)
    assert b[1].feed == pytest.approx(200.0 * MM / 60.0, rel=1e-14) and b[1].feed_per_rev == 0.0
    inch = [x for x in interpret("G20 S2500 M3\nG95 G1 X1. F0.002\nM30\n").blocks if isinstance(x, Linear)]
    assert inch[0].feed == pytest.approx(5.0 * 25.4e-3 / 60.0, rel=1e-14)


def test_g95_modal_f_follows_a_new_spindle_speed():
    # the F stays 0.1 mm/rev: at S2000 the feed is 200 mm/min, at S4000 400 mm/min
    b = [x for x in interpret("S2000 M3\nG95 G1 X10 F0.1\nS4000\nX20\nM30\n").blocks if isinstance(x, Linear)]
    assert [x.feed * 60.0 / MM for x in b] == pytest.approx([200.0, 400.0], rel=1e-14)


def test_g95_canned_cycle_feeds_are_per_revolution():
    b = interpret("S1000 M3\nG0 X0 Y0 Z5.\nG95 G81 X1. Z-2. R1. F0.12\nG80\nM30\n").blocks
    feeds = [x for x in b if isinstance(x, Linear)]
    assert feeds and all(x.feed == pytest.approx(0.12 * 1000 * MM / 60.0, rel=1e-14) for x in feeds)
    assert all(x.feed_per_rev == pytest.approx(0.12e-3) for x in feeds)


def test_g95_30_mm_line_at_f005_s6000_takes_the_derived_time():
    # v = 0.05 mm/rev x 6000 rev/min / 60 = 5 mm/s. Trapezoidal acc/dec before interpolation (no bell, no
    # after-interpolation filter), a = 2 m/s2: T = L/v + v/a = 30/5 + 0.005/2 = 6.0025 s from the first
    # moving sample (after the spindle arrival) to the end of the motion.
    k = NCKernel(program_text="S6000 M3\nG95 G1 X30. F0.05\nM30\n", accel_change_time_before_interp=0.0,
                 cutting_time_constant=0.0, accel_before_interp=2.0)
    k.setup(0.0)
    feed = k.plan_.feed[0]
    first = int(np.argmax(feed > 0))
    last = int(np.nonzero(feed > 0)[0][-1])
    assert (last - first + 1) * TS == pytest.approx(30.0 / 5.0 + 0.005 / 2.0, abs=2 * TS)
    assert feed.max() == pytest.approx(0.005, rel=1e-12)


def _g94_twin(text: str) -> str:
    """The same program in G94: F0.05 at S6000 is F300."""
    return text.replace("G95 G1 X30. F0.05", "G94 G1 X30. F300.")


def test_spindle_override_rescales_the_g95_feed_like_rewriting_the_s_word():
    text = "S6000 M3\nG95 G1 X30. F0.05\nM30\n"
    speeds = np.array([6000.0, 3000.0, 4500.0])
    k = NCKernel(program_text=text, batch=3)
    k.set_overrides(spindle={1: speeds * RPM})
    k.setup(0.0)
    # each member equals the rewritten program planned alone, and the G94 program at F = 0.05 S
    for i, s in enumerate(speeds):
        alone = NCKernel(program_text=rewrite_program(text, spindle_by_line={1: s}))
        alone.setup(0.0)
        g94 = NCKernel(program_text=_g94_twin(text).replace("F300.", f"F{0.05 * s:g}").replace("S6000", f"S{s:g}"))
        g94.setup(0.0)
        assert k.duration_[i] == alone.duration_[0] == pytest.approx(g94.duration_[0], abs=TS)
        assert k.plan_.feed[i].max() == pytest.approx(0.05 * s / 60.0 * MM, rel=1e-12)


def test_feed_override_on_a_g95_block_and_zero_speed_are_refused():
    text = "S6000 M3\nG95 G1 X30. F0.05\nM30\n"
    k = NCKernel(program_text=text)
    k.set_overrides(feed={2: 0.01})
    with pytest.raises(NCParameterError, match="line 2, a feed per revolution"):
        k.setup(0.0)
    k = NCKernel(program_text=text, batch=2)
    k.set_overrides(spindle={1: np.array([6000.0, 0.0]) * RPM})
    with pytest.raises(NCParameterError, match="line 2: feed per revolution .G95. at spindle speed 0"):
        k.setup(0.0)


def test_writer_refuses_an_f_word_under_g95_and_keeps_g94_lines():
    text = "S6000 M3\nG95 G1 X30. F0.05\nG94 G1 X40. F300.\nM30\n"
    assert per_revolution_lines(text, [1, 2, 3]) == {2}
    with pytest.raises(GCodeError) as info:
        rewrite_program(text, feed_by_line={2: 250.0}, file="p.nc")
    assert (info.value.file, info.value.line, info.value.word) == ("p.nc", 2, "F")
    assert rewrite_program(text, feed_by_line={3: 250.0}).splitlines()[2] == "G94 G1 X40. F250."


@pytest.mark.parametrize("text,line,word,fragment", [
    ("G95 G1 X1 F0.1\n", 1, "G1", "spindle is stopped"),
    ("S0 M3\nG95 G1 X1 F0.1\n", 2, "G1", "S0"),
    ("S1000 M3\nG95 G1 X1 F0.1\nM5\nX2\n", 4, "G1", "spindle is stopped"),
    ("S1000 M3\nG1 X1 F100\nG95 X2\n", 3, "G1", "modal F (line 2) is per minute (G94)"),
    ("S1000 M3\nG95 G1 X1 F0.1\nG94 X2\n", 3, "G1", "modal F (line 2) is per revolution (G95)"),
    ("G0 Z5\nG95 G81 X0 Z-1 R1 F0.1\n", 2, "G81", "canned cycle G81 while the spindle is stopped"),
])
def test_g95_errors_name_file_line_and_word(text, line, word, fragment):
    err = _error(text)
    assert (err.file, err.line, err.word) == ("part.nc", line, word)
    assert fragment in str(err)


def test_optimize_takes_g95_cutting_lines_as_genes_in_mm_per_min(tmp_path):
    from orchestrator.case import load_case
    from orchestrator.optimize import build_reference

    (tmp_path / "case.toml").write_text('program = "slot.nc"\n[stock]\nmin = [0.0, 0.0, -2.0]\n'
                                        'max = [5.0, 8.0, 0.0]\n')
    (tmp_path / "slot.nc").write_text("G21 G17 G90 G94 G54\nS3000 M3\nG0 X-4. Y4. Z2.\nG1 Z-1. F500.\n"
                                      "G95 X3. F0.08\nG0 Z2.\nM30\n")
    ctx = build_reference(load_case(tmp_path)).context
    assert ctx.lines.tolist() == [5] and ctx.per_rev_lines == frozenset({5})
    assert ctx.original_feed.tolist() == [pytest.approx(0.08 * 3000.0)]  # the gene is F x S, mm/min


# ---------------------------------------------------------------------------- M19 spindle orientation
def test_m19_stops_the_spindle_exactly_as_m5():
    # posts write M19 before a tool change: the spindle stops (ramping down at spindle_ramp) and waits for
    # M3/M4; the next S6000 M3 ramps it up again and the cut waits for the speed arrival, as after M5
    text = "G90 G0 X0 Y0 Z1.\nS6000 M3\nG1 Z-1. F600\nX10.\nG0 Z5.\n{stop}\nT2 M6\nS6000 M3\nG1 X20. F600\nM30\n"
    with_m5 = NCKernel(program_text=text.format(stop="M5"))
    with_m19 = NCKernel(program_text=text.format(stop="M19"))
    with_m5.setup(0.0)
    with_m19.setup(0.0)
    assert with_m19.duration_[0] == with_m5.duration_[0]
    np.testing.assert_array_equal(with_m19.plan_.position, with_m5.plan_.position)
    np.testing.assert_array_equal(with_m19.plan_.spindle_ref, with_m5.plan_.spindle_ref)
    assert np.any(with_m19.plan_.spindle_ref[0] == 0.0)           # it did stop between the two cuts
