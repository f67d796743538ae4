"""Blocks of batch members stepped side by side: :func:`.loop.run_chunk` in several threads, same results.

Batch members never interact: every kernel of the compiled loop works member by
member, with per-member substeps. A batch can therefore be split into blocks of
members, each block stepped by its own thread (``run_chunk`` releases the GIL),
and every member's numbers are those of the whole batch run in one thread, bit
for bit. What couples the members is the master's schedule around the loop:
the run stops when *all* members meet the stop condition, and divergence checks,
member failures, the time limit and the end of a chunk return to Python for the
whole batch at one step.

:class:`MemberBlocks` keeps exactly that schedule:

* Each block gets copies of the member columns of every array the loop writes
  (values, states) and read-only views of the NC plans; the batch's own arrays
  are touched only when a pass is accepted. The exception is the recording: each
  block writes its members' columns of the batch's recording rows after the
  accepted samples directly (a strided view, no copy afterwards). Rows past the
  accepted samples are only ever overwritten later with the same steps' values
  (a replay runs the same steps from the same state), so they need no undo.
* The blocks run with ``stop_record``: instead of returning at the stop condition
  they note, step by step, whether all their members meet it.
* A pass is accepted when every block reached the same step with no event (or the
  time limit), and the stop condition never held for all blocks at once: the block
  columns are copied back, and the result is the single-thread one.
* Otherwise the batch's arrays are still those of the start of the pass. The first
  step at which a block met an event or all blocks met the stop condition is
  ``k_target``: the blocks run again up to ``k_target`` (same start, same steps: the
  same numbers), and from there one step runs in a single thread, which returns
  the event exactly as the single-thread loop does.

Passes are short (:data:`PASS_STEPS`), so an event wastes at most one pass.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from fmus_src.threads import MIN_MEMBERS_PER_BLOCK, usable_cores

from ..errors import CncTwinError
from .loop import EV_CHECK, EV_CHUNK, EV_TIME, NO_STOP_FLAGS, run_chunk

#: Longest pass of the blocks between two returns to Python, steps.
PASS_STEPS = 500


@dataclass(frozen=True)
class _Members:
    """A ``run_chunk`` argument with the batch members along ``axis``; ``copy=False``: read-only, a view."""

    axis: int
    copy: bool = True


_COUNTER = "counter"  # an array all members share and every block advances alike (the MCU tick): copied whole
_HAS_FAILED = "has_failed"  # per component, "some member failed": recomputed for the block's members

# Member axes of run_chunk's arguments (None: shared by all members). HEAD: max_steps ... probe_factor;
# TAIL: real_ptr ... cut, zmap. The recording buffers (between them) and the stop flags are the blocks' own.
# n_samples, positions (shared); offset, length (B,); runs (shared); done index (B,); period, start
_NCK = (None, None) + (_Members(0, copy=False),) * 2 + (None,) * 6 + (_Members(0, copy=False), None, None)
_MCU = (_Members(2), _Members(2), _Members(0), None, None, None, None, _COUNTER, _Members(0), _Members(2),
        _Members(0))
_DRIVES = (_Members(2), _Members(1), _Members(1), _Members(1), _Members(1), None, _Members(1))
# path mode: par, state, engaged; table and settings (shared); clocks, status; ka; axial table (shared); z at start;
# the table's station cutters (shared)
_CUT = ((_Members(1), _Members(1), _Members(0)) + (None,) * 11 + (_Members(0),) * 4
        + (_Members(0, copy=False), None, None, _Members(0), None, None))
_RO = _Members(0, copy=False)
# Z-map heights, grid, cells, rho; ring buffer points, arc, head, count; spacing, lag; start position, angle;
# radius, flutes (spacing, lag, radius and flutes written at a tool change); steps, Kt, Ke, Ka; clocks (time,
# torque, angle); status, diag (2, B); max substeps; the tool table (number, radius, flutes: (B, 1 + n))
_ZMAP = ((_Members(0), _RO, _RO, _RO) + (_Members(0),) * 8 + (_Members(0),) * 2 + (_RO,) * 4
         + (_Members(0),) * 4 + (_Members(1), None) + (_RO,) * 3)
HEAD = (None,) * 6 + (_Members(1),) + (None,) * 14 + (_Members(0), _Members(0, copy=False), None, None)
TAIL = (None, None, _Members(1, copy=False), _HAS_FAILED, _NCK, _MCU, _DRIVES, _CUT, _ZMAP)
_STOP_ROWS = 20  # position of stop_rows in HEAD
_DECIMATION = 5  # position of decimation in HEAD
_PROBE_ROWS = 23  # position of probe_rows in HEAD
_COMP_FAILED, _COMP_HAS_FAILED = 2, 3  # positions in TAIL


def block_count(batch: int, threads: int | None) -> int:
    """Number of member blocks for a batch of ``batch`` members.

    ``threads`` None: one per core this process may use, with at least
    :data:`MIN_MEMBERS_PER_BLOCK` members each; otherwise ``threads``, at most one per member.
    """
    if threads is None:
        cores = usable_cores()
        return max(1, min(cores, batch // MIN_MEMBERS_PER_BLOCK))
    return max(1, min(int(threads), batch))


def _split(value: object, spec: object, b0: int, b1: int, batch: int) -> object:
    """The block ``b0:b1`` of a ``run_chunk`` argument (see :data:`HEAD`)."""
    if spec is None:
        return value
    if spec is _COUNTER:
        return value.copy()
    if spec is _HAS_FAILED:
        return None  # filled in by _block_tail
    if isinstance(spec, tuple):
        return tuple(_split(v, s, b0, b1, batch) for v, s in zip(value, spec, strict=True))
    if value.shape[spec.axis] != batch:
        raise CncTwinError(f"compiled loop: an array of shape {value.shape} has no member axis {spec.axis} "
                           f"of length {batch} (layout and blocks disagree)")
    part = value[(slice(None),) * spec.axis + (slice(b0, b1),)]
    return np.array(part, order="C") if spec.copy else np.ascontiguousarray(part)


def _merge(full: object, block: object, spec: object, b0: int, b1: int, first: bool) -> None:
    """Copy a block's columns of a written argument back into the batch's array."""
    if spec is None or spec is _HAS_FAILED:
        return
    if spec is _COUNTER:
        if first:
            full[...] = block
        return
    if isinstance(spec, tuple):
        for f, b, s in zip(full, block, spec, strict=True):
            _merge(f, b, s, b0, b1, first)
        return
    if spec.copy:
        full[(slice(None),) * spec.axis + (slice(b0, b1),)] = block


@dataclass
class _Pass:
    """One block's arguments, recording views, stop flags and ``run_chunk`` result.

    ``rec`` is the block's member columns of the batch's recording after the accepted samples (a view: the
    block writes the batch's rows directly); ``rec_t`` is the block's own column of sample times (a strided
    view of a scratch array, so it has ``rec``'s array layout and the loop needs no second compilation).
    """

    head: tuple
    tail: tuple
    rec_t: np.ndarray
    rec: np.ndarray
    flags: np.ndarray
    result: tuple = ()

    @property
    def k(self) -> int:
        return int(self.result[0])

    @property
    def n_rec(self) -> int:
        return int(self.result[1])

    @property
    def event(self) -> int:
        return int(self.result[2])


class MemberBlocks:
    """Runs :func:`.loop.run_chunk` over blocks of members in threads, with the single-thread schedule.

    Parameters
    ----------
    batch : int
        Number of members B.
    n_blocks : int
        Number of blocks (threads), 2 <= n_blocks <= B.
    head, tail : tuple
        ``run_chunk``'s arguments before and after the recording buffers (the batch's own arrays; they stay
        the same objects for the whole run).
    """

    def __init__(self, batch: int, n_blocks: int, head: tuple, tail: tuple) -> None:
        if not 2 <= n_blocks <= batch:
            raise CncTwinError(f"compiled loop: {n_blocks} blocks for {batch} members")
        edges = np.linspace(0, batch, n_blocks + 1).round().astype(int)
        self.bounds = [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
        self.batch = batch
        self.head = head
        self.tail = tail
        self._executor = ThreadPoolExecutor(max_workers=n_blocks - 1, thread_name_prefix="cnctwin-block")

    def close(self) -> None:
        """Stop the worker threads."""
        self._executor.shutdown(wait=True)

    # ------------------------------------------------------------------ one pass of all blocks
    def _block_tail(self, b0: int, b1: int) -> tuple:
        tail = list(_split(self.tail, TAIL, b0, b1, self.batch))
        tail[_COMP_HAS_FAILED] = tail[_COMP_FAILED].any(axis=1)
        return tuple(tail)

    def _pass(self, k: int, k_limit: int, rec: np.ndarray, n_rec: int) -> list[_Pass]:
        capacity = (k_limit - k) // int(self.head[_DECIMATION]) + 2
        if rec.shape[1] < n_rec + capacity:
            raise CncTwinError(f"compiled loop: recording holds {rec.shape[1]} samples, a pass from step {k} to "
                               f"{k_limit} may need {n_rec + capacity}")
        times = np.empty((capacity, len(self.bounds)))
        passes = [_Pass(_split(self.head, HEAD, b0, b1, self.batch), self._block_tail(b0, b1), times[:, i],
                        rec[:, n_rec:, b0:b1], np.zeros(k_limit - k + 1, dtype=np.bool_))
                  for i, (b0, b1) in enumerate(self.bounds)]

        def run(p: _Pass) -> tuple:
            return run_chunk(k, k_limit, *p.head, p.rec_t, p.rec, 0, *p.tail, True, p.flags)

        futures = [self._executor.submit(run, p) for p in passes[1:]]
        passes[0].result = run(passes[0])
        for p, f in zip(passes[1:], futures):
            p.result = f.result()
        return passes

    def _accept(self, passes: list[_Pass], rec_t: np.ndarray, n_rec: int, n_new: int) -> None:
        for i, ((b0, b1), p) in enumerate(zip(self.bounds, passes)):
            _merge(self.head, p.head, HEAD, b0, b1, i == 0)
            _merge(self.tail, p.tail, TAIL, b0, b1, i == 0)
        rec_t[n_rec:n_rec + n_new] = passes[0].rec_t[:n_new]  # the probes' samples are in place already

    def _stop_step(self, k: int, passes: list[_Pass]) -> int | None:
        """First step of the pass at whose top every block met the stop condition (None: none)."""
        if self.head[_STOP_ROWS].shape[0] == 0:
            return None
        # tops of steps evaluated: up to the step reached, and the step itself after EV_TIME or a failure inside it
        n_eval = min(p.k - k + (0 if p.event in (EV_CHUNK, EV_CHECK) else 1) for p in passes)
        together = np.logical_and.reduce([p.flags[:n_eval] for p in passes])
        return k + int(np.argmax(together)) if together.any() else None

    # ------------------------------------------------------------------ the schedule
    def run(self, k: int, k_limit: int, rec_t: np.ndarray, rec: np.ndarray,
            n_rec: int) -> tuple[int, int, int, int, int, int, int]:
        """``run_chunk(k, k_limit, ...)`` of the whole batch (same state afterwards, same return value).

        ``rec_t`` and ``rec`` must hold ``(k_limit - k) // decimation + 2`` more samples after ``n_rec``.
        """
        passes = self._pass(k, k_limit, rec, n_rec)
        k_stop = self._stop_step(k, passes)
        events = [p.k for p in passes if p.event != EV_CHUNK]
        if k_stop is None and (not events or all(p.event == EV_TIME for p in passes)):
            n_new = passes[0].n_rec
            self._accept(passes, rec_t, n_rec, n_new)
            return passes[0].k, n_rec + n_new, passes[0].event, -1, 0, 0, 0
        k_target = min(([] if k_stop is None else [k_stop]) + events)
        if k_target > k:
            same = all(p.k == k_target and p.event in (EV_CHUNK, EV_CHECK) for p in passes)
            if not same:  # blocks ran past k_target or stopped inside it: run them again up to it
                passes = self._pass(k, k_target, rec, n_rec)
                if not all(p.k == k_target and p.event in (EV_CHUNK, EV_CHECK) for p in passes):
                    raise CncTwinError(f"compiled loop: blocks replayed to step {k_target} ended at "
                                       f"{[(p.k, p.event) for p in passes]}")
            n_new = min(p.n_rec for p in passes)  # EV_CHECK returns before recording its step
            self._accept(passes, rec_t, n_rec, n_new)
            n_rec += n_new
            if any(p.event == EV_CHECK for p in passes):
                return k_target, n_rec, EV_CHECK, -1, 0, 0, 0
        # the event's step in one thread: its return value is the single-thread loop's
        return run_chunk(k_target, k_target + 1, *self.head, rec_t, rec, n_rec, *self.tail, False,
                         NO_STOP_FLAGS)

