"""Window-limited speed: a run of blocks too short for the look-ahead window runs at one ceiling (fmus_src.nck.spans).

Default machine (NCParams defaults = models/machines/default.toml): bell-shaped acc/dec before interpolation
a = 2 m/s2, tc = 32 ms (a tc = 0.064 m/s), window W = 40 blocks, linear filter after interpolation T = 16 ms,
Ts = 1 ms. At the end of block k the tool must be able to stop within the blocks read beyond it,
D = (W - 1) l for equal blocks of length l. The window-limited speed v_w is the largest speed whose stop
distance fits in D:

* v_w >= a tc: the stop takes v/a + tc and covers v/2 (v/a + tc) = D, so v_w = (sqrt((a tc)^2 + 8 a D) - a tc) / 2;
* v_w <  a tc: the stop takes 2 sqrt(v tc / a) and covers v^(3/2) sqrt(tc / a) = D, so v_w = (D^2 a / tc)^(1/3).

A path of length L at cruise speed v from rest to rest takes L/v + t(v) (t: duration of one speed change, the
ramps covering v t(v) together), plus T for the filter.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.nck import NCKernel
from fmus_src.nck.interpreter import interpret
from fmus_src.nck.lookahead import block_windows, plan_chain_speeds
from fmus_src.nck.planner import build_schedule, plan_batch
from fmus_src.nck.profiles import SpeedChange
from fmus_src.nck.settings import MM
from orchestrator.bench.planning import PLAN_FIELDS, same_plan

A, TC, W, T, TS = 2.0, 0.032, 40, 0.016, 1e-3
MM_MIN = MM / 60.0


def _v_w(distance: float) -> float:
    """Window-limited speed (m/s) of bell-shaped acc/dec for a remaining window ``distance`` (m), closed form."""
    v = 0.5 * (math.sqrt((A * TC) ** 2 + 8.0 * A * distance) - A * TC)
    return v if v >= A * TC else (distance * distance * A / TC) ** (1.0 / 3.0)


def _ramp(v: float) -> float:
    """Duration (s) of a bell-shaped speed change 0 <-> v."""
    return v / A + TC if v >= A * TC else 2.0 * math.sqrt(v * TC / A)


def _segments(step_mm: float, length_mm: float, feed: float, head: str = "") -> str:
    n = int(round(length_mm / step_mm))
    return (f"G90 G0 X0 Y0\n{head}G1 F{feed:g}\n" + "".join(f"X{step_mm * k:.3f}\n" for k in range(1, n + 1))
            + "M30\n")


def _kernel(text: str, **params) -> NCKernel:
    kernel = NCKernel(program_text=text, **params)
    kernel.setup(0.0)
    return kernel


def _motion_end(kernel: NCKernel) -> int:
    """Sample index from which the reference no longer changes."""
    moving = np.nonzero(np.any(np.diff(kernel.plan_.position[0], axis=0) != 0.0, axis=1))[0]
    return int(moving[-1]) + 1


def _samples(seconds: float) -> int:
    return math.ceil(seconds / TS - 1e-9)


def _chain_speeds(text: str):
    """Planned speeds of the single feed chain of a program with the default machine."""
    program = interpret(text, "window.nc")
    chains = [it for it in build_schedule(program.blocks, program.initial).items if it.kind == "chain"]
    assert len(chains) == 1
    blocks = [program.blocks[i] for i in chains[0].blocks]
    windows = block_windows([b.lookahead_limit for b in blocks], W)
    return plan_chain_speeds(chains[0].geometry, np.array([b.feed for b in blocks]), SpeedChange(A, TC),
                             max_cutting_feed=10000 * MM_MIN, arc_accel=1.0,
                             corner_velocity_difference=400 * MM_MIN, lookahead_blocks=windows)


def test_window_limited_speed_is_the_stop_within_the_window():
    # 0.1 mm blocks: D = 39 x 0.1 mm = 3.9 mm; v_w = (sqrt(0.064^2 + 16 x 0.0039) - 0.064) / 2 = 0.0969341 m/s
    # (5816 mm/min, above a tc: the first law). The acc/dec law's own stop distance and reach agree.
    v = _v_w(3.9e-3)
    assert v == pytest.approx(0.0969341, rel=1e-6) and v > A * TC
    sc = SpeedChange(A, TC)
    assert sc.distance(v, 0.0) == pytest.approx(3.9e-3, rel=1e-12)
    assert sc.reach(0.0, 3.9e-3) == pytest.approx(v, rel=1e-12)
    # G103 P5: window 6, D = 0.5 mm; the stop from a tc would take 2.05 mm, so the second law: 0.025 m/s
    assert _v_w(0.5e-3) == pytest.approx(0.025, rel=1e-12)
    assert sc.reach(0.0, 0.5e-3) == pytest.approx(0.025, rel=1e-12)


@pytest.mark.parametrize("v0, v1", [(0.0, 0.01), (0.02, 0.05), (0.0, 0.0969), (0.05, 0.1)])
def test_earliest_distance_is_the_fastest_ramp(v0, v1):
    # jerk a/tc up to a, then constant a: v = v0 + j t^2 / 2 (t <= tc), s = v0 t + j t^3 / 6; beyond tc the
    # speed grows at a from v0 + a tc / 2. Integrated here at 1 us; trapezoid: (v1^2 - v0^2) / (2 a)
    sc = SpeedChange(A, TC)
    dt, t, v, s_num = 1e-6, 0.0, v0, 0.0
    while v < v1:
        acc = min(A / TC * (t + 0.5 * dt), A)
        s_num += (v + 0.5 * acc * dt) * dt
        v += acc * dt
        t += dt
    assert sc.earliest_distance(v0, v1) == pytest.approx(s_num, rel=1e-3)
    assert SpeedChange(A, 0.0).earliest_distance(v0, v1) == pytest.approx((v1 ** 2 - v0 ** 2) / (2 * A), rel=1e-12)
    assert sc.earliest_distance(v1, v0) == 0.0
    # no bell ramp of the law from v0 gets to v1 in less: a full change to v1 covers at least this distance
    assert sc.distance(v0, v1) >= sc.earliest_distance(v0, v1)


def test_short_blocks_at_high_feed_run_at_the_window_limited_speed():
    # 50 mm of 0.1 mm blocks at F6000 (0.1 m/s > v_w): one span at v_w instead of a ramp block by block.
    # T = L / v_w + t(v_w) + 16 ms = 0.51582 + 0.08047 + 0.016 = 0.612 s (block by block it was 1.260 s).
    # The last 40 blocks see the chain end in their window and may run a little above v_w before the stop,
    # which can only shorten the time; 1 sample of rounding either way.
    v = _v_w(3.9e-3)
    kernel = _kernel(_segments(0.1, 50.0, 6000))
    expected = _samples(0.05 / v + _ramp(v)) + _samples(T)
    assert abs(_motion_end(kernel) - expected) <= 1
    assert _motion_end(kernel) <= 615
    feed = kernel.plan_.feed[0]
    np.testing.assert_allclose(feed[150:450], v, rtol=1e-9)  # cruise: 0.1 s after the ramp, 0.1 s before the stop
    assert feed.max() <= 0.1
    sp = _chain_speeds(_segments(0.1, 50.0, 6000))
    n, starts = len(sp.vmax), sp.span_start.tolist()
    # spans: the ramp from rest runs in one span across the first 39 blocks at least (block 0 starts at rest and
    # cannot exceed v_w in 0.1 mm: it joins); every span up to block n - 41 is capped at v_w (the window
    # lengths differ only by rounding, and a span may end where its cap is lowest at no cost, .spans); the last
    # 40 blocks, whose window reaches the chain end, form one span at F
    assert starts[1] >= 39 and starts[-2:] == [n - W, n]
    np.testing.assert_allclose(sp.ceiling[:-1], v, rtol=1e-12)
    assert sp.ceiling[-1] == 0.1
    assert sp.junction[n - W] == pytest.approx(v, rel=1e-9)


@pytest.mark.parametrize("step_mm", [1.0, 0.5])
def test_blocks_long_enough_for_the_window_are_not_window_limited(step_mm):
    # 0.5 mm blocks: D = 19.5 mm, more than the stop from F6000, v/2 (v/a + tc) = 0.05 (0.05 + 0.032) = 4.1 mm:
    # one span at F, the time of a single 50 mm block, L/F + F/a + tc + T = 0.5 + 0.05 + 0.032 + 0.016 s
    kernel = _kernel(_segments(step_mm, 50.0, 6000))
    assert abs(_motion_end(kernel) - (_samples(0.5 + 0.05 + TC) + _samples(T))) <= 1
    assert kernel.plan_.feed[0].max() == pytest.approx(0.1, rel=1e-12)
    sp = _chain_speeds(_segments(step_mm, 50.0, 6000))
    assert sp.span_start.tolist() == [0, len(sp.vmax)] and sp.ceiling.tolist() == [0.1]


def test_g103_p5_lowers_the_window_limited_speed():
    # G103 P5: window min(40, 5 + 1) = 6 blocks, D = 5 x 0.1 mm = 0.5 mm, v_w = (D^2 a / tc)^(1/3) = 0.025 m/s;
    # T = L / v_w + 2 sqrt(v_w tc / a) + 16 ms = 2.0 + 0.04 + 0.016 s (block by block it was 2.102 s)
    v = _v_w(0.5e-3)
    kernel = _kernel(_segments(0.1, 50.0, 6000, head="G103 P5\n"))
    expected = _samples(0.05 / v + _ramp(v)) + _samples(T)
    assert abs(_motion_end(kernel) - expected) <= 1
    np.testing.assert_allclose(kernel.plan_.feed[0][500:1500], v, rtol=1e-9)


def test_a_long_block_before_short_ones_keeps_its_feed():
    # 20 mm in one block, then 20 mm of 0.1 mm blocks, at F6000: the long block runs at F and slows to v_w
    # within itself (it could exceed v_w, so it does not join the short blocks' span); they run at v_w
    text = "G90 G0 X0 Y0\nG1 X20. F6000\n" + "".join(f"X{20 + 0.1 * k:.1f}\n" for k in range(1, 201)) + "M30\n"
    kernel = _kernel(text, cutting_time_constant=0.0)
    pos, feed = kernel.plan_.position[0], kernel.plan_.feed[0]
    assert feed.max() == pytest.approx(0.1, rel=1e-12)
    short = (pos[:, 0] > 0.0205) & (pos[:, 0] < 0.035)
    np.testing.assert_allclose(feed[short], _v_w(3.9e-3), rtol=1e-9)


def test_a_cluster_of_tinier_blocks_slows_only_its_neighbourhood():
    # 25 mm of 0.1 mm blocks, 20 blocks of 0.02 mm, 25 mm of 0.1 mm, at F6000. Junctions whose window holds the
    # cluster have lower caps, down to D = 20 x 0.02 + 19 x 0.1 = 2.3 mm (v = 0.0705 m/s) at the junction before
    # it. The span is split at that lowest cap, where the path slows down to it and speeds up again, so the
    # runs away from the cluster keep v_w (not the cluster's speed all along), and no junction exceeds its cap.
    lengths = [0.1] * 250 + [0.02] * 20 + [0.1] * 250
    xs = np.cumsum(lengths)
    text = "G90 G0 X0 Y0\nG1 F6000\n" + "".join(f"X{x:.2f}\n" for x in xs) + "M30\n"
    kernel = _kernel(text, cutting_time_constant=0.0)
    pos, feed = kernel.plan_.position[0], kernel.plan_.feed[0]
    v = _v_w(3.9e-3)
    np.testing.assert_allclose(feed[(pos[:, 0] > 0.005) & (pos[:, 0] < 0.015)], v, rtol=1e-9)
    np.testing.assert_allclose(feed[(pos[:, 0] > 0.035) & (pos[:, 0] < 0.045)], v, rtol=1e-9)
    at_cluster = int(np.argmin(np.abs(pos[:, 0] - 0.025)))
    assert feed[at_cluster] <= _v_w(0.4e-3 + 1.9e-3) * (1 + 1e-9)
    sp = _chain_speeds(text)
    caps = np.array([SpeedChange(A, TC).reach(0.0, float(sp_d)) for sp_d in
                     np.convolve(np.array(lengths) * MM, np.ones(W - 1), "valid")[1:]])
    assert np.all(sp.junction[1:len(caps) + 1] <= caps * (1 + 1e-9))


def test_corner_between_window_limited_runs():
    # 25 mm of 0.1 mm blocks along X, then along Y, at F6000: v_w on both runs after the 3.9 mm ramp from rest
    # (the ramp to v_w covers the stop distance D by definition); the 90 deg corner is passed at the allowable
    # velocity difference (400 mm/min). The blocks less than a window before the corner keep their junction
    # caps (the stop within their window passes the corner), so the slow-down starts some 8 mm before it.
    text = ("G90 G0 X0 Y0\nG1 F6000\n" + "".join(f"X{0.1 * k:.1f}\n" for k in range(1, 251))
            + "".join(f"Y{0.1 * k:.1f}\n" for k in range(1, 251)) + "M30\n")
    kernel = _kernel(text, cutting_time_constant=0.0)
    pos, feed = kernel.plan_.position[0], kernel.plan_.feed[0]
    at_corner = int(np.argmin(np.hypot(pos[:, 0] - 0.025, pos[:, 1])))
    assert feed[at_corner] == pytest.approx(400 * MM_MIN, rel=0.05)
    along_x = pos[:, 1] == 0.0
    assert feed[along_x].max() <= _v_w(3.9e-3) * (1 + 1e-12)
    np.testing.assert_allclose(feed[(pos[:, 0] > 0.0045) & (pos[:, 0] < 0.015)], _v_w(3.9e-3), rtol=1e-9)


def _assert_same(a, b) -> None:
    """Every array of two batch plans holds the same bits."""
    for name in PLAN_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name
    assert same_plan(a, b)


@pytest.mark.parametrize("text", [
    _segments(0.1, 50.0, 6000),
    _segments(0.1, 50.0, 6000, head="G103 P5\n"),
    "G90 G0 X0 Y0\nG1 X20. F6000\n" + "".join(f"X{20 + 0.1 * k:.1f}\n" for k in range(1, 201))
    + "".join(f"Y{0.07 * k * (1 + (k % 3)) / 2:.3f}\n" for k in range(1, 151)) + "M30\n",
    "G90 G0 X0 Y0\nG1 F6000\n" + "".join(f"X{x:.2f}\n" for x in np.cumsum([0.1] * 150 + [0.02] * 20 + [0.1] * 150))
    + "M30\n",
])
def test_compiled_planning_equals_the_reference_bit_for_bit(text):
    kernel = NCKernel(program_text=text, batch=4)
    kernel.set_overrides(feed={2: np.array([3000.0, 6000.0, 9000.0, 10000.0]) * MM_MIN})
    args = kernel.planning_inputs()
    _assert_same(plan_batch(*args), plan_batch(*args, reference=True))
