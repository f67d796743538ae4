"""Optional chamfering and corner R (FANUC ``,C`` / ``,R``): an extra block at the corner of two G1 blocks.

``G1 X.. Y.. ,C c`` cuts the corner between this block and the next one by a straight chamfer whose ends lie
``c`` from the virtual corner (the programmed end point) along both blocks; ``G1 X.. Y.. ,R r`` rounds it by an
arc of radius ``r`` tangent to both blocks (its tangent points lie ``r tan(theta/2)`` from the corner, theta
the change of direction; ``r`` for a 90 deg corner; a chamfer is the chord ``2 c cos(theta/2)``). The block
with the word ends at the first chamfer/tangent point, the next block starts at the second, and the inserted
:class:`~.blocks.Linear` / :class:`~.blocks.Arc` (G2 for a right turn, G3 for a left turn) runs between them.
The inserted block carries the source line of the block with the ``,C``/``,R`` word and that block's feed
(feed, feed line, G95 feed per revolution, exact-stop flag), so per-line F overrides of that line apply to it.

Conventions (FANUC 0i-MF / 31i-B "optional chamfering and corner R"; the twin's reading where noted)
--------------------------------------------------------------------------------------------------
* Both blocks are G1 moves in the plane of G17/G18/G19 (no motion along the plane normal). FANUC's 31i also
  accepts G2/G3 on either side; the twin does not insert those (a clear error naming the line).
* The next *executed* block must be that G1 move (comment-only and block-delete-skipped lines do not count);
  a block without a move, a rapid, the program end, or a plane change is an error on the line of the word
  (FANUC alarms PS0051 "missing move after CNR/CHF" and PS0052 "code is not G01 after CHF/CNR"). A chamfer or
  radius that needs more than either block's length is an error (PS0055 "missing move value in CHF/CNR").
* A collinear continuation has no corner: nothing is inserted. A reversal (the next block runs back along
  the first) has no chamfer or tangent circle: an error.
* The value is in the program unit (G20/G21) and must be > 0; ``,C`` and ``,R`` in one block, and either in
  a block with G0, G4, G10, G28/G30/G53, G52/G92, a canned cycle, M0/M1/M2/M30 or M98/M99, are errors.
* Under G51 the size is scaled with the plane (different factors of its two axes: an error); G51.1/G68 move
  the corner with the path (:mod:`.transforms`).
* Cutter compensation: the corner is part of the programmed contour and is offset with it (an outer corner
  R under G41/G42 becomes an arc of radius R + r), as FANUC does. The compensation state (G40/G41/G42 and
  the radius of D) must be the same in both blocks; a start-up or cancel between them is an error.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Callable

from .blocks import PLANE_AXES, Arc, Block, Linear, Rapid, Vec3
from .codes import MWords, ValueWords
from .errors import ErrorFactory, GCodeError, fmt_number
from .lexer import Word
from .modal import ModalState
from .settings import INCH

#: A change of direction below this (rad) is a straight continuation: no corner is inserted.
STRAIGHT = 1e-9
#: Chamfer/tangent distances may exceed a block's length by this much (rounding), m.
FIT_TOLERANCE = 1e-9
#: Source letters of the words.
KIND_NAME = {",C": "chamfer", ",R": "corner R"}


@dataclass(frozen=True)
class OpenCorner:
    """A ``,C``/``,R`` block waiting for the next block.

    Attributes
    ----------
    kind : str
        ``",C"`` (chamfer) or ``",R"`` (corner R).
    size : float
        Chamfer distance or corner radius (m, > 0).
    word : str
        The word as written (``",C1."``), for messages.
    line : int
        1-based source line of the block with the word.
    text : str
        Its source text.
    index : int
        Index of its :class:`~.blocks.Linear` in the interpreter's block list.
    plane : str
        Plane of the block (``"XY"``, ``"ZX"``, ``"YZ"``).
    comp : tuple of (int, float)
        Cutter compensation G code and tool radius (m) in the block.
    inch : bool
        G20 in effect (numbers in messages in inch).
    """

    kind: str
    size: float
    word: str
    line: int
    text: str
    index: int
    plane: str
    comp: tuple[int, float]
    inch: bool


def corner_word(vals: ValueWords, err: ErrorFactory) -> Word | None:
    """Take the block's ``,C`` or ``,R`` word out of ``vals`` (None without one); both in one block: error."""
    if ",C" in vals and ",R" in vals:
        w = vals[",R"]
        raise err(w.letter + w.text, "chamfer ,C and corner R ,R in one block", "one of ,C and ,R per block")
    for name in (",C", ",R"):
        if name in vals:
            return vals.pop(name)
    return None


def open_corner(st: ModalState, word: Word | None, moved: bool, ms: MWords, out: list[Block], begin: int,
                line: int, text: str, err: ErrorFactory) -> None:
    """Check the block's ``,C``/``,R`` word and leave the corner open for the next block (``st.corner``).

    Parameters
    ----------
    st : ModalState
        Modal state after the block.
    word : Word or None
        The block's ``,C``/``,R`` word (:func:`corner_word`).
    moved : bool
        The block was a G0-G3 motion block (not a dwell, cycle, machine move or data setting).
    ms : MWords
        The block's M codes.
    out : list of Block
        The program's blocks; those from ``begin`` on are this block's.
    begin : int
        Index of this block's first typed block.
    line : int
        1-based source line.
    text : str
        Source text of the block.
    err : ErrorFactory
        Builds the error for this block.
    """
    if word is None:
        return
    name = word.letter + word.text
    what = KIND_NAME[word.letter]
    if not moved or st.motion == 0:
        raise err(name, f"{what} {word.letter} in a block that is not a G1 move",
                  f"{word.letter} in a G1 block with an end point in the plane")
    if st.motion in (2, 3):
        raise err(name, f"{what} {word.letter} after a G{st.motion} arc is not supported by the twin (FANUC 31i "
                  "accepts it)", f"{word.letter} between two G1 blocks (write the corner as its own G2/G3 block)")
    for kind in ("stop", "end", "subprogram"):
        if kind in ms:
            raise err(name, f"{what} {word.letter} in a block with M{ms[kind][0]}",
                      f"{word.letter} in a G1 block followed by the next G1 block")
    if word.value <= 0.0:
        raise err(name, f"{what} {name} is not positive", f"{word.letter} followed by a number > 0")
    last = out[-1] if len(out) > begin else None
    if not isinstance(last, Linear):
        raise err(name, f"{what} {word.letter} in a block without an end point (FANUC alarm PS0055)",
                  f"{word.letter} in a G1 block with an end point in the plane")
    _check_planar(last, st.plane, lambda problem: err(name, problem, f"{word.letter} between two G1 moves "
                                                      f"in the {st.plane} plane"))
    factor = st.xf.plane_factor(st.plane)  # G51 scaling scales the corner (G51.1/G68 move it with the path)
    if factor is None:
        raise err(name, f"{what} {word.letter} under scaling with different factors on the two {st.plane} axes",
                  f"the same magnification on both plane axes (G51 P_) for {word.letter}")
    st.corner = OpenCorner(word.letter, word.value * st.scale * factor, name, line, text, len(out) - 1, st.plane,
                           (st.comp, st.tool_radius() if st.comp != 40 else 0.0), st.scale == INCH)


def close_corner(st: ModalState, out: list[Block], begin: int, line: int, text: str, file: str) -> None:
    """Insert the open corner of the previous block (if any) between it and this block's move.

    Raises
    ------
    GCodeError
        On the line of the ``,C``/``,R`` word: this block is not a G1 move in the same plane, the compensation
        state changed, the corner does not fit (see the module docstring).
    """
    corner = st.corner
    if corner is None:
        return
    st.corner = None
    here = f"the next block (line {line} '{text}')"
    expected = f"{corner.word[:2]} followed by a G1 move in the {corner.plane} plane"

    def fail(problem: str, wanted: str = expected) -> GCodeError:
        return GCodeError(file, corner.line, corner.word, wanted, problem, corner.text)

    what = KIND_NAME[corner.kind]
    moves = [i for i in range(begin, len(out)) if isinstance(out[i], (Rapid, Linear, Arc))]
    if not moves:
        raise fail(f"{what} {corner.word}: {here} has no move (FANUC alarm PS0051)")
    nxt = out[moves[0]]
    if isinstance(nxt, Arc) and len(moves) == 1:
        raise fail(f"{what} {corner.word}: {here} is a G2/G3 arc; corners next to arcs are not supported by the "
                   "twin (FANUC 31i accepts them)", f"{corner.word[:2]} between two G1 blocks (write the corner as "
                   "its own block)")
    if not isinstance(nxt, Linear) or len(moves) > 1 or nxt.tap_pitch or nxt.rigid_tap:
        kind = "a rapid G0" if isinstance(nxt, Rapid) else "not one G1 move"
        raise fail(f"{what} {corner.word}: {here} is {kind} (FANUC alarm PS0052)")
    if st.plane != corner.plane:
        raise fail(f"{what} {corner.word}: {here} changes the plane to {st.plane}")
    comp = (st.comp, st.tool_radius() if st.comp != 40 else 0.0)
    if comp != corner.comp:
        raise fail(f"{what} {corner.word}: the cutter compensation changes in {here} (G{corner.comp[0]} -> "
                   f"G{comp[0]} or another radius)")
    _check_planar(nxt, corner.plane, lambda problem: fail(f"{here}: {problem}"))
    first = out[corner.index]
    assert isinstance(first, Linear)
    inserted, end_a, start_b = corner_geometry(first, nxt, corner, fail)
    out[corner.index] = replace(first, end=end_a)
    out[moves[0]] = replace(nxt, start=start_b)
    if inserted is not None:
        out.insert(corner.index + 1, inserted)


def corner_geometry(a: Linear, b: Linear, corner: OpenCorner,
                    fail: Callable[[str], GCodeError]) -> tuple[Linear | Arc | None, Vec3, Vec3]:
    """The chamfer/corner-R block between the G1 moves ``a`` and ``b`` and the new end of ``a``, start of ``b``.

    Parameters
    ----------
    a, b : Linear
        The block with the word and the next one (``a.end`` is the virtual corner; both in ``corner.plane``).
    corner : OpenCorner
        Kind and size (m).
    fail : callable
        Builds the error from a problem text.

    Returns
    -------
    block : Linear, Arc or None
        The inserted block (line and feed of ``a``); None for a straight continuation.
    end_a, start_b : Vec3
        Machine positions (m) of the first and second chamfer/tangent point.
    """
    i1, i2, _ = PLANE_AXES[corner.plane]
    u = (a.end[i1] - a.start[i1], a.end[i2] - a.start[i2])
    v = (b.end[i1] - b.start[i1], b.end[i2] - b.start[i2])
    la, lb = math.hypot(*u), math.hypot(*v)
    unit = INCH if corner.inch else 1e-3
    name = "in" if corner.inch else "mm"
    what = KIND_NAME[corner.kind]
    if la <= FIT_TOLERANCE or lb <= FIT_TOLERANCE:
        which = "the block" if la <= FIT_TOLERANCE else "the next block"
        raise fail(f"{what} {corner.word}: {which} has no length in the {corner.plane} plane (FANUC alarm PS0051)")
    cross = u[0] * v[1] - u[1] * v[0]
    dot = u[0] * v[0] + u[1] * v[1]
    theta = math.atan2(abs(cross), dot)  # change of direction, 0..pi
    if theta <= STRAIGHT:
        return None, a.end, b.start
    if math.pi - theta <= STRAIGHT:
        raise fail(f"{what} {corner.word}: the next block reverses the direction (no {what} exists)")
    t = corner.size if corner.kind == ",C" else corner.size * math.tan(0.5 * theta)
    if t > la + FIT_TOLERANCE or t > lb + FIT_TOLERANCE:
        raise fail(f"{what} {corner.word} needs {fmt_number(t / unit)} {name} of both blocks, but they are "
                   f"{fmt_number(la / unit)} and {fmt_number(lb / unit)} {name} long in the {corner.plane} plane "
                   "(FANUC alarm PS0055)", f"a {what} that takes at most {fmt_number(min(la, lb) / unit)} {name} "
                   "of either block")
    ua, vb = (u[0] / la, u[1] / la), (v[0] / lb, v[1] / lb)
    p = list(a.end)
    q1, q2 = list(p), list(p)
    q1[i1], q1[i2] = p[i1] - t * ua[0], p[i2] - t * ua[1]
    q2[i1], q2[i2] = p[i1] + t * vb[0], p[i2] + t * vb[1]
    end_a, start_b = tuple(q1), tuple(q2)
    if corner.kind == ",C":
        block: Linear | Arc = Linear(corner.line, end_a, start_b, a.feed, a.feed_line,  # type: ignore[arg-type]
                                     a.exact_stop, a.feed_per_rev, lookahead_limit=a.lookahead_limit)
    else:
        left = cross > 0.0  # a left turn: counter-clockwise about the plane normal (G3)
        n = (-ua[1], ua[0]) if left else (ua[1], -ua[0])
        c = list(q1)
        c[i1], c[i2] = q1[i1] + corner.size * n[0], q1[i2] + corner.size * n[1]
        block = Arc(corner.line, end_a, start_b, tuple(c), corner.plane, not left,  # type: ignore[arg-type]
                    a.feed, a.feed_line, exact_stop=a.exact_stop, feed_per_rev=a.feed_per_rev,
                    lookahead_limit=a.lookahead_limit)
    return block, end_a, start_b  # type: ignore[return-value]


def check_no_open_corner(st: ModalState, file: str) -> None:
    """At the end of the program: a ``,C``/``,R`` block without a next block is an error (FANUC PS0051)."""
    corner = st.corner
    if corner is None:
        return
    raise GCodeError(file, corner.line, corner.word, f"{corner.word[:2]} followed by a G1 move in the "
                     f"{corner.plane} plane", f"{KIND_NAME[corner.kind]} {corner.word}: the program ends after this "
                     "block (FANUC alarm PS0051)", corner.text)


def _check_planar(block: Linear, plane: str, fail: Callable[[str], GCodeError]) -> None:
    """The move has no motion along the normal of ``plane`` (chamfer and corner R are in the plane)."""
    k = PLANE_AXES[plane][2]
    if abs(block.end[k] - block.start[k]) > FIT_TOLERANCE:
        raise fail(f"the move has a component along {'XYZ'[k]}, the normal of the {plane} plane "
                   "(chamfer and corner R are in the plane only)")
