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
S word would). An F word under G95 is overridden with a *feed-per-revolution*
override (``feed_per_rev``, m/rev): the block's feed is then that value x the
member's spindle speed in effect (rev/s), computed as the interpreter computes
a written ``F`` under G95 (``F x S / 2 pi``), so the override and the
rewritten word agree bit for bit. Both kinds are one modal F: the latest
override line that ran governs, whichever kind it is. A feed override (m/s)
that would govern a G95 block, or a feed-per-revolution override that would
govern a G94 block, is an :class:`NCParameterError` (the interpreter refuses a
modal F given in the other feed mode), and so is a spindle override that
leaves a G95 block at speed 0.

:func:`modal_before` gives, for every run of every override line, the modal F
and S that a word written on that line replaces (resolved with all the
overrides): a word equal to it changes nothing.
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
                    spindle: Mapping[int, object] | None = None,
                    feed_per_rev: Mapping[int, object] | None = None
                    ) -> tuple[tuple[Block, ...], np.ndarray, np.ndarray]:
    """:func:`insert_spindle_commands` then :func:`resolve_values` on an interpreted program, every run of a line
    told apart (:attr:`fmus_src.nck.blocks.Program.segment_blocks`).

    Parameters
    ----------
    program : Program
    batch : int
        B.
    feed : mapping line -> scalar or (B,), m/s
    spindle : mapping line -> scalar or (B,), rad/s
    feed_per_rev : mapping line -> scalar or (B,), m/rev, optional
        Overrides of F words under G95 (see the module notes).

    Returns
    -------
    blocks : tuple of Block
        The program's blocks with the inserted spindle commands.
    feeds, speeds : ndarray (B, n_blocks)
        As :func:`resolve_values`.
    """
    blocks, runs = _insert(program.blocks, list(spindle or {}), program.segments, program.segment_blocks)
    feeds, speeds = resolve_values(blocks, batch, feed, spindle, program.segments, runs, feed_per_rev)
    return blocks, feeds, speeds


def modal_before(program: Program, batch: int, feed: Mapping[int, object] | None = None,
                 spindle: Mapping[int, object] | None = None, feed_per_rev: Mapping[int, object] | None = None
                 ) -> tuple[dict[int, np.ndarray], dict[int, np.ndarray]]:
    """The modal F and S in effect when each run of each override line starts, with all the overrides applied.

    A word written on line L with the value of L's override changes nothing in a run where the value in effect
    before L already equals it: the rewritten program then runs exactly as without that word.

    Parameters
    ----------
    program : Program
        The interpreted program.
    batch : int
        B.
    feed, spindle, feed_per_rev : mapping line -> scalar or (B,)
        As :func:`apply_overrides` (m/s, rad/s, m/rev).

    Returns
    -------
    feed_before : dict line -> ndarray (runs, B)
        For each feed or feed-per-revolution override line, the modal F its word replaces in each run: m/s
        under G94, m/rev under G95 (the kind of the line's override). NaN where it is not known from the line's
        own blocks: the line sets F itself in the program, has no feed block in that run, or the F in effect
        was given in the other feed mode.
    speed_before : dict line -> ndarray (runs, B)
        For each spindle override line, the modal spindle speed (rad/s, 0 before the first S) its word
        replaces in each run.
    """
    blocks, runs = _insert(program.blocks, list(spindle or {}), program.segments, program.segment_blocks)
    before: tuple[dict[int, list[np.ndarray]], dict[int, list[np.ndarray]]] = ({}, {})
    resolve_values(blocks, batch, feed, spindle, program.segments, runs, feed_per_rev, _before=before)
    return ({k: np.array(v) for k, v in before[0].items()}, {k: np.array(v) for k, v in before[1].items()})


def resolve_values(blocks: Sequence[Block], batch: int, feed: Mapping[int, object] | None = None,
                   spindle: Mapping[int, object] | None = None,
                   segments: Sequence[tuple[int, int]] = (), runs: Sequence[int] = (),
                   feed_per_rev: Mapping[int, object] | None = None,
                   _before: tuple[dict, dict] | None = None) -> tuple[np.ndarray, np.ndarray]:
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
    feed_per_rev : mapping line -> scalar or (B,), m/rev, optional
        Overrides of F words under G95: the governed G95 blocks' feed is this value x the member's spindle
        speed in effect (rev/s).

    Returns
    -------
    feeds, speeds : ndarray (B, n_blocks)
        NaN where the block has no feed (speed). A G95 block's feed is its ``feed_per_rev`` (or the governing
        feed-per-revolution override) x the member's spindle speed in effect (rev/s).

    Raises
    ------
    NCParameterError
        A line has both a feed and a feed-per-revolution override, a feed override would govern a G95 (feed
        per revolution) block or a feed-per-revolution override a G94 block, or a G95 block runs at speed 0.
    """
    n = len(blocks)
    feeds = np.full((batch, n), np.nan)
    speeds = np.full((batch, n), np.nan)
    f_over = {int(k): as_batch(v, batch, f"feed override of line {k}", positive=True) for k, v in (feed or {}).items()}
    per_rev_over = {int(k): as_batch(v, batch, f"feed-per-revolution override of line {k}", positive=True)
                    for k, v in (feed_per_rev or {}).items()}
    both = sorted(set(f_over) & set(per_rev_over))
    if both:
        raise NCParameterError(f"line {both[0]} has a feed override (m/s) and a feed-per-revolution override "
                               "(m/rev); expected one F per line")
    f_over.update(per_rev_over)
    per_rev_lines = set(per_rev_over)
    s_over = {int(k): as_batch(v, batch, f"spindle override of line {k}", positive=False)
              for k, v in (spindle or {}).items()}
    ran: dict[int, int] = {}  # line -> step of its latest execution
    f_cur: tuple[int, int] | None = None  # (step, line) of the latest feed override line that ran
    s_cur: tuple[int, int] | None = None
    speed_now = np.zeros(batch)  # rad/s, per member
    for step, (line, i0, i1, _) in enumerate(_walk(blocks, segments, runs)):
        ran[line] = step
        if _before is not None:
            if line in f_over:
                _before[0].setdefault(line, []).append(
                    _feed_before(blocks[i0:i1], line, f_cur, ran, f_over, per_rev_lines, batch))
            if line in s_over:
                _before[1].setdefault(line, []).append(speed_now.copy())
        if line in f_over:
            f_cur = (step, line)
        if line in s_over:
            s_cur = (step, line)
        for i in range(i0, i1):
            b = blocks[i]
            if isinstance(b, (Linear, Arc)):
                use = f_cur is not None and f_cur[0] >= ran.get(b.feed_line, -1)
                over = f_cur[1] if use else None  # type: ignore[index]
                if over is not None and (over in per_rev_lines) != (b.feed_per_rev > 0.0):
                    _mode_error(b, over, over in per_rev_lines)
                if b.feed_per_rev > 0.0:
                    per_rev = per_rev_over[over] if over is not None else np.full(batch, b.feed_per_rev)
                    feeds[:, i] = _per_revolution(b, speed_now, per_rev)
                else:
                    feeds[:, i] = f_over[over] if over is not None else b.feed
            elif isinstance(b, SpindleSpeed):
                use = s_cur is not None and s_cur[0] >= ran.get(b.speed_line, -1)
                speeds[:, i] = s_over[s_cur[1]] if use else b.speed  # type: ignore[index]
                speed_now = speeds[:, i]
    return feeds, speeds


def _mode_error(block: Linear | Arc, override_line: int, per_rev: bool) -> None:
    """Raise for an override of the other feed mode than the block it would govern."""
    if per_rev:
        raise NCParameterError(f"feed-per-revolution override of line {override_line} would govern line "
                               f"{block.line}, a feed per minute (G94) block; a G94 block needs a feed override "
                               "(m/s)")
    raise NCParameterError(f"feed override of line {override_line} would govern line {block.line}, a feed per "
                           f"revolution (G95) block whose F (line {block.feed_line}) is in mm/rev; expected a "
                           "feed-per-revolution override (m/rev) for F words under G95")


def _feed_before(line_blocks: Sequence[Block], line: int, f_cur: tuple[int, int] | None, ran: dict[int, int],
                 f_over: dict[int, np.ndarray], per_rev_lines: set[int], batch: int) -> np.ndarray:
    """Modal F in effect when one run of override line ``line`` starts (m/s, or m/rev when ``per_rev``).

    Read from the run's first feed block, whose ``feed_line`` is the modal F line at the start of the run when
    ``line`` does not set F itself; ``f_cur`` is the latest override line that ran before this run and
    ``per_rev_lines`` the lines of feed-per-revolution overrides. NaN where not known (see :func:`modal_before`).
    """
    per_rev = line in per_rev_lines
    b = next((x for x in line_blocks if isinstance(x, (Linear, Arc))), None)
    if b is None or b.feed_line == line or (b.feed_per_rev > 0.0) != per_rev:
        return np.full(batch, np.nan)
    if f_cur is not None and f_cur[0] >= ran.get(b.feed_line, -1):
        if (f_cur[1] in per_rev_lines) != per_rev:
            return np.full(batch, np.nan)  # without this line's word, its blocks would have an F of the other mode
        return f_over[f_cur[1]].copy()
    return np.full(batch, b.feed_per_rev if per_rev else b.feed)


def _per_revolution(block: Linear | Arc, speed: np.ndarray, per_rev: np.ndarray) -> np.ndarray:
    """Feed (m/s) of a G95 block: ``per_rev`` (m/rev, shape (B,)) at the members' spindle speeds ``speed``
    (rad/s, shape (B,)), as the interpreter computes a written F under G95."""
    stopped = ~(speed > 0.0)
    if stopped.any():
        raise NCParameterError(f"line {block.line}: feed per revolution (G95) at spindle speed 0 (batch member "
                               f"{int(np.argmax(stopped))}, from a spindle override); expected S > 0")
    return per_rev * speed / (2.0 * math.pi)
