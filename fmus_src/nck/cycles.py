"""Canned cycles (FANUC milling G73 G74 G76 G81-G87 G89) → typed blocks.

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
G84       tapping (right-hand tap, spindle CW in, see below).
G74       left-hand tapping: as G84 with the spindle directions exchanged.
G76       fine boring: feed to Z, dwell P, spindle orientation (stop), rapid
          shift by Q in the direction :attr:`CycleMachine.boring_shift`
          (FANUC No. 5101 #4 RD1 / #5 RD2), rapid retract, rapid shift back,
          spindle restarted clockwise.
G87       back boring: at the initial level spindle orientation, shift by Q,
          rapid down to R (below the part), shift back, spindle clockwise,
          feed *up* to Z (Z above R), dwell P, orientation, shift by Q, rapid
          retract to the initial level, shift back, spindle clockwise. FANUC
          returns only to the initial level: G87 under G99 is an error.
G88       not supported (the operator jogs the tool out at the bottom): an error.
========  ================================================================

Tapping G84/G74 (FANUC 0i-MF / 31i-B "Tapping cycle" and "Rigid tapping"):
``G84 X Y Z R P F K``. The feed must match the thread: pitch = F / S under
G94 (F mm/min, S rev/min), pitch = F under G95 (mm/rev); every tapping feed
block carries the pitch (:attr:`Linear.tap_pitch`), so the optimiser keeps
the line as programmed. Q (peck tapping) is an error.

* Conventional tapping (no M29, :attr:`CycleMachine.rigid_always` off): the
  spindle turns CW (M3; M4 for G74 — anything else is an error) at S. Feed to
  Z, dwell P, spindle reversed (a spindle command -S: the twin ramps through
  zero and the retract feed waits for speed arrival, as every cutting feed),
  feed back to R, spindle forward again (+S), rapid to the initial level
  under G98. The tapping holder's float, which absorbs the spindle running on
  while Z stops, is not modelled.
* Rigid tapping (``M29 S..`` before or in the G84 block, or
  :attr:`CycleMachine.rigid_always`, FANUC No. 5200#0): M29 stops the spindle
  and puts it under position control; each stroke R→Z and Z→R is a
  :class:`Linear` with ``rigid_tap`` = the spindle direction of the stroke
  (+1 CW, -1 CCW), which the planner runs with Z synchronised to the spindle
  (:mod:`.tapping`): both start from rest, accelerate together, stop at the
  bottom (dwell P), reverse and stop again at R. The spindle stays stopped
  after the cycle (M3/M4 restart it).

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
CYCLES = (73, 74, 76, 81, 82, 83, 84, 85, 86, 87, 89)
#: Tapping cycles (G84 right-hand, G74 left-hand) -> spindle direction while feeding in (+1 CW, -1 CCW).
TAPPING = {84: 1, 74: -1}
#: Shift direction of G76/G87 (FANUC No. 5101 #4 RD1, #5 RD2 in G17) -> unit vector in X, Y.
BORING_SHIFTS = {"+X": (1.0, 0.0), "-X": (-1.0, 0.0), "+Y": (0.0, 1.0), "-Y": (0.0, -1.0)}
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
    rigid_always : bool
        G84/G74 are rigid tapping without M29 (FANUC No. 5200#0 G84 = 1).
    boring_shift : {"+X", "-X", "+Y", "-Y"}
        Direction of the G76/G87 tool shift Q after the spindle orientation (FANUC No. 5101 #4 RD1, #5 RD2).
    """

    g73_retract: float = 0.2e-3
    g83_clearance: float = 0.5e-3
    rigid_always: bool = False
    boring_shift: str = "+X"

    def __post_init__(self) -> None:
        for name in ("g73_retract", "g83_clearance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise NCParameterError(f"NC parameter {name} must be a finite number >= 0 m, got {value!r}")
        if self.boring_shift not in BORING_SHIFTS:
            raise NCParameterError(f"NC parameter boring_shift must be one of {sorted(BORING_SHIFTS)}, "
                                   f"got {self.boring_shift!r}")


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
        One of :data:`CYCLES`.
    line : int
        Source line of the block drilling the hole.
    x, y : float
        Hole position.
    initial, r_level, bottom : float
        Z of the initial level, of the R point and of the hole bottom (``bottom < r_level``; G87:
        ``bottom`` is the top Z of the back bore, above ``r_level``).
    return_to_initial : bool
        G98 (True) or G99 (False).
    feed : float
        Cutting feed (m/s); ``feed_line`` the line whose F word set it.
    peck : float or None
        Q (m, > 0): the peck depth of G73/G83, the shift of G76/G87.
    dwell : float
        P at the bottom (s) for G74/G76/G82/G84/G87/G89.
    spindle : tuple (speed rad/s, direction, speed_line)
        Spindle command in effect: restarted after the G86 retract, reversed by conventional tapping.
    pitch : float
        Thread pitch of G84/G74 (m/rev, > 0).
    rigid : bool
        G84/G74 as rigid tapping (M29 or :attr:`CycleMachine.rigid_always`).
    feed_per_rev : float
        G95: the feed per revolution of the feed blocks (m/rev), 0.0 under G94.
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
    pitch: float = 0.0
    rigid: bool = False
    feed_per_rev: float = 0.0


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
        Position after the retract: (x, y, initial level) under G98 (and always for G87), (x, y, R) under G99.
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

    def feed(z: float, rigid_tap: int = 0) -> None:
        p = pos[0]
        q = (p[0], p[1], z)
        if abs(z - p[2]) > SAME_POINT:
            out.append(Linear(line, p, q, hole.feed, hole.feed_line, exact_stop=True, feed_per_rev=hole.feed_per_rev,
                              tap_pitch=hole.pitch, rigid_tap=rigid_tap))
        pos[0] = q

    def dwell() -> None:
        if hole.dwell > 0.0:
            out.append(Dwell(line, hole.dwell))

    speed, direction, speed_line = hole.spindle
    shift = BORING_SHIFTS[machine.boring_shift]
    q = hole.peck or 0.0

    def shifted(on: bool) -> None:  # G76/G87: rapid tool shift by Q (on) or back to the hole axis (off)
        k = 1.0 if on else 0.0
        rapid(pos[0][2], hole.x + k * q * shift[0], hole.y + k * q * shift[1])

    def orient() -> None:  # spindle orientation: the next move waits for the spindle at rest
        out.append(SpindleStop(line, orient=True))

    code = hole.code
    ret = hole.initial if (hole.return_to_initial or code == 87) else hole.r_level
    rapid(start[2], hole.x, hole.y)  # (1) positioning at the current level
    if code == 87:  # back boring: orient and shift before going down past the part
        orient()
        shifted(True)
        rapid(hole.r_level)
        shifted(False)
        out.append(SpindleSpeed(line, speed, 1, speed_line))
        feed(hole.bottom)  # up to Z
        dwell()
        orient()
        shifted(True)
        rapid(ret)
        shifted(False)
        out.append(SpindleSpeed(line, speed, 1, speed_line))
        return out, pos[0]
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
        out.append(SpindleSpeed(line, speed, direction, speed_line))
    elif code in TAPPING:
        d = TAPPING[code]
        if hole.rigid:  # Z synchronised with the spindle, from rest to rest (planned by .tapping)
            feed(hole.bottom, rigid_tap=d)
            dwell()
            feed(hole.r_level, rigid_tap=-d)
        else:
            feed(hole.bottom)
            dwell()
            out.append(SpindleSpeed(line, speed, -d, speed_line))  # reverse: the retract waits for the speed
            feed(hole.r_level)
            out.append(SpindleSpeed(line, speed, d, speed_line))  # forward again at R
        rapid(ret)
    elif code == 76:
        feed(hole.bottom)
        dwell()
        orient()
        shifted(True)  # away from the wall
        rapid(ret)
        shifted(False)
        out.append(SpindleSpeed(line, speed, 1, speed_line))  # FANUC restarts the spindle clockwise
    else:
        raise CycleError(f"G{code}", f"G{code} is not a supported canned cycle",
                         "one of " + " ".join(f"G{c}" for c in CYCLES))
    return out, pos[0]
