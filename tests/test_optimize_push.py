"""Onto the load limit: the post-pass raising the search's best feeds (:mod:`orchestrator.optimize.push`).

The rounds are checked on analytic evaluators (no twin): line i of length ``length_i`` mm takes
``60 length_i / F_i`` s, the cycle time is their sum rounded up to the 1 ms step, and its load is
``k_i (F_i / S_i) ** p`` N within 60 N (p = 1: Eq. 10–13 are linear in the feed per tooth; p = 1.1: a load
that grows faster, so the chip-load rule overshoots and the pass must bisect). Every expected feed follows
from these numbers. The twin test pushes a full slot at half the limit; its expected feed is the hand value of
Eq. 10–13, Kt a fz sqrt(1 + Ke^2) (A6061: Kt = 1.23e9 N/m^2, Ke = 0.5).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from orchestrator.optimize import OptimizeSettings, optimize
from orchestrator.optimize.context import ProblemContext, Ranges
from orchestrator.optimize.evaluate import Evaluation
from orchestrator.optimize.push import feed_in_effect, push_genes

LIMIT_N = 60.0


def _context(L: int, per_rev: frozenset[int] = frozenset()) -> ProblemContext:
    """Cutting lines 10, 11, ... at 300 mm/min, 6000 rpm (the reference is not used by the pass)."""
    return ProblemContext(None, "", np.arange(10, 10 + L), np.arange(10, 10 + L), {}, np.full(L, 300.0),
                          np.full(L, 6000.0), Ranges(), LIMIT_N, original_load_N=np.full(L, 30.0),
                          per_rev_lines=per_rev)


class Analytic:
    """Evaluator of the model in the module docstring, on the feed in effect; counts the members it evaluates."""

    def __init__(self, ctx: ProblemContext, k: list[float], length_mm: list[float], p: float = 1.0,
                 floor_N: list[float] | None = None) -> None:
        self.ctx, self.k, self.length, self.p = ctx, np.asarray(k, float), np.asarray(length_mm, float), p
        self.floor = np.zeros(len(k)) if floor_N is None else np.asarray(floor_N, float)
        self.members = 0

    def __call__(self, feeds: np.ndarray, spindles: np.ndarray) -> Evaluation:
        F, S = np.atleast_2d(feeds), np.atleast_2d(spindles)
        B, L = F.shape
        self.members += B
        eff = np.array([[feed_in_effect(self.ctx, i, F[b, i], S[b, i]) for i in range(L)] for b in range(B)])
        line_t = 60.0 * self.length / eff
        t = np.ceil(line_t.sum(axis=1) * 1000.0 - 1e-9) / 1000.0
        line_load = np.maximum(self.k * (eff / S) ** self.p, self.floor)
        load = line_load.max(axis=1)
        ok = load <= LIMIT_N
        return Evaluation(t, t.copy(), load, np.zeros(B), line_t, line_load, np.ones(B, bool), ok,
                          ["" if o else "over the load limit" for o in ok])


def _time(ev: Evaluation) -> np.ndarray:
    return ev.cycle_time_s


def test_a_line_at_half_the_limit_lands_on_it_and_a_line_at_the_top_of_the_range_stays():
    """k = 1000 N per mm/tooth-ish at 6000 rpm: F180 loads 30 N (half the limit), the chip-load rule gives
    180 * 60 / 30 = 360 mm/min (60.0 N, not above). F500 is the top of the range (50 N with k = 600): unchanged.
    F350 with k = 1020 loads 59.5 N: the rule gives 352.9, rounded down 350: unchanged."""
    ctx = _context(3)
    ev = Analytic(ctx, [1000.0, 600.0, 1020.0], [20.0, 20.0, 20.0])
    r = push_genes(ctx, ev, _time, np.array([180.0, 500.0, 350.0]), np.full(3, 6000.0))
    assert r.feeds.tolist() == [360.0, 500.0, 350.0]
    assert r.spindles.tolist() == [6000.0] * 3
    assert r.objective_before == pytest.approx(math.ceil(60e3 * (20 / 180 + 20 / 500 + 20 / 350)) / 1e3)
    assert r.objective_after == pytest.approx(math.ceil(60e3 * (20 / 360 + 20 / 500 + 20 / 350)) / 1e3)
    assert [(m["line"], m["feed_before_mm_per_min"], m["feed_after_mm_per_min"]) for m in r.moves] == [
        (10, 180.0, 360.0)]
    assert r.moves[0]["load_before_N"] == pytest.approx(30.0) and r.moves[0]["load_after_N"] == pytest.approx(60.0)


def test_a_load_growing_faster_than_the_feed_is_bisected_to_the_last_grid_feed_within_the_limit():
    """p = 1.1, F200 at 30 N: the largest feed within 60 N is 200 * 2 ** (1 / 1.1) = 375.6 mm/min, so 370 on the
    10 mm/min grid (59.5 N; 380 would load 61.2 N). The rule's 400 overloads, the bisection gets there."""
    ctx = _context(1)
    k = 30.0 / (200.0 / 6000.0) ** 1.1
    ev = Analytic(ctx, [k], [20.0], p=1.1)
    r = push_genes(ctx, ev, _time, np.array([200.0]), np.array([6000.0]))
    assert r.feeds.tolist() == [370.0]
    assert k * (370.0 / 6000.0) ** 1.1 <= LIMIT_N < k * (380.0 / 6000.0) ** 1.1
    assert r.objective_after == pytest.approx(math.ceil(60e3 * 20 / 370) / 1e3)
    assert r.rounds <= 4 and ev.members <= 1 + 4 * 9


def test_several_lines_are_raised_together_and_the_evaluations_stay_bounded():
    """Four lines at 20, 25, 30 and 40 N (F100, S6000; k = load * 60): the rule puts each at 60 N: F300, 240,
    200, 150. All four go in one round (the all-lines member is feasible and fastest)."""
    loads = [20.0, 25.0, 30.0, 40.0]
    ctx = _context(4)
    ev = Analytic(ctx, [x * 60.0 for x in loads], [10.0] * 4)
    r = push_genes(ctx, ev, _time, np.full(4, 100.0), np.full(4, 6000.0), max_candidates=8)
    assert r.feeds.tolist() == [300.0, 240.0, 200.0, 150.0]
    assert ev.members <= 1 + 4 * (8 + 1)


def test_a_line_whose_load_does_not_follow_its_feed_goes_to_the_top_of_the_range():
    """The line's largest load is 57 N whatever its feed (set by the line before it; its own chip loads
    20 N at F300): the rule asks 300 * 60 / 57 = 315.8 -> 310, the load stays 57 N, and the secant through
    (300, 57) and (310, 57) then sends it to the top, F500 (own chip 33.3 N)."""
    ctx = _context(1)
    ev = Analytic(ctx, [20.0 * 6000.0 / 300.0], [20.0], floor_N=[57.0])
    r = push_genes(ctx, ev, _time, np.array([300.0]), np.array([6000.0]))
    assert [m["feed_after_mm_per_min"] for m in r.moves] == [310.0, 500.0]
    assert r.feeds.tolist() == [500.0] and r.rounds == 2


def test_the_pass_never_worsens_the_objective_and_leaves_an_infeasible_start_alone():
    """An objective that prefers slow lines (minus the cycle time): no raise is kept. A start over the limit
    (F500 at k = 1000: 83.3 N) is not touched."""
    ctx = _context(2)
    ev = Analytic(ctx, [1000.0, 1000.0], [20.0, 20.0])
    slow = push_genes(ctx, ev, lambda e: -e.cycle_time_s, np.array([180.0, 200.0]), np.full(2, 6000.0))
    assert slow.feeds.tolist() == [180.0, 200.0] and slow.moves == []
    assert slow.objective_after == slow.objective_before
    over = push_genes(ctx, ev, _time, np.array([500.0, 200.0]), np.full(2, 6000.0))
    assert over.feeds.tolist() == [500.0, 200.0] and over.rounds == 0


def test_a_g95_line_gets_the_largest_gene_whose_written_word_stays_within_the_limit():
    """G95 at 7000 rpm, load 980 N per mm/rev: the limit is 0.0612 mm/rev, so the word 0.061 (427 mm/min,
    59.78 N; 0.062 loads 60.76 N). Gene 210 writes 0.030 (29.4 N); the rule's 428.6 mm/min is reached by the
    gene 430 (430 / 7000 = 0.06143 -> 0.061), not only by 420 (0.060) as rounding the gene down would give."""
    ctx = _context(1, per_rev=frozenset({10}))
    ev = Analytic(ctx, [980.0], [20.0])
    r = push_genes(ctx, ev, _time, np.array([210.0]), np.array([7000.0]))
    assert r.feeds.tolist() == [430.0]
    assert ctx.feed_per_rev_word(10, 430.0, 7000.0) == pytest.approx(0.061)
    assert r.moves[-1]["load_after_N"] == pytest.approx(980.0 * 0.061)


#: One 1 mm deep full slot through the 4 x 6 mm block of the helper case, line 5, at F170 and S4000.
HALF_SLOT = """%
G21 G17 G90 G94 G54
S4000 M3
G0 X-3.5 Y3. Z1.
G1 Z-1. F600
X7.5 F170
G0 Z1.
M30
%
"""
#: Hand load of the slot per mm/min at S4000, 2 flutes: Kt a sqrt(1 + Ke^2) / (2 S) = 0.1719 N per mm/min.
N_PER_MM_MIN = 1.23e9 * 1e-3 * math.sqrt(1.25) * 1e-3 / (2 * 4000.0)


def test_a_slot_on_the_twin_at_half_the_limit_is_pushed_within_one_grid_step_of_it(tmp_path):
    """F170 loads 170 * 0.1719 = 29.2 N; the largest grid feed within 60 N is 340 (58.4 N; 350: 60.2 N)."""
    from orchestrator.optimize.backends import CachedEvaluator, SerialBackend
    from orchestrator.optimize.reference import build_reference
    from orchestrator.simulate import resolve_case
    from tests.test_optimize_cases import CASE_TOML

    assert 340 * N_PER_MM_MIN <= LIMIT_N < 350 * N_PER_MM_MIN
    (tmp_path / "case.toml").write_text(CASE_TOML)
    (tmp_path / "program.nc").write_text(HALF_SLOT)
    ref = build_reference(resolve_case(None, tmp_path, None), ranges=Ranges(), load_limit_N=LIMIT_N)
    ctx = ref.context
    assert ctx.lines.tolist() == [6]
    assert ref.evaluation.max_load_N[0] == pytest.approx(170 * N_PER_MM_MIN, abs=0.1)
    ev = CachedEvaluator(ctx, SerialBackend())
    r = push_genes(ctx, ev, _time, ctx.original_feed, ctx.original_spindle)
    assert r.feeds.tolist() == [340.0] and r.spindles.tolist() == [4000.0]
    assert r.moves[-1]["load_after_N"] == pytest.approx(340 * N_PER_MM_MIN, abs=0.1)
    assert r.moves[-1]["load_after_N"] <= LIMIT_N
    assert r.objective_after < r.objective_before


def test_optimize_reports_the_push_and_the_opt_out_skips_it(tmp_path):
    from tests.test_optimize_cases import CASE_TOML

    (tmp_path / "case.toml").write_text(CASE_TOML)
    (tmp_path / "program.nc").write_text(HALF_SLOT)
    base = dict(objective="time", load_limit_N=60.0, pop=3, gens=1, seed=2, progress=False, plot=False)
    on = optimize(case=tmp_path, settings=OptimizeSettings(**base), out=tmp_path / "on")
    off = optimize(case=tmp_path, settings=OptimizeSettings(**base, push=False), out=tmp_path / "off")
    report = json.loads((tmp_path / "on" / "report.json").read_text())
    assert report["settings"]["push"] is True and off.push is None
    assert json.loads((tmp_path / "off" / "report.json").read_text())["push"] is None
    push = report["push"]
    assert push["objective_after"] <= push["objective_before"]
    assert push["objective_before"] == pytest.approx(min(h["best"] for h in off.history))
    # the same search ran in both jobs; after it, "on" adds the push and its equal-feeds pass, "off" its own pass
    tidy_off = json.loads((tmp_path / "off" / "report.json").read_text())["tidy"]
    assert push["evaluations"] + report["tidy"]["evaluations"] - tidy_off["evaluations"] \
        == on.evaluations - off.evaluations
    assert on.after["max_cutting_load_N"] <= 60.0
    assert on.after["cycle_time_s"] <= off.after["cycle_time_s"]
