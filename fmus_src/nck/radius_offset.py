"""Cutter radius compensation C with a nonzero radius (FANUC 0i-MF / 31i-B, G17): the tool-centre path.

The interpreter writes the programmed path (the part contour) as typed blocks and, for every executed
block (source line), a :class:`LineRecord` of the compensation state after its words (G40/G41/G42 and the
radius of the active D). :class:`RadiusOffset` then makes one pass over the blocks with a look-ahead to the
next XY move and replaces the XY coordinates of the moves by the tool-centre path; every block keeps its
source line, the interpreter's block list stays the single source (no re-parsing). With a zero radius
(CAM "wear"-mode posts, which post the tool-centre path) nothing changes.

Conventions (FANUC cutter compensation C, as the 0i-MF / 31i-B operator's manuals describe it; the twin's
reading where noted)
-----------------------------------------------------------------------------------------------------------
* Offset vector: length r (the D register, geometry + wear), to the left of the direction of travel under
  G41, to the right under G42; a negative r swaps G41 and G42, and so does a G51.1 mirror (or a negative
  G51 factor) of one of X and Y (:mod:`.transforms`): the offset is made on the transformed path. The
  vector at the end of a block comes from the offset elements of this and the next move (line: the parallel
  line; arc: the circle with the same centre and radius R -+ r): the vector of a block is computed with the
  r in effect in that block, so a D change (D word or ``G10 L12/L13``) in offset mode applies to the end of
  the next move.
* Corners in offset mode, by the angle alpha between the two moves on the workpiece side:
  inner corners (alpha >= 180 deg) and outer corners with 90 <= alpha < 180 deg: the intersection of the
  two offset elements (line-line, line-arc, arc-line, arc-arc; of two intersections the one nearest the
  corner); none: alarm PS0033. Outer corners with alpha < 90 deg: FANUC's type C corner: the first offset
  element is extended along its end tangent by r, the second back along its start tangent by r, and the
  two ends are joined by straight lines (one extra line between two lines, up to three between arcs).
  Tangent transitions (the same direction within :data:`TANGENT_SIN`) add nothing.
* Start-up (type A, FANUC No. 5003#0 SUP = 0): the first block with XY motion after G41/G42 from G40;
  it must be G0/G1 (PS0034). It starts at the programmed point (vector 0) and ends at the intersection for
  an inner corner, else at the vector perpendicular to the next move at its start point. Z moves under
  G41/G42 before it keep the vector 0.
* Cancel (type A): the first move after G40 (any axis, also Z only; G2/G3 is PS0034). The move before it
  ends at the intersection for an inner corner, else (and when the cancel block has no XY motion) at the
  vector perpendicular to it at its end; the cancel block runs from there to its programmed end point.
  A program ending in offset mode ends with that perpendicular vector.
* Blocks without XY motion between two moves (Z moves, dwells, M/S/T codes, mode-only blocks, M0/M1) are
  looked through: up to :data:`MAX_NON_MOVE_BLOCKS` of them in a row (the twin's setting of FANUC's
  read-ahead, No. 19625). After more of them FANUC keeps the vector perpendicular to the previous move at
  its end point (the manuals warn of overcutting): the next line runs from that point to its own end
  vector; an arc is reached by a straight line to its offset start (the twin's choice; FANUC would
  interpolate from the kept point). Z moves in between run at the corner point.
* Extra moves of a corner carry the line (and feed) of the block before the corner; a straight line to an
  arc's offset start carries the arc's line. Rapid moves are offset like feed moves.
* Interference (alarm PS0041 style): an arc whose offset radius would be <= 0, an arc whose offset sweep
  differs from the programmed one by more than 180 deg, and a line in offset mode whose tool-centre
  motion runs against its programmed direction are errors naming the file and line.
* G18/G19, G41/G42 switched directly into each other, canned cycles, G28/G30 and G53 with a nonzero radius
  are errors (:mod:`.compensation`).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from typing import Sequence

from .blocks import Arc, Block, Linear, Rapid
from .compensation import RADIUS_ZERO
from .errors import GCodeError, fmt_length, fmt_number
from .modal import ModalState
from .offset_geometry import (
    TANGENT_SIN, Element, Point, cross, distance, dot, element_of, left_normal, nearest, offset_intersections,
)
from .settings import INCH

log = logging.getLogger(__name__)

#: Blocks without XY motion in a row that the offset looks through (FANUC look-ahead No. 19625, as set here).
MAX_NON_MOVE_BLOCKS = 3
#: Points closer than this are the same, m.
SAME_POINT = 1e-9


@dataclass(frozen=True, slots=True)
class LineRecord:
    """Compensation state after the words of one executed block.

    Attributes
    ----------
    line : int
        1-based source line.
    text : str
        Source text of the block (for messages).
    first : int
        Index of the block's first typed block in the interpreter's block list.
    side : int
        +1 under G41, -1 under G42, 0 under G40.
    offset : float
        Signed offset (m): side x the radius of the active D (positive: left of the direction of travel).
    d : int
        Active D number.
    inch : bool
        G20 in effect (messages in inch).
    """

    line: int
    text: str
    first: int
    side: int
    offset: float
    d: int
    inch: bool


@dataclass
class _Move:
    """A move of a compensation stretch: its block index, record index, role and signed offset."""

    index: int
    rec: int
    role: str  # "start-up", "offset" or "cancel"
    offset: float
    planar: bool
    element: Element | None = None


@dataclass(frozen=True)
class _Joint:
    """Where the move before a corner ends, the extra points of the corner, and where the next move starts.

    The corner moves run ``end_a -> corner[0] -> ... -> corner[-1]`` (the line of the move before), then
    ``-> connect[0] -> ... -> connect[-1]`` (the line of the move after); the next move starts at ``start_b``.
    """

    end_a: Point
    corner: tuple[Point, ...]
    connect: tuple[Point, ...]
    start_b: Point

    @property
    def mid(self) -> Point:
        """Where blocks without XY motion between the two moves run."""
        return self.corner[-1] if self.corner else self.end_a


class RadiusOffset:
    """Records the compensation state block by block, then offsets the finished block list.

    Parameters
    ----------
    file : str
        Program name for messages.
    """

    def __init__(self, file: str) -> None:
        self.file = file
        self.records: list[LineRecord] = []
        self._used = False  # G41/G42 seen

    def record(self, st: ModalState, line: int, text: str, first: int) -> None:
        """Note the state after block ``line`` (``first``: index of its first typed block); nothing before the
        first G41/G42 (those blocks run as programmed)."""
        if st.comp == 40 and not self._used:
            return
        self._used = True
        side = {40: 0, 41: 1, 42: -1}[st.comp] * st.xf.handedness("XY")  # a mirror exchanges G41/G42 (FANUC)
        offset = side * st.tool_radius() if side else 0.0
        self.records.append(LineRecord(line, text, first, side, offset, st.d, st.scale == INCH))

    def apply(self, blocks: Sequence[Block], runs: Sequence[int]) -> tuple[list[Block], list[int]]:
        """The blocks with the tool-centre path of every G41/G42 stretch with a nonzero radius.

        Parameters
        ----------
        blocks : sequence of Block
            The programmed blocks in execution order.
        runs : sequence of int
            Blocks of each run of source lines (:attr:`~fmus_src.nck.blocks.Program.segment_blocks`).

        Returns
        -------
        blocks : list of Block
            Offset moves, plus the extra corner moves right after the move before the corner.
        runs : list of int
            ``runs`` counting the extra moves.

        Raises
        ------
        GCodeError
            PS0034 (start-up on an arc), PS0033 (no intersection), PS0041-style interference.
        """
        if not self._used:
            return list(blocks), list(runs)
        owner = self._owners(len(blocks))
        replaced: dict[int, Block] = {}
        after: dict[int, list[Block]] = {}
        before: dict[int, list[Block]] = {}
        logged = False
        for stretch in self._stretches(blocks, owner):
            if all(abs(m.offset) <= RADIUS_ZERO for m in stretch if m.role != "cancel"):
                if not logged:
                    rec = self.records[stretch[0].rec]
                    log.info("%s:%d: G4%d with D%d = 0: the programmed path is taken as the tool-centre path "
                             "(a CAM 'wear'-mode post)", self.file, rec.line, 1 if rec.side > 0 else 2, rec.d)
                    logged = True
                continue
            self._offset(stretch, blocks, owner, replaced, after, before)
        if not replaced:  # zero radius everywhere ("wear"-mode posts): the programmed blocks
            return list(blocks), list(runs)
        out: list[Block] = []
        expansion: list[int] = []
        for i, b in enumerate(blocks):
            pre, post = before.get(i, []), after.get(i, [])
            out.extend(pre)
            out.append(replaced.get(i, b))
            out.extend(post)
            expansion.append(1 + len(pre) + len(post))
        new_runs: list[int] = []
        i = 0
        for count in runs:
            new_runs.append(sum(expansion[i:i + count]))
            i += count
        return out, new_runs

    # ------------------------------------------------------------------ stretches
    def _owners(self, n: int) -> list[int]:
        """Record index of every block (-1 for blocks before the first record or after the last one's blocks)."""
        owner = [-1] * n
        recs = self.records
        for k, rec in enumerate(recs):
            stop = recs[k + 1].first if k + 1 < len(recs) else n
            for i in range(rec.first, min(stop, n)):
                owner[i] = k
        return owner

    def _stretches(self, blocks: Sequence[Block], owner: list[int]) -> list[list[_Move]]:
        """The moves from each start-up to its cancel (or to the end of the program)."""
        stretches: list[list[_Move]] = []
        current: list[_Move] = []
        for i, b in enumerate(blocks):
            if not isinstance(b, (Rapid, Linear, Arc)) or owner[i] < 0:
                continue
            rec = self.records[owner[i]]
            planar = _has_xy(b)
            if rec.side == 0:
                if current:
                    current.append(_Move(i, owner[i], "cancel", 0.0, planar))
                    stretches.append(current)
                    current = []
            elif planar:
                current.append(_Move(i, owner[i], "offset" if current else "start-up", rec.offset, True))
        if current:
            stretches.append(current)
        return stretches

    # ------------------------------------------------------------------ one stretch
    def _offset(self, moves: list[_Move], blocks: Sequence[Block], owner: list[int], replaced: dict[int, Block],
                after: dict[int, list[Block]], before: dict[int, list[Block]]) -> None:
        """Offset the moves of one stretch (see the module docstring)."""
        first = blocks[moves[0].index]
        if isinstance(first, Arc):
            rec = self.records[moves[0].rec]
            g = "G2" if first.clockwise else "G3"
            raise self._error(rec, g, f"cutter compensation start-up after G41/G42 in circular interpolation {g} "
                              "(FANUC alarm PS0034)", "the first XY move after G41/G42 in G0 or G1")
        for m in moves:
            b = blocks[m.index]
            if m.planar:
                m.element = element_of(b)  # type: ignore[arg-type]
            if isinstance(b, Arc) and m.role != "cancel":
                self._check_arc_radius(m, b)
        starts: dict[int, Point] = {0: moves[0].element.start}  # type: ignore[union-attr]
        ends: dict[int, Point] = {}
        for j in range(len(moves) - 1):
            a, b = moves[j], moves[j + 1]
            joint = self._joint(a, b, b.rec - a.rec - 1)
            ends[j], starts[j + 1] = joint.end_a, joint.start_b
            ba, bb = blocks[a.index], blocks[b.index]
            z_a = ba.end[2]  # type: ignore[union-attr]
            after[a.index] = _segments(ba, joint.end_a, joint.corner, z_a)  # type: ignore[arg-type]
            before[b.index] = _segments(bb, joint.mid, joint.connect, bb.start[2])  # type: ignore[arg-type,union-attr]
            self._place_between(blocks, a.index + 1, b.index, joint.mid, replaced)
        last = moves[-1]
        if last.role != "cancel":  # the program ends in offset mode: perpendicular vector
            ends[len(moves) - 1] = last.element.offset_point(last.offset, True)  # type: ignore[union-attr]
            self._place_between(blocks, last.index + 1, len(blocks), ends[len(moves) - 1], replaced)
        for j, m in enumerate(moves):
            b = blocks[m.index]
            s = starts[j]
            e = ends.get(j, (b.end[0], b.end[1]))  # type: ignore[union-attr]
            new = replace(b, start=(s[0], s[1], b.start[2]),  # type: ignore[type-var,union-attr]
                          end=(e[0], e[1], b.end[2]))  # type: ignore[union-attr]
            if m.role == "offset":
                self._check_direction(m, b, new)  # type: ignore[arg-type]
            replaced[m.index] = new

    def _joint(self, a: _Move, b: _Move, gap: int) -> _Joint:
        """Corner between move ``a`` and the next move ``b`` with ``gap`` blocks without XY motion between."""
        ea, sa = a.element, a.offset
        assert ea is not None
        perp = ea.offset_point(sa, True)
        if b.role == "cancel":
            if not b.planar or gap > MAX_NON_MOVE_BLOCKS:
                return _Joint(perp, (), (), perp)
            assert b.element is not None
            if self._kind(ea, b.element, sa) == "inner":
                x = self._intersection(a, sa, b, sa)
                return _Joint(x, (), (), x)
            return _Joint(perp, (), (), perp)
        eb, sb = b.element, b.offset
        assert eb is not None
        if gap > MAX_NON_MOVE_BLOCKS:  # FANUC keeps the vector perpendicular to the previous move
            return _reach(eb, sb, perp, ())
        kind = self._kind(ea, eb, sa or sb)
        if a.role == "start-up":  # type A: the intersection inside, else perpendicular to the next move
            if kind == "inner":
                x = self._intersection(a, sa, b, sb)
                return _Joint(x, (), (), x)
            n = left_normal(eb.tangent(False))
            return _reach(eb, sb, (eb.start[0] + sa * n[0], eb.start[1] + sa * n[1]), ())
        if kind == "tangent":
            return _reach(eb, sb, perp, ())
        if kind in ("inner", "obtuse"):
            x = self._intersection(a, sa, b, sb)
            return _Joint(x, (), (), x)
        # outer corner with alpha < 90 deg: FANUC type C (extend both offsets by r, join by a line)
        ta, tb = ea.tangent(True), eb.tangent(False)
        xb = eb.offset_point(sb, False)
        v1 = (perp[0] + abs(sa) * ta[0], perp[1] + abs(sa) * ta[1])
        v2 = (xb[0] - abs(sb) * tb[0], xb[1] - abs(sb) * tb[1])
        pts = ([perp] if ea.is_arc else []) + [v1, v2] + ([xb] if eb.is_arc else [])
        return _Joint(pts[0], tuple(pts[1:]), (), pts[-1])

    @staticmethod
    def _kind(ea: Element, eb: Element, s: float) -> str:
        """Corner type for the offset side of ``s``: "tangent", "inner", "obtuse" (outer, alpha >= 90 deg),
        "acute" (outer, alpha < 90 deg, including a reversal)."""
        ta, tb = ea.tangent(True), eb.tangent(False)
        turn, along = cross(ta, tb), dot(ta, tb)
        if abs(turn) <= TANGENT_SIN and along > 0.0:
            return "tangent"
        if s * turn > 0.0:
            return "inner"
        return "obtuse" if along >= -TANGENT_SIN else "acute"

    def _intersection(self, a: _Move, sa: float, b: _Move, sb: float) -> Point:
        """Intersection of the offset elements nearest the corner, or PS0033 naming ``a``'s line."""
        ea, eb = a.element, b.element
        assert ea is not None and eb is not None
        points = offset_intersections(ea, sa, eb, sb)
        if not points:
            rec, nxt = self.records[a.rec], self.records[b.rec]
            raise self._error(rec, f"D{rec.d}", "cutter compensation finds no intersection of the offset paths of "
                              f"this block and line {nxt.line} (FANUC alarm PS0033)",
                              "a tool radius offset for which the offset paths of adjacent blocks meet")
        pa, pb = ea.offset_point(sa, True), eb.offset_point(sb, False)
        return nearest(points, (0.5 * (pa[0] + pb[0]), 0.5 * (pa[1] + pb[1])))

    @staticmethod
    def _place_between(blocks: Sequence[Block], i0: int, i1: int, p: Point, replaced: dict[int, Block]) -> None:
        """Moves without XY motion in ``blocks[i0:i1]`` run at the XY point ``p``."""
        for i in range(i0, i1):
            b = blocks[i]
            if isinstance(b, (Rapid, Linear)):
                replaced[i] = replace(b, start=(p[0], p[1], b.start[2]), end=(p[0], p[1], b.end[2]))

    # ------------------------------------------------------------------ checks
    def _check_arc_radius(self, m: _Move, b: Arc) -> None:
        """An arc whose offset radius would be <= 0 (PS0041-style interference)."""
        assert m.element is not None
        r_off = min(m.element.offset_radius(m.offset, False), m.element.offset_radius(m.offset, True))
        if r_off > SAME_POINT:
            return
        rec = self.records[m.rec]
        u, unit = self._unit(rec)
        g = "G2" if b.clockwise else "G3"
        raise self._error(rec, g, f"arc radius {fmt_length(b.radius_start, u)} {unit} with the tool radius offset "
                          f"D{rec.d} = {fmt_length(abs(m.offset), u)} {unit} on its inside gives a tool-centre arc "
                          f"radius of {fmt_length(r_off, u)} {unit} (too small an arc: interference, FANUC alarm "
                          "PS0041 style)", "an arc radius larger than the tool radius where the tool is inside the "
                          "arc (G41 on G3, G42 on G2)")

    def _check_direction(self, m: _Move, old: Rapid | Linear | Arc, new: Rapid | Linear | Arc) -> None:
        """The tool-centre move of an offset block must run the programmed way (PS0041-style interference)."""
        rec = self.records[m.rec]
        if isinstance(old, Arc):
            assert isinstance(new, Arc)
            if abs(new.sweep - old.sweep) <= math.pi:
                return
            problem = (f"the tool-centre arc sweeps {fmt_number(math.degrees(new.sweep))} deg where the programmed "
                       f"arc sweeps {fmt_number(math.degrees(old.sweep))} deg")
            word = "G2" if old.clockwise else "G3"
        else:
            assert m.element is not None
            t = m.element.tangent(False)
            along = (new.end[0] - new.start[0]) * t[0] + (new.end[1] - new.start[1]) * t[1]
            if along >= -SAME_POINT:
                return
            u, unit = self._unit(rec)
            problem = (f"the tool-centre path runs {fmt_number(-along * u)} {unit} against the programmed direction")
            word = f"D{rec.d}"
        raise self._error(rec, word, f"{problem}: the tool radius offset D{rec.d} is too large for this block "
                          "(interference, FANUC alarm PS0041 style)",
                          "steps and inside corners larger than the tool radius")

    @staticmethod
    def _unit(rec: LineRecord) -> tuple[float, str]:
        return (1.0 / INCH, "in") if rec.inch else (1e3, "mm")

    def _error(self, rec: LineRecord, word: str, problem: str, expected: str) -> GCodeError:
        return GCodeError(self.file, rec.line, word, expected, problem, rec.text.strip())


def _has_xy(b: Rapid | Linear | Arc) -> bool:
    """The block moves in X or Y (an XY arc always does)."""
    if isinstance(b, Arc) and b.plane == "XY":
        return True
    return math.hypot(b.end[0] - b.start[0], b.end[1] - b.start[1]) > SAME_POINT


def _reach(eb: Element, sb: float, end_a: Point, corner: tuple[Point, ...]) -> _Joint:
    """A joint ending the move before at ``end_a`` (then ``corner``): a line starts where that ends, an arc is
    reached by a straight line to its offset start when that is elsewhere (a D change, a kept vector)."""
    mid = corner[-1] if corner else end_a
    if not eb.is_arc:
        return _Joint(end_a, corner, (), mid)
    xb = eb.offset_point(sb, False)
    return _Joint(end_a, corner, (xb,) if distance(mid, xb) > SAME_POINT else (), xb)


def _segments(template: Rapid | Linear | Arc, start: Point, points: tuple[Point, ...], z: float) -> list[Block]:
    """Straight moves ``start -> points[0] -> ...`` at height ``z``, of the kind, line and feed of ``template``
    (a rapid gives rapids; a feed move gives linear feed moves without exact stop; zero-length ones left out)."""
    out: list[Block] = []
    p = start
    for q in points:
        if distance(p, q) > SAME_POINT:
            a, b = (p[0], p[1], z), (q[0], q[1], z)
            if isinstance(template, Rapid):
                out.append(Rapid(template.line, a, b))
            else:
                out.append(Linear(template.line, a, b, template.feed, template.feed_line,
                                  isinstance(template, Linear) and template.exact_stop, template.feed_per_rev,
                                  lookahead_limit=template.lookahead_limit))
        p = q
    return out
