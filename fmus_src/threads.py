"""Cores and member blocks for the compiled kernels that run batch members side by side in threads.

A compiled kernel that releases the GIL (:func:`fmus_src.jit.njit_nogil`) and treats every batch member on its
own (no sums over members) can run blocks of members in threads with the same numbers, member for member.
"""
from __future__ import annotations

import os

import numpy as np

#: Fewest members per block (below this a thread costs more than it saves).
MIN_MEMBERS_PER_BLOCK = 4


def usable_cores() -> int:
    """Cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def member_blocks(batch: int, parallel_calls: int = 1) -> list[tuple[int, int]]:
    """Member ranges ``(b0, b1)`` so that ``parallel_calls`` independent calls times the blocks keep every core busy.

    Parameters
    ----------
    batch : int
        Members B.
    parallel_calls : int
        Calls already running side by side for each block (e.g. one per axis).

    Returns
    -------
    list of (int, int)
        Contiguous ranges covering ``0 .. batch``, at least :data:`MIN_MEMBERS_PER_BLOCK` members each; one range
        when the calls alone fill the cores.
    """
    wanted = -(-usable_cores() // max(parallel_calls, 1))
    blocks = max(1, min(wanted, batch // MIN_MEMBERS_PER_BLOCK))
    edges = np.linspace(0, batch, blocks + 1).round().astype(int)
    return [(int(edges[j]), int(edges[j + 1])) for j in range(blocks)]
