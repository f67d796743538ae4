"""Issue 7: every Pareto-front point is re-checked with its written program on the Z-map cutting model."""
from __future__ import annotations

import json

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.cli import main as cnctwin_main
from orchestrator.optimize import (
    Evaluation, OptimizeError, OptimizeSettings, build_reference, check_front_zmap, optimize,
)
from orchestrator.optimize.report import _plot_front
from tests.test_optimize_cases import write_case

ZMAP_KEYS = ("zmap_cycle_time_s", "zmap_cost_KRW", "zmap_max_cutting_load_N", "zmap_feasible", "zmap_reason",
             "zmap_batch")
TINY = dict(objective="pareto", pop=4, gens=2, seed=3, feed_range=(100.0, 600.0), progress=False)


@pytest.fixture(scope="module")
def case_dir(tmp_path_factory):
    return write_case(tmp_path_factory.mktemp("frontcase"))


@pytest.fixture(scope="module")
def reference(case_dir):
    s = OptimizeSettings(**TINY)
    return build_reference(load_case(case_dir), ranges=s.ranges(), load_limit_N=s.load_limit_N)


@pytest.fixture(scope="module")
def pareto(case_dir, reference, tmp_path_factory):
    out = tmp_path_factory.mktemp("pareto")
    return optimize(case=case_dir, settings=OptimizeSettings(**TINY), out=out, reference=reference), out


def _point(ctx, feed: float, spindle: float) -> dict:
    L = ctx.n_lines
    return {"X": ctx.as_dict(np.full(L, feed), np.full(L, spindle))}


def test_every_front_point_carries_the_zmap_figures(pareto):
    result, out = pareto
    report = json.loads((out / "report.json").read_text())
    assert report["settings"]["check_front"] is True
    assert len(result.front) >= 2, "the tiny run should give a front of at least two points"
    assert report["pareto_front"] == json.loads(json.dumps(result.front))
    for point in report["pareto_front"]:
        assert set(ZMAP_KEYS) <= set(point)
        assert isinstance(point["zmap_cycle_time_s"], float) and isinstance(point["zmap_cost_KRW"], float)
        load = point["zmap_max_cutting_load_N"]
        assert point["zmap_feasible"] is (load <= 60.0)  # the knee's rule: no tolerance on the limit
        assert (point["zmap_reason"] == "") is point["zmap_feasible"]
        # the Z-map load of the written program is close to the search's path-mode load (README: within 0.1 N)
        assert load == pytest.approx(point["max_cutting_load_N"], abs=0.1)
    assert (out / "report.png").stat().st_size > 0


def test_the_knee_equals_after_exactly(pareto):
    result, _ = pareto
    front = result.front
    # the knee by the documented rule: closest to the ideal point after scaling each objective to the front's range
    F = np.array([[p["cycle_time_s"], p["cost_KRW"]] for p in front])
    lo, hi = F.min(axis=0), F.max(axis=0)
    knee = int(np.argmin(np.linalg.norm((F - lo) / np.where(hi > lo, hi - lo, 1.0), axis=1)))
    assert front[knee]["X"] == result.X
    assert front[knee]["zmap_feasible"] and result.after["feasible"]
    assert front[knee]["zmap_batch"] == 1
    assert front[knee]["zmap_cycle_time_s"] == result.after["cycle_time_s"]
    assert front[knee]["zmap_cost_KRW"] == result.after["cost_KRW"]
    assert front[knee]["zmap_max_cutting_load_N"] == result.after["max_cutting_load_N"]


def test_an_overloading_point_is_marked_and_a_light_one_passes(reference):
    """Two hand-made points in one batched run (B = 2), expectations from Eq. 10-13 and the 60 N limit.

    Full 1 mm deep slot with the 2-flute 6 mm tool: one tooth engaged, h = fz sin(phi), the resultant peaks at
    Kt a fz sqrt(1 + Ke^2). F300 at S3000 is fz = 0.05 mm (about 69 N), F200 at S6000 is fz = 0.0167 mm (about 23 N).
    """
    ctx = reference.context
    material = ctx.case.machine.si("material.A6061")
    kt, ke = material["kt"], material["ke"]
    heavy, light = _point(ctx, 300.0, 3000.0), _point(ctx, 200.0, 6000.0)
    checked = check_front_zmap(ctx, [heavy, light])
    for point, (feed, spindle) in zip(checked, ((300.0, 3000.0), (200.0, 6000.0))):
        fz = feed / (2 * spindle) * 1e-3  # m per tooth
        expected = kt * 1e-3 * fz * np.sqrt(1.0 + ke**2)
        assert abs(expected - ctx.load_limit_N) > 0.1 * ctx.load_limit_N  # far from the limit either way
        assert point["zmap_batch"] == 2
        assert point["zmap_max_cutting_load_N"] == pytest.approx(expected, rel=0.02)
        assert point["zmap_feasible"] is bool(expected <= ctx.load_limit_N)
    assert not checked[0]["zmap_feasible"] and "exceeds the limit 60 N" in checked[0]["zmap_reason"]
    assert checked[1]["zmap_feasible"] and checked[1]["zmap_reason"] == ""
    assert checked[0]["X"] == heavy["X"] and "zmap_feasible" not in heavy  # copies, input untouched


def test_points_simulated_alone_are_reused_not_rerun(reference):
    ctx = reference.context
    point = _point(ctx, 250.0, 5000.0)
    key = tuple(np.full(ctx.n_lines, 250.0)) + tuple(np.full(ctx.n_lines, 5000.0))
    L = ctx.n_lines
    known = Evaluation(np.array([1.5]), np.array([7.0]), np.array([61.0]), np.array([0.001]), np.zeros((1, L)),
                       np.zeros((1, L)), np.array([True]), np.array([False]), ["cutting load 61.0 N exceeds"])
    (checked,) = check_front_zmap(ctx, [point], {key: known})  # no twin run: the given figures come back
    figures = (checked["zmap_cycle_time_s"], checked["zmap_cost_KRW"], checked["zmap_max_cutting_load_N"])
    assert figures == (1.5, 7.0, 61.0)
    assert checked["zmap_feasible"] is False and checked["zmap_batch"] == 1
    with pytest.raises(OptimizeError, match="missing gene"):
        check_front_zmap(ctx, [{"X": {"L0007.feed": 200.0}}])


def test_settings_and_cli_switch_the_check_off(case_dir, pareto, tmp_path):
    with pytest.raises(OptimizeError, match="check_front"):
        OptimizeSettings(check_front="no")
    with pytest.raises(TypeError):
        OptimizeSettings(front_check=False)  # an unknown key is refused
    out = tmp_path / "cli"
    args = ["optimize", "--case", str(case_dir), "--objective", "pareto", "--pop", "4", "--gens", "2", "--seed", "3",
            "--feed-range", "100,600", "--out", str(out), "--no-front-check"]
    assert cnctwin_main(args) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["settings"]["check_front"] is False
    assert report["pareto_front"] and all(not set(ZMAP_KEYS) & set(p) for p in report["pareto_front"])
    # the check does not change the search nor the chosen program
    checked, _ = pareto
    assert report["X"] == checked.X and report["after"] == checked.after


def test_plot_marks_points_over_the_limit_hollow():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    front = [{"cycle_time_s": 3.0, "cost_KRW": 13.0, "zmap_feasible": True},
             {"cycle_time_s": 3.5, "cost_KRW": 12.5, "zmap_feasible": False},
             {"cycle_time_s": 4.0, "cost_KRW": 12.0, "zmap_feasible": True}]
    fig, ax = plt.subplots()
    _plot_front(ax, front)
    hollow = [ln for ln in ax.lines if ln.get_markerfacecolor() == "none"]
    filled = [ln for ln in ax.lines if ln.get_marker() == "o" and ln.get_markerfacecolor() != "none"]
    plt.close(fig)
    assert len(hollow) == 1 and hollow[0].get_xdata().tolist() == [3.5]
    assert len(filled) == 1 and filled[0].get_xdata().tolist() == [3.0, 4.0]
