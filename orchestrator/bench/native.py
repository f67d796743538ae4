"""Timing of the native twin (all four components; compiled or Python master loop) and of the fused reference."""
from __future__ import annotations

import logging
import time
from pathlib import Path

import numpy as np

from fmus_src.cutting.table import EngagementTable
from fmus_src.nck.settings import MM, RPM

from ..case import Case
from ..compiled import compiled_support
from ..compiled.blocks import block_count
from ..master import Master, MasterSettings
from ..simulate import resolve_case
from ..twin import TwinOptions, build_twin, engagement_table

#: The benchmark program: the paper-like part without the tool change (cutting from about 1.5 s).
BENCH_PROGRAM = Path(__file__).resolve().parent / "bench_part.nc"
#: Its case (stock, tool, material, machine).
BENCH_CASE = Path(__file__).resolve().parents[2] / "models" / "examples" / "paper_part"
#: Source lines of :data:`BENCH_PROGRAM` with the F words of its three cuts (mm/min) and its S word (rpm): what the
#: variants of a population change (:func:`variant_overrides`).
BENCH_FEED_LINES = {10: 300.0, 14: 400.0, 18: 400.0}
BENCH_SPINDLE_LINE = (7, 6000.0)


def variant_overrides(batch: int, seed: int = 0) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """F and S overrides of ``batch`` distinct variants of :data:`BENCH_PROGRAM`, as an optimiser's population.

    Each cut's feed is drawn from 0.8-1.25 times the program's (on a 10 mm/min grid) and the spindle speed from
    5000-7000 rpm (on a 50 rpm grid), seeded; member 0 is the program as written.

    Returns
    -------
    feed, spindle : dict line -> ndarray (B,)
        m/s and rad/s, for :meth:`fmus_src.nck.component.NCKernel.set_overrides`.
    """
    rng = np.random.default_rng(seed)
    feed = {}
    for line, f in BENCH_FEED_LINES.items():
        values = np.round(f * rng.uniform(0.8, 1.25, batch) / 10.0) * 10.0
        values[0] = f
        feed[line] = values * MM / 60.0
    line, s = BENCH_SPINDLE_LINE
    speeds = np.round(rng.uniform(5000.0, 7000.0, batch) / 50.0) * 50.0
    speeds[0] = s
    return feed, {line: speeds * RPM}


def bench_case() -> Case:
    """The benchmark case: ``paper_part``'s stock, tool and machine with :data:`BENCH_PROGRAM`."""
    return resolve_case(program=BENCH_PROGRAM, case=BENCH_CASE)


def time_twin(case: Case, batch: int, seconds: float, cutting: bool = True, step: float = 1e-3,
              cutting_mode: str = "path", engagement: EngagementTable | None = None, compiled: bool = True,
              integrator: str = "exponential", threads: int | None = None, variants: bool = False) -> dict:
    """Run the native twin for ``seconds`` of simulated time and time it.

    Parameters
    ----------
    case : Case
        What to run (the program may end earlier: then its own length counts).
    batch : int
        Identical members ``B`` in one batched run.
    seconds : float
        Simulated time limit, s.
    cutting : bool
        Include the cutting load.
    step : float
        Communication step, s.
    cutting_mode : {"path", "zmap"}
        Cutting load from the engagement table along the program path, or from a Z-map per member.
    engagement : EngagementTable, optional
        The table of ``cutting_mode="path"`` (built once by the caller; built here otherwise, untimed).
    compiled : bool
        ``MasterSettings.compiled``: the compiled loop where it covers the system.
    integrator : {"exponential", "rk4"}
        ``TwinOptions.drive_integrator``.
    threads : int, optional
        ``MasterSettings.threads`` (None: one per core, at least 4 members each).
    variants : bool
        Distinct members (:func:`variant_overrides`, seeded) instead of ``B`` copies of the program.

    Returns
    -------
    dict
        ``batch``, ``sim_s`` (simulated time per member), ``steps``, ``build_s`` (assembly),
        ``wall_s`` (run incl. set-up), ``rt_factor`` (``B · sim_s / wall_s``, aggregate),
        ``us_per_step`` (wall per communication step of the batch), ``us_per_member_step``,
        ``compiled_loop`` (whether the compiled loop ran), ``threads`` (member blocks stepped side by side),
        ``cutting_mode``, ``integrator``.
    """
    if cutting and cutting_mode == "path" and engagement is None and case.stock is not None:
        engagement = engagement_table(case, TwinOptions(step=step))
    t_build = time.perf_counter()
    options = TwinOptions(step=step, cutting=cutting, cutting_mode=cutting_mode, engagement=engagement,
                          drive_integrator=integrator)
    twin = build_twin(case, batch=batch, options=options)
    if variants:
        feed, spindle = variant_overrides(batch)
        twin.nck.set_overrides(feed=feed, spindle=spindle)
    build = time.perf_counter() - t_build
    settings = MasterSettings(step=step, time_limit=seconds, stop_when=twin.stop_when, limits=twin.limits or {},
                              compiled=compiled, threads=threads)
    master = Master(twin.system, settings, twin.probes)
    compiled_loop = compiled and compiled_support(master) is None
    quiet = logging.getLogger("orchestrator")  # a timing run that ends at its time limit is not news
    level = quiet.level
    quiet.setLevel(logging.CRITICAL)
    try:
        t0 = time.perf_counter()
        run = master.run()
        wall = time.perf_counter() - t0
    finally:
        quiet.setLevel(level)
    sim = run.t_end - settings.t0
    return {
        "batch": batch, "cutting": twin.cutting is not None, "sim_s": sim, "steps": run.steps,
        "build_s": build, "wall_s": wall, "rt_factor": batch * sim / wall,
        "us_per_step": wall / max(run.steps, 1) * 1e6, "us_per_member_step": wall / max(run.steps, 1) / batch * 1e6,
        "success": run.success, "message": run.message, "compiled_loop": compiled_loop,
        "threads": block_count(batch, threads) if compiled_loop else 1,
        "cutting_mode": cutting_mode if twin.cutting is not None else "none", "integrator": integrator,
        "variants": variants,
    }


def time_fused(problem, repeats: int = 1) -> dict:  # problem: FusedProblem
    """Time :meth:`FusedProblem.run` (best of ``repeats``; compiled before timing)."""
    best = np.inf
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        problem.run()
        best = min(best, time.perf_counter() - t0)
    sim = problem.n_steps * problem.step
    return {
        "batch": problem.batch, "sim_s": sim, "steps": problem.n_steps, "wall_s": best,
        "rt_factor": problem.batch * sim / best, "us_per_step": best / problem.n_steps * 1e6,
        "us_per_member_step": best / problem.n_steps / problem.batch * 1e6,
    }
