"""Optimisation of feed and spindle speed per G-code line on the twin (Sim & Lee 2023, section 3).

Public API
----------
optimize, OptimizeSettings, OptimizeResult
    Problem → Algorithm → Termination → Result, with checkpoints, workers and Dask.
check_front_zmap
    Pareto front points re-checked with their written programs on the Z-map cutting model.
evaluate_population, Evaluation
    B individuals in one batched twin call.
build_reference, ProblemContext, Ranges
    The problem (cutting lines, genes, S-word placement) from one reference run.
LineProblem
    The pymoo problem (and the line-wise operators in :mod:`.problem`).
push_genes
    Onto the load limit: the post-pass raising the search's best program's feeds (:mod:`.push`).
tidy_genes
    Equal feeds on equal cuts: the post-pass on the search's best program (:mod:`.tidy`).
"""
from __future__ import annotations

from .context import ProblemContext, Ranges
from .errors import OptimizeError
from .evaluate import Evaluation, evaluate_population
from .problem import LineProblem
from .push import PushResult, push_genes
from .reference import Reference, build_reference
from .run import OptimizeResult, OptimizeSettings, check_front_zmap, optimize
from .tidy import TidyResult, tidy_genes

__all__ = [
    "Evaluation", "LineProblem", "OptimizeError", "OptimizeResult", "OptimizeSettings", "ProblemContext", "PushResult",
    "Ranges", "Reference", "TidyResult", "build_reference", "check_front_zmap", "evaluate_population", "optimize",
    "push_genes", "tidy_genes",
]
