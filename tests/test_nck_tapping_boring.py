"""Tapping G84/G74 (conventional and M29 rigid), fine boring G76, back boring G87, and small dialect gaps
(``%O1000``, LinuxCNC ``G64 P Q``, ``G90.1``/``G91.1``).

Expected moves are written by hand from the FANUC 0i-MF / 31i-B cycle definitions; times are derived from
the machine data: spindle ramp 4000 rpm/s, speed-arrival tolerance 5 %, rigid-tapping acceleration
min(4000 rpm/s, 8000 rpm / 2 s) = 4000 rpm/s, Ts = 1 ms. All lengths in mm unless stated.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.nck import (
    Arc, Dwell, GCodeError, InterpreterSettings, Linear, NCKernel, ProgramEnd, Rapid, SpindleSpeed, SpindleStop,
    interpret,
)
from fmus_src.nck.cycles import CycleMachine
from fmus_src.nck.tapping import rigid_tap_accel, rigid_tap_stroke

MM = 1e-3
RPM = 2.0 * math.pi / 60.0
TS = 1e-3
START = "G90 G0 X0 Y0 Z10\n"  # line 1: initial level Z10


def mm(p):
    return tuple(round(v / MM, 9) for v in p)


def trace(text: str, **kw):
    out = []
    for b in interpret(text, "t.nc", InterpreterSettings(**kw) if kw else None).blocks:
        if isinstance(b, Rapid):
            out.append(("G0", mm(b.end)))
        elif isinstance(b, Linear):
            out.append(("G1", mm(b.end)))
        elif isinstance(b, Dwell):
            out.append(("D", b.seconds))
        elif isinstance(b, SpindleSpeed):
            out.append(("S", b.direction))
        elif isinstance(b, SpindleStop):
            out.append(("orient" if b.orient else "stop",))
    return out


def plan(text: str, **params):
    k = NCKernel(program_text=text, **params)
    k.setup(0.0)
    return k


def runs(feed: np.ndarray, peak: float):
    """(first, last) sample of each run of 0 < feed <= ``peak`` (m/s) that reaches ``peak`` (a rapid, faster,
    ends a run even when it starts in the sample after a feed move)."""
    pos = (feed > 1e-12) & (feed <= peak * (1 + 1e-9))
    edges = np.diff(np.concatenate(([0], pos.astype(int), [0])))
    starts, stops = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1
    return [(a, b) for a, b in zip(starts, stops) if abs(feed[a : b + 1].max() - peak) < 1e-9]


# ------------------------------------------------------------------ conventional tapping
def test_g84_conventional_moves_dwell_and_spindle_reversal_g98():
    tr = trace(START + "S1000 M3\nG98 G84 X5 Y0 Z-10. R2. P500 F1000.\n")
    assert tr[2:] == [
        ("G0", (5, 0, 10)), ("G0", (5, 0, 2)),  # positioning, rapid to R
        ("G1", (5, 0, -10)), ("D", 0.5),  # tap in, dwell P500 = 0.5 s
        ("S", -1), ("G1", (5, 0, 2)), ("S", 1),  # spindle reversed, tap out, forward again at R
        ("G0", (5, 0, 10)),  # G98: initial level
    ]
    taps = [b for b in interpret(START + "S1000 M3\nG84 X5 Z-10. R2. F1000.\n").blocks if isinstance(b, Linear)]
    assert all(b.tap_pitch == pytest.approx(1.0 * MM) and b.feed == pytest.approx(1000 * MM / 60) for b in taps)


def test_g84_g99_returns_to_r_and_pitch_is_f_over_s():
    tr = trace(START + "S500 M3\nG99 G84 X5 Z-10. R2. F1000.\nX8\n")
    assert tr[-5:] == [("G0", (8, 0, 2)), ("G1", (8, 0, -10)), ("S", -1), ("G1", (8, 0, 2)), ("S", 1)]  # at R
    tap = next(b for b in interpret(START + "S500 M3\nG84 X5 Z-10. R2. F1000.\n").blocks if isinstance(b, Linear))
    assert tap.tap_pitch == pytest.approx(2.0 * MM)  # 1000 mm/min / 500 rev/min


def test_g74_left_hand_tapping_reverses_the_other_way():
    tr = trace(START + "S1000 M4\nG74 X5 Z-10. R2. F1000.\n")
    assert [t for t in tr if t[0] == "S"] == [("S", -1), ("S", 1), ("S", -1)]  # M4, CW out, CCW again at R


def test_g95_tapping_feed_is_the_pitch():
    b = next(b for b in interpret(START + "S1000 M3\nG95 G84 X5 Z-10. R2. F1.\n").blocks if isinstance(b, Linear))
    assert b.tap_pitch == pytest.approx(1.0 * MM) and b.feed_per_rev == pytest.approx(1.0 * MM)
    assert b.feed == pytest.approx(1.0 * MM * 1000 / 60)  # 1 mm/rev x 1000 rev/min


def test_conventional_reversal_costs_the_spindle_ramp():
    # at the bottom: in position, dwell 0.5 s, then -S: the retract waits for speed arrival from +1000 to -1000
    # rpm within 5 %: (2000 - 50) rpm / 4000 rpm/s = 0.4875 s
    k = plan(START + "S1000 M3\nG98 G84 X5 Z-10. R2. P500 F1000.\nG80\nM30\n")
    feed = k.plan_.feed[0]
    (a0, a1), (b0, b1) = runs(feed, 1000 * MM / 60)
    idle = (b0 - 1) - (a1 + 1)  # samples between the end of the tap in and the start of the tap out
    reversal = (2000 - 0.05 * 1000) / 4000
    assert 0.5 + reversal - TS <= idle * TS <= 0.5 + reversal + 0.016 + 2 * TS  # + in-position after T = 16 ms
    ref = k.plan_.spindle_ref[0] / RPM
    assert np.all(ref[a0 : a1 + 1] == pytest.approx(1000)) and np.all(ref[b0 : b1 + 1] == pytest.approx(-1000))


# ------------------------------------------------------------------ rigid tapping
def test_rigid_stroke_is_a_synchronised_trapezoid():
    a = rigid_tap_accel(4000 * RPM, 8000 * RPM, 2.0)
    assert a == pytest.approx(4000 * RPM)
    assert rigid_tap_accel(4000 * RPM, 8000 * RPM, 4.0) == pytest.approx(2000 * RPM)  # the time constant limits
    v = 1000 * MM / 60
    seg, omega = rigid_tap_stroke((0, 0, 2 * MM), (0, 0, -10 * MM), v, 1 * MM, 1, a, TS)
    # Z accel = 4000/60 rev/s2 x 1 mm = 66.67 mm/s2: 0.25 s to 1000 rpm; 12 mm / (1000/60 mm/s) + 0.25 = 0.97 s
    assert seg.duration == pytest.approx(12 / (1000 / 60) + 0.25, rel=1e-12)
    assert seg.position[-1, 2] == -10 * MM and seg.position[0, 2] == 2 * MM
    assert omega.max() == pytest.approx(1000 * RPM) and omega[0] == 0 and omega[-1] == 0
    # synchronised: Z travel = pitch x spindle revolutions, sample by sample (trapezoidal rule of the speed)
    dz = -np.diff(seg.position[:, 2])
    revs = 0.5 * (omega[1:] + omega[:-1]) * TS / (2 * math.pi)
    assert np.allclose(dz, revs * 1 * MM, atol=1e-9)
    assert revs.sum() == pytest.approx(12.0, abs=1e-3)
    # a stroke too short for full speed: triangle, 2 sqrt(D / a_z) for D = 1 mm
    seg, _ = rigid_tap_stroke((0, 0, 0), (0, 0, -1 * MM), v, 1 * MM, -1, a, TS)
    assert seg.duration == pytest.approx(2 * math.sqrt(1 * MM / (4000 / 60 * 1 * MM)), rel=1e-12)


def test_m29_g84_rigid_tapping_in_the_plan():
    k = plan(START + "S1000 M3\nM29 S1000\nG99 G84 X5 Y0 Z-10. R2. P500 F1000.\nG80\nM30\n")
    blocks = k.blocks_
    strokes = [b for b in blocks if isinstance(b, Linear)]
    assert [(mm(b.end), b.rigid_tap) for b in strokes] == [((5, 0, -10), 1), ((5, 0, 2), -1)]
    assert isinstance(blocks[2], SpindleStop) and blocks[2].line == 3  # M29 stops the spindle (then its S)
    p = k.plan_
    (a0, a1), (b0, b1) = runs(p.feed[0], 1000 * MM / 60)
    stroke = 12 / (1000 / 60) + 0.25  # 0.97 s each way
    assert (a1 - a0 + 2) * TS == pytest.approx(stroke, abs=1.01 * TS)
    assert (b1 - b0 + 2) * TS == pytest.approx(stroke, abs=1.01 * TS)
    assert (b0 - 1) - (a1 + 1) == 500  # both at rest at the bottom: exactly the dwell P500
    z = p.position[0, :, 2]
    assert z.min() == pytest.approx(-10 * MM, abs=1e-12)  # no after-interpolation filter on the stroke
    ref = p.spindle_ref[0] / RPM
    assert ref[a0 : a1 + 1].min() > 0 and ref[a0 : a1 + 1].max() == pytest.approx(1000)  # CW in
    assert ref[b0 : b1 + 1].max() < 0 and ref[b0 : b1 + 1].min() == pytest.approx(-1000)  # CCW out
    assert np.all(ref[a1 + 2 : b0] == 0)  # stopped at the bottom
    assert np.all(p.spindle_speed[0, b1 + 2 :] == 0)  # stays stopped after the cycle (M3 restarts it)
    revs_in = p.spindle_speed[0, a0 - 1 : a1 + 2].sum() * TS / (2 * math.pi)
    assert revs_in == pytest.approx(12.0, abs=1e-2)  # 12 mm at 1 mm/rev
    assert z[-1] == pytest.approx(2 * MM)  # G99: at R


def test_rigid_tapping_always_machine_parameter_and_g74_direction():
    text = START + "S1000 M4\nG98 G74 X5 Z-10. R2. F1000.\nG80\nM30\n"
    assert not any(isinstance(b, Linear) and b.rigid_tap for b in interpret(text).blocks)
    blocks = interpret(text, settings=InterpreterSettings(cycles=CycleMachine(rigid_always=True))).blocks
    assert [b.rigid_tap for b in blocks if isinstance(b, Linear)] == [-1, 1]  # G74: CCW in, CW out
    k = plan(text, rigid_tapping_mode="always")
    (a0, a1), _ = runs(k.plan_.feed[0], 1000 * MM / 60)
    assert k.plan_.spindle_ref[0, a0 + 10] < 0


def test_rigid_tapping_above_the_maximum_speed_is_an_error():
    with pytest.raises(GCodeError) as info:
        plan(START + "M29 S9000\nG84 X5 Z-10. R2. F9000.\nG80\nM30\n")
    assert info.value.line == 3 and "maximum spindle speed" in str(info.value)


# ------------------------------------------------------------------ boring
def test_g76_orients_shifts_by_q_and_retracts():
    text = START + "S500 M3\nG98 G76 X5 Y0 Z-10. R2. Q0.5 P200 F100.\n"
    assert trace(text)[2:] == [
        ("G0", (5, 0, 10)), ("G0", (5, 0, 2)), ("G1", (5, 0, -10)), ("D", 0.2),
        ("orient",), ("G0", (5.5, 0, -10)),  # shift Q0.5 in +X (No. 5101 RD1 = RD2 = 0)
        ("G0", (5.5, 0, 10)), ("G0", (5, 0, 10)), ("S", 1),  # retract, shift back, spindle CW
    ]
    tr = trace(text.replace("G98", "G99"), cycles=CycleMachine(boring_shift="-Y"))
    assert tr[7:10] == [("G0", (5, -0.5, -10)), ("G0", (5, -0.5, 2)), ("G0", (5, 0, 2))]


def test_g76_shift_waits_for_the_spindle_at_rest():
    k = plan(START + "S500 M3\nG98 G76 X5 Y0 Z-10. R2. Q0.5 P200 F100.\nG80\nM30\n")
    p = k.plan_
    x = p.position[0, :, 0]
    shift = int(np.nonzero(x > 5 * MM + 1e-9)[0][0])
    assert p.spindle_speed[0, shift - 1] == 0.0  # oriented (stopped) before the tool moves off the axis
    (a0, a1), = runs(p.feed[0], 100 * MM / 60)
    wait = (shift - 1 - (a1 + 1)) * TS  # end of the boring feed -> shift
    stop = 500 / 4000  # 0.125 s to stop from 500 rpm
    assert 0.2 + stop - TS <= wait <= 0.2 + stop + 0.016 + 3 * TS


def test_g87_back_boring():
    tr = trace(START + "S500 M3\nG87 X5 Y0 Z-2. R-12. Q0.5 F100.\n")
    assert tr[2:] == [
        ("G0", (5, 0, 10)), ("orient",), ("G0", (5.5, 0, 10)), ("G0", (5.5, 0, -12)), ("G0", (5, 0, -12)),
        ("S", 1), ("G1", (5, 0, -2)),  # bore upwards from R to Z
        ("orient",), ("G0", (5.5, 0, -2)), ("G0", (5.5, 0, 10)), ("G0", (5, 0, 10)), ("S", 1),
    ]


# ------------------------------------------------------------------ dialect gaps
def test_percent_with_text_is_the_tape_mark():
    text = "%O1000\nO1000 (PART)\nG0 X1\n% (end of tape)\nG0 X2\n"
    blocks = interpret(text).blocks
    assert [mm(b.end) for b in blocks if isinstance(b, Rapid)] == [(1, 0, 0)]
    assert blocks[-1] == ProgramEnd(4, "%")


def test_linuxcnc_g64_p_q_is_g64():
    body = "G1 X10 F600\nX20 Y5\nM30\n"
    assert interpret("G61\nG64 P0.01 Q0.005\n" + body).blocks[:-1] == interpret("G61\nG64\n" + body).blocks[:-1]
    for text, word in (("G64 P-1\n", "P-1"), ("G0 Z10\nG81 X0 Z-2 R1 F100\nG64 P0.1\n", "P0.1")):
        with pytest.raises(GCodeError) as info:
            interpret(text)
        assert info.value.word == word


def test_g90_1_absolute_arc_centre():
    off = {54: (100 * MM, 50 * MM, 0.0)}
    inc = interpret("G54 G0 X10 Y0\nG2 X0 Y-10 I-10 J0 F100\n", settings=InterpreterSettings(work_offsets=off))
    ab = interpret("G54 G0 X10 Y0\nG90.1 G2 X0 Y-10 I0 J0 F100\n", settings=InterpreterSettings(work_offsets=off))
    a, b = (next(x for x in p.blocks if isinstance(x, Arc)) for p in (inc, ab))
    assert b.center == pytest.approx((100 * MM, 50 * MM, 0.0)) and a.center == pytest.approx(b.center)
    # G91.1 returns to incremental centres
    back = interpret("G0 X10 Y0\nG90.1\nG91.1 G3 X-10 Y0 I-10 J0 F100\n")
    assert next(x for x in back.blocks if isinstance(x, Arc)).center == pytest.approx((0, 0, 0))
    with pytest.raises(GCodeError) as info:
        interpret("G0 X10 Y0\nG90.1 G2 X0 Y-10 I0 F100\n")
    assert info.value.line == 2 and "G90.1" in str(info.value)
