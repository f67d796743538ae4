"""Timing of NC planning of a population: the compiled planner against the numpy reference, in one run.

:func:`planning_inputs` interprets a case's program with per-line F and S overrides exactly as the twin's
NC kernel does at set-up (:meth:`fmus_src.nck.component.NCKernel.planning_inputs`); :func:`time_planning`
plans the same population with :func:`fmus_src.nck.planner.plan_batch` both ways, interleaved, and reports
the best of a few repeats of each and their ratio.
"""
from __future__ import annotations

import time
from typing import Mapping

import numpy as np

from fmus_src.nck.batch_plan import BatchPlan
from fmus_src.nck.planner import plan_batch
from fmus_src.nck.settings import MM, RPM

from ..case import Case
from ..twin import TwinOptions, build_twin
from .native import bench_case, variant_overrides

#: BatchPlan arrays compared bit for bit (every field of every member's plan is in one of them).
PLAN_FIELDS = ("flat_position", "offset", "length", "run_key", "run_feed", "run_spindle_ref", "run_spindle_speed",
               "run_line", "run_tool", "done_index")


def planning_inputs(case: Case, batch: int, feed: Mapping[int, object] | None = None,
                    spindle: Mapping[int, object] | None = None) -> tuple:
    """The arguments of :func:`~fmus_src.nck.planner.plan_batch` for ``case`` with overrides, as the twin plans.

    Parameters
    ----------
    case : Case
        Program and machine (the NC parameters come from the machine file).
    batch : int
        B.
    feed, spindle : mapping source line -> scalar or ndarray (B,), optional
        F overrides (m/s) and S overrides (rad/s), as :meth:`fmus_src.nck.component.NCKernel.set_overrides`.

    Returns
    -------
    tuple
        ``(schedule, params, feeds, speeds)``.
    """
    twin = build_twin(case, batch=batch, options=TwinOptions(cutting=False))
    twin.nck.set_overrides(feed=feed or {}, spindle=spindle or {})
    return twin.nck.planning_inputs()


def ga_population(lines: list[int], batch: int, seed: int = 0, feed_mm_per_min: tuple[float, float] = (100.0, 500.0),
                  speed_rpm: tuple[float, float] = (1000.0, 8000.0)) -> tuple[dict[int, np.ndarray],
                                                                              dict[int, np.ndarray]]:
    """A random population as a genetic algorithm draws it: F and S per cutting line, seeded.

    Parameters
    ----------
    lines : list of int
        Source lines of the cutting moves (each gets its own F and S gene).
    batch : int
        B.
    seed : int
        Random seed.
    feed_mm_per_min, speed_rpm : (float, float)
        Ranges (mm/min on a 10 mm/min grid, rpm on a 50 rpm grid).

    Returns
    -------
    feed, spindle : dict line -> ndarray (B,)
        m/s and rad/s.
    """
    rng = np.random.default_rng(seed)
    f = np.round(rng.uniform(*feed_mm_per_min, (batch, len(lines))) / 10.0) * 10.0
    s = np.round(rng.uniform(*speed_rpm, (batch, len(lines))) / 50.0) * 50.0
    return ({line: f[:, i] * MM / 60.0 for i, line in enumerate(lines)},
            {line: s[:, i] * RPM for i, line in enumerate(lines)})


def same_plan(a: BatchPlan, b: BatchPlan) -> bool:
    """Whether two batch plans hold the same bits in every array (dtype and shape included)."""
    for name in PLAN_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        if x.dtype != y.dtype or x.shape != y.shape or x.tobytes() != y.tobytes():
            return False
    return a.period == b.period


def time_planning(batch: int = 100, repeats: int = 3, case: Case | None = None) -> dict:
    """Plan ``batch`` distinct variants of the bench program (:func:`.native.variant_overrides`) both ways.

    Parameters
    ----------
    batch : int
        Members (distinct F/S variants, seeded).
    repeats : int
        Runs of each path, interleaved; the best of each counts.
    case : Case, optional
        Default: :func:`.native.bench_case`.

    Returns
    -------
    dict
        ``batch``, ``reference_s`` and ``compiled_s`` (best wall times), ``ratio`` (reference / compiled),
        ``ms_per_member`` of each, ``identical`` (bit-identical plans).
    """
    feed, spindle = variant_overrides(batch)
    args = planning_inputs(case or bench_case(), batch, feed, spindle)
    new = plan_batch(*args)  # compiles or loads the numba caches
    best = {"reference": np.inf, "compiled": np.inf}
    ref = new
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        ref = plan_batch(*args, reference=True)
        best["reference"] = min(best["reference"], time.perf_counter() - t0)
        t0 = time.perf_counter()
        new = plan_batch(*args)
        best["compiled"] = min(best["compiled"], time.perf_counter() - t0)
    return {"batch": batch, "reference_s": best["reference"], "compiled_s": best["compiled"],
            "ratio": best["reference"] / best["compiled"], "identical": same_plan(ref, new),
            "ms_per_member_reference": best["reference"] / batch * 1e3,
            "ms_per_member_compiled": best["compiled"] / batch * 1e3}
