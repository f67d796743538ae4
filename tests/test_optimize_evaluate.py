"""evaluate_population: one batched twin call; spindle changes cost their ramp; batch vs single."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.machine import load_machine
from orchestrator.optimize import Ranges, build_reference, evaluate_population
from tests.test_optimize_cases import write_case

RANGES = Ranges((100.0, 600.0), (1000.0, 8000.0))


@pytest.fixture(scope="module")
def spindle_params():
    s = load_machine("default").si("spindle")
    ramp_rpm_per_s = s["ramp"] * 60.0 / (2.0 * np.pi)
    return ramp_rpm_per_s, s["speed_arrival_tolerance"]


def _saving_and_wait(second_mm, f1, f2, s1, s2, ramp, tol):
    """Time saved on line 2 by the higher feed, and the speed-arrival wait of the S change (s)."""
    saving = second_mm / f1 * 60.0 - second_mm / f2 * 60.0
    wait = (abs(s2 - s1) - tol * s2) / ramp
    return saving, wait


@pytest.fixture(scope="module")
def short_ref(tmp_path_factory):
    return build_reference(load_case(write_case(tmp_path_factory.mktemp("short"), 2.0)), ranges=RANGES)


@pytest.mark.parametrize("second_mm, worth_it", [(2.0, False), (10.0, True)])
def test_spindle_change_costs_its_ramp(tmp_path, short_ref, spindle_params, second_mm, worth_it):
    """Doubling S and F on line 2 keeps the chip load but waits for the spindle: pays only on a long line."""
    ramp, tol = spindle_params
    ref = short_ref if second_mm == 2.0 else build_reference(load_case(write_case(tmp_path, second_mm)), ranges=RANGES)
    ctx = ref.context
    feeds = np.array([[250.0, 250.0], [250.0, 500.0]])
    spindles = np.array([[3000.0, 3000.0], [3000.0, 6000.0]])
    ev = evaluate_population(ctx, feeds, spindles)
    saving, wait = _saving_and_wait(second_mm, 250.0, 500.0, 3000.0, 6000.0, ramp, tol)
    delta = ev.cycle_time_s[1] - ev.cycle_time_s[0]
    # The S change also stops the path (member 0's repeated S3000 does not, and it keeps 250 mm/min): bell-shaped
    # acc/dec with v < a tc loses t_change / 2 = sqrt(v tc / a) per change from or to rest (t_change = 2 sqrt(v tc / a),
    # see test_nck_planner), here decelerating from v1 = 250 and accelerating to v2 = 500 mm/min.
    nck = load_machine("default").si("nck")
    a, tc = nck["accel_before_interp"], nck["accel_change_time_before_interp"]
    v1, v2 = 250.0 / 60000.0, 500.0 / 60000.0
    stop = np.sqrt(v1 * tc / a) + np.sqrt(v2 * tc / a)  # 19.7 ms
    # Line 2 ends at the rapid G0 Z1., which waits until the servo's lag e at the stop has decayed into the
    # in-position width w: ln(e / w) / Kv. The lag is at most v / Kv and shrinks with the deceleration, which lasts
    # longer at 500 than at 250 mm/min, so doubling the feed at most doubles it: member 1 waits longer by between
    # 0 and ln(2) / Kv (13.9 ms at Kv = 50/s).
    kv = load_machine("default").si("axis.x")["position_gain"]
    # rounding to the interpolation period at each item boundary: a few ms
    assert wait - saving + stop - 0.006 <= delta <= wait - saving + stop + np.log(2.0) / kv + 0.006
    assert (delta < 0) == worth_it
    # same feed per tooth on line 2: the same load level
    assert ev.line_max_load_N[1, 1] == pytest.approx(ev.line_max_load_N[0, 1], rel=0.1)
    # the higher speed uses more tool life (Taylor, n = 0.15)
    assert ev.tool_life_used[1] > ev.tool_life_used[0]


def test_batch_member_matches_single_run(short_ref):
    """A batch member has the figures of its rewritten program run alone (B = 1)."""
    from orchestrator.optimize.evaluate import figures, run_twin

    ctx = short_ref.context
    feeds = np.array([[300.0, 300.0], [200.0, 400.0], [100.0, 100.0]])
    spindles = np.array([[3000.0, 3000.0], [5000.0, 5000.0], [3000.0, 3000.0]])
    ev = evaluate_population(ctx, feeds, spindles)
    # member 2 needs > 6 mm / (100 mm/min) = 3.6 s of cutting alone: beyond the cut-off of ceil(1.5 x cycle)
    assert ctx.time_limit_s == np.ceil(1.5 * short_ref.evaluation.cycle_time_s[0])
    assert not ev.success[2] and not ev.feasible[2] and "cut-off" in ev.reason[2]
    alone = figures(ctx, run_twin(ctx, None, None, 1, program_text=ctx.program_for(feeds[1], spindles[1])), 1)
    # bit for bit: every member uses its own substeps, and the F/S overrides convert as the interpreter does
    assert ev.cycle_time_s[1] == alone.cycle_time_s[0]
    assert ev.cost_KRW[1] == alone.cost_KRW[0]
    assert ev.max_load_N[1] == alone.max_load_N[0]
    # member 0 has the original values; its S word on line 8 repeats S3000, which changes nothing (no stop)
    assert ev.cycle_time_s[0] == short_ref.evaluation.cycle_time_s[0]
    assert ev.max_load_N[0] == short_ref.evaluation.max_load_N[0]
    assert np.all(ev.success[:2])
    # feasibility is the load limit
    assert list(ev.feasible[:2]) == list(ev.max_load_N[:2] <= ctx.load_limit_N)
    # per-line times add up to less than the cycle (rapids, plunge, ramp wait are not cutting lines)
    assert np.all(ev.line_time_s[:2].sum(axis=1) < ev.cycle_time_s[:2])
    # line time of a constant-feed line: length / feed (+ acc/dec), line 7 is 4 mm
    assert ev.line_time_s[0, 0] == pytest.approx(4.0 / 300.0 * 60.0, abs=0.05)


def test_cost_matches_eq_19_to_22(short_ref):
    """Cp from the twin = Tp (Ep + Cd) + Miner's sum (Pt + Tc (Ep + Cd)); check against a hand integration."""
    from orchestrator.cost import CostModel

    ref = short_ref
    model = CostModel.from_machine(ref.context.case.machine)
    rec = ref.recording
    t, rpm = np.asarray(rec.t), np.asarray(rec["spindle_rpm"]).ravel()
    tp = ref.evaluation.cycle_time_s[0]
    n = np.searchsorted(t, tp + 1e-12)
    v = np.pi * 6.0 * rpm[:n] / 1000.0  # m/min
    rate = (v / model.taylor_C) ** (1.0 / model.taylor_n) / 60.0  # 1 / Tl, Tl = (C / V)^(1/n) min
    used = np.sum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t[:n]))
    rate_krw = model.labor_KRW_per_s + model.depreciation_KRW_per_s
    expected = tp * rate_krw + used * (model.tool_price_KRW + model.tool_change_time_s * rate_krw)
    assert ref.evaluation.cost_KRW[0] == pytest.approx(expected, rel=1e-9)


def test_population_split_by_memory_budget_changes_no_figure(short_ref, monkeypatch):
    """A population larger than one run's memory budget runs in several batched runs with the same figures."""
    from orchestrator.optimize import evaluate as evaluate_module

    ctx = short_ref.context
    feeds = np.array([[300.0, 300.0], [200.0, 400.0], [250.0, 350.0]])
    spindles = np.array([[3000.0, 3000.0], [5000.0, 5000.0], [4000.0, 6000.0]])
    whole = evaluate_population(ctx, feeds, spindles)
    steps = ctx.time_limit_s / ctx.step
    per_member = 8 * 7 * (steps + 2)  # 4 recorded channels per step + 3 plan positions per 1 ms period
    assert evaluate_module.members_per_run(ctx, int(2.5 * per_member)) == 2
    monkeypatch.setattr(evaluate_module, "EVAL_MEMORY_BYTES", int(1.5 * per_member))  # one member per run
    runs = []
    real_run = evaluate_module.run_twin
    monkeypatch.setattr(evaluate_module, "run_twin", lambda *a, **k: runs.append(a[3]) or real_run(*a, **k))
    split = evaluate_population(ctx, feeds, spindles)
    assert runs == [1, 1, 1]
    for name in ("cycle_time_s", "cost_KRW", "max_load_N", "tool_life_used", "line_time_s", "line_max_load_N",
                 "success", "feasible"):
        np.testing.assert_array_equal(getattr(split, name), getattr(whole, name), err_msg=name)
    assert split.reason == whole.reason
    assert list(split.tool_use) == list(whole.tool_use) and set(whole.tool_use[0]) == {0}  # no M6: tool 0 throughout


def test_per_line_time_and_load_from_hand_samples():
    """Line times are the sums of the samples' weights, loads their maxima; other lines are ignored."""
    from orchestrator.optimize.evaluate import per_line

    lines = np.array([12, 7, 30])                       # cutting lines, in the problem's order
    executing = np.array([5, 7, 7, 12, 12, 12, 7, np.nan, 40, 12, 0])
    weight = np.array([1.0, 2.0, 3.0, 0.5, 0.5, 0.5, 4.0, 9.0, 9.0, 0.25, 1.0])
    load = np.array([99.0, 10.0, 11.0, 20.0, 25.0, 21.0, 12.0, 99.0, 99.0, 30.0, 99.0])
    time_s, max_load = per_line(lines, executing, weight, load)
    np.testing.assert_array_equal(time_s, [1.75, 9.0, 0.0])   # line 12: 0.5 * 3 + 0.25; line 7: 2 + 3 + 4
    np.testing.assert_array_equal(max_load, [30.0, 12.0, 0.0])  # line 30 never ran: 0 N
    _, with_nan = per_line(lines, executing, weight, np.where(np.arange(11) == 4, np.nan, load))
    assert np.isnan(with_nan[0]) and with_nan[1] == 12.0
