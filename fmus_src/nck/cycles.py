"""Canned drilling cycles (FANUC milling G73 G81 G82 G83 G85 G86 G89) → typed blocks.

One hole of a cycle is expanded into the moves the control makes, all carrying
the source line of the block that drilled the hole, so recordings, the
per-line feed overrides of the optimiser (the feed blocks keep the modal
``feed_line``) and messages point at that line. Everything here is in
machine coordinates (m): the interpreter converts the programmed levels
(work coordinates + work offset + tool length on Z) before calling.

Sequence of one hole (FANUC 0i-MF / 31i-B operator's manual, "Canned cycle
for drilling"): (1) positioning of X and Y at rapid traverse at the current Z
(the initial level for the first hole, the return level afterwards),
(2) rapid traverse to the R point, (3) the hole machining, (4) the operation
at the bottom, (5)-(6) the retract to the return level: the initial level
under G98, the R point under G99. Per cycle:

========  ================================================================
G81       feed to Z, rapid retract.
G82       feed to Z, dwell P, rapid retract.
G73       high-speed peck: feed Q, rapid back ``d`` (No. 5114,
          :attr:`CycleMachine.g73_retract`), feed Q + d, ... until Z,
          rapid retract.
G83       peck: feed Q, rapid to R, rapid down to ``d`` (No. 5115,
          :attr:`CycleMachine.g83_clearance`) above the previous bottom,
          feed to Q below it, ... until Z, rapid retract.
G85       feed to Z, feed back to R, rapid to the initial level under G98.
G89       as G85 with a dwell P at the bottom.
G86       feed to Z, spindle stop, rapid retract, spindle restarted in its
          previous direction and speed.
========  ================================================================

Levels (FANUC 0i-MF / 31i-B, "Absolute command and incremental command"):
under G90, R and Z are the work-coordinate Z of the R point and of the hole
bottom; under G91, R is the distance from the initial level to the R point
and Z the distance from the R point to the bottom. The initial level is the
programmed Z when the canned-cycle mode starts (a G73-G89 code after G80 or
a group 01 code) and stays until the mode ends. R and Z are modal *as
programmed* (:class:`LevelWord`: value and distance mode) and the levels are
recomputed from them for every hole (:func:`cycle_levels`): after ``G91 G81
X10. R-3. Z-5.`` from an initial level of 10, a block ``X10. R-2.`` drills
from R 8 to 3 (the bottom stays 5 below the new R point). A value keeps the
mode it was given in when G90/G91 switches while the cycle is modal (``G90
... R2.`` then ``G91 X10. Z-3.``: R stays at 2, the bottom is -1). Under
G91, X and Y move by their value for each of the K repeats; the levels are
the same for all of them (measured from the initial level, also under G99).

The pecks of G73/G83 reach R - Q, R - 2Q, ... and the last one ends at Z
exactly. Every cutting feed of a cycle is an exact stop (the axes come to
rest and are in position before the next move, as FANUC executes the
operations of a cycle). Moves of zero length (the hole at the current X/Y,
the tool already at R) are left out.
"""
from __future__ import annotations

from dataclasses import dataclass

import math

from .blocks import Block, Dwell, Linear, Rapid, SpindleSpeed, SpindleStop, Vec3
from .errors import NCParameterError

#: Canned cycles this module expands.
CYCLES = (73, 81, 82, 83, 85, 86, 89)
#: Positions closer than this are the same (m).
SAME_POINT = 1e-9
#: Most moves one block may expand to (pecks x repeats); beyond it the interpreter raises GCodeError.
MAX_CYCLE_MOVES = 100_000


class CycleError(ValueError):
    """A hole cannot be expanded; the interpreter turns it into a :class:`GCodeError` naming the word."""

    def __init__(self, word: str, problem: str, expected: str) -> None:
        super().__init__(problem)
        self.word = word
        self.problem = problem
        self.expected = expected


@dataclass(frozen=True)
class CycleMachine:
    """Machine data of the drilling cycles (SI).

    Attributes
    ----------
    g73_retract : float
        Return amount ``d`` of the G73 high-speed peck (FANUC No. 5114), m, >= 0.
    g83_clearance : float
        Clearance ``d`` of the G83 peck cycle above the previous bottom (FANUC No. 5115), m, >= 0.
    """

    g73_retract: float = 0.2e-3
    g83_clearance: float = 0.5e-3

    def __post_init__(self) -> None:
        for name in ("g73_retract", "g83_clearance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise NCParameterError(f"NC parameter {name} must be a finite number >= 0 m, got {value!r}")


@dataclass(frozen=True)
class LevelWord:
    """The R or Z word of a canned cycle as programmed, modal until the cycle mode ends.

    Attributes
    ----------
    value : float
        m: a work-coordinate Z (G90) or a distance (G91: R from the initial level, Z from the R point).
    incremental : bool
        True when given under G91.
    """

    value: float
    incremental: bool


def cycle_levels(initial: float, r: LevelWord, z: LevelWord) -> tuple[float, float]:
    """Work-coordinate Z of the R point and of the hole bottom (m) from the modal R and Z words.

    Parameters
    ----------
    initial : float
        Initial level (m, work Z at the start of the cycle mode).
    r, z : LevelWord
        The modal R and Z words.

    Returns
    -------
    r_level, bottom : float
        ``r_level = r.value`` (G90) or ``initial + r.value`` (G91); ``bottom = z.value`` (G90) or
        ``r_level + z.value`` (G91).
    """
    r_level = initial + r.value if r.incremental else r.value
    bottom = r_level + z.value if z.incremental else z.value
    return r_level, bottom


@dataclass(frozen=True)
class Hole:
    """One hole of a canned cycle, machine coordinates (m).

    Attributes
    ----------
    code : int
        73, 81, 82, 83, 85, 86 or 89.
    line : int
        Source line of the block drilling the hole.
    x, y : float
        Hole position.
    initial, r_level, bottom : float
        Z of the initial level, of the R point and of the hole bottom (``bottom < r_level``).
    return_to_initial : bool
        G98 (True) or G99 (False).
    feed : float
        Cutting feed (m/s); ``feed_line`` the line whose F word set it.
    peck : float or None
        Q (m, > 0) for G73/G83.
    dwell : float
        P at the bottom (s) for G82/G89.
    spindle : tuple (speed rad/s, direction, speed_line)
        Spindle command restarted after the G86 retract.
    """

    code: int
    line: int
    x: float
    y: float
    initial: float
    r_level: float
    bottom: float
    return_to_initial: bool
    feed: float
    feed_line: int
    peck: float | None = None
    dwell: float = 0.0
    spindle: tuple[float, int, int] = (0.0, 0, 0)


def peck_depths(r_level: float, bottom: float, peck: float) -> list[float]:
    """Bottoms of the successive pecks of G73/G83 (m): R - Q, R - 2Q, ..., ending exactly at ``bottom``.

    Parameters
    ----------
    r_level, bottom : float
        Z of the R point and the hole bottom (m), ``bottom < r_level``.
    peck : float
        Q (m), > 0.

    Returns
    -------
    list of float

    Raises
    ------
    CycleError
        If the hole needs more than :data:`MAX_CYCLE_MOVES` pecks.
    """
    n = int((r_level - bottom) / peck + 1.0 - 1e-9)
    if n > MAX_CYCLE_MOVES:
        raise CycleError("Q", f"the peck depth would make {n} pecks", f"at most {MAX_CYCLE_MOVES} pecks per hole")
    out: list[float] = []
    k = 1
    while True:
        depth = r_level - k * peck
        if depth <= bottom + SAME_POINT:
            out.append(bottom)
            return out
        out.append(depth)
        k += 1


def expand_hole(hole: Hole, start: Vec3, machine: CycleMachine) -> tuple[list[Block], Vec3]:
    """The typed blocks of one hole and the position after it.

    Parameters
    ----------
    hole : Hole
    start : Vec3
        Machine position before the hole (m).
    machine : CycleMachine

    Returns
    -------
    blocks : list of Block
        All with ``line = hole.line``; feed blocks with ``feed_line = hole.feed_line`` and ``exact_stop``.
    end : Vec3
        Position after the retract: (x, y, initial level) under G98, (x, y, R) under G99.
    """
    line = hole.line
    out: list[Block] = []
    pos: list[Vec3] = [start]

    def rapid(z: float, x: float | None = None, y: float | None = None) -> None:
        p = pos[0]
        q = (p[0] if x is None else x, p[1] if y is None else y, z)
        if max(abs(q[i] - p[i]) for i in range(3)) > SAME_POINT:
            out.append(Rapid(line, p, q))
        pos[0] = q

    def feed(z: float) -> None:
        p = pos[0]
        q = (p[0], p[1], z)
        if abs(z - p[2]) > SAME_POINT:
            out.append(Linear(line, p, q, hole.feed, hole.feed_line, exact_stop=True))
        pos[0] = q

    ret = hole.initial if hole.return_to_initial else hole.r_level
    code = hole.code
    rapid(start[2], hole.x, hole.y)  # (1) positioning at the current level
    rapid(hole.r_level)  # (2) to the R point
    if code in (73, 83):
        assert hole.peck is not None
        d = machine.g73_retract if code == 73 else machine.g83_clearance
        depths = peck_depths(hole.r_level, hole.bottom, hole.peck)
        for k, depth in enumerate(depths):
            if k > 0:
                prev = depths[k - 1]
                back = min(prev + d, hole.r_level)
                if code == 73:
                    rapid(back)  # retract d
                else:
                    rapid(hole.r_level)  # full retract to R,
                    rapid(back)  # then down to d above the previous bottom
            feed(depth)
        rapid(ret)
    elif code in (81, 82):
        feed(hole.bottom)
        if code == 82:
            out.append(Dwell(line, hole.dwell))
        rapid(ret)
    elif code in (85, 89):
        feed(hole.bottom)
        if code == 89:
            out.append(Dwell(line, hole.dwell))
        feed(hole.r_level)  # retract at cutting feed
        rapid(ret)
    elif code == 86:
        feed(hole.bottom)
        out.append(SpindleStop(line))
        rapid(ret)
        speed, direction, speed_line = hole.spindle
        out.append(SpindleSpeed(line, speed, direction, speed_line))
    else:
        raise CycleError(f"G{code}", f"G{code} is not a supported canned cycle",
                         "one of " + " ".join(f"G{c}" for c in CYCLES))
    return out, pos[0]
