"""Cutting-line rule, genes, S-word placement, and overrides == rewritten program."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck.blocks import Linear, Rapid, SpindleSpeed
from orchestrator.case import load_case
from orchestrator.optimize import OptimizeError, Ranges, build_reference
from orchestrator.optimize.context import classify_lines
from orchestrator.twin import build_twin
from tests.test_optimize_cases import write_case


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    folder = write_case(tmp_path_factory.mktemp("ctx"))
    return build_reference(load_case(folder), ranges=Ranges((100.0, 600.0), (1000.0, 8000.0)))


def test_cutting_lines_and_removed_volume(reference):
    ctx = reference.context
    # lines 7 and 8 cut; the plunge (line 6, outside the stock) and rapids do not
    assert ctx.lines.tolist() == [7, 8]
    # volume: 1 mm deep full slot, 6 mm wide, through the 4 mm block: 24 mm3 (+ the cusp-free exit)
    total = ctx.removed_mm3[7] + ctx.removed_mm3[8]
    assert total == pytest.approx(6.0 * 1.0 * 4.0, rel=0.03)
    assert ctx.removed_mm3.get(6, 0.0) < 0.1
    # S of line 7 goes on the program's S word (line 4): the spindle ramps during the rapids
    assert ctx.spindle_lines.tolist() == [4, 8]
    assert ctx.original_feed.tolist() == [300.0, 300.0]
    assert ctx.original_spindle.tolist() == [3000.0, 3000.0]
    assert ctx.keys == ["L0007.feed", "L0007.spindle", "L0008.feed", "L0008.spindle"]


def test_pins_keep_non_cutting_feeds():
    """A non-cutting feed line inheriting F from a cutting line gets its original F written."""
    mm = 1e-3
    blocks = (
        SpindleSpeed(2, 600.0, 1, 2),
        Rapid(3, (0, 0, 0), (0, 0, mm)),
        Linear(4, (0, 0, mm), (5 * mm, 0, mm), 300 / 60000, 4),
        Linear(5, (5 * mm, 0, mm), (5 * mm, 0, 5 * mm), 300 / 60000, 4),
    )
    lines, s_lines, pins, feeds, speeds = classify_lines(blocks, {4: 10.0, 5: 0.0}, 0.1)
    assert lines == [4] and pins == {5: pytest.approx(300.0)}
    assert s_lines == [2]  # the original S word before the rapid
    assert feeds == [pytest.approx(300.0)] and speeds == [pytest.approx(600.0 * 60 / (2 * np.pi))]


def test_a_straight_retract_credited_with_the_cuts_lag_tail_is_not_a_cutting_line():
    """A G1 straight up +Z removes nothing itself, whatever the reference run credited to it; a ramp out does cut."""
    mm = 1e-3
    blocks = (
        SpindleSpeed(2, 600.0, 1, 2),
        Rapid(3, (0, 0, 0), (0, 0, mm)),
        Linear(4, (0, 0, mm), (5 * mm, 0, mm), 300 / 60000, 4),
        Linear(5, (5 * mm, 0, mm), (5 * mm, 0, 5 * mm), 1000 / 60000, 5),  # G1 Z5. F1000. (Fusion's retract)
        Linear(6, (5 * mm, 0, 5 * mm), (5 * mm, 0, mm), 300 / 60000, 6),
        Linear(7, (5 * mm, 0, mm), (9 * mm, 0, 3 * mm), 300 / 60000, 6),  # a ramp out: sideways while rising
    )
    removed = {4: 10.0, 5: 0.67, 6: 0.0, 7: 0.67}  # 0.67 mm3: what the servo lag left on a Fusion retract
    lines, _, pins, feeds, _ = classify_lines(blocks, removed, 0.1)
    assert lines == [4, 7] and feeds == [pytest.approx(300.0), pytest.approx(300.0)]
    assert 5 not in pins  # its own F word (F1000) stays as written


def test_a_plunge_that_removes_material_with_its_end_edges_is_not_a_cutting_line():
    """A G1 straight down -Z into the stock removes pi R^2 depth with the end edges (the axial chip) but gives no
    lateral load fc, which the search limits: it keeps its F; a ramp (sideways while sinking) is a cutting line."""
    mm = 1e-3
    blocks = (
        SpindleSpeed(2, 600.0, 1, 2),
        Rapid(3, (0, 0, 0), (0, 0, mm)),
        Linear(4, (0, 0, mm), (0, 0, -2 * mm), 120 / 60000, 4),  # G1 Z-2. F120 (plunge into solid)
        Linear(5, (0, 0, -2 * mm), (5 * mm, 0, -2 * mm), 300 / 60000, 5),
        Linear(6, (5 * mm, 0, -2 * mm), (9 * mm, 0, -3 * mm), 300 / 60000, 5),  # a ramp: sideways while sinking
    )
    removed = {4: np.pi * 3.0 ** 2 * 3.0, 5: 10.0, 6: 5.0}  # the plunge: a 6 mm end mill 3 mm down, mm3
    lines, _, pins, feeds, _ = classify_lines(blocks, removed, 0.1)
    assert lines == [5, 6] and feeds == [pytest.approx(300.0), pytest.approx(300.0)]
    assert 4 not in pins  # its own F word (F120) stays as written


def test_snap_to_machinist_grid(reference):
    f, s = reference.context.snap(np.array([[123.0, 999.0]]), np.array([[6024.0, 100.0]]))
    assert f.tolist() == [[120.0, 600.0]]
    assert s.tolist() == [[6000.0, 1000.0]]


def test_overrides_equal_rewritten_program(reference):
    """The batched overrides and the rewritten program plan the same motion (the writer emits the same program)."""
    ctx = reference.context
    rng = np.random.default_rng(7)
    feeds, spindles = ctx.snap(rng.uniform(100, 600, (3, 2)), rng.uniform(1000, 8000, (3, 2)))
    twin = build_twin(ctx.case, batch=3, program_text=ctx.program_text)
    twin.nck.set_overrides(*ctx.overrides(feeds, spindles))
    twin.nck.setup(0.0)
    for b in range(3):
        text = ctx.program_for(feeds[b], spindles[b])
        single = build_twin(ctx.case, batch=1, program_text=text)
        single.nck.setup(0.0)
        assert single.nck.duration_[0] == pytest.approx(twin.nck.duration_[b], abs=1e-12)
        k = single.nck.plan_.position.shape[1]  # the batch plan is padded to its longest member
        np.testing.assert_allclose(single.nck.plan_.position[0], twin.nck.plan_.position[b, :k], rtol=0, atol=1e-12)
        np.testing.assert_allclose(single.nck.plan_.spindle_speed[0], twin.nck.plan_.spindle_speed[b, :k], rtol=1e-12)
        # only F and S words changed
        changed = [(a, c) for a, c in zip(ctx.program_text.splitlines(), text.splitlines()) if a != c]
        for old, new in changed:
            assert [w for w in old.split() if w[0] not in "FS"] == [w for w in new.split() if w[0] not in "FS"]


def test_ranges_refuse_nonsense():
    with pytest.raises(OptimizeError, match="feed range"):
        Ranges((500.0, 100.0))
    with pytest.raises(OptimizeError, match="no multiple"):
        Ranges((101.0, 105.0))


def test_air_cut_is_refused(tmp_path):
    folder = write_case(tmp_path)
    case = load_case(folder)
    case.stock = None
    with pytest.raises(OptimizeError, match="no \\[stock\\]"):
        build_reference(case)


def _toy_problem(n_lines=5):
    from orchestrator.case import Case, Tool
    from orchestrator.machine import load_machine
    from orchestrator.optimize.context import ProblemContext
    from orchestrator.optimize.problem import LineProblem

    case = Case(Path("."), Path("toy.nc"), None, None, Tool(), load_machine("default"), "")
    ctx = ProblemContext(case, "", np.arange(10, 10 + n_lines), np.arange(10, 10 + n_lines), {},
                         np.full(n_lines, 305.0), np.full(n_lines, 6000.0), Ranges(), 60.0,
                         original_load_N=np.array([90.0, 30.0] + [60.0] * (n_lines - 3) + [0.0]))
    return LineProblem(ctx)


def test_chip_load_feeds_scale_with_feed_per_tooth():
    """Eq. 10-13 are linear in the chip thickness: F/S scaled by Flim/load puts the load at the limit."""
    ctx = _toy_problem().ctx
    f = ctx.chip_load_feeds(np.full(5, 8000.0), 1.0)
    fz = 305.0 / 6000.0
    assert f[0] == pytest.approx(fz * 8000.0 * 60.0 / 90.0)
    assert f[1] == pytest.approx(fz * 8000.0 * 60.0 / 30.0)
    assert f[4] == 500.0  # a line that did not load the tool: top of the range


def test_operators_stay_on_grid_and_move_whole_lines():
    from orchestrator.optimize.problem import LinewiseCrossover, LinewiseMutation, SeededSampling

    problem = _toy_problem()
    rng = np.random.default_rng(5)
    X = SeededSampling()._do(problem, 9, random_state=rng)
    assert X.shape == (9, 10)
    assert X[0].tolist() == [310.0, 6000.0] * 5  # the original, snapped to 10 mm/min
    # rows 1-3: one spindle speed (the top of the range first), feeds at 80-100 % of the limit's chip load
    assert np.all(X[1:4, 1::2] == X[1:4, 1:2]) and X[1, 1] == 8000.0
    target = problem.ctx.chip_load_feeds(X[1:4, 1::2], 1.0)
    ratio = X[1:4, [0, 4]] / target[:, [0, 2]]  # lines 0 and 2 stay inside the feed range
    assert np.all((ratio > 0.78) & (ratio < 1.02))
    assert np.all(X[4:6, 0::2] == X[4:6, :1]) and np.all(X[4:6, 1::2] == X[4:6, 1:2])  # uniform programs
    for x in (X, LinewiseMutation()._do(problem, X, random_state=rng)):
        assert np.all(np.mod(x[:, 0::2], 10.0) == 0) and np.all(np.mod(x[:, 1::2], 50.0) == 0)
        assert np.all(x >= problem.xl) and np.all(x <= problem.xu)
    parents = np.stack([X[5:7], X[7:9]])  # (2 parents, 2 matings, n_var)
    kids = LinewiseCrossover()._do(problem, parents, random_state=rng)
    for m in range(2):
        for j in range(5):
            pair = [tuple(parents[p, m, 2 * j: 2 * j + 2]) for p in range(2)]
            for k in range(2):
                assert tuple(kids[k, m, 2 * j: 2 * j + 2]) in pair


class _FixedOperator:
    """A random generator whose choice of mutation operator (``integers(7)``) is fixed."""

    def __init__(self, op, seed=0):
        self.op, self.rng = op, np.random.default_rng(seed)

    def integers(self, n, *args, **kwargs):
        return self.op if n == 7 else self.rng.integers(n, *args, **kwargs)

    def __getattr__(self, name):
        return getattr(self.rng, name)


def test_mutation_to_the_load_limit_uses_the_chip_load_rule():
    """Operator 5: F = fz_ref S (u Flim) / load_ref with u in [0.9, 1], rounded down to 10 mm/min."""
    from orchestrator.optimize.problem import LinewiseMutation

    problem = _toy_problem()
    X = np.tile([310.0, 6000.0], (40, 5))
    Y = LinewiseMutation()._do(problem, X, random_state=_FixedOperator(5))
    # line 0 (90 N at 305 mm/min, 6000 rpm): F at the limit = 305 * 60 / 90 = 203.3 mm/min -> 180..200
    # line 1 (30 N): 610 -> top of the range 500 at u >= 0.82; line 4 (no load): the top of the range
    bounds = {0: (180.0, 200.0), 1: (500.0, 500.0), 2: (270.0, 300.0), 3: (270.0, 300.0), 4: (500.0, 500.0)}
    changed = 0
    for row in Y:
        assert np.all(row[1::2] == 6000.0)  # spindle speeds untouched
        for j, (lo, hi) in bounds.items():
            if row[2 * j] != 310.0:
                assert lo <= row[2 * j] <= hi
                changed += 1
    assert changed >= 40  # at least one line per individual


def test_mutation_to_one_spindle_speed_keeps_each_feed_per_tooth():
    """Operator 6: every line takes one line's S, each feed scaled by S_new / S_old (same chip load)."""
    from orchestrator.optimize.problem import LinewiseMutation

    problem = _toy_problem()
    spindles = np.array([3000.0, 4000.0, 5000.0, 6000.0, 2000.0])
    feeds = np.array([150.0, 200.0, 250.0, 300.0, 100.0])  # 0.025 mm/tooth everywhere
    X = np.tile(np.stack([feeds, spindles], axis=1).ravel(), (20, 1))
    Y = LinewiseMutation()._do(problem, X, random_state=_FixedOperator(6))
    for row in Y:
        s = row[1]
        assert s in spindles and np.all(row[1::2] == s)
        # F = 0.025 mm * 2 flutes * S... i.e. feeds / spindles = 0.05 on every line, within the range
        np.testing.assert_allclose(row[0::2], np.clip(0.05 * s, 100.0, 500.0), atol=5.0)


def test_failed_and_penalised_objectives():
    from orchestrator.optimize.evaluate import Evaluation
    from orchestrator.optimize.problem import FAILED, objectives

    ev = Evaluation(np.array([10.0, 12.0, np.nan]), np.array([100.0, 90.0, np.nan]), np.array([50.0, 70.0, np.nan]),
                    np.zeros(3), np.zeros((3, 1)), np.zeros((3, 1)), np.array([True, True, False]),
                    np.array([True, False, False]), ["", "", ""])
    F, G = objectives(ev, "time", "default", 60.0, 1.0)
    assert F[:, 0].tolist() == [10.0, 12.0, FAILED] and G[:, 0].tolist() == [-10.0, 10.0, FAILED]
    F, G = objectives(ev, "cost", "paper", 60.0, 2.0)  # Eq. 18: Cp + w max(0, Fcf - Flim)
    assert G is None and F[:, 0].tolist() == [100.0, 90.0 + 2.0 * 10.0, FAILED]
    F, _ = objectives(ev, "pareto", "default", 60.0, 1.0)
    assert F.shape == (3, 2)
