"""Per-line feed and spindle-speed overrides for a batch (the optimiser's genes).

An override of source line ``L`` behaves exactly like rewriting the F (or S)
word of line ``L`` with :func:`fmus_src.nck.writer.rewrite_program` and
re-interpreting: F and S are modal, so the new value governs every block from
line ``L`` on until the next line that sets F (S) in the program or in the
overrides, in execution order (:attr:`fmus_src.nck.blocks.Program.segments`:
a subprogram line runs once per M98 call). A spindle override on a line
without an S word inserts a spindle command there at each run of the line
(as appending an S word would).

Feed per revolution (G95): the feed of a G95 block is its F (m/rev) x the
spindle speed in effect, so a spindle override rescales it (as rewriting the
S word would). A feed override is in m/s and cannot stand for an F word in
mm/rev: a feed override that would govern a G95 block is an
:class:`NCParameterError` (the writer refuses such F words too), and so is a
spindle override that leaves a G95 block at speed 0.
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np

from .blocks import Arc, Block, Linear, Program, ProgramEnd, SpindleSpeed, SpindleStop
from .errors import NCParameterError


def as_batch(values: object, batch: int, what: str, *, positive: bool) -> np.ndarray:
    """Broadcast an override value to shape (B,) and check it."""
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 0:
        arr = np.full(batch, float(arr))
    if arr.shape != (batch,):
        raise NCParameterError(f"{what}: expected a scalar or shape ({batch},), got {arr.shape}")
    bad = ~np.isfinite(arr) | ((arr <= 0.0) if positive else (arr < 0.0))
    if bad.any():
        raise NCParameterError(f"{what}: values must be finite and {'> 0' if positive else '>= 0'}, "
                               f"got {arr[bad][:3].tolist()}")
    return arr


def _walk(blocks: Sequence[Block], segments: Sequence[tuple[int, int]], runs: Sequence[int] = ()):
    """Yield ``(line, i0, i1, k)`` for every source line in execution order: ``blocks[i0:i1]`` are its blocks,
    ``k`` the index of its run in ``segments``.

    ``segments`` are the runs of :attr:`fmus_src.nck.blocks.Program.segments`; empty means one run from line 1
    to the last block's line (a program without subprogram calls). The end block of an empty program (line 0)
    comes after the runs. ``runs`` (:attr:`fmus_src.nck.blocks.Program.segment_blocks`, for these blocks) gives
    the number of blocks of each run; without it a run takes every following block of its lines, which merges
    two runs of the same line with no block in between (a one-line subprogram called twice in a row).

    Raises
    ------
    NCParameterError
        The blocks do not follow the runs (blocks of another program).
    """
    if not segments:
        segments = ((1, blocks[-1].line),) if blocks else ()
    if runs and (len(runs) != len(segments) or sum(runs) != len(blocks)):
        raise NCParameterError(f"{len(runs)} run block counts adding up to {sum(runs)} do not fit {len(segments)} "
                               f"runs and {len(blocks)} blocks (pass the segment_blocks of these blocks)")
    i, n = 0, len(blocks)
    for k, (first, last) in enumerate(segments):
        stop = i + runs[k] if runs else n
        for line in range(first, last + 1):
            i0 = i
            while i < stop and blocks[i].line == line:
                i += 1
            yield line, i0, i, k
        if runs and i < stop and all(isinstance(b, ProgramEnd) for b in blocks[i:stop]):
            yield blocks[i].line, i, stop, k  # the end block of an empty program (line 0) in its run
            i = stop
        if runs and i != stop:
            break
    if i < n and all(isinstance(b, ProgramEnd) for b in blocks[i:]):
        yield blocks[i].line, i, n, max(len(segments) - 1, 0)  # the end block of an empty program (line 0)
        i = n
    if i != n:
        raise NCParameterError(f"block {i} (line {blocks[i].line}) does not follow the program's execution order "
                               "(pass the segments of the program the blocks come from)")


def insert_spindle_commands(blocks: Sequence[Block], lines: Sequence[int],
                            segments: Sequence[tuple[int, int]] = (), runs: Sequence[int] = ()) -> tuple[Block, ...]:
    """Insert a spindle command at override lines that have none (modal speed and direction).

    The command goes before the blocks of the line, at every execution of the line (a subprogram line runs
    once per call, see ``segments``).

    Parameters
    ----------
    blocks : sequence of Block
        Interpreted program.
    lines : sequence of int
        Lines with a spindle override.
    segments : sequence of (int, int), optional
        :attr:`fmus_src.nck.blocks.Program.segments` (empty: the lines run in order).
    runs : sequence of int, optional
        :attr:`fmus_src.nck.blocks.Program.segment_blocks` (empty: runs told apart by line numbers only).

    Raises
    ------
    NCParameterError
        If a line is never executed (e.g. after the program end).
    """
    return _insert(blocks, lines, segments, runs)[0]


def _insert(blocks: Sequence[Block], lines: Sequence[int], segments: Sequence[tuple[int, int]],
            runs: Sequence[int]) -> tuple[tuple[Block, ...], tuple[int, ...]]:
    """:func:`insert_spindle_commands` and the block counts of the runs after the insertion."""
    has = {b.line for b in blocks if isinstance(b, SpindleSpeed)}
    need = set(lines) - has
    if not need:
        return tuple(blocks), tuple(runs)
    out: list[Block] = []
    executed: set[int] = set()
    speed, direction, speed_line = 0.0, 0, 0
    added = [0] * len(runs)
    for line, i0, i1, k in _walk(blocks, segments, runs):
        if line in need:
            out.append(SpindleSpeed(line, speed, direction, speed_line))
            executed.add(line)
            if runs:
                added[k] += 1
        for b in blocks[i0:i1]:
            out.append(b)
            if isinstance(b, SpindleSpeed):
                speed, direction, speed_line = b.speed, b.direction, b.speed_line
            elif isinstance(b, SpindleStop):
                direction = 0
    missing = sorted(need - executed)
    if missing:
        end_line = blocks[-1].line if blocks else 0
        raise NCParameterError(f"spindle override for line {missing[0]}: the line is never executed "
                               f"(the program runs from line 1 to {end_line})")
    return tuple(out), tuple(r + a for r, a in zip(runs, added))


def apply_overrides(program: Program, batch: int, feed: Mapping[int, object] | None = None,
                    spindle: Mapping[int, object] | None = None) -> tuple[tuple[Block, ...], np.ndarray, np.ndarray]:
    """:func:`insert_spindle_commands` then :func:`resolve_values` on an interpreted program, every run of a line
    told apart (:attr:`fmus_src.nck.blocks.Program.segment_blocks`).

    Parameters
    ----------
    program : Program
    batch : int
        B.
    feed : mapping line -> scalar or (B,), m/s
    spindle : mapping line -> scalar or (B,), rad/s

    Returns
    -------
    blocks : tuple of Block
        The program's blocks with the inserted spindle commands.
    feeds, speeds : ndarray (B, n_blocks)
        As :func:`resolve_values`.
    """
    blocks, runs = _insert(program.blocks, list(spindle or {}), program.segments, program.segment_blocks)
    feeds, speeds = resolve_values(blocks, batch, feed, spindle, program.segments, runs)
    return blocks, feeds, speeds


def resolve_values(blocks: Sequence[Block], batch: int, feed: Mapping[int, object] | None = None,
                   spindle: Mapping[int, object] | None = None,
                   segments: Sequence[tuple[int, int]] = (), runs: Sequence[int] = ()) -> tuple[np.ndarray, np.ndarray]:
    """Feed of every feed block and speed of every spindle command, per batch member.

    An override of line L governs a block when L ran after the line whose F (S) word set the block's value
    (:attr:`Linear.feed_line`, :attr:`SpindleSpeed.speed_line`), or is that line, and no later override line ran
    before the block: exactly what rewriting the F (S) word of L and re-interpreting gives, also when L is in a
    subprogram (execution order from ``segments``).

    Parameters
    ----------
    blocks : sequence of Block
        Blocks after :func:`insert_spindle_commands`.
    batch : int
        B.
    feed : mapping line -> scalar or (B,), m/s
    spindle : mapping line -> scalar or (B,), rad/s
    segments : sequence of (int, int), optional
        :attr:`fmus_src.nck.blocks.Program.segments` (empty: the lines run in order).
    runs : sequence of int, optional
        Blocks of each run for ``blocks`` (after the insertion: use :func:`apply_overrides`); empty: runs told
        apart by line numbers only.

    Returns
    -------
    feeds, speeds : ndarray (B, n_blocks)
        NaN where the block has no feed (speed). A G95 block's feed is its ``feed_per_rev`` x the member's
        spindle speed in effect (rev/s).

    Raises
    ------
    NCParameterError
        A feed override would govern a G95 (feed per revolution) block, or a G95 block runs at speed 0.
    """
    n = len(blocks)
    feeds = np.full((batch, n), np.nan)
    speeds = np.full((batch, n), np.nan)
    f_over = {int(k): as_batch(v, batch, f"feed override of line {k}", positive=True) for k, v in (feed or {}).items()}
    s_over = {int(k): as_batch(v, batch, f"spindle override of line {k}", positive=False)
              for k, v in (spindle or {}).items()}
    ran: dict[int, int] = {}  # line -> step of its latest execution
    f_cur: tuple[int, int] | None = None  # (step, line) of the latest feed override line that ran
    s_cur: tuple[int, int] | None = None
    speed_now = np.zeros(batch)  # rad/s, per member
    for step, (line, i0, i1, _) in enumerate(_walk(blocks, segments, runs)):
        ran[line] = step
        if line in f_over:
            f_cur = (step, line)
        if line in s_over:
            s_cur = (step, line)
        for i in range(i0, i1):
            b = blocks[i]
            if isinstance(b, (Linear, Arc)):
                use = f_cur is not None and f_cur[0] >= ran.get(b.feed_line, -1)
                if b.feed_per_rev > 0.0:
                    feeds[:, i] = _per_revolution(b, speed_now, f_cur[1] if use else None)  # type: ignore[index]
                else:
                    feeds[:, i] = f_over[f_cur[1]] if use else b.feed  # type: ignore[index]
            elif isinstance(b, SpindleSpeed):
                use = s_cur is not None and s_cur[0] >= ran.get(b.speed_line, -1)
                speeds[:, i] = s_over[s_cur[1]] if use else b.speed  # type: ignore[index]
                speed_now = speeds[:, i]
    return feeds, speeds


def _per_revolution(block: Linear | Arc, speed: np.ndarray, override_line: int | None) -> np.ndarray:
    """Feed (m/s) of a G95 block at the members' spindle speeds ``speed`` (rad/s, shape (B,))."""
    if override_line is not None:
        raise NCParameterError(f"feed override of line {override_line} would govern line {block.line}, a feed per "
                               f"revolution (G95) block whose F (line {block.feed_line}) is in mm/rev; feed "
                               "overrides are feeds per minute: override F only on G94 lines")
    stopped = ~(speed > 0.0)
    if stopped.any():
        raise NCParameterError(f"line {block.line}: feed per revolution (G95) at spindle speed 0 (batch member "
                               f"{int(np.argmax(stopped))}, from a spindle override); expected S > 0")
    return block.feed_per_rev * speed / (2.0 * math.pi)
