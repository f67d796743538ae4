"""Evaluate a population on the twin in ONE batched run.

:func:`evaluate_population` is the single entry point the optimiser uses:
``build_twin(batch=B)`` + ``nck.set_overrides`` + ``Master.run``. Faster
components (a fast cutting mode, numba servo) plug in behind it unchanged.

Figures per member ``b``
------------------------
* cycle time ``Tp`` (Eq. 17 with ``Num(Dt) Ts``): the time the member met the
  twin's stop condition (program done and in position);
* production cost ``Cp`` (Eq. 19–22, :func:`orchestrator.cost.production_cost`):
  Taylor tool life with Miner's sum over the member's actual (ramped) spindle
  speed history up to ``Tp``, each sample's wear to the tool in the spindle
  (``nck.tool``) with that tool's diameter, price and Taylor constants;
* cutting load ``Fcf``: the largest ``fc_peak`` (largest resultant cutting
  force within each communication step, Eq. 13) up to ``Tp``;
* per cutting line: time the NC kernel executed it and its largest load.

A member still running at ``ctx.time_limit_s`` (the cycle-time cut-off, by
default 1.5 times the original cycle) is not simulated further: it is marked
failed (``success`` False). The batch then costs at most the cut-off in
simulated time, however slow its slowest member would be.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..cost import CostModel, ToolUse, case_tool_lives, production_cost
from ..master import Master, MasterSettings
from ..recording import Recording
from ..twin import TwinOptions, build_twin
from .context import ProblemContext

#: Channels an evaluation records (a full recording of a large batch would not fit in memory).
EVAL_CHANNELS = ("line", "spindle_rpm", "fc_peak_N", "tool")
#: Memory one batched run of an evaluation may hold for its members' recordings and NC plans, bytes. A larger
#: population of a long program runs in several batched runs, one after the other (:func:`members_per_run`).
EVAL_MEMORY_BYTES = 1 << 30


@dataclass
class Evaluation:
    """Figures of merit of B individuals.

    Attributes
    ----------
    cycle_time_s : ndarray (B,)
        Machining time Tp, s (NaN when the member failed).
    cost_KRW : ndarray (B,)
        Production cost Cp, KRW.
    max_load_N : ndarray (B,)
        Largest cutting load Fcf, N.
    tool_life_used : ndarray (B,)
        Fraction of one tool life used (Miner's sum).
    line_time_s : ndarray (B, L)
        Time spent on each cutting line, s.
    line_max_load_N : ndarray (B, L)
        Largest cutting load on each cutting line, N.
    success : ndarray of bool (B,)
        The member reached the program end without diverging.
    feasible : ndarray of bool (B,)
        ``success`` and ``max_load_N <= load_limit_N``.
    reason : list of str
        Empty for feasible members, else why not.
    tool_use : sequence of dict int -> ToolUse
        Per member, each tool's life used and cost (:attr:`orchestrator.cost.CostBreakdown.tools`); empty for a
        failed member (and for every member when not given).
    """

    cycle_time_s: np.ndarray
    cost_KRW: np.ndarray
    max_load_N: np.ndarray
    tool_life_used: np.ndarray
    line_time_s: np.ndarray
    line_max_load_N: np.ndarray
    success: np.ndarray
    feasible: np.ndarray
    reason: list[str] = field(default_factory=list)
    tool_use: tuple[dict[int, ToolUse], ...] | list[dict[int, ToolUse]] = ()

    def _tool_use(self, b: int) -> dict[int, ToolUse]:
        """Member ``b``'s tool use (empty when not known, e.g. an Evaluation pickled before it existed)."""
        use = getattr(self, "tool_use", ())
        return use[b] if b < len(use) else {}

    @property
    def batch(self) -> int:
        """Number of members B."""
        return int(self.cycle_time_s.shape[0])

    def take(self, index: np.ndarray | list[int]) -> "Evaluation":
        """The members ``index`` (a new Evaluation)."""
        idx = np.asarray(index, dtype=int)
        return Evaluation(
            self.cycle_time_s[idx], self.cost_KRW[idx], self.max_load_N[idx], self.tool_life_used[idx],
            self.line_time_s[idx], self.line_max_load_N[idx], self.success[idx], self.feasible[idx],
            [self.reason[i] for i in idx.tolist()], [self._tool_use(i) for i in idx.tolist()],
        )

    @staticmethod
    def concatenate(parts: list["Evaluation"]) -> "Evaluation":
        """Join evaluations member-wise, in order."""
        return Evaluation(
            *(np.concatenate([getattr(p, name) for p in parts]) for name in (
                "cycle_time_s", "cost_KRW", "max_load_N", "tool_life_used", "line_time_s", "line_max_load_N",
                "success", "feasible")),
            reason=[r for p in parts for r in p.reason],
            tool_use=[p._tool_use(b) for p in parts for b in range(p.batch)],
        )

    def member(self, b: int) -> dict[str, object]:
        """Member ``b`` as JSON-ready scalars (NaN as None)."""
        def clean(x: float) -> float | None:
            return float(x) if math.isfinite(float(x)) else None

        return {
            "cycle_time_s": clean(self.cycle_time_s[b]),
            "cost_KRW": clean(self.cost_KRW[b]),
            "max_cutting_load_N": clean(self.max_load_N[b]),
            "tool_life_used": clean(self.tool_life_used[b]),
            "tools": {f"T{k}": {"tool_life_used": clean(u.life_used), "tool_KRW": clean(u.KRW)}
                      for k, u in sorted(self._tool_use(b).items())},
            "feasible": bool(self.feasible[b]),
            "reason": self.reason[b],
        }


def run_twin(ctx: ProblemContext, feeds: np.ndarray | None, spindles: np.ndarray | None, batch: int,
             channels: tuple[str, ...] | None = EVAL_CHANNELS, program_text: str | None = None,
             threads: int | None = None):
    """One batched twin run with per-line overrides; returns the Master's RunResult.

    Parameters
    ----------
    ctx : ProblemContext
        The problem.
    feeds, spindles : ndarray (B, L) or None
        mm/min and rpm per cutting line; None runs the program as written.
    batch : int
        B.
    channels : tuple of str or None
        Recording channels (None: all of the twin's).
    program_text : str, optional
        Program to run instead of ``ctx.program_text``.
    threads : int, optional
        ``MasterSettings.threads`` (None: one per core, at least 4 members each).
    """
    options = TwinOptions(step=ctx.step, cutting_mode="path" if ctx.engagement is not None else "zmap",
                          engagement=ctx.engagement)
    twin = build_twin(ctx.case, batch=batch, options=options,
                      program_text=program_text if program_text is not None else ctx.program_text)
    if feeds is not None and spindles is not None:
        feed, spindle, per_rev = ctx.overrides(feeds, spindles)
        twin.nck.set_overrides(feed=feed, spindle=spindle, feed_per_rev=per_rev)
    probes = twin.probes if channels is None else [p for p in twin.probes if p.channel in channels]
    settings = MasterSettings(step=twin.options.step, time_limit=ctx.time_limit_s, stop_when=twin.stop_when,
                              limits=getattr(twin, "limits", None) or {}, threads=threads)
    return Master(twin.system, settings, probes).run()


def _column(recording: Recording, name: str, batch: int) -> np.ndarray:
    x = np.asarray(recording[name], dtype=float)
    return x.reshape(-1, 1) if batch == 1 and x.ndim == 1 else x


def per_line(cutting_lines: np.ndarray, executing: np.ndarray, weight: np.ndarray,
             load: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Time and largest load of each cutting line over one member's samples, in O(samples).

    Parameters
    ----------
    cutting_lines : ndarray (L,) of int
        Source lines of the cutting lines (distinct).
    executing : ndarray (n,)
        Line executing at each sample (the recording's ``line``, float; NaN where unknown).
    weight : ndarray (n,)
        Time each sample stands for, s.
    load : ndarray (n,)
        ``fc_peak`` at each sample, N.

    Returns
    -------
    time_s, max_load_N : ndarray (L,)
        Sum of ``weight`` and maximum of ``load`` over the samples executing each line; a line never executed
        has time 0 and load 0 (a NaN load on a line's sample makes its maximum NaN).
    """
    L = len(cutting_lines)
    time_s, max_load = np.zeros(L), np.zeros(L)
    if L == 0 or len(executing) == 0:
        return time_s, max_load
    column = np.full(int(np.max(cutting_lines)) + 1, -1, dtype=np.int64)
    column[np.asarray(cutting_lines, dtype=np.int64)] = np.arange(L)
    known = np.isfinite(executing) & (executing >= 0) & (executing < len(column))
    index = np.full(len(executing), -1, dtype=np.int64)
    index[known] = column[executing[known].astype(np.int64)]
    # samples run line by line: reduce each run of one line, then the runs of each cutting line
    starts = np.flatnonzero(np.r_[True, index[1:] != index[:-1]])
    run_line = index[starts]
    cut = run_line >= 0
    run_line = run_line[cut]
    seen = np.zeros(L, dtype=bool)
    seen[run_line] = True
    max_load[seen] = -np.inf
    with np.errstate(invalid="ignore"):  # a NaN load makes its line's maximum NaN, as max() does
        np.add.at(time_s, run_line, np.add.reduceat(weight, starts)[cut])
        np.maximum.at(max_load, run_line, np.maximum.reduceat(load, starts)[cut])
    return time_s, max_load


def _failure_line(ctx: ProblemContext, t: np.ndarray, lines: np.ndarray, why: str) -> str:
    """``"<program>:<line>: "`` of the line a member executed when it failed at the time ``why`` names
    (``"... at t = 1.234000 s: ..."``, the master's member failures), or ``""`` when unknown."""
    found = re.search(r"at t = ([0-9.eE+-]+) s", why)
    if found is None:
        return ""
    n = int(np.searchsorted(t, float(found.group(1)), side="right"))
    known = np.flatnonzero(np.isfinite(lines[:n]) & (lines[:n] > 0))
    return f"{ctx.case.program}:{int(lines[known[-1]])}: " if known.size else ""


def figures(ctx: ProblemContext, run, batch: int) -> Evaluation:
    """Evaluation of a finished batched run (see the module docstring)."""
    rec = run.recording
    t = np.asarray(rec.t, dtype=float)
    lines = _column(rec, "line", batch)
    rpm = _column(rec, "spindle_rpm", batch)
    load = _column(rec, "fc_peak_N", batch) if "fc_peak_N" in rec else np.zeros_like(rpm)
    in_spindle = _column(rec, "tool", batch) if "tool" in rec else None
    model = CostModel.from_machine(ctx.case.machine)
    default_tool, tools = case_tool_lives(model, ctx.case)
    failed = np.asarray(getattr(run, "failed", np.zeros(batch, bool)), dtype=bool)
    if failed.shape != (batch,):
        failed = np.zeros(batch, bool)
    failures = list(getattr(run, "failures", []) or [None] * batch)
    stopped = np.asarray(run.stopped_at, dtype=float)
    L = ctx.n_lines
    out = {k: np.full(batch, np.nan) for k in ("time", "cost", "load", "used")}
    line_time = np.full((batch, L), np.nan)
    line_load = np.full((batch, L), np.nan)
    success = np.zeros(batch, bool)
    reasons = []
    tool_use: list[dict[int, ToolUse]] = [{} for _ in range(batch)]
    dt = np.zeros_like(t)
    dt[:-1] = np.diff(t)
    for b in range(batch):
        ok = not failed[b] and math.isfinite(stopped[b])
        if not ok:
            why = failures[b] if b < len(failures) and failures[b] else (run.message or "")
            if "time limit" in why or (run.success and not failed[b]):
                reasons.append(f"not done within the cycle-time cut-off of {ctx.time_limit_s:g} s")
            else:
                reasons.append(f"simulation failed: {_failure_line(ctx, t, lines[:, b], why)}{why}")
            continue
        tp = float(stopped[b] - t[0])
        n = int(np.searchsorted(t, stopped[b], side="right"))
        c = production_cost(t[:n], rpm[:n, b], default_tool, model, tp,
                            None if in_spindle is None else in_spindle[:n, b], tools)
        out["time"][b], out["cost"][b], out["used"][b] = tp, c.total_KRW, c.tool_life_used
        tool_use[b] = dict(c.tools)
        out["load"][b] = float(np.nanmax(load[:n, b])) if n else 0.0
        w = dt[:n].copy()
        if n:
            w[-1] = 0.0
        line_time[b], line_load[b] = per_line(ctx.lines, lines[:n, b], w, load[:n, b])
        success[b] = True
        reasons.append("")
    feasible = success & (np.nan_to_num(out["load"], nan=np.inf) <= ctx.load_limit_N)
    for b in np.flatnonzero(success & ~feasible):
        reasons[b] = f"cutting load {out['load'][b]:.1f} N exceeds the limit {ctx.load_limit_N:g} N"
    return Evaluation(out["time"], out["cost"], out["load"], out["used"], line_time, line_load, success,
                      feasible, reasons, tool_use)


def evaluate_population(ctx: ProblemContext, feeds: np.ndarray, spindles: np.ndarray,
                        threads: int | None = None) -> Evaluation:
    """Evaluate B individuals in one batched twin run.

    Parameters
    ----------
    ctx : ProblemContext
        The problem (case, program, cutting lines, limit).
    feeds : ndarray, shape (B, L)
        Feed per cutting line, mm/min.
    spindles : ndarray, shape (B, L)
        Spindle speed per cutting line, rpm.
    threads : int, optional
        Threads of the batched run (``MasterSettings.threads``; None: one per core). The figures
        do not depend on it.

    Returns
    -------
    Evaluation
    """
    feeds = np.atleast_2d(np.asarray(feeds, dtype=float))
    spindles = np.atleast_2d(np.asarray(spindles, dtype=float))
    if feeds.shape != spindles.shape or feeds.shape[1] != ctx.n_lines:
        from .errors import OptimizeError

        raise OptimizeError(f"feeds {feeds.shape} and spindles {spindles.shape} must both be (B, {ctx.n_lines})")
    batch = feeds.shape[0]
    runs = max(1, math.ceil(batch / members_per_run(ctx)))
    parts = []
    for idx in np.array_split(np.arange(batch), runs):
        run = run_twin(ctx, feeds[idx], spindles[idx], len(idx), threads=threads)
        parts.append(figures(ctx, run, len(idx)))
        del run  # its recording and plan go before the next run's are built
    return parts[0] if runs == 1 else Evaluation.concatenate(parts)


def members_per_run(ctx: ProblemContext, memory_bytes: int | None = None) -> int:
    """Most members one batched evaluation run holds within ``memory_bytes`` (default :data:`EVAL_MEMORY_BYTES`).

    A member holds, up to the cycle-time cut-off ``ctx.time_limit_s``, one recorded row of
    :data:`EVAL_CHANNELS` per communication step and its NC plan, three reference positions per interpolation
    period of the case's machine (8 bytes each). Members are independent, so splitting a population changes no
    figure, only how many members step side by side.

    Returns
    -------
    int
        At least 1.
    """
    period = float(ctx.case.machine.si("nck").get("interpolation_period", ctx.step))
    per_member = 8 * (len(EVAL_CHANNELS) * (ctx.time_limit_s / ctx.step + 2) + 3 * (ctx.time_limit_s / period + 2))
    budget = EVAL_MEMORY_BYTES if memory_bytes is None else memory_bytes
    return max(1, int(budget // per_member))
