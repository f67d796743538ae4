"""Equal feeds on equal cuts: the post-pass on the search's best program (:mod:`orchestrator.optimize.tidy`).

The post-pass is checked on an analytic evaluator (no twin): line i of length ``length_i`` mm takes
``60 length_i / F_i`` s, the cycle time is their sum rounded up to the 1 ms step, and its load is
``k_i F_i / S_i`` N (Eq. 10–13 are linear in the feed per tooth), within 60 N. Every expected feed follows
from these numbers. The end-to-end test runs ``optimize`` on a short contour.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from orchestrator.optimize import OptimizeSettings, Ranges, optimize
from orchestrator.optimize.context import ProblemContext
from orchestrator.optimize.evaluate import Evaluation
from orchestrator.optimize.tidy import equal_cut_classes, tidy_genes

LIMIT_N = 60.0


def _context(k: list[float], feed0: float = 300.0, speed0: float = 6000.0) -> ProblemContext:
    """Cutting lines 10, 11, ... whose reference load at ``feed0``/``speed0`` is ``k feed0 / speed0``."""
    L = len(k)
    load = np.asarray(k, float) * feed0 / speed0
    return ProblemContext(None, "", np.arange(10, 10 + L), np.arange(10, 10 + L), {}, np.full(L, feed0),
                          np.full(L, speed0), Ranges(), LIMIT_N, original_load_N=load)


class Analytic:
    """Evaluator of the model in the module docstring; counts the members it evaluates."""

    def __init__(self, k: list[float], length_mm: list[float]) -> None:
        self.k, self.length = np.asarray(k, float), np.asarray(length_mm, float)
        self.members = 0

    def __call__(self, feeds: np.ndarray, spindles: np.ndarray) -> Evaluation:
        F, S = np.atleast_2d(feeds), np.atleast_2d(spindles)
        B, L = F.shape
        self.members += B
        line_t = 60.0 * self.length / F
        t = np.ceil(line_t.sum(axis=1) * 1000.0 - 1e-9) / 1000.0
        line_load = self.k * F / S
        load = line_load.max(axis=1)
        ok = load <= LIMIT_N
        return Evaluation(t, t.copy(), load, np.zeros(B), line_t, line_load, np.ones(B, bool), ok,
                          ["" if o else "over the load limit" for o in ok])


def _time(ev: Evaluation) -> np.ndarray:
    return ev.cycle_time_s


def test_contour_of_equal_cuts_gets_one_feed_the_fastest_feasible():
    """F410/F420/F410 on three equal 20 mm cuts: at 6000 rpm 420 mm/min loads k * 0.07 = 58.8 N, feasible, so
    both ends take the middle's F420 (faster); 430 is not tried: the pass only copies existing feeds."""
    k = [840.0, 840.0, 840.0]
    ev = Analytic(k, [20.0, 20.0, 20.0])
    ctx = _context(k)
    r = tidy_genes(ctx, ev, _time, np.array([410.0, 420.0, 410.0]), np.full(3, 6000.0))
    assert r.feeds.tolist() == [420.0, 420.0, 420.0]
    assert r.spindles.tolist() == [6000.0] * 3
    assert r.objective_before == pytest.approx(np.ceil(60e3 * (40 / 410 + 20 / 420)) / 1e3)
    assert r.objective_after == pytest.approx(np.ceil(60e3 * 60 / 420) / 1e3)
    assert sorted(m["line"] for m in r.moves) == [10, 12]
    assert all(m["from_line"] == 11 and m["feed_after_mm_per_min"] == 420.0 for m in r.moves)


def test_a_lower_feed_is_taken_only_when_it_costs_no_time():
    """Ends at 420 mm/min would load 60.6 N (k = 866): they stay at 410. The middle (k 3 % lower, alike) at 420
    loads 58.8 N. On a 0.01 mm middle line 410 instead of 420 costs 0.0000035 s, less than the 1 ms step: it is
    copied. On a 20 mm middle it costs 70 ms: the program keeps F410/F420/F410."""
    k = [866.0, 840.0, 866.0]
    short = tidy_genes(_context(k), Analytic(k, [20.0, 0.01, 20.0]), _time, np.array([410.0, 420.0, 410.0]),
                       np.full(3, 6000.0))
    assert short.feeds.tolist() == [410.0, 410.0, 410.0]
    assert short.objective_after == short.objective_before
    long = tidy_genes(_context(k), Analytic(k, [20.0, 20.0, 20.0]), _time, np.array([410.0, 420.0, 410.0]),
                      np.full(3, 6000.0))
    assert long.feeds.tolist() == [410.0, 420.0, 410.0]
    assert long.moves == [] and long.objective_after == long.objective_before


def test_straight_sides_between_arcs_find_each_other_and_arcs_keep_theirs():
    """Sides (k = 800: 430 mm/min at 6000 rpm is 57.3 N, 480 would be 64 N) alternate with corner arcs (k = 480,
    38.4 N at 480 mm/min). The sides end at 430, the fastest side feed found; the arcs keep 480 (a side's 430
    would be slower; a side at an arc's 480 is over the limit)."""
    k = [800.0, 480.0, 800.0, 480.0, 800.0]
    classes = equal_cut_classes(_context(k))
    assert classes[0] == classes[2] == classes[4] != classes[1] == classes[3]
    r = tidy_genes(_context(k), Analytic(k, [20.0, 3.0, 20.0, 3.0, 20.0]), _time,
                   np.array([410.0, 480.0, 420.0, 480.0, 430.0]), np.full(5, 6000.0))
    assert r.feeds.tolist() == [430.0, 480.0, 430.0, 480.0, 430.0]
    assert r.objective_after < r.objective_before


def test_a_different_speed_is_copied_with_its_feed_and_an_infeasible_start_is_left_alone():
    """The neighbour at another speed gives its (F, S) pair: one chip load and no spindle change."""
    k = [840.0, 840.0]
    r = tidy_genes(_context(k), Analytic(k, [20.0, 20.0]), _time, np.array([350.0, 420.0]),
                   np.array([5000.0, 6000.0]))
    assert (r.feeds.tolist(), r.spindles.tolist()) == ([420.0, 420.0], [6000.0, 6000.0])
    over = tidy_genes(_context(k), Analytic(k, [20.0, 20.0]), _time, np.array([500.0, 420.0]), np.full(2, 6000.0))
    assert over.feeds.tolist() == [500.0, 420.0] and over.rounds == 0


def test_equal_cut_classes_use_load_per_feed_per_revolution():
    """Same load per mm/rev within 5 %: one class; a line without load (< 1 N) is in none."""
    ctx = _context([800.0, 830.0, 900.0, 10.0])
    assert ctx.original_load_N.tolist() == pytest.approx([40.0, 41.5, 45.0, 0.5])
    assert equal_cut_classes(ctx).tolist() == [0, 0, 1, -1]


#: A 1 mm deep slot in three straight pieces (lines 6-8), through the 4 x 6 mm block of the helper case.
THREE_PIECES = """%
G21 G17 G90 G94 G54
S4000 M3
G0 X-3.5 Y3. Z1.
G1 Z-1. F600
X-0.5 F300
X3.
X7.5
G0 Z1.
M30
%
"""


def test_optimize_reports_the_post_pass_and_it_never_costs_objective(tmp_path):
    from tests.test_optimize_cases import CASE_TOML

    (tmp_path / "case.toml").write_text(CASE_TOML)
    (tmp_path / "program.nc").write_text(THREE_PIECES)
    base = dict(objective="time", load_limit_N=60.0, feed_range=(100.0, 600.0), pop=4, gens=1, seed=5,
                progress=False, plot=False)
    on = optimize(case=tmp_path, settings=OptimizeSettings(**base), out=tmp_path / "on")
    off = optimize(case=tmp_path, settings=OptimizeSettings(**base, tidy=False), out=tmp_path / "off")
    report = json.loads((tmp_path / "on" / "report.json").read_text())
    assert report["settings"]["tidy"] is True and off.tidy is None
    tidy = report["tidy"]
    assert tidy["objective_after"] <= tidy["objective_before"]
    # the search's own best (the run without the pass) is where the pass started
    assert tidy["objective_before"] == pytest.approx(min(h["best"] for h in off.history))
    # the same search and push ran in both jobs (the push runs before the pass): the difference is the pass's
    assert tidy["evaluations"] == on.evaluations - off.evaluations
    for move in tidy["moves"]:
        assert move["line"] in (6, 7, 8) and move["from_line"] in (6, 7, 8)
    assert on.after["max_cutting_load_N"] <= 60.0
