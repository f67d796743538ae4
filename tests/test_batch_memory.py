"""Ragged batch plans: memory grows with the sum of the members' lengths, and every member reads as alone.

The reference of each check is the member planned or run on its own (B = 1), an independent computation of
the same numbers; nothing here is the batch code's own output pasted back.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fmus_src.nck import NCKernel
from orchestrator.case import load_case
from orchestrator.optimize import Ranges, build_reference, evaluate_population
from orchestrator.optimize.evaluate import figures, run_twin
from tests.test_optimize_cases import write_case

PROG = """%
O2001 (two slots)
G90 G17 G21 G54
T1 M6
S3000 M3
G0 X0 Y0 Z5
G1 Z-1 F150
X30 F300
G0 Z5
S5000
G0 X0 Y10
G1 Z-1 F150
X30 F300
G0 Z50
M30
%
"""
RPM = 2 * math.pi / 60
MM_PER_MIN = 1e-3 / 60
# feed of line 8 per member (modal to line 13, where it is rewritten), mm/min: members 1 and 3 are alike,
# member 2 runs the slots at a quarter of member 0's feed (about three times as long in all)
FEEDS = np.array([300.0, 900.0, 75.0, 900.0])
SPEEDS = np.array([5000.0, 8000.0, 1000.0, 8000.0])  # rpm of line 10


def _kernel(feed: np.ndarray, speed: np.ndarray) -> NCKernel:
    k = NCKernel(batch=len(feed), program_text=PROG)
    k.set_overrides(feed={8: feed * MM_PER_MIN, 13: feed * MM_PER_MIN}, spindle={10: speed * RPM})
    k.setup(0.0)
    return k


@pytest.fixture(scope="module")
def kernels():
    batch = _kernel(FEEDS, SPEEDS)
    alone = [_kernel(FEEDS[b:b + 1], SPEEDS[b:b + 1]) for b in range(len(FEEDS))]
    return batch, alone


def test_plan_stores_the_sum_of_distinct_member_lengths(kernels):
    """Stored samples = sum(K_b + 1) over distinct members (one sentinel each), far below B x the longest."""
    batch, alone = kernels
    lengths = [k.plan_.member(0).feed.shape[0] for k in alone]
    assert lengths[1] == lengths[3] and max(lengths) > 2 * min(lengths)
    distinct = lengths[:3]  # member 3 repeats member 1 and shares its samples
    plan = batch.plan_
    assert plan.stored_samples == sum(n + 1 for n in distinct)
    assert plan.stored_samples < 0.6 * len(FEEDS) * max(lengths)
    assert plan.offset[3] == plan.offset[1]
    assert plan.length.tolist() == lengths
    assert plan.n_samples == max(lengths)


def test_members_equal_their_plans_alone_and_pad_like_before(kernels):
    """member(b) is the member planned alone, bit for bit; the padded views hold values (feed 0) past its end."""
    batch, alone = kernels
    plan = batch.plan_
    K = plan.n_samples
    padded = {name: getattr(plan, name) for name in ("position", "feed", "spindle_ref", "spindle_speed", "line",
                                                      "tool")}
    for b, single in enumerate(alone):
        own = single.plan_.member(0)
        got = plan.member(b)
        n = own.feed.shape[0]
        for name in ("position", "feed", "spindle_ref", "spindle_speed", "line", "tool"):
            np.testing.assert_array_equal(getattr(got, name), getattr(own, name), err_msg=name)
            assert padded[name].shape[:2] == (len(FEEDS), K)
            np.testing.assert_array_equal(padded[name][b, :n], getattr(own, name), err_msg=name)
            after = np.zeros_like(getattr(own, name)[-1]) if name == "feed" else getattr(own, name)[-1]
            assert np.all(padded[name][b, n:] == after), name
        assert got.done_index == own.done_index == plan.done_index[b]
    # the longest member's padded rows are its own samples
    assert plan.length[2] == K


def _expected(own, kf: float, K: int) -> dict[str, float]:
    """Outputs at fractional sample ``kf`` from a member's dense samples padded to K (the padded plan's reading)."""
    n = own.feed.shape[0]

    def at(a: np.ndarray, k: int, after: float | None = None):
        return a[k] if k < n else (a[-1] if after is None else after)

    kf = min(max(kf, 0.0), K - 1.0)
    k0 = int(math.floor(kf + 1e-9))
    frac = kf - k0 if kf - k0 >= 1e-9 else 0.0
    k1 = min(k0 + 1, K - 1)
    out = {"x_ref": own.position[min(k0, n - 1), 0], "y_ref": own.position[min(k0, n - 1), 1],
           "z_ref": own.position[min(k0, n - 1), 2], "feed_ref": at(own.feed, k0, 0.0),
           "spindle_speed": at(own.spindle_speed, k0)}
    if frac > 0.0:
        for i, name in enumerate(("x_ref", "y_ref", "z_ref")):
            out[name] = out[name] + frac * (own.position[min(k1, n - 1), i] - out[name])
        out["feed_ref"] = out["feed_ref"] + frac * (at(own.feed, k1, 0.0) - out["feed_ref"])
        out["spindle_speed"] = out["spindle_speed"] + frac * (at(own.spindle_speed, k1) - out["spindle_speed"])
    out.update(spindle_ref=at(own.spindle_ref, k0), line=at(own.line, k0), tool=at(own.tool, k0),
               done=k0 >= own.done_index)
    return out


def test_kernel_outputs_equal_each_member_alone_past_every_end(kernels):
    """Stepping off the interpolation grid (h = 0.7 Ts) past the longest end: outputs equal the members alone
    and the linear interpolation of each member's own samples, held (feed 0) after its end."""
    batch, alone = kernels
    plan = batch.plan_
    own = [single.plan_.member(0) for single in alone]
    h = 0.7e-3
    n = int(math.ceil(batch.duration_.max() / h)) + 5
    names = ("x_ref", "y_ref", "z_ref", "feed_ref", "spindle_ref", "spindle_speed", "line", "tool", "done")
    checked_past_end = np.zeros(len(alone), dtype=bool)
    ramps = 0
    for i in range(0, n, 7):  # every 7th step (steps are independent reads of the plan)
        t = i * h
        batch.do_step(t, h)
        kf = (t + h) / plan.period
        for b, single in enumerate(alone):
            single.do_step(t, h)
            want = _expected(own[b], kf, plan.n_samples)
            for name in names:
                a, s = batch.values[name][b:b + 1], single.values[name][:1]
                assert a.tobytes() == s.tobytes(), (name, b, t, a, s)  # bit for bit (-0.0 too)
                assert a[0] == want[name], (name, b, t, a, want[name])
            checked_past_end[b] |= t + h > single.plan_.length[0] * single.plan_.period
            k = int(kf)
            ramps += k + 1 < own[b].feed.shape[0] and own[b].spindle_speed[k] != own[b].spindle_speed[k + 1]
    assert checked_past_end[[0, 1, 3]].all()  # the shorter members were read past their last sample
    assert ramps > 10  # reads between two different spindle speeds (interpolated) were among them


@pytest.fixture(scope="module")
def long_ctx(tmp_path_factory):
    ref = build_reference(load_case(write_case(tmp_path_factory.mktemp("ragged"), 6.0)),
                          ranges=Ranges((100.0, 600.0), (1000.0, 8000.0)))
    # a cut-off long enough for a member at a sixth of the fastest feed
    return dataclasses.replace(ref.context, time_limit_s=8.0 * ref.evaluation.cycle_time_s[0])


def test_batched_evaluation_equals_each_member_alone_with_very_different_lengths(long_ctx):
    """Figures of a batch whose members run from 1x to about 3x the shortest one's time equal each run alone."""
    ctx = long_ctx
    feeds = np.array([[600.0, 600.0], [100.0, 100.0], [300.0, 150.0], [600.0, 600.0]])
    spindles = np.array([[6000.0, 6000.0], [2000.0, 2000.0], [4000.0, 3000.0], [6000.0, 6000.0]])
    ev = evaluate_population(ctx, feeds, spindles, threads=2)  # two blocks of members share the ragged plan
    assert ev.success.all()
    assert ev.cycle_time_s[1] > 2.0 * ev.cycle_time_s[0]
    for b in range(3):
        run = run_twin(ctx, None, None, 1, program_text=ctx.program_for(feeds[b], spindles[b]))
        alone = figures(ctx, run, 1)
        for name in ("cycle_time_s", "cost_KRW", "max_load_N", "tool_life_used", "line_time_s", "line_max_load_N"):
            np.testing.assert_array_equal(getattr(ev, name)[b], getattr(alone, name)[0], err_msg=f"{name}[{b}]")
    for name in ("cycle_time_s", "cost_KRW", "max_load_N", "line_time_s"):
        np.testing.assert_array_equal(getattr(ev, name)[3], getattr(ev, name)[0])
