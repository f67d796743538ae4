"""Planner: cycle times against analytic acc/dec profiles, corner and arc clamps, filters, spindle waits.

All expected numbers are derived in the comments; Ts = 1 ms throughout.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.nck import NCKernel
from fmus_src.nck.filters import apply_fir, box_lengths
from fmus_src.nck.profiles import SpeedChange

TS = 1e-3
MPM = 1e-3 / 60.0  # mm/min -> m/s


def plan(text: str, **params) -> NCKernel:
    k = NCKernel(program_text=text, **params)
    k.setup(0.0)
    return k


def motion_end(k: NCKernel) -> int:
    """Sample index from which the reference no longer changes (the filters are flushed)."""
    pos = k.plan_.position[0]
    moving = np.nonzero(np.any(np.diff(pos, axis=0) != 0.0, axis=1))[0]
    return int(moving[-1]) + 1


def n_ceil(seconds: float) -> int:
    return math.ceil(seconds / TS - 1e-9)


# ---------------------------------------------------------------------------- straight moves
@pytest.mark.parametrize("filt", ["linear", "bell"])
def test_trapezoidal_move_time_plus_filter_length(filt):
    # trapezoid, L = 100 mm, v = 600 mm/min = 0.01 m/s, a = 2 m/s2: T = L/v + v/a = 10.005 s.
    # A moving average of length T_f (linear: one box, bell: two boxes of T_f/2) lengthens the move by T_f.
    k = plan("G1 X100 F600\nM30\n", accel_change_time_before_interp=0.0, cutting_filter=filt,
             cutting_time_constant=0.016)
    assert motion_end(k) == n_ceil(0.1 / 0.01 + 0.01 / 2.0) + 16
    np.testing.assert_array_equal(k.plan_.position[0, -1], [0.1, 0.0, 0.0])


def test_short_trapezoidal_move_never_reaches_feed():
    # L = 1 mm, a = 2 m/s2, F = 6000 mm/min (0.1 m/s): v^2/a = 5 mm > L, so a triangle: T = 2 sqrt(L/a)
    k = plan("G1 X1 F6000\nM30\n", accel_change_time_before_interp=0.0, cutting_time_constant=0.0)
    assert motion_end(k) == n_ceil(2 * math.sqrt(1e-3 / 2.0))
    assert k.plan_.feed.max() == pytest.approx(math.sqrt(2.0 * 1e-3), abs=2.0 * TS)  # peak sqrt(a L)


@pytest.mark.parametrize("feed_mm_min", [600.0, 6000.0])
def test_bell_shaped_move_time(feed_mm_min):
    # jerk-limited acc/dec, a = 2 m/s2, tc = 32 ms (jerk a/tc). A speed change dv takes
    #   dv/a + tc         if dv >= a tc = 0.064 m/s (6000 mm/min: 0.1 m/s)
    #   2 sqrt(dv tc / a) otherwise                (600 mm/min: 0.01 m/s)
    # and covers v/2 of it; so T = L/v + t_change. Plus the 16 ms linear filter.
    v = feed_mm_min * MPM
    t_change = v / 2.0 + 0.032 if v >= 2.0 * 0.032 else 2.0 * math.sqrt(v * 0.032 / 2.0)
    k = plan("G1 X100 F%g\nM30\n" % feed_mm_min)
    assert motion_end(k) == n_ceil(0.1 / v + t_change) + 16


def test_jerk_is_bounded_by_accel_over_change_time():
    k = plan("G1 X20 F6000\nM30\n", cutting_time_constant=0.0)
    v = k.plan_.feed[0]
    acc = np.diff(v) / TS
    jerk = np.diff(acc) / TS
    assert np.abs(acc).max() <= 2.0 * (1 + 1e-9)
    assert np.abs(jerk).max() <= 2.0 / 0.032 * (1 + 1e-6)
    assert np.abs(acc).max() == pytest.approx(2.0, rel=1e-6)  # dv = 0.1 > a tc: the plateau is reached


def test_in_position_width_ends_the_program_early_by_the_derived_amount():
    # Trapezoid decel a into the end: remaining distance a s^2/2 at time s before the interpolation end.
    # A box of length T averages it: at T - tau after the end the reference is a tau^3/(6T) short.
    # Done when that equals the in-position width w: tau = (6 T w / a)^(1/3) (valid for tau <= v/a, T).
    a, T, w, v = 2.0, 0.016, 0.02e-3, 3000 * MPM
    tau = (6 * T * w / a) ** (1 / 3)
    assert tau < min(v / a, T)
    k = plan("G1 X100 F3000\nM30\n", accel_change_time_before_interp=0.0, cutting_time_constant=T,
             in_position_width=w)
    t_interp = n_ceil(0.1 / v + v / a) * TS
    assert k.duration_[0] == pytest.approx(t_interp + T - tau, abs=2 * TS)
    assert k.plan_.done_index[0] < motion_end(k)


# ---------------------------------------------------------------------------- rapids
def test_rapid_uses_slowest_axis_and_rapid_filter():
    # X 100 mm at 36 m/min takes 0.1667 s, Y 50 mm 0.0833 s, Z 20 mm at 30 m/min 0.04 s: T = 0.1667 s.
    # Step speed filtered by the 60 ms bell filter: motion ends 60 ms after the interpolation.
    k = plan("G0 X100 Y50 Z20\nM30\n", in_position_width=1e-9)
    assert motion_end(k) == n_ceil(0.1 / 0.6) + 60
    assert k.plan_.feed[0, 5] == pytest.approx(math.sqrt(0.1**2 + 0.05**2 + 0.02**2) / (0.1 / 0.6))
    assert k.duration_[0] == pytest.approx((n_ceil(0.1 / 0.6) + 60) * TS, abs=TS)


def test_rapid_exact_stop_before_next_move():
    # the feed move starts only when the rapid's filtered reference is within the in-position width
    k = plan("G0 X10\nG1 X20 F600\nM30\n")
    pos = k.plan_.position[0]
    feed = k.plan_.feed[0]
    n_rapid = n_ceil(0.01 / 0.6)
    first_cut = n_rapid + 1 + int(np.argmax(feed[n_rapid + 1:] > 0))
    # the cut's first sample is its start (speed 0): the in-position sample is first_cut - 1
    start_cut = first_cut - 1
    remaining = 0.01 - pos[:, 0]
    assert remaining[start_cut] <= 0.02e-3 + 1e-12  # in position when the cut starts ...
    assert remaining[start_cut - 1] > 0.02e-3        # ... and not one period earlier


# ---------------------------------------------------------------------------- corners and arcs
@pytest.mark.parametrize("dx, dy", [(0.0, 10.0), (10.0, 10.0), (20.0, 10.0)])
def test_corner_speed_from_allowable_velocity_difference(dx, dy):
    # X move then a turn at 3000 mm/min. Tangents t1 = (1, 0), t2 = (dx, dy)/|.|; the corner speed is
    # vd / max_axis |t2 - t1| (FANUC No. 1783): 90 deg -> vd, 45 deg -> vd sqrt2, 26.6 deg -> vd sqrt5.
    t2 = np.array([dx, dy]) / math.hypot(dx, dy)
    dmax = np.abs(t2 - np.array([1.0, 0.0])).max()
    second = f"X{dx:g} Y{dy:g}"
    vd = 400 * MPM
    vc = vd / dmax
    k = plan(f"G1 X10 F3000\nG91 {second}\nM30\n", cutting_time_constant=0.0, accel_change_time_before_interp=0.0)
    feed = k.plan_.feed[0]
    pos = k.plan_.position[0]
    near = np.hypot(pos[:, 0] - 0.01, pos[:, 1]) < 0.5e-3  # within 0.5 mm of the corner
    vmin = feed[near].min()
    assert vmin < 3000 * MPM  # slow-down visible
    assert vmin == pytest.approx(vc, abs=2.0 * TS)  # reaches the corner speed within a*Ts
    # per-axis velocity change across the corner (pre-filter reference) stays within vd (+ accel over 2 Ts)
    vel = np.diff(k.plan_.position[0], axis=0) / TS
    assert np.abs(np.diff(vel, axis=0)).max() <= vd + 2 * 2.0 * TS


def test_arc_feed_clamped_by_centripetal_acceleration():
    # full circle R = 5 mm at F 10000 mm/min: v <= sqrt(arc_accel R) = sqrt(1 * 0.005) = 0.0707 m/s.
    # Trapezoid from rest to rest: T = 2 pi R / v + v / a.
    R, a_arc, a = 0.005, 1.0, 2.0
    v = math.sqrt(a_arc * R)
    k = plan("G2 I5 F10000\nM30\n", accel_change_time_before_interp=0.0, cutting_time_constant=0.0, arc_accel=a_arc)
    assert k.plan_.feed[0].max() == pytest.approx(v, rel=1e-9)
    assert motion_end(k) == n_ceil(2 * math.pi * R / v + v / a)
    r = np.hypot(k.plan_.position[0, :, 0] - R, k.plan_.position[0, :, 1])
    np.testing.assert_allclose(r, R, atol=1e-12)


def test_lookahead_window_limits_speed_on_short_blocks():
    # 300 collinear 0.01 mm blocks, W blocks of look-ahead, trapezoid: the tool must stop within the W-1 blocks
    # after the executing one, so it runs at the window-limited speed sqrt(2 a (W-1) l) across the blocks
    # (one acc/dec span, .spans); only the last W blocks, whose window reaches the chain end, may rise above it:
    # from sqrt(2 a (W-1) l) to rest within W blocks, peak sqrt(a l (2W - 1)).
    a, l = 2.0, 1e-5
    prog = "G91 G1 F6000\n" + "X0.01\n" * 300 + "M30\n"
    for W in (3, 10):
        k = plan(prog, lookahead_blocks=W, accel_change_time_before_interp=0.0, cutting_time_constant=0.0)
        feed = k.plan_.feed[0]
        cruise = feed[len(feed) // 4: len(feed) // 2]
        np.testing.assert_allclose(cruise, math.sqrt(2 * a * (W - 1) * l), rtol=1e-9)
        assert feed.max() <= math.sqrt(a * l * (2 * W - 1)) * (1 + 1e-9)


# ---------------------------------------------------------------------------- filters
@pytest.mark.parametrize("kind", ["linear", "bell"])
def test_after_interpolation_filter_preserves_end_point_and_delays_by_half_t(kind):
    rng = np.random.default_rng(7)
    inc = np.zeros((400, 3))
    inc[:200] = rng.normal(size=(200, 3)) * 1e-4
    boxes = box_lengths(0.060, kind, TS)
    out = apply_fir(inc, boxes)
    assert sum(boxes) == 60
    np.testing.assert_allclose(out.sum(axis=0), inc.sum(axis=0), rtol=0, atol=1e-15)
    assert np.all(out[260:] == 0.0)  # length + T: nothing after
    # constant-speed input: the output lags by exactly T/2 = 30 samples once settled (centroid of the kernel)
    ramp = np.zeros((300, 1))
    ramp[1:200] = 1.0
    pos_in, pos_out = np.cumsum(ramp, axis=0), np.cumsum(apply_fir(ramp, boxes), axis=0)
    assert pos_in[150, 0] - pos_out[150, 0] == pytest.approx(30.0)


def test_program_end_point_exact_after_arc_with_bell_filter():
    k = plan("G1 X3 Y1 F2000\nG3 X-2 Y4 R5\nM30\n", cutting_filter="bell", cutting_time_constant=0.04)
    end = np.array(k.blocks_[-2].end)
    assert np.abs(k.plan_.position[0, -1] - end).max() <= 1e-12


# ---------------------------------------------------------------------------- spindle, dwell, tool change
def test_spindle_acceleration_time_from_standstill():
    # S3000 M3 from rest: arrival when 3000 - w <= 0.05 * 3000: t = 3000 (1 - 0.05) / 4000 = 0.7125 s
    k = plan("S3000 M3\nG1 X10 F600\nM30\n")
    feed = k.plan_.feed[0]
    first_moving = int(np.argmax(feed > 0))
    assert first_moving - 1 == n_ceil(3000 * (1 - 0.05) / 4000)
    ramp = np.diff(k.plan_.spindle_speed[0, :700])
    np.testing.assert_allclose(ramp, 4000 * 2 * math.pi / 60 * TS, rtol=1e-9)


def test_spindle_speed_change_costs_derived_time():
    # From S2000 (settled) to S5000: wait until |w - 5000| <= 0.05 * 5000 -> (3000 - 250) rpm / 4000 rpm/s
    # = 0.6875 s. S2050 is a change within the arrival tolerance (50 <= 0.05 * 2050): it stops the path but
    # waits 0 s, so the wait alone is duration(S5000) - duration(S2050).
    base = "S2000 M3\nG4 P3000\nG1 X10 F600\nS{}\nG1 X20\nM30\n"
    t_stop = plan(base.format(2050)).duration_[0]
    t_up = plan(base.format(5000)).duration_[0]
    assert t_up - t_stop == pytest.approx((3000 - 0.05 * 5000) / 4000, abs=1.5 * TS)


# Bell-shaped acc/dec (a = 2 m/s2, tc = 32 ms) at 600 mm/min = 0.01 m/s < a tc: a speed change 0 <-> v takes
# t_change = 2 sqrt(v tc / a) and covers v t_change / 2, so a move from rest to rest lasts L/v + t_change
# (test_bell_shaped_move_time). A stop between two collinear lines therefore costs exactly one more t_change.
T_CHANGE_600 = 2.0 * math.sqrt(0.01 * 0.032 / 2.0)  # 25.3 ms


def test_repeated_s_word_does_not_stop_the_path():
    # An S word repeating the speed in effect changes no command: no stop, no wait. The two 10 mm lines are
    # one 20 mm move: motion lasts L/v + t_change + 16 ms (filter), the same as without the S word.
    base = "S2000 M3\nG4 P1000\nG1 X10 F600\n{}G1 X20\nM30\n"
    plain, repeated = plan(base.format("")), plan(base.format("S2000\n"))
    assert repeated.duration_[0] == plain.duration_[0]
    start = int(np.argmax(repeated.plan_.feed[0] > 0)) - 1
    assert motion_end(repeated) - start == n_ceil(0.02 / 0.01 + T_CHANGE_600) + 16
    assert np.all(repeated.plan_.feed[0, start + 100: start + 1900] == pytest.approx(0.01))  # never slows down
    # an S word on the second line itself, and M3 repeated with the same S, change nothing either
    assert plan(base.format("").replace("G1 X20", "G1 X20 S2000")).duration_[0] == plain.duration_[0]
    assert plan(base.format("M3 S2000\n")).duration_[0] == plain.duration_[0]


def test_changed_s_word_stops_the_path_for_one_more_speed_change():
    # S2050 changes the command (within the arrival tolerance, so no wait): the path stops, one more t_change
    base = "S2000 M3\nG4 P1000\nG1 X10 F600\n{}G1 X20\nM30\n"
    t_plain = plan(base.format("")).duration_[0]
    t_changed = plan(base.format("S2050\n")).duration_[0]
    assert t_changed - t_plain == pytest.approx(T_CHANGE_600, abs=1.5 * TS)


def test_repeated_s_word_is_decided_per_batch_member():
    # Spindle overrides of line 4 (the S word): member 0 repeats 2000 rpm, member 1 commands 2050 rpm.
    # Member 0 plans as the program without the S word, member 1 stops for one more t_change.
    text = "S2000 M3\nG4 P1000\nG1 X10 F600\nS2000\nG1 X20\nM30\n"
    k = NCKernel(batch=2, program_text=text)
    k.set_overrides(spindle={4: np.array([2000.0, 2050.0]) * 2 * math.pi / 60})
    k.setup(0.0)
    t_plain = plan(text.replace("S2000\nG1 X20", "G1 X20")).duration_[0]
    assert k.duration_[0] == t_plain
    assert k.duration_[1] - t_plain == pytest.approx(T_CHANGE_600, abs=1.5 * TS)


def test_spindle_clamped_and_stopped_at_program_end():
    k = plan("S12000 M4\nG4 P10\nM30\n")
    ref = k.plan_.spindle_ref[0]
    assert ref.min() == pytest.approx(-8000 * 2 * math.pi / 60)
    assert ref[-1] == 0.0 and k.plan_.spindle_speed[0, -1] == 0.0


def test_dwell_and_tool_change_add_their_time():
    a = plan("G0 X10\nG1 X20 F600\nM30\n").duration_[0]
    b = plan("G0 X10\nG4 P500\nG1 X20 F600\nM30\n").duration_[0]
    c = plan("G0 X10\nT2 M6\nG1 X20 F600\nM30\n", tool_change_time=2.5).duration_[0]
    assert b - a == pytest.approx(0.5, abs=1e-9)
    assert c - a == pytest.approx(2.5, abs=1e-9)


def test_speed_change_law_closed_forms():
    sc = SpeedChange(2.0, 0.032)
    for v, L in [(0.0, 1e-6), (0.0, 1e-3), (0.05, 1e-4), (0.1, 0.05)]:
        w = sc.reach(v, L)
        assert sc.distance(v, w) == pytest.approx(L, rel=1e-12)
    vp = sc.peak(0.0, 0.02, 5e-4, 1.0)
    assert sc.distance(0.0, vp) + sc.distance(0.02, vp) == pytest.approx(5e-4, rel=1e-10)
