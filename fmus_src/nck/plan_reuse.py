"""What the members of one batch share while they are planned: items that do not depend on their F and S.

An optimiser's population varies the feed and spindle speed of a few lines; every member still interpolates
the same rapids, and the chains whose feeds no override touches (approach and plunge moves, or cuts whose
gene happens to be equal) are identical in many members. :class:`PlanReuse` keeps, for one
:func:`.planner.plan_batch` call, the interpolated rapids and chains and the in-position counts of the segments,
keyed on everything they depend on (the member's :class:`.params.NCParams`, the block indices, the chain's
feeds), so each is computed at most twice per batch. The cached segments are the very objects a member would
compute itself (same function, same inputs), so reuse cannot change a bit; they are read, never written.

Memory: a segment is kept only from its second request on (a key seen once is remembered without its
segment), so a population whose chains all differ holds none of them: the batch plan stays the only dense copy
of the members' references (:mod:`.batch_plan`).
"""
from __future__ import annotations

from typing import Callable, Hashable

from .interpolator import Segment


class PlanReuse:
    """Segments and in-position counts shared by the members of one batch (see the module docstring)."""

    def __init__(self) -> None:
        self._seen: set[Hashable] = set()
        self._segments: dict[Hashable, Segment] = {}
        self._kept: set[int] = set()  # id() of the kept segments (alive as long as this object)
        self._settle: dict[tuple, int] = {}

    def segment(self, key: Hashable, make: Callable[[], Segment]) -> Segment:
        """The segment of ``key``: made by ``make()``, kept from the second request of ``key`` on.

        Parameters
        ----------
        key : hashable
            Everything the segment depends on (e.g. ``("chain", params, blocks, feeds bytes)``).
        make : callable
            Computes the segment.
        """
        seg = self._segments.get(key)
        if seg is not None:
            return seg
        seg = make()
        if key in self._seen:
            self._segments[key] = seg
            self._kept.add(id(seg))
        else:
            self._seen.add(key)
        return seg

    def in_position(self, seg: Segment, boxes: list[int], width: float, count: Callable[[], int],
                    servo: Hashable = None) -> int:
        """Samples after ``seg``'s start until its own filtered reference is in position (kept for kept segments).

        Parameters
        ----------
        seg : Segment
            The move.
        boxes : list of int
            Its after-interpolation filter boxes.
        width : float
            In-position width (m).
        count : callable
            Computes the count (:func:`.planner._in_position`).
        servo : hashable, optional
            The servo model of the count when it is the servo's check before a rapid (position gains and period,
            :func:`.servo_settle.servo_in_position`); None: the filtered reference's check.
        """
        if id(seg) not in self._kept:
            return count()
        key = (id(seg), tuple(boxes), float(width), servo)
        n = self._settle.get(key)
        if n is None:
            n = self._settle[key] = count()
        return n
