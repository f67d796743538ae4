"""The paper's optimiser: a pymoo genetic algorithm with batched evaluation.

Sim & Lee 2023 stop their GA at a maximum number of generations or when the
fitness reaches a limit (friction: 500 / 100, servo: 100 / 10, cutting:
500 / 1). The population size is not published; 50 is MATLAB ``ga``'s
default for up to five variables and is used here.

:func:`run_ga_lockstep` advances several independent GAs together so that one
batched simulation evaluates all their populations at once (one GA per axis,
one closed-loop simulation with ``B = pop_size`` members).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

#: Population size (MATLAB ``ga`` default for <= 5 variables; the paper does not give one).
PAPER_POP_SIZE = 50


@dataclass
class GAResult:
    """Best individual of one GA.

    Attributes
    ----------
    x : ndarray, shape (n_var,)
        Best variables.
    f : float
        Its fitness.
    generations : int
        Generations run.
    evaluations : int
        Fitness evaluations.
    history : list of float
        Best fitness after each generation.
    """

    x: np.ndarray
    f: float
    generations: int
    evaluations: int
    history: list[float] = field(default_factory=list)


def run_ga_lockstep(
    evaluate: Callable[[list[np.ndarray]], list[np.ndarray]],
    bounds: Sequence[tuple[np.ndarray, np.ndarray]],
    n_gen: int,
    fitness_limit: float,
    seed: int = 0,
    pop_size: int = PAPER_POP_SIZE,
) -> list[GAResult]:
    """Run ``len(bounds)`` independent GAs in lockstep.

    Parameters
    ----------
    evaluate : callable
        ``evaluate([X_0, X_1, ...]) -> [F_0, F_1, ...]`` with ``X_i`` of shape
        ``(P_i, n_var_i)`` and ``F_i`` of shape ``(P_i,)``. Problems that have
        already stopped get an empty ``X_i`` (shape ``(0, n_var_i)``).
    bounds : sequence of (lower, upper)
        Box of each problem.
    n_gen : int
        Maximum generations.
    fitness_limit : float
        A GA stops once its best fitness is at or below this.
    seed : int
        Seed of the first GA (the others use ``seed + i``).
    pop_size : int
        Population size.

    Returns
    -------
    list of GAResult
    """
    from pymoo.algorithms.soo.nonconvex.ga import GA
    from pymoo.core.evaluator import Evaluator
    from pymoo.core.problem import Problem
    from pymoo.problems.static import StaticProblem

    algos, problems = [], []
    for i, (lo, hi) in enumerate(bounds):
        lo = np.asarray(lo, dtype=float)
        hi = np.asarray(hi, dtype=float)
        problem = Problem(n_var=lo.size, n_obj=1, xl=lo, xu=hi)
        algo = GA(pop_size=pop_size, eliminate_duplicates=True)
        algo.setup(problem, termination=("n_gen", n_gen), seed=seed + i, verbose=False)
        algos.append(algo)
        problems.append(problem)
    history: list[list[float]] = [[] for _ in algos]
    evaluations = [0] * len(algos)
    active = [True] * len(algos)
    while any(active):
        pops = [algo.ask() if act else None for algo, act in zip(algos, active)]
        xs = [p.get("X") if p is not None else np.zeros((0, problems[i].n_var)) for i, p in enumerate(pops)]
        fs = evaluate(xs)
        for i, (algo, pop) in enumerate(zip(algos, pops)):
            if pop is None:
                continue
            f = np.asarray(fs[i], dtype=float).reshape(-1, 1)
            f = np.where(np.isfinite(f), f, 1e300)
            Evaluator().eval(StaticProblem(problems[i], F=f), pop)
            algo.tell(infills=pop)
            evaluations[i] += len(pop)
            best = float(algo.opt.get("F").min())
            history[i].append(best)
            if best <= fitness_limit or not algo.has_next():
                active[i] = False
    out = []
    for i, algo in enumerate(algos):
        opt = algo.opt
        k = int(np.argmin(opt.get("F")[:, 0]))
        out.append(GAResult(np.asarray(opt.get("X")[k], dtype=float), float(opt.get("F")[k, 0]),
                            len(history[i]), evaluations[i], history[i]))
    return out


def run_ga(
    fitness: Callable[[np.ndarray], np.ndarray],
    lower: np.ndarray,
    upper: np.ndarray,
    n_gen: int,
    fitness_limit: float,
    seed: int = 0,
    pop_size: int = PAPER_POP_SIZE,
) -> GAResult:
    """One GA; ``fitness(X)`` maps ``(P, n_var)`` to ``(P,)`` (vectorised)."""
    return run_ga_lockstep(lambda xs: [fitness(xs[0])], [(lower, upper)], n_gen, fitness_limit, seed, pop_size)[0]


def paper_objective(residuals: np.ndarray) -> np.ndarray:
    """Fitness of Eq. (4), (7), (14): ``sum e^2 + max |e|`` over the last axis."""
    r = np.asarray(residuals, dtype=float)
    return np.sum(r * r, axis=-1) + np.max(np.abs(r), axis=-1)
