"""Ragged storage of the sampled references of B batch members (:class:`BatchPlan`).

A batch plan used to pad every member to the longest one (B × K_max samples); members of a long
program differ by minutes, and an optimiser's population then paid for B copies of its slowest
member. The plan is stored ragged instead, so memory grows with the *sum* of the members' lengths:

* the positions of all members are concatenated in one array ``position`` (N, 3); member ``b``
  owns the rows ``offset[b] .. offset[b] + length[b]``, the last one a *sentinel* holding the
  "after the end" position (the last sample's), so ``N = sum(length + 1)`` over distinct members
  (identical members share their rows);
* the piecewise-constant quantities (feed, spindle reference and actual speed, line, tool) are
  stored as runs: run ``i`` starts at global sample ``run_key[i]`` and holds ``run_feed[i]`` …
  ``run_tool[i]`` up to the next run (a feed or spindle ramp is one run per sample, a cut at
  constant feed and speed one run). The sentinel has feed 0 and holds the rest.

Member ``b`` at sample ``k`` (any ``k >= 0``) is global sample ``offset[b] + min(k, length[b])``:
exactly the values the padded plan held (:func:`.sampling.read_member` reads it; the properties
:attr:`BatchPlan.position` … :attr:`BatchPlan.tool` rebuild the padded (B, K) arrays for inspection).

The plan is built member by member (:class:`BatchPlanBuilder`): each member's samples are appended to a
position array grown to the exact new size in place (``ndarray.resize``: ``realloc``, which moves pages
rather than copying them for large arrays on Linux) and the member's own arrays are released before the
next member is planned, so the dense reference is never held twice and no spare capacity is touched.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..jit import NUMBA_AVAILABLE
from .plan_runs import run_starts

if TYPE_CHECKING:
    from .planner import MemberPlan

#: Per-sample quantities stored as runs, in :class:`BatchPlan` field order (``run_<name>``).
RUN_FIELDS = ("feed", "spindle_ref", "spindle_speed", "line", "tool")


@dataclass
class BatchPlan:
    """Sampled references of B members, stored ragged (see the module docstring).

    Attributes
    ----------
    flat_position : ndarray (N, 3)
        Reference positions after acc/dec after interpolation of all distinct members, one sentinel row after
        each (m).
    offset, length : ndarray (B,) of int64
        First global sample of member ``b`` and its sample count K_b (its sentinel is ``offset + length``).
    run_key : ndarray (R,) of int64
        First global sample of each run (strictly increasing; every member's first sample and sentinel start
        a run).
    run_feed, run_spindle_ref, run_spindle_speed : ndarray (R,)
        Path speed before the after-interpolation filter (m/s), commanded and actual spindle speed (rad/s).
    run_line, run_tool : ndarray (R,) of int64
        Executing source line, tool in the spindle.
    done_index : ndarray (B,) of int64
        First sample at which each member is finished.
    period : float
        Ts (s).
    """

    flat_position: np.ndarray
    offset: np.ndarray
    length: np.ndarray
    run_key: np.ndarray
    run_feed: np.ndarray
    run_spindle_ref: np.ndarray
    run_spindle_speed: np.ndarray
    run_line: np.ndarray
    run_tool: np.ndarray
    done_index: np.ndarray
    period: float

    @property
    def batch(self) -> int:
        """Number of members B."""
        return int(self.offset.shape[0])

    @property
    def n_samples(self) -> int:
        """Samples of the longest member (K of the padded view)."""
        return int(self.length.max())

    @property
    def stored_samples(self) -> int:
        """Position rows held: ``sum(length + 1)`` over distinct members."""
        return int(self.flat_position.shape[0])

    @property
    def duration(self) -> np.ndarray:
        """Program time until done (s), shape (B,)."""
        return self.done_index * self.period

    def arrays(self) -> tuple[np.ndarray, ...]:
        """``flat_position, offset, length, run_key, run_feed, run_spindle_ref, run_spindle_speed, run_line,
        run_tool, done_index``: the arguments of :func:`.sampling.read_plan` after ``kf, n_samples``."""
        return (self.flat_position, self.offset, self.length, self.run_key, self.run_feed, self.run_spindle_ref,
                self.run_spindle_speed, self.run_line, self.run_tool, self.done_index)

    # ------------------------------------------------------------------ padded views (inspection, small batches)
    def _global(self, members: np.ndarray, n: int) -> np.ndarray:
        """Global sample of ``members`` at samples ``0 .. n-1``, shape (len(members), n)."""
        k = np.arange(n, dtype=np.int64)
        return self.offset[members, None] + np.minimum(k[None, :], self.length[members, None])

    def _runs(self, name: str, g: np.ndarray) -> np.ndarray:
        return getattr(self, f"run_{name}")[np.searchsorted(self.run_key, g, side="right") - 1]

    def member(self, b: int) -> "MemberPlan":
        """Member ``b``'s own samples (K_b of them, no sentinel) as a :class:`.planner.MemberPlan`."""
        from .planner import MemberPlan

        o, n = int(self.offset[b]), int(self.length[b])
        g = np.arange(o, o + n, dtype=np.int64)
        return MemberPlan(self.flat_position[o:o + n], *(self._runs(name, g) for name in (
            "feed", "line", "tool", "spindle_ref", "spindle_speed")), int(self.done_index[b]))

    def _padded(self, name: str) -> np.ndarray:
        g = self._global(np.arange(self.batch), self.n_samples)
        return self.flat_position[g] if name == "position" else self._runs(name, g)

    @property
    def position(self) -> np.ndarray:
        """Padded copy (B, K, 3) of the positions, held after each member's end (m). Costs B × K: inspection only."""
        return self._padded("position")

    @property
    def feed(self) -> np.ndarray:
        """Padded copy (B, K) of the feed, 0 after each member's end (m/s)."""
        return self._padded("feed")

    @property
    def spindle_ref(self) -> np.ndarray:
        """Padded copy (B, K) of the commanded spindle speed (rad/s)."""
        return self._padded("spindle_ref")

    @property
    def spindle_speed(self) -> np.ndarray:
        """Padded copy (B, K) of the actual spindle speed (rad/s)."""
        return self._padded("spindle_speed")

    @property
    def line(self) -> np.ndarray:
        """Padded copy (B, K) of the executing line."""
        return self._padded("line")

    @property
    def tool(self) -> np.ndarray:
        """Padded copy (B, K) of the tool in the spindle."""
        return self._padded("tool")


def _bits(a: np.ndarray) -> np.ndarray:
    """``a`` as integers of its own width (equal bit patterns ↔ equal integers: -0.0 and NaN stay distinct)."""
    return a.view(np.int64) if a.dtype == np.float64 else a


class BatchPlanBuilder:
    """Collects distinct member plans into the ragged storage of a :class:`BatchPlan`.

    Parameters
    ----------
    reference : bool
        Find the runs with numpy only (the specification); by default the compiled
        :func:`.plan_runs.run_starts` does it, with identical results.
    """

    def __init__(self, reference: bool = False) -> None:
        self._compiled = NUMBA_AVAILABLE and not reference
        self._position = np.empty((0, 3))
        self._n = 0
        self._runs: list[tuple[np.ndarray, ...]] = []
        self._lengths: list[int] = []
        self._offsets: list[int] = []
        self._done: list[int] = []

    def add(self, plan: "MemberPlan") -> int:
        """Store one member's samples (copied; the caller may drop ``plan``); returns its index.

        The member's samples plus one sentinel (position, spindle, line and tool held, feed 0) are appended.
        """
        K = int(plan.feed.shape[0])
        need = self._n + K + 1
        self._position.resize((need, 3), refcheck=False)  # realloc to the exact size (no view of it exists)
        o = self._n
        self._position[o:o + K] = plan.position
        self._position[o + K] = plan.position[K - 1]
        self._n = need
        if self._compiled and all(getattr(plan, name).dtype == (np.int64 if name in ("line", "tool") else np.float64)
                                  for name in RUN_FIELDS):
            starts, *values = run_starts(*(_bits(np.ascontiguousarray(getattr(plan, name))) for name in RUN_FIELDS))
            runs = tuple(v.view(np.float64) if name not in ("line", "tool") else v
                         for name, v in zip(RUN_FIELDS, values))
            self._runs.append((starts + o,) + runs)
            self._offsets.append(o)
            self._lengths.append(K)
            self._done.append(int(plan.done_index))
            return len(self._lengths) - 1
        values = []
        changed = np.zeros(K + 1, dtype=bool)
        changed[0] = True
        for name in RUN_FIELDS:
            a = getattr(plan, name)
            full = np.empty(K + 1, dtype=a.dtype)
            full[:K] = a
            full[K] = 0 if name == "feed" else a[K - 1]
            bits = _bits(full)
            changed[1:] |= bits[1:] != bits[:-1]
            values.append(full)
        starts = np.flatnonzero(changed)
        self._runs.append((starts + o,) + tuple(v[starts] for v in values))
        self._offsets.append(o)
        self._lengths.append(K)
        self._done.append(int(plan.done_index))
        return len(self._lengths) - 1

    def finish(self, members: list[int], period: float) -> BatchPlan:
        """The batch plan of members ``members`` (indices returned by :meth:`add`, one per batch member)."""
        idx = np.asarray(members, dtype=np.int64)
        runs = [np.concatenate([r[i] for r in self._runs]) for i in range(1 + len(RUN_FIELDS))]
        plan = BatchPlan(self._position, np.asarray(self._offsets, dtype=np.int64)[idx],
                         np.asarray(self._lengths, dtype=np.int64)[idx], runs[0].astype(np.int64), *runs[1:],
                         done_index=np.asarray(self._done, dtype=np.int64)[idx], period=float(period))
        self._position = np.empty((0, 3))
        self._runs = []
        return plan
