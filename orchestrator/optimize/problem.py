"""The pymoo problem and the line-wise operators.

Decision vector ``x`` (length ``2 L``): ``[feed_0, spindle_0, feed_1, spindle_1, ...]``
in mm/min and rpm, one pair per cutting line, named ``L0042.feed``,
``L0042.spindle`` (:attr:`.context.ProblemContext.keys`), always on the
machinist's grid (10 mm/min, or 0.1 in/min for a G20 program; 50 rpm) after :class:`GridRepair`.

Objectives and constraint (``method="default"``)
    ``time``: F = Tp (s); ``cost``: F = Cp (KRW); ``pareto``: F = (Tp, Cp).
    G = Fcf − Flim <= 0 (N): the load limit is a constraint, handled
    feasibility-first by pymoo (a feasible individual beats an infeasible one;
    two infeasible ones compare by violation).
Paper's reference (``method="paper"``, Eq. 17/18)
    F = J = Tp (or Cp) + w · max(0, Fcf − Flim), no constraint.
A failed simulation gets F = G = :data:`FAILED`.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
from pymoo.core.crossover import Crossover
from pymoo.core.mutation import Mutation
from pymoo.core.problem import Problem
from pymoo.core.repair import Repair
from pymoo.core.sampling import Sampling

from .context import ProblemContext
from .evaluate import Evaluation

#: Objective and violation given to individuals whose simulation failed.
FAILED = 1e9

OBJECTIVES = ("time", "cost", "pareto")
METHODS = ("default", "paper")


def split(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Decision vectors (N, 2L) → feeds (N, L) mm/min, spindles (N, L) rpm."""
    x = np.atleast_2d(x)
    return x[:, 0::2], x[:, 1::2]


def join(feeds: np.ndarray, spindles: np.ndarray) -> np.ndarray:
    """Feeds and spindles (N, L) → decision vectors (N, 2L)."""
    feeds, spindles = np.atleast_2d(feeds), np.atleast_2d(spindles)
    x = np.empty((feeds.shape[0], 2 * feeds.shape[1]))
    x[:, 0::2], x[:, 1::2] = feeds, spindles
    return x


def objectives(ev: Evaluation, objective: str, method: str, load_limit_N: float, weight: float
               ) -> tuple[np.ndarray, np.ndarray | None]:
    """F (N, n_obj) and G (N, 1) or None of evaluated individuals (see the module docstring)."""
    cols = {"time": [ev.cycle_time_s], "cost": [ev.cost_KRW], "pareto": [ev.cycle_time_s, ev.cost_KRW]}[objective]
    F = np.stack(cols, axis=1).astype(float)
    excess = np.asarray(ev.max_load_N, float) - load_limit_N
    failed = ~np.asarray(ev.success, bool)
    if method == "paper":
        F = F + weight * np.maximum(0.0, excess)[:, None]
        F[failed] = FAILED
        return F, None
    F[failed] = FAILED
    G = excess[:, None].copy()
    G[failed] = FAILED
    return F, G


class LineProblem(Problem):
    """pymoo problem: per-line feed and spindle speed of a G-code program.

    Parameters
    ----------
    ctx : ProblemContext
        Lines, ranges, load limit.
    objective : {"time", "cost", "pareto"}
    method : {"default", "paper"}
    penalty_weight : float
        w of Eq. 17/18 for ``method="paper"`` (objective unit per N).
    evaluator : callable, optional
        ``evaluator(feeds, spindles) -> Evaluation``; not pickled (set again on resume).
    """

    def __init__(self, ctx: ProblemContext, objective: str = "time", method: str = "default",
                 penalty_weight: float = 1.0,
                 evaluator: Callable[[np.ndarray, np.ndarray], Evaluation] | None = None) -> None:
        r = ctx.ranges
        lo, hi = ctx.snap(np.array([r.feed_mm_per_min[0]]), np.array([r.spindle_rpm[0]]))
        lo2, hi2 = ctx.snap(np.array([r.feed_mm_per_min[1]]), np.array([r.spindle_rpm[1]]))
        xl = np.tile([lo[0], hi[0]], ctx.n_lines)
        xu = np.tile([lo2[0], hi2[0]], ctx.n_lines)
        super().__init__(n_var=2 * ctx.n_lines, n_obj=2 if objective == "pareto" else 1,
                         n_ieq_constr=0 if method == "paper" else 1, xl=xl, xu=xu)
        self.ctx = ctx
        self.objective = objective
        self.method = method
        self.penalty_weight = float(penalty_weight)
        self.evaluator = evaluator
        self.x_original = join(*ctx.snap(ctx.original_feed[None, :], ctx.original_spindle[None, :]))[0]

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        state["evaluator"] = None  # executors and clients are not pickled
        return state

    def _evaluate(self, X: np.ndarray, out: dict, *args: object, **kwargs: object) -> None:
        if self.evaluator is None:
            from .errors import OptimizeError

            raise OptimizeError("LineProblem has no evaluator (set problem.evaluator after loading a checkpoint)")
        ev = self.evaluator(*split(X))
        F, G = objectives(ev, self.objective, self.method, self.ctx.load_limit_N, self.penalty_weight)
        out["F"] = F
        if G is not None:
            out["G"] = G


class GridRepair(Repair):
    """Round feeds to 10 mm/min (0.1 in/min under G20) and speeds to 50 rpm (the grid of the ranges) and clip."""

    def _do(self, problem: LineProblem, X: np.ndarray, **kwargs: object) -> np.ndarray:
        return join(*problem.ctx.snap(*split(np.asarray(X, float))))


class SeededSampling(Sampling):
    """Initial population: the original program, chip-load-scaled programs, uniform and random programs.

    * row 0: the original program (snapped into the ranges);
    * a third of the rest: one spindle speed for all lines (evenly spread from the top of the range down), each
      line's feed set by :meth:`.context.ProblemContext.chip_load_feeds` to 80–97 % of the load limit
      (rounded down)
      (the force is linear in the feed per tooth, so these start near the constraint boundary);
    * a third: one feed and one spindle speed for all lines (no spindle change, no ramp wait);
    * the rest: every line drawn independently.
    """

    def _do(self, problem: LineProblem, n_samples: int, *args: object, random_state=None, **kwargs: object
            ) -> np.ndarray:
        ctx = problem.ctx
        L = ctx.n_lines
        lo_f, lo_s, hi_f, hi_s = problem.xl[0], problem.xl[1], problem.xu[0], problem.xu[1]
        X = np.empty((n_samples, 2 * L))
        n_scaled = (n_samples - 1 + 2) // 3
        n_uniform = (n_samples - 1 - n_scaled + 1) // 2
        scalable = ctx.original_load_N.size == L and np.any(ctx.original_load_N > 0)
        for i in range(n_samples):
            if i == 0:
                X[i] = problem.x_original
            elif i <= n_scaled and scalable:
                s = hi_s - (i - 1) * (hi_s - lo_s) / n_scaled  # stratified: the top of the range first
                fraction = random_state.uniform(0.8, 0.97)
                step_f = ctx.feed_step  # round the feeds down: the load estimate is linear, not exact
                feeds = np.floor(ctx.chip_load_feeds(np.full(L, s), fraction) / step_f) * step_f
                X[i] = join(feeds, np.full(L, s))[0]
            elif i <= n_scaled + n_uniform:
                f, s = random_state.uniform(lo_f, hi_f), random_state.uniform(lo_s, hi_s)
                X[i] = join(np.full(L, f), np.full(L, s))[0]
            else:
                X[i] = join(random_state.uniform(lo_f, hi_f, L), random_state.uniform(lo_s, hi_s, L))[0]
        return join(*ctx.snap(*split(X)))


class LinewiseCrossover(Crossover):
    """Uniform crossover of whole lines: each line's (feed, spindle) pair comes from one parent."""

    def __init__(self, prob: float = 0.9) -> None:
        super().__init__(2, 2, prob=prob)

    def _do(self, problem: LineProblem, X: np.ndarray, *args: object, random_state=None, **kwargs: object
            ) -> np.ndarray:
        _, n_matings, n_var = X.shape
        swap_line = random_state.random((n_matings, n_var // 2)) < 0.5
        swap = np.repeat(swap_line, 2, axis=1)
        Y = X.copy()
        Y[0][swap], Y[1][swap] = X[1][swap], X[0][swap]
        return Y


class LinewiseMutation(Mutation):
    """Mutate whole lines: each line with probability ``1/L`` (at least one line per individual).

    A mutated line gets one of (equally likely):

    0. a Gaussian step of its feed (σ = 15 % of the range);
    1. a Gaussian step of its spindle speed;
    2. the spindle speed of the previous cutting line with the feed scaled to keep the feed per tooth
       (removing a spindle change and its ramp at about the same load);
    3. the feed and speed of a neighbouring line;
    4. feed and speed scaled together by a log-normal factor (σ = 15 %: same feed per tooth, so about the same
       load);
    5. the feed that puts the line at ``U(boundary)`` of the load limit at its spindle speed
       (:meth:`.context.ProblemContext.chip_load_feeds`: the force of Eq. 10–13 is linear in the feed per tooth,
       so the optimum of either objective lies on the load limit);
    6. its spindle speed for *every* line, each line's feed scaled to keep its feed per tooth (no spindle change
       left, about the same loads); this ends the individual's mutation.
    """

    #: Range of the load fraction of operator 5.
    boundary: tuple[float, float] = (0.9, 1.0)

    def __init__(self, prob: float = 1.0, sigma: float = 0.15) -> None:
        super().__init__(prob=prob)
        self.sigma = float(sigma)

    def _do(self, problem: LineProblem, X: np.ndarray, *args: object, random_state=None, **kwargs: object
            ) -> np.ndarray:
        X = np.asarray(X, float).copy()
        n, n_var = X.shape
        L = n_var // 2
        span_f = problem.xu[0] - problem.xl[0]
        span_s = problem.xu[1] - problem.xl[1]
        for i in range(n):
            lines = np.flatnonzero(random_state.random(L) < 1.0 / L)
            if lines.size == 0:
                lines = np.array([random_state.integers(L)])
            for j in lines.tolist():
                op = random_state.integers(7)
                if op == 5 and problem.ctx.original_load_N.size == L:  # to the load limit at this line's S
                    fraction = random_state.uniform(*self.boundary)
                    step_f = problem.ctx.feed_step  # rounded down: the load estimate is linear, not exact
                    X[i, 2 * j] = np.floor(problem.ctx.chip_load_feeds(X[i, 1::2], fraction)[j] / step_f) * step_f
                    continue
                if op == 6 and L > 1:  # this line's S everywhere, same feed per tooth on every line
                    s = X[i, 2 * j + 1]
                    X[i, 0::2] *= s / X[i, 1::2]
                    X[i, 1::2] = s
                    break
                if op == 0:
                    X[i, 2 * j] += random_state.normal(0.0, self.sigma * span_f)
                elif op == 1:
                    X[i, 2 * j + 1] += random_state.normal(0.0, self.sigma * span_s)
                elif op == 4:  # change S and F together: same feed per tooth, same load, other speed
                    factor = np.exp(random_state.normal(0.0, self.sigma))
                    X[i, 2 * j] *= factor
                    X[i, 2 * j + 1] *= factor
                elif op == 2 and L > 1:  # the previous line's S (no spindle change), same feed per tooth
                    k = j - 1 if j > 0 else 1
                    X[i, 2 * j] *= X[i, 2 * k + 1] / X[i, 2 * j + 1]
                    X[i, 2 * j + 1] = X[i, 2 * k + 1]
                elif L > 1:
                    k = min(L - 1, max(0, j + (1 if random_state.random() < 0.5 else -1)))
                    X[i, 2 * j : 2 * j + 2] = X[i, 2 * k : 2 * k + 2]
                else:
                    X[i, 2 * j + 1] += random_state.normal(0.0, self.sigma * span_s)
        X = np.clip(X, problem.xl, problem.xu)
        return join(*problem.ctx.snap(*split(X)))
