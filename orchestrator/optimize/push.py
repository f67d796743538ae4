"""Onto the load limit: a post-pass that raises feeds of the search's best program toward the load limit.

Both optima (``time`` and ``cost``) lie on the load limit, but a short search ends with lines a few newtons
below it (the paper part's contour at 57–58 N at the default budget). Eq. 10–13 are linear in the feed per
tooth, so at a fixed spindle speed a line's largest load scales about as its feed ``F``: :func:`push_genes`
proposes, for every cutting line below the limit and below the top of the feed range, the feed
``F · limit / load`` (the *chip-load rule*), rounded DOWN to the feed grid and clipped to the range.

Only feeds change, at the line's spindle speed, for both objectives: at a fixed S a higher feed shortens the
line, and tool wear (Taylor, summed over time at the actual speed) falls with the time spent, so time and cost
both fall. A change of S at the same chip load trades machine time against tool wear; that trade is the
search's job (its mutations scale F and S together), not this pass's.

Rounds
    Each round proposes, from the current program's per-line loads, in ONE batched call of at most
    ``max_candidates`` members: every eligible line raised to its target at once, each line alone at its
    target, then the same at half-way (the bisection toward the limit). A line raised before follows the
    secant through its last two (feed, load) points instead: the same target when its load rose with its feed,
    the top of the range when it did not (its largest load is then set elsewhere, e.g. by the servo lag's tail
    of the line before it). A line whose raise overloads the
    tool (its own load over the limit, or any overload when it was raised alone) gets a cap: its next target
    stays a grid step below the lowest feed known to overload. The lines raised alone that stayed feasible
    and not worse are then combined (each at its highest such feed) and evaluated as one more member. The best
    feasible member not worse than the current program is kept (ties: the one with the larger sum of feeds,
    i.e. nearer the limit). Rounds stop when nothing is kept and no new cap was learnt, or after ``max_rounds``.
    So the pass never makes the objective (the search's path-mode figure) worse and never leaves feasibility.

Grid
    Genes are written on the search's grid (:attr:`.context.ProblemContext.feed_step`: 10 mm/min, 0.1 in/min for
    an inch program). On a G95 line the feed in effect is the written word (mm/rev, rounded half up by
    :meth:`.context.ProblemContext.feed_per_rev_word`) times S; the target gene is lowered until that feed in
    effect is at most the chip-load rule's, so the rounding of the word does not push past the target.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from fmus_src.nck.writer import MM_PER_INCH

from .context import ProblemContext
from .evaluate import Evaluation

#: Default number of rounds of the post-pass.
PUSH_ROUNDS = 4
#: Lines whose largest load is at most this (N) have no load to scale from: they are left alone.
MIN_LOAD_N = 1.0


@dataclass
class PushResult:
    """Outcome of :func:`push_genes`.

    Attributes
    ----------
    feeds, spindles : ndarray, shape (L,)
        The pushed genes, mm/min and rpm (the spindle speeds are those given).
    objective_before, objective_after : float
        Objective of the given and of the pushed program (s or KRW), path-mode figures of the search.
    moves : list of dict
        Accepted raises in order: ``line``, ``round`` (1-based), ``feed_before_mm_per_min``,
        ``feed_after_mm_per_min`` (genes), ``spindle_rpm``, ``load_before_N``, ``load_after_N`` (the line's
        largest load in the program before and after the round).
    rounds : int
        Rounds run.
    members : int
        Members submitted to the evaluator (before its cache).
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
    members: int = 0
    evaluations: int = 0

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready summary (``report.json``'s ``push``)."""
        return {"objective_before": self.objective_before, "objective_after": self.objective_after,
                "rounds": self.rounds, "evaluations": self.evaluations, "moves": self.moves}


def feed_in_effect(ctx: ProblemContext, i: int, feed: float, spindle: float) -> float:
    """The feed the NC kernel runs on cutting line ``i`` for a feed gene and a spindle gene, mm/min.

    A G94 line runs its gene (an inch line its in/min word, the gene on the 0.1 in/min grid); a G95 line runs
    its written word (mm/rev or in/rev, rounded to its grid) times S.

    Parameters
    ----------
    ctx : ProblemContext
        The problem.
    i : int
        Index of the cutting line (0-based, gene order).
    feed : float
        Feed gene, mm/min.
    spindle : float
        Spindle gene, rpm.

    Returns
    -------
    float
        mm/min.
    """
    line = int(ctx.lines[i])
    inch = line in ctx.inch_lines
    if line in ctx.per_rev_lines:
        return ctx.feed_per_rev_word(line, feed, spindle) * (MM_PER_INCH if inch else 1.0) * float(spindle)
    if inch:
        return ctx.feed_word(line, feed) * MM_PER_INCH
    return float(feed)


def top_feed(ctx: ProblemContext) -> float:
    """The highest feed gene on the grid within the feed range, mm/min."""
    step = ctx.feed_step
    return math.floor(ctx.ranges.feed_mm_per_min[1] / step + 1e-9) * step


def line_targets(ctx: ProblemContext, feeds: np.ndarray, spindles: np.ndarray, loads: np.ndarray,
                 caps: np.ndarray, previous: dict[int, tuple[float, float]] | None = None
                 ) -> dict[int, tuple[float, float | None]]:
    """Target and half-way feed genes of every line that can move toward the load limit.

    Parameters
    ----------
    ctx : ProblemContext
        The problem (``load_limit_N``, ranges and grid).
    feeds, spindles : ndarray, shape (L,)
        Current genes, mm/min and rpm.
    loads : ndarray, shape (L,)
        Largest load of each line in the current program, N.
    caps : ndarray, shape (L,)
        Lowest feed gene known to overload each line, mm/min (inf: none).
    previous : dict, optional
        ``{i: (feed in effect mm/min, load N)}`` of line ``i`` before its last kept raise (same spindle speed).
        The rule then follows the secant through that point and the current one: a line whose load rose as
        its feed (the chip-load rule's case) gets the same target, one whose load did not rise (its largest
        load set by the line before it, e.g. the servo lag's tail of a cut at the limit) the top of the range.

    Returns
    -------
    dict
        ``{i: (target, half)}``: the largest grid feed whose feed in effect is at most the chip-load rule's
        ``F · limit / load`` (F the feed in effect now; on a G94 line the rule rounded down to the grid), at
        most the top of the range and one step below the cap; ``half`` is the grid feed half-way from the
        current one (None when there is no grid feed strictly between). Lines with no load (<= :data:`MIN_LOAD_N`), at or over the limit, at the
        top of the range, or whose target would not raise the feed in effect, are left out.
    """
    step = ctx.feed_step
    top = top_feed(ctx)
    out: dict[int, tuple[float, float | None]] = {}
    for i in range(ctx.n_lines):
        f, s, load = float(feeds[i]), float(spindles[i]), float(loads[i])
        if not (MIN_LOAD_N < load < ctx.load_limit_N) or f >= top:
            continue
        now = feed_in_effect(ctx, i, f, s)
        rule = now * ctx.load_limit_N / load
        if previous is not None and i in previous and previous[i][0] < now:
            f0, l0 = previous[i]
            rule = now + (ctx.load_limit_N - load) * (now - f0) / (load - l0) if load > l0 else math.inf
        g = min(math.ceil(min(rule, top) / step - 1e-9) * step, top, float(caps[i]) - step)
        while g > f and feed_in_effect(ctx, i, g, s) > rule * (1.0 + 1e-12):  # G94: the grid feed below
            g -= step
        if g <= f or feed_in_effect(ctx, i, g, s) <= now:
            continue
        half = f + math.floor((g - f) / (2.0 * step) + 1e-9) * step
        ok_half = f < half < g and feed_in_effect(ctx, i, half, s) > now
        out[i] = (float(g), float(half) if ok_half else None)
    return out


def _proposals(feeds: np.ndarray, targets: dict[int, tuple[float, float | None]], gain: np.ndarray,
               max_members: int) -> list[dict[int, float]]:
    """Raises to evaluate, most promising first: all lines at target, each alone, all half-way, each half-way."""
    order = sorted(targets, key=lambda i: (-gain[i], i))
    full = {i: targets[i][0] for i in order}
    half = {i: targets[i][1] for i in order if targets[i][1] is not None}
    rows: list[dict[int, float]] = []
    for group in (full, half):
        if len(group) > 1:
            rows.append(dict(group))
        rows += [{i: g} for i, g in group.items()]
    seen: set[tuple] = set()
    out = []
    for row in rows:
        key = tuple(sorted(row.items()))
        if key not in seen:
            seen.add(key)
            out.append(row)
    return out[:max_members]


def push_genes(ctx: ProblemContext, evaluate: Callable[[np.ndarray, np.ndarray], Evaluation],
               score: Callable[[Evaluation], np.ndarray], feeds: np.ndarray, spindles: np.ndarray,
               max_candidates: int = 8, max_rounds: int = PUSH_ROUNDS) -> PushResult:
    """Raise cutting lines' feeds toward the load limit wherever the program stays feasible and no worse.

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
        Members of a round's batched call at most (one more for the combination of single raises).
    max_rounds : int
        Rounds at most.

    Returns
    -------
    PushResult
    """
    f = np.asarray(feeds, float).copy()
    s = np.asarray(spindles, float).copy()
    ev = evaluate(f[None, :], s[None, :])
    base = float(score(ev)[0])
    result = PushResult(f, s, base, base, members=1)
    if not bool(ev.feasible[0]) or ctx.n_lines == 0:
        return result
    loads = np.asarray(ev.line_max_load_N[0], float)
    caps = np.full(ctx.n_lines, np.inf)
    previous: dict[int, tuple[float, float]] = {}
    limit = ctx.load_limit_N
    for round_no in range(1, max_rounds + 1):
        targets = line_targets(ctx, f, s, loads, caps, previous)
        if not targets:
            break
        gain = np.asarray(ev.line_time_s[0], float) * (1.0 - f / np.maximum(
            [targets.get(i, (f[i], None))[0] for i in range(ctx.n_lines)], 1e-9))
        rows = _proposals(f, targets, gain, max(1, int(max_candidates)))
        result.rounds = round_no
        F = np.repeat(f[None, :], len(rows), axis=0)
        for r, row in enumerate(rows):
            for i, g in row.items():
                F[r, i] = g
        S = np.repeat(s[None, :], len(rows), axis=0)
        batch = evaluate(F, S)
        result.members += len(rows)
        sc = np.asarray(score(batch), float)
        new_cap = False
        ok: list[int] = []
        for r, row in enumerate(rows):
            if bool(batch.feasible[r]):
                if sc[r] <= base:
                    ok.append(r)
                continue
            over = [i for i in row if batch.line_max_load_N[r, i] > limit]
            for i in over or (list(row) if len(row) == 1 else []):
                if row[i] < caps[i]:
                    caps[i], new_cap = row[i], True
        members = [(F[r], batch.take([r]), sc[r]) for r in ok]
        best_single: dict[int, float] = {}
        for r in ok:
            if len(rows[r]) == 1:
                (i, g), = rows[r].items()
                best_single[i] = max(best_single.get(i, g), g)
        if len(best_single) > 1:
            combo = f.copy()
            for i, g in best_single.items():
                combo[i] = g
            if not any(np.array_equal(combo, F[r]) for r in range(len(rows))):
                ev_c = evaluate(combo[None, :], s[None, :])
                result.members += 1
                sc_c = float(score(ev_c)[0])
                if bool(ev_c.feasible[0]) and sc_c <= base:
                    members.append((combo, ev_c, sc_c))
        if not members:
            if new_cap:
                continue
            break
        new_f, new_ev, new_score = min(members, key=lambda m: (m[2], -float(np.sum(m[0]))))
        new_loads = np.asarray(new_ev.line_max_load_N[0], float)
        for i in np.flatnonzero(new_f != f).tolist():
            previous[i] = (feed_in_effect(ctx, i, f[i], s[i]), float(loads[i]))
            result.moves.append({"line": int(ctx.lines[i]), "round": round_no,
                                 "feed_before_mm_per_min": float(f[i]), "feed_after_mm_per_min": float(new_f[i]),
                                 "spindle_rpm": float(s[i]), "load_before_N": float(loads[i]),
                                 "load_after_N": float(new_loads[i])})
        f, ev, base, loads = np.asarray(new_f, float).copy(), new_ev, float(new_score), new_loads
    result.feeds, result.spindles, result.objective_after = f, s, base
    return result
