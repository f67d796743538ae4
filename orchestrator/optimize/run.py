"""``optimize``: Problem → Algorithm → Termination → Result, with checkpoints and workers.

Default method (``method="default"``)
    GA (``time``, ``cost``) or NSGA-II (``pareto``) with the seeded sampling,
    line-wise crossover and mutation and the grid repair of :mod:`.problem`;
    the load limit is a constraint (feasibility first).
Paper's reference (``method="paper"``)
    GA with pymoo's default real-coded operators (random sampling, SBX, PM),
    the penalty fitness of Eq. 17/18 with weight ``penalty_weight`` and the
    paper's stopping rule (``gens`` generations, or best fitness <=
    ``fitness_limit``). Values are snapped to the same grid so that both
    methods write the same kind of program.

Onto the load limit (``push``, time and cost with the default method)
    After the search, :func:`.push.push_genes` raises the best program's
    feeds toward the load limit by the chip-load rule (``F · limit / load``,
    rounded down to the grid), in a few batched rounds, keeping only
    feasible programs that are not worse.
Equal feeds on equal cuts (``tidy``, time and cost with the default method)
    Then :func:`.tidy.tidy_genes` copies feeds between
    neighbouring cutting lines and lines that cut alike wherever the program
    stays feasible and its objective is not worse; the result is the first
    candidate below. When the push ran, the other candidates are every
    feasible program evaluated (search and passes), best first, so a pushed
    program that fails the Z-map check below falls back to the next pushed one.

The chosen program is re-simulated on its own (B = 1, rewritten text) with
the Z-map cutting model (material removed from the stock, not the search's
path-mode engagement): the ``after`` figures are those of the written
program. With the default method a candidate that exceeds the load limit in
this re-simulation is skipped for the next best; when none of the best five
passes, the next 40 are checked in one batched Z-map run and the first within
the limit is re-simulated alone; the original program is kept (with a note)
only when none of these passes.

Pareto front check (``objective="pareto"``, ``check_front=True``)
    Every point of the front is re-checked the same way: its written program
    on the Z-map cutting model, load within the limit (no tolerance, as for
    the chosen program). Points already re-simulated alone while choosing
    (the knee at least) keep that run's figures, so the knee's equal
    ``after``; the others run in ONE batched twin call (B = their number),
    each member with its own F/S words as NC-kernel overrides. A point over
    the limit stays on the front, marked ``zmap_feasible`` False.
"""
from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Callable

import numpy as np
from pymoo.algorithms.moo.nsga2 import NSGA2, binary_tournament
from pymoo.algorithms.soo.nonconvex.ga import GA, comp_by_cv_and_fitness
from pymoo.operators.selection.tournament import TournamentSelection
from pymoo.operators.crossover.sbx import SBX
from pymoo.operators.mutation.pm import PM
from pymoo.operators.sampling.rnd import FloatRandomSampling
from pymoo.termination.max_gen import MaximumGenerationTermination
from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

from fmus_src.nck.blocks import ToolChange
from fmus_src.nck.writer import MM_PER_INCH

from ..case import Case
from ..summary import tool_notes
from .backends import CachedEvaluator, DaskBackend, ProcessBackend, SerialBackend
from .checkpoint import latest_checkpoint, read_pickle, write_checkpoint, write_pickle
from .context import Ranges
from .errors import OptimizeError
from .evaluate import Evaluation, figures, run_twin
from .problem import (
    METHODS, OBJECTIVES, GridRepair, LineProblem, LinewiseCrossover, LinewiseMutation, SeededSampling,
    objectives,
)
from .reference import MAX_CYCLE_FACTOR, MIN_REMOVED_MM3, Reference, build_reference, member_off_path, search_on_zmap
from .push import PushResult, push_genes
from .tidy import TidyResult, tidy_genes


@dataclass
class OptimizeSettings:
    """Settings of :func:`optimize` (CLI flags in brackets).

    Attributes
    ----------
    objective : {"time", "cost", "pareto"}
        [--objective] machining time (Eq. 17), production cost (Eq. 18–22) or both (NSGA-II).
    method : {"default", "paper"}
        [--method] constraint-handling GA/NSGA-II, or the paper's penalty GA.
    load_limit_N : float
        [--load-limit-N] cutting load limit Flim, N (paper: 60).
    feed_range : (float, float)
        [--feed-range] mm/min (paper: 100–500).
    spindle_range : (float, float)
        [--spindle-range] rpm (paper: 1000–8000).
    feed_step, spindle_step : float
        Grid a machinist writes: 10 mm/min, 50 rpm.
    feed_step_in_per_min : float
        Feed grid of a program whose cutting lines run under G20 (inch): 0.1 in/min (2.54 mm/min).
    feed_step_mm_per_rev, feed_step_in_per_rev : float
        [--feed-step-mm-per-rev, --feed-step-in-per-rev] grid of the F words written on G95 (feed per
        revolution) cutting lines: 0.001 mm/rev, 0.0001 in/rev under G20.
    pop, gens : int
        [--pop, --gens] population size and number of generations.
    seed : int
        [--seed] random seed.
    workers : int
        [--workers] worker processes (population split into that many batched chunks).
    dask : str or None
        [--dask] Dask scheduler address (or a ``dask.distributed.Client``).
    resume : bool
        [--resume] continue from the newest checkpoint in the output folder.
    penalty_weight : float
        w of Eq. 17/18 for the paper's method (objective unit per N).
    fitness_limit : float or None
        The paper's "fitness limit": stop when the best fitness reaches it (paper method only).
    min_removed_mm3 : float
        Cutting-line threshold (removed volume in the reference run), mm3.
    max_cycle_factor : float
        [--max-cycle-factor] an individual still running at this multiple of the original cycle time is
        stopped and counted as failed (it cannot be the best: bounds the cost of a generation).
    step : float
        Communication step of the twin, s.
    time_limit_s : float
        Simulated-time limit per run, s.
    progress : bool
        Progress bar on stderr (only when stderr is a terminal).
    plot : bool
        Write ``report.png``.
    check_front : bool
        [--no-front-check] Pareto objective: re-simulate every front point's written program on the Z-map
        cutting model (:func:`check_front_zmap`). Off saves one batched run; ignored for ``time`` and ``cost``.
    tidy : bool
        [--no-tidy] ``time`` and ``cost`` with the default method: after the search, copy feeds between
        neighbouring cutting lines and lines that cut alike wherever the program stays feasible and its
        objective is not worse (:func:`.tidy.tidy_genes`: equal feeds on equal cuts). Ignored for ``pareto``
        and the paper's method.
    push : bool
        [--no-push] ``time`` and ``cost`` with the default method: after the search and before the equal-feeds
        pass, raise the best program's feeds toward the load limit by the chip-load rule wherever the program
        stays feasible and its objective is not worse (:func:`.push.push_genes`: onto the load limit). Ignored
        for ``pareto`` and the paper's method.
    """

    objective: str = "time"
    method: str = "default"
    load_limit_N: float = 60.0
    feed_range: tuple[float, float] = (100.0, 500.0)
    spindle_range: tuple[float, float] = (1000.0, 8000.0)
    feed_step: float = 10.0
    spindle_step: float = 50.0
    feed_step_in_per_min: float = 0.1
    feed_step_mm_per_rev: float = 0.001
    feed_step_in_per_rev: float = 0.0001
    pop: int = 20
    gens: int = 10
    seed: int = 1
    workers: int = 1
    dask: Any = None
    resume: bool = False
    penalty_weight: float = 1.0
    fitness_limit: float | None = None
    min_removed_mm3: float = MIN_REMOVED_MM3
    max_cycle_factor: float = MAX_CYCLE_FACTOR
    step: float = 1e-3
    time_limit_s: float = 3600.0
    progress: bool = True
    plot: bool = True
    check_front: bool = True
    tidy: bool = True
    push: bool = True

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES:
            raise OptimizeError(f"objective must be one of {OBJECTIVES}, got {self.objective!r}")
        if self.method not in METHODS:
            raise OptimizeError(f"method must be one of {METHODS}, got {self.method!r}")
        if self.method == "paper" and self.objective == "pareto":
            raise OptimizeError("the paper's method optimises one objective: use --objective time or cost")
        if int(self.pop) != self.pop or self.pop < 2:
            raise OptimizeError(f"population size must be an integer >= 2, got {self.pop!r}")
        if int(self.gens) != self.gens or self.gens < 1:
            raise OptimizeError(f"number of generations must be an integer >= 1, got {self.gens!r}")
        if int(self.workers) != self.workers or self.workers < 1:
            raise OptimizeError(f"workers must be an integer >= 1, got {self.workers!r}")
        if not isinstance(self.check_front, (bool, np.bool_)):
            raise OptimizeError(f"check_front must be True or False, got {self.check_front!r}")
        if not isinstance(self.tidy, (bool, np.bool_)):
            raise OptimizeError(f"tidy must be True or False, got {self.tidy!r}")
        if not isinstance(self.push, (bool, np.bool_)):
            raise OptimizeError(f"push must be True or False, got {self.push!r}")

    def ranges(self) -> Ranges:
        """The search ranges and grid."""
        return Ranges(tuple(map(float, self.feed_range)), tuple(map(float, self.spindle_range)),  # type: ignore[arg-type]
                      float(self.feed_step), float(self.spindle_step), float(self.feed_step_in_per_min),
                      float(self.feed_step_mm_per_rev), float(self.feed_step_in_per_rev))

    def identity(self) -> dict[str, Any]:
        """Settings that must match for ``resume`` (everything but gens, workers, progress, plot)."""
        keep = ("objective", "method", "load_limit_N", "feed_range", "spindle_range", "feed_step", "spindle_step",
                "feed_step_in_per_min", "pop", "seed", "penalty_weight", "fitness_limit", "min_removed_mm3",
                "max_cycle_factor", "step")
        d = asdict(self)
        return {k: (list(d[k]) if isinstance(d[k], tuple) else d[k]) for k in keep}


@dataclass
class OptimizeResult:
    """Outcome of :func:`optimize` (pymoo style).

    Attributes
    ----------
    X : dict[str, float]
        Chosen individual, ``{"L0042.feed": mm/min, "L0042.spindle": rpm, ...}``.
    program_text : str
        The optimised program (only F and S words changed).
    before, after : dict
        ``cycle_time_s``, ``cost_KRW``, ``max_cutting_load_N``, ``tool_life_used`` of the original and the
        optimised program (each re-simulated alone).
    lines : list of dict
        Per cutting line: feed (mm/min) and spindle (rpm) before/after, time (s) and largest load (N)
        before/after; on a G20 line also ``feed_before_in_per_min`` and ``feed_after_in_per_min`` (the F words
        as written). On a G95 line the feeds are the feeds in effect, F x S in mm/min (the written word times
        the spindle speed), beside the words as written (``feed_before_mm_per_rev``, ``feed_after_mm_per_rev``;
        ``_in_per_rev`` under G20) and the search's gene (``feed_gene_mm_per_min``, mm/min).
    history : list of dict
        Per generation: evaluations so far, best objective, feasible count.
    front : list of dict
        Pareto objective: the feasible non-dominated individuals (time, cost, genes), in order of cycle time;
        with ``check_front`` also ``zmap_cycle_time_s``, ``zmap_cost_KRW``, ``zmap_max_cutting_load_N``,
        ``zmap_feasible``, ``zmap_reason`` and ``zmap_batch`` (see :func:`check_front_zmap`).
    evaluations : int
        Distinct individuals simulated.
    wall_time_s : float
        Wall time of the optimisation (all sessions of a resumed job), s.
    files : dict[str, Path]
        Files written.
    tool_changes : list of dict
        ``{"line": ..., "tool": ...}`` per M6 of the program, in execution order.
    notes : list of str
        What the twin assumed (as ``cnctwin simulate``'s summary): a tool of the program that the case's tool
        table (``[tools.T<n>]``) does not list has its cutting load computed with ``[tool]``. Also when the
        original program was written because no candidate passed the Z-map check (and whether the original
        itself exceeds the limit).
    tidy : dict or None
        The equal-feeds post-pass (``settings.tidy``): objective before and after (s or KRW, the search's
        path-mode figures), rounds and the accepted copies (:class:`.tidy.TidyResult`); None when it did not run.
    push : dict or None
        The onto-the-load-limit post-pass (``settings.push``): objective before and after (s or KRW, path-mode
        figures of the search), rounds, the accepted raises (:class:`.push.PushResult`) and ``evaluations``
        (distinct simulations it added); None when it did not run.
    """

    X: dict[str, float]
    program_text: str
    before: dict[str, Any]
    after: dict[str, Any]
    lines: list[dict[str, Any]]
    history: list[dict[str, Any]]
    front: list[dict[str, Any]] = field(default_factory=list)
    evaluations: int = 0
    wall_time_s: float = 0.0
    files: dict[str, Path] = field(default_factory=dict)
    recording_before: Any = None
    recording_after: Any = None
    tidy: dict[str, Any] | None = None
    push: dict[str, Any] | None = None
    tool_changes: list[dict[str, int]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


class _ProgressBar:
    """One line on stderr: generation, best objective, feasible members (TTY only)."""

    def __init__(self, enabled: bool, total: int) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self.total = total

    def __call__(self, row: dict[str, Any]) -> None:
        if not self.enabled:
            return
        frac = min(1.0, row["generation"] / self.total)
        best = row.get("best")
        best_txt = "-" if best is None else ("/".join(f"{b:.4g}" for b in best) if isinstance(best, list) else f"{best:.4g}")
        sys.stderr.write(f"\roptimize [{'#' * int(25 * frac):<25}] gen {row['generation']}/{self.total} "
                         f"best {best_txt} feasible {row['feasible']}/{row['pop']} evals {row['evaluations']}   ")
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")
            sys.stderr.flush()


#: Best candidates of the search re-simulated alone on the Z-map model, one after the other, until one is within
#: the load limit.
ALONE_CANDIDATES = 5
#: When none of those is, the next ones are checked in one batched Z-map run (the first within the limit is then
#: re-simulated alone).
BATCH_CANDIDATES = 40


def _ga_comparison(pop, P, **kwargs):
    """pymoo's GA tournament (feasibility first, then fitness), as a picklable module-level function."""
    return comp_by_cv_and_fitness(pop, P, **kwargs)


def _nsga2_comparison(pop, P, **kwargs):
    """pymoo's NSGA-II binary tournament, as a picklable module-level function."""
    return binary_tournament(pop, P, **kwargs)


def make_algorithm(problem: LineProblem, settings: OptimizeSettings):
    """The pymoo algorithm of the settings (not yet set up; picklable for checkpoints)."""
    ga_selection = TournamentSelection(func_comp=_ga_comparison)
    if settings.method == "paper":
        return GA(pop_size=settings.pop, sampling=FloatRandomSampling(), selection=ga_selection,
                  crossover=SBX(prob=0.8), mutation=PM(), repair=GridRepair(), eliminate_duplicates=True)
    ops = dict(sampling=SeededSampling(), crossover=LinewiseCrossover(), mutation=LinewiseMutation(),
               repair=GridRepair(), eliminate_duplicates=True)
    if settings.objective == "pareto":
        return NSGA2(pop_size=settings.pop, selection=TournamentSelection(func_comp=_nsga2_comparison), **ops)
    return GA(pop_size=settings.pop, selection=ga_selection, **ops)


def _backend(settings: OptimizeSettings):
    if settings.dask is not None:
        return DaskBackend(settings.dask)
    if settings.workers > 1:
        return ProcessBackend(settings.workers)
    return SerialBackend()


def _generation_row(algorithm, generation: int, evaluator: CachedEvaluator, settings: OptimizeSettings
                    ) -> dict[str, Any]:
    """History row: evaluations so far, members within the load limit, best objective among them."""
    pop = algorithm.pop
    X = pop.get("X")
    ev = evaluator(X[:, 0::2], X[:, 1::2])  # cached: no simulation
    F = pop.get("F")
    feasible = np.asarray(ev.feasible, bool)
    best: Any = None
    if feasible.any():
        if settings.objective == "pareto":
            best = [float(F[feasible, 0].min()), float(F[feasible, 1].min())]
        else:
            best = float(F[feasible, 0].min())
    return {"generation": generation, "evaluations": evaluator.evaluations, "pop": len(pop),
            "feasible": int(feasible.sum()), "best": best}


def _candidates(ctx, cache: dict, settings: OptimizeSettings) -> tuple[list[tuple], list[dict[str, Any]]]:
    """Evaluated individuals in order of preference, and the Pareto front (pareto objective)."""
    keys = list(cache)
    if not keys:
        return [], []
    ev = Evaluation.concatenate([cache[k] for k in keys])
    F, _ = objectives(ev, settings.objective, settings.method, ctx.load_limit_N, settings.penalty_weight)
    L = ctx.n_lines
    front: list[dict[str, Any]] = []
    if settings.method == "paper":
        order = np.argsort(F[:, 0], kind="stable")
        return [keys[i] for i in order if ev.success[i]], front
    feas = np.flatnonzero(ev.feasible)
    if settings.objective != "pareto":
        order = feas[np.argsort(F[feas, 0], kind="stable")]
        return [keys[i] for i in order], front
    if feas.size == 0:
        return [], front
    nd = feas[NonDominatedSorting().do(F[feas], only_non_dominated_front=True)]
    nd = nd[np.argsort(F[nd, 0], kind="stable")]
    lo, hi = F[nd].min(axis=0), F[nd].max(axis=0)
    scaled = (F[nd] - lo) / np.where(hi > lo, hi - lo, 1.0)
    knee = nd[np.argsort(np.linalg.norm(scaled, axis=1), kind="stable")]
    for i in nd.tolist():
        k = keys[i]
        front.append({"cycle_time_s": float(F[i, 0]), "cost_KRW": float(F[i, 1]),
                      "max_cutting_load_N": float(ev.max_load_N[i]),
                      "X": ctx.as_dict(np.array(k[:L]), np.array(k[L:]))})
    on_front = set(knee.tolist())
    rest = [int(i) for i in feas[np.argsort(F[feas, 0], kind="stable")] if int(i) not in on_front]
    return [keys[i] for i in knee] + [keys[i] for i in rest], front


def _score(ctx, settings: OptimizeSettings) -> Callable[[Evaluation], np.ndarray]:
    """Objective of each member of an Evaluation (s or KRW, lower is better) as the search ranks it."""
    def score(ev: Evaluation) -> np.ndarray:
        return objectives(ev, settings.objective, settings.method, ctx.load_limit_N, settings.penalty_weight)[0][:, 0]

    return score


def _single_objective_pass(settings: OptimizeSettings, candidates: list[tuple]) -> bool:
    """The post-passes run on time and cost with the default method, when the search found a feasible program."""
    return settings.method == "default" and settings.objective != "pareto" and bool(candidates)


def _post_pass(run_pass: Callable[..., PushResult | TidyResult], enabled: bool, ctx, evaluator: CachedEvaluator,
               candidates: list[tuple], settings: OptimizeSettings) -> PushResult | TidyResult | None:
    """A post-pass (:func:`.push.push_genes` or :func:`.tidy.tidy_genes`) on the best feasible individual (time
    and cost, default method), or None when it is off or does not apply; ``evaluations`` counts the distinct
    simulations it added."""
    if not enabled or not _single_objective_pass(settings, candidates):
        return None
    L = ctx.n_lines
    best = np.array(candidates[0], float)
    before = evaluator.evaluations
    result = run_pass(ctx, evaluator, _score(ctx, settings), best[:L], best[L:],
                      max_candidates=max(8, int(settings.pop)))
    result.evaluations = evaluator.evaluations - before
    return result


def _resimulate(ctx, text: str):
    """The written program alone (B = 1) on the Z-map cutting model, not the search's path-mode engagement."""
    run = run_twin(replace(ctx, engagement=None), None, None, 1, channels=None, program_text=text)
    return figures(ctx, run, 1), run.recording


def _genes(ctx, X: dict[str, float]) -> tuple[float, ...]:
    """Cache key (feeds then spindles, mm/min and rpm) of an individual given as ``{"L0042.feed": ...}``."""
    keys = ctx.keys
    try:
        return tuple(float(X[k]) for k in keys[0::2]) + tuple(float(X[k]) for k in keys[1::2])
    except KeyError as exc:
        raise OptimizeError(f"front point {sorted(X)}: missing gene {exc.args[0]!r}; "
                            f"expected the keys {keys}") from None


def check_front_zmap(ctx, front: list[dict[str, Any]], alone: dict[tuple, Evaluation] | None = None
                     ) -> list[dict[str, Any]]:
    """Re-check Pareto front points with their written programs on the Z-map cutting model.

    Parameters
    ----------
    ctx : ProblemContext
        The problem (``ctx.load_limit_N`` is the limit; no tolerance, as for the chosen program).
    front : list of dict
        Front points, each with ``X`` = ``{"L0042.feed": mm/min, "L0042.spindle": rpm, ...}``.
    alone : dict, optional
        Programs already re-simulated alone (B = 1) on the Z-map model, keyed by genes (feeds then spindles),
        each a one-member :class:`~.evaluate.Evaluation`; their figures are reused, not simulated again.

    Returns
    -------
    list of dict
        Copies of the points in the same order, each with ``zmap_cycle_time_s`` (s), ``zmap_cost_KRW``,
        ``zmap_max_cutting_load_N`` (N), ``zmap_feasible`` (finished and load <= limit), ``zmap_reason`` (empty
        when feasible) and ``zmap_batch`` (B of the run the figures come from: 1 = alone).

    Notes
    -----
    The points not in ``alone`` run in ONE batched twin call: the first one's written program
    (:meth:`~.context.ProblemContext.program_for`, the writer of ``optimized.nc``) with every member's F and S
    as NC-kernel overrides, which act as rewritten words. Every member keeps its own substep counts, so a batched
    member's figures equal its run alone with the same overrides bit for bit; against its written program run
    alone they can differ in the last digits (an S override and a written S word round differently).
    """
    alone = dict(alone or {})
    keys = [_genes(ctx, p["X"]) for p in front]
    todo = [i for i, k in enumerate(keys) if k not in alone]
    figures_of: dict[int, tuple[dict[str, Any], int]] = {
        i: (alone[k].member(0), 1) for i, k in enumerate(keys) if k in alone}
    if todo:
        L = ctx.n_lines
        genes = np.array([keys[i] for i in todo], dtype=float)
        feeds, spindles = genes[:, :L], genes[:, L:]
        batch = len(todo)
        zctx = replace(ctx, engagement=None)
        text = ctx.program_for(feeds[0], spindles[0])
        run = run_twin(zctx, feeds if batch > 1 else None, spindles if batch > 1 else None, batch,
                       program_text=text)
        ev = figures(zctx, run, batch)
        for b, i in enumerate(todo):
            figures_of[i] = (ev.member(b), batch)
    out = []
    for i, point in enumerate(front):
        m, batch = figures_of[i]
        out.append({**point, "zmap_cycle_time_s": m["cycle_time_s"], "zmap_cost_KRW": m["cost_KRW"],
                    "zmap_max_cutting_load_N": m["max_cutting_load_N"], "zmap_feasible": m["feasible"],
                    "zmap_reason": m["reason"], "zmap_batch": batch})
    return out


def optimize(program: str | Path | None = None, case: str | Path | Case | None = None,
             settings: OptimizeSettings | None = None, out: str | Path | None = None,
             machine: str | Path | None = None,
             callback: Callable[[dict[str, Any]], None] | None = None,
             reference: Reference | None = None) -> OptimizeResult:
    """Optimise feed and spindle speed per cutting line of a program on the twin.

    Parameters
    ----------
    program : str or Path, optional
        G-code file (overrides the case's program).
    case : str, Path or Case
        Case folder / ``case.toml`` with a stock (the twin must cut something).
    settings : OptimizeSettings, optional
        Objective, method, ranges, budget, workers, resume.
    out : str or Path, optional
        Output folder: ``optimized.nc``, ``report.json``, ``report.png`` and
        ``checkpoints/`` (one per generation). Required for ``resume``.
    machine : str or Path, optional
        Machine set overriding the case's.
    callback : callable, optional
        Called with the history row after every generation.
    reference : Reference, optional
        A reference run from :func:`~.reference.build_reference` with the same case, ranges, limit and
        step (skips the reference run; several optimisations of one program can share it).

    Returns
    -------
    OptimizeResult
    """
    from ..simulate import resolve_case
    from .report import write_outputs

    settings = settings or OptimizeSettings()
    if settings.resume and out is None:
        raise OptimizeError("resume needs the output folder of the interrupted job (--out)")
    resolved = resolve_case(program, case, machine)
    out_path = Path(out) if out is not None else None
    t_start = time.perf_counter()
    state = latest_checkpoint(out_path) if (settings.resume and out_path is not None) else None
    if settings.resume and out_path is not None and state is None and (out_path / "checkpoints").exists():
        raise OptimizeError(f"{out_path}/checkpoints: no readable checkpoint to resume from")

    ref_file = out_path / "checkpoints" / "reference.pkl" if out_path is not None else None
    if state is not None and ref_file is not None and ref_file.is_file():
        reference = read_pickle(ref_file)  # the resumed job's own reference run
    elif reference is not None:
        c = reference.context
        if (c.ranges != settings.ranges() or c.load_limit_N != settings.load_limit_N or c.step != settings.step
                or c.program_text != resolved.program.read_text(encoding="utf-8")):
            raise OptimizeError("the given reference was built for another program, ranges, load limit or step")
    else:
        reference = build_reference(resolved, ranges=settings.ranges(), load_limit_N=settings.load_limit_N,
                                    min_removed_mm3=settings.min_removed_mm3, step=settings.step,
                                    time_limit_s=settings.time_limit_s, max_cycle_factor=settings.max_cycle_factor)
    if ref_file is not None and state is None:
        write_pickle(ref_file, reference)
    ctx = reference.context

    backend = _backend(settings)
    try:
        if state is not None:
            if state["identity"] != settings.identity() or state["fingerprint"] != ctx.fingerprint():
                raise OptimizeError(
                    f"{state['path']}: the checkpoint belongs to another job (settings {state['identity']}); "
                    "resume with the same program, case and settings, or use a new --out")
            algorithm = state["algorithm"]
            evaluator = CachedEvaluator(ctx, backend, state["cache"])
            history = list(state["history"])
            generation = int(state["generation"])
            wall_before = float(state["wall_s"])
            problem = algorithm.problem
            algorithm.termination = MaximumGenerationTermination(settings.gens)
        else:
            evaluator = CachedEvaluator(ctx, backend)
            problem = LineProblem(ctx, settings.objective, settings.method, settings.penalty_weight)
            algorithm = make_algorithm(problem, settings)
            algorithm.setup(problem, termination=MaximumGenerationTermination(settings.gens), seed=settings.seed,
                            verbose=False)
            history, generation, wall_before = [], 0, 0.0
        problem.evaluator = evaluator
        bar = _ProgressBar(settings.progress, settings.gens)
        stop_early = any(h.get("fitness_limit_reached") for h in history)
        while generation < settings.gens and not stop_early and algorithm.has_next():
            pop = algorithm.ask()
            algorithm.evaluator.eval(problem, pop, algorithm=algorithm)
            algorithm.tell(infills=pop)
            generation += 1
            row = _generation_row(algorithm, generation, evaluator, settings)
            if settings.method == "paper" and settings.fitness_limit is not None:
                row["fitness_limit_reached"] = bool(algorithm.pop.get("F")[:, 0].min() <= settings.fitness_limit)
                stop_early = row["fitness_limit_reached"]
            history.append(row)
            lost = member_off_path(evaluator.cache) if ctx.engagement is not None else ""
            if lost:  # the path mode cannot follow every member (the original it does): restart on the Z-map
                search_on_zmap(ctx, lost)
                if ref_file is not None:
                    write_pickle(ref_file, reference)  # a resumed job searches on the Z-map model as well
                    for old in ref_file.parent.glob("gen_*.pkl"):  # the path-mode generations: not resumed
                        old.unlink()
                evaluator = CachedEvaluator(ctx, backend)
                problem = LineProblem(ctx, settings.objective, settings.method, settings.penalty_weight)
                problem.evaluator = evaluator
                algorithm = make_algorithm(problem, settings)
                algorithm.setup(problem, termination=MaximumGenerationTermination(settings.gens),
                                seed=settings.seed, verbose=False)
                history, generation, stop_early = [], 0, False
                continue
            if out_path is not None:
                write_checkpoint(out_path, generation, {
                    "identity": settings.identity(), "fingerprint": ctx.fingerprint(), "algorithm": algorithm,
                    "cache": evaluator.cache, "history": history,
                    "wall_s": wall_before + time.perf_counter() - t_start})
            bar(row)
            if callback is not None:
                callback(row)
        bar.close()
        L = ctx.n_lines
        candidates, front = _candidates(ctx, evaluator.cache, settings)
        pushed = _post_pass(push_genes, settings.push, ctx, evaluator, candidates, settings)
        if pushed is not None:
            key = tuple(float(v) for v in np.concatenate([pushed.feeds, pushed.spindles]))
            candidates = [key] + [k for k in candidates if k != key]
        tidied = _post_pass(tidy_genes, settings.tidy, ctx, evaluator, candidates, settings)
        if pushed is not None:  # every feasible program evaluated, best first: the pushed ones lead the fallbacks
            candidates, _ = _candidates(ctx, evaluator.cache, settings)
        if tidied is not None or pushed is not None:
            first = tidied if tidied is not None else pushed
            key = tuple(float(v) for v in np.concatenate([first.feeds, first.spindles]))
            candidates = [key] + [k for k in candidates if k != key]
    finally:
        backend.close()

    # choose and re-simulate the written program
    before = reference.evaluation
    chosen = None
    alone: dict[tuple, Evaluation] = {}
    notes: list[str] = []
    for key in candidates[:ALONE_CANDIDATES]:
        f, s = np.array(key[:L]), np.array(key[L:])
        text = ctx.program_for(f, s)
        ev_after, rec_after = _resimulate(ctx, text)
        alone[tuple(float(v) for v in key)] = ev_after
        if settings.method == "paper" or bool(ev_after.feasible[0]):
            chosen = (f, s, text, ev_after, rec_after)
            break
    if chosen is None and settings.method == "default" and len(candidates) > ALONE_CANDIDATES:
        # a long search crowds its best around the limit: the next ones, checked in one batched Z-map run
        extra = candidates[ALONE_CANDIDATES:ALONE_CANDIDATES + BATCH_CANDIDATES]
        checked = check_front_zmap(ctx, [{"X": ctx.as_dict(np.array(k[:L]), np.array(k[L:]))} for k in extra])
        for key, point in zip(extra, checked):
            if not point["zmap_feasible"]:
                continue
            f, s = np.array(key[:L]), np.array(key[L:])
            text = ctx.program_for(f, s)
            ev_after, rec_after = _resimulate(ctx, text)
            alone[tuple(float(v) for v in key)] = ev_after
            if bool(ev_after.feasible[0]):
                chosen = (f, s, text, ev_after, rec_after)
                break
    if chosen is None:
        chosen = (ctx.original_feed.copy(), ctx.original_spindle.copy(), ctx.program_text, before, reference.recording)
        if settings.method == "default":
            tried = min(len(candidates), ALONE_CANDIDATES + BATCH_CANDIDATES)
            over = "" if before.feasible[0] else f", although it exceeds the load limit ({before.max_load_N[0]:.4g} N)"
            notes.append(f"none of the {tried} best programs of the search stays within the load limit on the Z-map "
                         f"cutting model (or the search found none within it): the original program is written"
                         f"{over}")
    f, s, text, ev_after, rec_after = chosen
    original = text == ctx.program_text
    if front and settings.check_front:
        front = check_front_zmap(ctx, front, alone)
    lines = []
    for i, line in enumerate(ctx.lines.tolist()):
        lines.append({
            "line": int(line), "key": ctx.keys[2 * i][:-5], "s_word_line": int(ctx.spindle_lines[i]),
            "feed_before_mm_per_min": float(ctx.original_feed[i]), "feed_after_mm_per_min": float(f[i]),
            "spindle_before_rpm": float(ctx.original_spindle[i]), "spindle_after_rpm": float(s[i]),
            "time_before_s": float(before.line_time_s[0, i]), "time_after_s": float(ev_after.line_time_s[0, i]),
            "max_load_before_N": float(before.line_max_load_N[0, i]),
            "max_load_after_N": float(ev_after.line_max_load_N[0, i]),
        })
        if int(line) in ctx.per_rev_lines:  # G95: the F words as written, mm/rev (in/rev under G20)
            inch = int(line) in ctx.inch_lines
            unit = "in_per_rev" if inch else "mm_per_rev"
            word = ctx.original_feed_per_rev_word(line) if original else ctx.feed_per_rev_word(line, f[i], s[i])
            lines[-1][f"feed_before_{unit}"] = ctx.original_feed_per_rev_word(line)
            lines[-1][f"feed_after_{unit}"] = word
            # the feed in effect is the written word x S (what the NC kernel runs), not the gene it came from
            lines[-1]["feed_after_mm_per_min"] = round(word * (MM_PER_INCH if inch else 1.0) * float(s[i]), 6)
            lines[-1]["feed_gene_mm_per_min"] = float(f[i])
        elif int(line) in ctx.inch_lines:  # G20: the F words as written, in/min
            lines[-1]["feed_before_in_per_min"] = ctx.feed_word(line, ctx.original_feed[i])
            lines[-1]["feed_after_in_per_min"] = ctx.feed_word(line, f[i])
    result = OptimizeResult(
        X=ctx.as_dict(f, s), program_text=text, before=before.member(0), after=ev_after.member(0), lines=lines,
        history=history, front=front, evaluations=evaluator.evaluations,
        wall_time_s=wall_before + time.perf_counter() - t_start,
        recording_before=reference.recording, recording_after=rec_after,
        tidy=None if tidied is None else tidied.as_dict(),
        push=None if pushed is None else pushed.as_dict(),
    )
    changes = [(b.line, b.tool) for b in ctx.interpreted().blocks if isinstance(b, ToolChange)]
    result.tool_changes, tool_text = tool_notes(changes, True, ctx.case.tool.diameter_mm, ctx.case.tool.flutes,
                                                ctx.case.tools)
    result.notes = tool_text + ([ctx.search_model_note] if ctx.search_model_note else []) + notes
    if out_path is not None:
        result.files = write_outputs(result, ctx, settings, out_path)
    return result
