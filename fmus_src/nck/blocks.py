"""Typed blocks: the interpreter's output (canonical machining commands).

Every block is a frozen dataclass carrying the 1-based source ``line`` it came
from. Positions are machine coordinates in metres (programmed tool-tip
position + active work offset + active tool length on Z), feeds in m/s,
spindle speeds in rad/s, times in s. Downstream code never re-parses text.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

Vec3 = tuple[float, float, float]

#: Axis indices (first in-plane axis, second in-plane axis, normal axis) of each plane.
PLANE_AXES: dict[str, tuple[int, int, int]] = {"XY": (0, 1, 2), "ZX": (2, 0, 1), "YZ": (1, 2, 0)}
#: Index of an axis letter in a :data:`Vec3`.
AXIS_INDEX: dict[str, int] = {"X": 0, "Y": 1, "Z": 2}


@dataclass(frozen=True, slots=True)
class Rapid:
    """G0 positioning from ``start`` to ``end`` (m, machine coordinates)."""

    line: int
    start: Vec3
    end: Vec3


@dataclass(frozen=True, slots=True)
class Linear:
    """G1 linear cutting feed.

    Attributes
    ----------
    feed : float
        Programmed path feed (m/s), before any clamp.
    feed_line : int
        Source line whose F word set ``feed`` (used to apply per-line overrides).
    exact_stop : bool
        The path decelerates to rest at the end of this block and the next block waits for the
        in-position check (G61 mode, one-shot G9, or a canned-cycle feed).
    feed_per_rev : float
        G95: the programmed feed per revolution (m/rev), and ``feed`` is it x the commanded spindle speed in
        effect (rev/s); 0.0 under G94.
    tap_pitch : float
        A tapping feed of G84/G74 (F tied to S): the thread pitch (m/rev); 0.0 for any other feed.
    rigid_tap : int
        A rigid-tapping stroke: the spindle direction during it (+1 CW, -1 CCW), Z synchronised with the
        spindle from rest to rest (:mod:`fmus_src.nck.tapping`); 0 otherwise.
    lookahead_limit : int
        Haas ``G103 P<n>`` in effect when the block was read: the look-ahead may reach n blocks beyond this
        one (:mod:`fmus_src.nck.block_buffering`); 0: no limit (the machine's ``lookahead_blocks``).
    """

    line: int
    start: Vec3
    end: Vec3
    feed: float
    feed_line: int
    exact_stop: bool = False
    feed_per_rev: float = 0.0
    tap_pitch: float = 0.0
    rigid_tap: int = 0
    lookahead_limit: int = 0


@dataclass(frozen=True, slots=True)
class Arc:
    """G2/G3 circular (or helical) cutting feed.

    Attributes
    ----------
    center : Vec3
        Arc centre (m); its normal-axis coordinate equals the start's.
    plane : {"XY", "ZX", "YZ"}
        G17, G18, G19. Angles are counted from the first towards the second
        in-plane axis (right-handed about the plane normal +Z, +Y, +X).
    clockwise : bool
        True for G2.
    feed, feed_line
        As for :class:`Linear`.
    turns : int
        1 for an ordinary arc (at most one revolution). A full circle
        (IJK, end == start) has ``turns = 1`` and a sweep of 2 pi.
    exact_stop, feed_per_rev, lookahead_limit
        As for :class:`Linear`.
    """

    line: int
    start: Vec3
    end: Vec3
    center: Vec3
    plane: str
    clockwise: bool
    feed: float
    feed_line: int
    turns: int = 1
    exact_stop: bool = False
    feed_per_rev: float = 0.0
    lookahead_limit: int = 0

    @property
    def axes(self) -> tuple[int, int, int]:
        """Indices of (first in-plane, second in-plane, normal) axes."""
        return PLANE_AXES[self.plane]

    @property
    def radius_start(self) -> float:
        """Radius at the start point (m)."""
        i, j, _ = self.axes
        return math.hypot(self.start[i] - self.center[i], self.start[j] - self.center[j])

    @property
    def radius_end(self) -> float:
        """Radius at the end point (m); equals ``radius_start`` within 0.002 mm (0.002 in under G20)."""
        i, j, _ = self.axes
        return math.hypot(self.end[i] - self.center[i], self.end[j] - self.center[j])

    @property
    def start_angle(self) -> float:
        """Angle of the start point about the centre (rad)."""
        i, j, _ = self.axes
        return math.atan2(self.start[j] - self.center[j], self.start[i] - self.center[i])

    @property
    def sweep(self) -> float:
        """Signed swept angle (rad): positive counter-clockwise (G3), negative for G2."""
        i, j, _ = self.axes
        a0 = self.start_angle
        a1 = math.atan2(self.end[j] - self.center[j], self.end[i] - self.center[i])
        d = a1 - a0
        if self.clockwise:
            d = -((-d) % (2.0 * math.pi))
            if d == 0.0:
                d = -2.0 * math.pi
            return d - 2.0 * math.pi * (self.turns - 1)
        d = d % (2.0 * math.pi)
        if d == 0.0:
            d = 2.0 * math.pi
        return d + 2.0 * math.pi * (self.turns - 1)

    @property
    def helix(self) -> float:
        """Travel along the plane normal (m)."""
        k = self.axes[2]
        return self.end[k] - self.start[k]

    @property
    def length(self) -> float:
        """Path length (m) of the (possibly helical, slightly spiral) arc."""
        r = 0.5 * (self.radius_start + self.radius_end)
        return math.hypot(abs(self.sweep) * r, self.helix)


@dataclass(frozen=True, slots=True)
class Dwell:
    """G4 dwell of ``seconds`` (s), after the axes are in position."""

    line: int
    seconds: float


@dataclass(frozen=True, slots=True)
class SpindleSpeed:
    """Spindle command: ``speed`` (rad/s, >= 0), ``direction`` +1 (M3), -1 (M4), 0 (not turning).

    ``speed_line`` is the source line whose S word set ``speed``.
    """

    line: int
    speed: float
    direction: int
    speed_line: int


@dataclass(frozen=True, slots=True)
class SpindleStop:
    """M5 spindle stop; ``orient``: a spindle orientation of G76/G87 (the next move waits for the spindle at rest)."""

    line: int
    orient: bool = False


@dataclass(frozen=True, slots=True)
class ToolChange:
    """M6 tool change to ``tool`` (the last T word); ``at_rest``: the change starts when the spindle is at rest
    (``tool_change_spindle = "stop"``, :mod:`.auxiliary_functions`)."""

    line: int
    tool: int
    at_rest: bool = False


@dataclass(frozen=True, slots=True)
class Coolant:
    """M7/M8 (``on=True``) or M9 (``on=False``)."""

    line: int
    on: bool


@dataclass(frozen=True, slots=True)
class ProgramStop:
    """M0 program stop or M1 optional stop: the axes come to rest (in-position check), no added time.

    The twin does not wait for an operator and its optional-stop switch is off; the path still stops
    because FANUC does not pre-read the block after M00/M01. ``code`` is ``"M0"`` or ``"M1"``.
    """

    line: int
    code: str


@dataclass(frozen=True, slots=True)
class ProgramEnd:
    """Program end: ``reason`` is ``"M30"``, ``"M2"``, ``"%"`` or ``"end of file"``."""

    line: int
    reason: str


Block = Rapid | Linear | Arc | Dwell | SpindleSpeed | SpindleStop | ToolChange | Coolant | ProgramStop | ProgramEnd
Motion = (Rapid, Linear, Arc)


@dataclass(frozen=True)
class Program:
    """An interpreted program.

    Attributes
    ----------
    file : str
        Name used in messages.
    blocks : tuple of Block
        Typed blocks in execution order; the last one is a :class:`ProgramEnd`.
    initial : Vec3
        Machine position before the first block (m).
    segments : tuple of (int, int)
        The source lines in execution order, as runs ``(first, last)`` of 1-based lines executed one after the
        other (inclusive). ``((1, n),)`` for a program without subprogram calls; every M98 call and M99 return
        (or repeat) starts a new run, so a subprogram's lines appear once per call. Empty: not known (read as
        one run from line 1 to the last block's line). Per-line overrides follow it
        (:mod:`fmus_src.nck.overrides`).
    segment_blocks : tuple of int
        Number of blocks of each run of ``segments`` (same length; they add up to ``len(blocks)``). It tells
        apart runs that line numbers cannot: a one-line subprogram ``X1. M99`` called twice in a row gives two
        runs of the same line with no block in between. Empty: not known (runs told apart by line numbers).
    """

    file: str
    blocks: tuple[Block, ...]
    initial: Vec3
    segments: tuple[tuple[int, int], ...] = ()
    segment_blocks: tuple[int, ...] = ()
