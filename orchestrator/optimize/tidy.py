"""Equal feeds on equal cuts: a post-pass on the search's best program that never costs objective value.

The genetic search gives every cutting line its own feed, so a contour whose lines cut alike comes out
F410/F420/F410. A machinist expects one feed for one kind of cut. :func:`tidy_genes` takes the best individual
of the search and copies a line's feed from another cutting line wherever the program that results is feasible
and its objective is not worse (equal counts: a cycle time is a whole number of 1 ms steps, so a slightly lower
feed on a short line often costs nothing).

Where a line's feed is copied from (its *sources*)
    * the cutting lines just before and after it in the file (gene order);
    * the nearest lines before and after it that cut alike: the same largest load per feed per revolution in
      the reference run (``original_load_N * S / F``, N per mm/rev, within :data:`EQUAL_CUT_TOLERANCE`), so
      the four straight sides of a contour with arcs between them find each other.
    When the source runs at the same spindle speed, only the feed is copied; otherwise the (feed, speed) pair
    (one chip load, and no spindle change between the two lines).

Rounds
    Each round evaluates every candidate (one copy each, at most ``max_candidates``, smallest relative change
    first) in one batched call through the search's cached evaluator, keeps those that are feasible and not
    worse than the current program, and applies as many of them as do not touch each other's lines. When the
    combination is itself feasible and not worse, it is kept, else only the best single copy. Rounds stop when
    nothing is accepted or after ``max_rounds``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from .context import ProblemContext
from .evaluate import Evaluation

#: Two lines cut alike when their largest reference load per feed per revolution differ by at most this fraction.
EQUAL_CUT_TOLERANCE = 0.05
#: Lines whose reference load is below this (N) have no meaningful load per feed: only their neighbours count.
MIN_LOAD_N = 1.0
#: Default number of rounds of the post-pass.
TIDY_ROUNDS = 4


@dataclass
class TidyResult:
    """Outcome of :func:`tidy_genes`.

    Attributes
    ----------
    feeds, spindles : ndarray, shape (L,)
        The tidied genes, mm/min and rpm.
    objective_before, objective_after : float
        Objective of the search's best and of the tidied program (s or KRW), path-mode figures of the search.
    moves : list of dict
        Accepted copies in order: ``line`` (the line changed), ``from_line`` (its source), ``feed_before_mm_per_min``,
        ``feed_after_mm_per_min``, ``spindle_before_rpm``, ``spindle_after_rpm``.
    rounds : int
        Rounds run.
    evaluations : int
        Distinct simulations the pass added, set by the caller that owns the evaluator's cache
        (:func:`~.run.optimize`); 0 otherwise.
    """

    feeds: np.ndarray
    spindles: np.ndarray
    objective_before: float
    objective_after: float
    moves: list[dict[str, Any]] = field(default_factory=list)
    rounds: int = 0
    evaluations: int = 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (``report.json``'s ``tidy``)."""
        return {"objective_before": self.objective_before, "objective_after": self.objective_after,
                "rounds": self.rounds, "evaluations": self.evaluations, "moves": self.moves}


def equal_cut_classes(ctx: ProblemContext, tolerance: float = EQUAL_CUT_TOLERANCE) -> np.ndarray:
    """Class index of each cutting line (lines that cut alike share it; -1: no load to compare).

    Lines are compared by their largest reference load per feed per revolution, ``load * S / F`` (N per mm/rev;
    the force of Eq. 10–13 is linear in the feed per tooth, so at one engagement this is a constant). Sorted by
    that value, a line joins the class of the one before when the two differ by at most ``tolerance`` of the
    larger.

    Parameters
    ----------
    ctx : ProblemContext
        The problem (``original_load_N``, ``original_feed`` mm/min, ``original_spindle`` rpm).
    tolerance : float
        Relative tolerance of "alike".

    Returns
    -------
    ndarray of int, shape (L,)
    """
    L = ctx.n_lines
    load = np.asarray(ctx.original_load_N, float)
    out = np.full(L, -1, dtype=int)
    if load.size != L:
        return out
    feed = np.maximum(np.asarray(ctx.original_feed, float), 1e-9)
    k = load * np.asarray(ctx.original_spindle, float) / feed
    usable = np.flatnonzero((load > MIN_LOAD_N) & np.isfinite(k))
    cls = -1
    prev = None
    for i in usable[np.argsort(k[usable], kind="stable")].tolist():
        if prev is None or k[i] - prev > tolerance * k[i]:
            cls += 1
        out[i] = cls
        prev = k[i]
    return out


def _sources(classes: np.ndarray) -> list[list[int]]:
    """Per line: the lines its feed may be copied from (neighbours, then the nearest alike lines)."""
    L = classes.size
    out: list[list[int]] = []
    for i in range(L):
        src = [j for j in (i - 1, i + 1) if 0 <= j < L]
        if classes[i] >= 0:
            same = np.flatnonzero(classes == classes[i])
            before, after = same[same < i], same[same > i]
            for j in ([int(before[-1])] if before.size else []) + ([int(after[0])] if after.size else []):
                if j not in src:
                    src.append(j)
        out.append(src)
    return out


def _candidates(feeds: np.ndarray, spindles: np.ndarray, sources: list[list[int]]
                ) -> list[tuple[float, int, int, float, float]]:
    """Copies that change something: (relative change, line, source, new feed, new speed), smallest first."""
    seen: set[tuple[int, float, float]] = set()
    out = []
    for i, src in enumerate(sources):
        for j in src:
            if spindles[j] == spindles[i]:
                if feeds[j] == feeds[i]:
                    continue
                new = (float(feeds[j]), float(spindles[i]))
            else:
                new = (float(feeds[j]), float(spindles[j]))
            if (i, *new) in seen:
                continue
            seen.add((i, *new))
            change = abs(new[0] - feeds[i]) / max(feeds[i], new[0]) + abs(new[1] - spindles[i]) / max(
                spindles[i], new[1])
            out.append((change, i, j, *new))
    out.sort(key=lambda c: (c[0], c[1], c[2]))
    return out


def tidy_genes(ctx: ProblemContext, evaluate: Callable[[np.ndarray, np.ndarray], Evaluation],
               score: Callable[[Evaluation], np.ndarray], feeds: np.ndarray, spindles: np.ndarray,
               max_candidates: int = 32, max_rounds: int = TIDY_ROUNDS) -> TidyResult:
    """Copy feeds between lines that cut alike wherever the program stays feasible and no worse.

    Parameters
    ----------
    ctx : ProblemContext
        The problem.
    evaluate : callable
        ``evaluate(feeds (B, L) mm/min, spindles (B, L) rpm) -> Evaluation`` (the search's cached evaluator).
    score : callable
        Objective of each member of an Evaluation (s or KRW; lower is better).
    feeds, spindles : ndarray, shape (L,)
        The search's best individual, mm/min and rpm (on the grid, feasible).
    max_candidates : int
        Copies evaluated per round at most.
    max_rounds : int
        Rounds at most.

    Returns
    -------
    TidyResult
    """
    f = np.asarray(feeds, float).copy()
    s = np.asarray(spindles, float).copy()
    base_ev = evaluate(f[None, :], s[None, :])
    base = float(score(base_ev)[0])
    result = TidyResult(f, s, base, base)
    if ctx.n_lines < 2 or not bool(base_ev.feasible[0]):
        return result
    sources = _sources(equal_cut_classes(ctx))
    for _ in range(max_rounds):
        cands = _candidates(f, s, sources)[:max_candidates]
        if not cands:
            break
        result.rounds += 1
        F = np.repeat(f[None, :], len(cands), axis=0)
        S = np.repeat(s[None, :], len(cands), axis=0)
        for row, (_, i, _, nf, ns) in enumerate(cands):
            F[row, i], S[row, i] = nf, ns
        ev = evaluate(F, S)
        sc = np.asarray(score(ev), float)
        ok = [row for row in range(len(cands)) if bool(ev.feasible[row]) and sc[row] <= base]
        if not ok:
            break
        ok.sort(key=lambda row: (sc[row], row))
        chosen: list[int] = []
        touched: set[int] = set()
        for row in ok:
            _, i, j, _, _ = cands[row]
            if i in touched or j in touched:
                continue
            chosen.append(row)
            touched.update((i, j))
        new_f, new_s = f.copy(), s.copy()
        for row in chosen:
            _, i, _, nf, ns = cands[row]
            new_f[i], new_s[i] = nf, ns
        new_score = float(sc[chosen[0]])
        if len(chosen) > 1:
            ev_all = evaluate(new_f[None, :], new_s[None, :])
            all_score = float(score(ev_all)[0])
            if bool(ev_all.feasible[0]) and all_score <= base:
                new_score = all_score
            else:
                chosen = chosen[:1]
                _, i, _, nf, ns = cands[chosen[0]]
                new_f, new_s = f.copy(), s.copy()
                new_f[i], new_s[i] = nf, ns
        for row in chosen:
            _, i, j, nf, ns = cands[row]
            result.moves.append({"line": int(ctx.lines[i]), "from_line": int(ctx.lines[j]),
                                 "feed_before_mm_per_min": float(f[i]), "feed_after_mm_per_min": nf,
                                 "spindle_before_rpm": float(s[i]), "spindle_after_rpm": ns})
        f, s, base = new_f, new_s, new_score
    result.feeds, result.spindles, result.objective_after = f, s, base
    return result
