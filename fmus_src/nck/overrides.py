"""Per-line feed and spindle-speed overrides for a batch (the optimiser's genes).

An override of source line ``L`` behaves exactly like rewriting the F (or S)
word of line ``L`` with :func:`fmus_src.nck.writer.rewrite_program` and
re-interpreting: F and S are modal, so the new value governs every block from
line ``L`` on until the next line that sets F (S) in the program or in the
overrides. A spindle override on a line without an S word inserts a spindle
command there (as appending an S word would).
"""
from __future__ import annotations

import bisect
from typing import Mapping, Sequence

import numpy as np

from .blocks import Arc, Block, Linear, SpindleSpeed, SpindleStop
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


def insert_spindle_commands(blocks: Sequence[Block], lines: Sequence[int]) -> tuple[Block, ...]:
    """Insert a spindle command at override lines that have none (modal speed and direction).

    Raises
    ------
    NCParameterError
        If a line lies after the program end.
    """
    blocks = list(blocks)
    has = {b.line for b in blocks if isinstance(b, SpindleSpeed)}
    end_line = blocks[-1].line if blocks else 0
    for line in sorted(set(lines) - has):
        if line < 1 or line > end_line:
            raise NCParameterError(f"spindle override for line {line}: the program runs from line 1 to {end_line}")
        speed, direction, speed_line = 0.0, 0, 0
        pos = len(blocks)
        for i, b in enumerate(blocks):
            if b.line >= line:
                pos = i
                break
            if isinstance(b, SpindleSpeed):
                speed, direction, speed_line = b.speed, b.direction, b.speed_line
            elif isinstance(b, SpindleStop):
                direction = 0
        blocks.insert(pos, SpindleSpeed(line, speed, direction, speed_line))
    return tuple(blocks)


def _governing(source_line: int, line: int, override_lines: list[int]) -> int:
    k = bisect.bisect_right(override_lines, line) - 1
    if k >= 0 and override_lines[k] > source_line:
        return override_lines[k]
    return source_line


def resolve_values(blocks: Sequence[Block], batch: int, feed: Mapping[int, object] | None = None,
                   spindle: Mapping[int, object] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Feed of every feed block and speed of every spindle command, per batch member.

    Parameters
    ----------
    blocks : sequence of Block
        Blocks after :func:`insert_spindle_commands`.
    batch : int
        B.
    feed : mapping line -> scalar or (B,), m/s
    spindle : mapping line -> scalar or (B,), rad/s

    Returns
    -------
    feeds, speeds : ndarray (B, n_blocks)
        NaN where the block has no feed (speed).
    """
    n = len(blocks)
    feeds = np.full((batch, n), np.nan)
    speeds = np.full((batch, n), np.nan)
    f_over = {int(k): as_batch(v, batch, f"feed override of line {k}", positive=True) for k, v in (feed or {}).items()}
    s_over = {int(k): as_batch(v, batch, f"spindle override of line {k}", positive=False)
              for k, v in (spindle or {}).items()}
    f_lines = sorted(f_over)
    s_lines = sorted(s_over)
    for i, b in enumerate(blocks):
        if isinstance(b, (Linear, Arc)):
            g = _governing(b.feed_line, b.line, f_lines)
            feeds[:, i] = f_over[g] if g in f_over else b.feed
        elif isinstance(b, SpindleSpeed):
            g = _governing(b.speed_line, b.line, s_lines)
            speeds[:, i] = s_over[g] if g in s_over else b.speed
    return feeds, speeds
