"""What the members of one batch share while they are planned: items that do not depend on their F and S.

An optimiser's population varies the feed and spindle speed of a few lines; every member still interpolates
the same rapids, and the chains whose feeds no override touches (approach and plunge moves, or cuts whose
gene happens to be equal) are identical in many members. :class:`PlanReuse` keeps, for one
:func:`.planner.plan_batch` call, the interpolated rapids and chains and the in-position counts of the segments,
keyed on everything they depend on (the member's :class:`.params.NCParams`, the block indices, the chain's
feeds), so each is computed once per batch. The cached segments are the very objects a member would compute
itself (same function, same inputs), so reuse cannot change a bit; they are read, never written.
"""
from __future__ import annotations

from typing import Callable, Hashable

from .interpolator import Segment


class PlanReuse:
    """Segments and in-position counts shared by the members of one batch (see the module docstring)."""

    def __init__(self) -> None:
        self._segments: dict[Hashable, Segment] = {}
        self._settle: dict[tuple[int, tuple[int, ...], float], tuple[Segment, int]] = {}

    def segment(self, key: Hashable, make: Callable[[], Segment]) -> Segment:
        """The segment stored under ``key``, made by ``make()`` the first time.

        Parameters
        ----------
        key : hashable
            Everything the segment depends on (e.g. ``("chain", params, blocks, feeds bytes)``).
        make : callable
            Computes the segment.
        """
        seg = self._segments.get(key)
        if seg is None:
            seg = self._segments[key] = make()
        return seg

    def in_position(self, seg: Segment, boxes: list[int], width: float, count: Callable[[], int]) -> int:
        """Samples after ``seg``'s start until its own filtered reference is in position, computed once.

        Parameters
        ----------
        seg : Segment
            The move (the cache holds it, so its ``id`` stays unique).
        boxes : list of int
            Its after-interpolation filter boxes.
        width : float
            In-position width (m).
        count : callable
            Computes the count (:func:`.planner._in_position`).
        """
        key = (id(seg), tuple(boxes), float(width))
        hit = self._settle.get(key)
        if hit is None or hit[0] is not seg:
            hit = self._settle[key] = (seg, count())
        return hit[1]
