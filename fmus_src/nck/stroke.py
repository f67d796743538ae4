"""Stored stroke check 1 (FANUC No. 1320/1321): the planned path against the machine's travel, before it runs.

Conventions
-----------
* The limits are per axis, in machine coordinates (m): the interpreted blocks' axis-frame coordinates (the
  programmed tool-tip (tool-centre under G41/G42) position plus the work offset, G52/G92 shifts and the tool
  length on Z, and the G28/G30/G53 targets) minus ``machine_zero``, where machine zero sits in the axis frame
  (:attr:`.settings.InterpreterSettings.machine_zero`; 0: the axis frame is machine coordinates). An axis
  without limits is not checked.
* Checked: the machine position before the program, the end point of every move (rapids, feeds, the moves of
  canned cycles, reference returns) and the extremes of every arc inside its sweep (a quarter point
  ``centre ± r`` on an in-plane axis). The acc/dec after interpolation only averages positions of the path
  (a moving average with positive weights), so the reference never leaves the box of the path's extremes.
* A position beyond a limit by more than :data:`STROKE_TOLERANCE` (1 nm, far below the 0.001 mm least input
  increment) is the alarm OT0500 (+ side) / OT0501 (- side) of FANUC 0i-F/31i-B ("+ OVERTRAVEL (SOFT 1)"),
  raised as a :class:`.errors.GCodeError` naming the file, the line of the block, the axis, the position and
  the limit (in mm). FANUC raises it when the axis gets there; the twin, which plans the whole program at
  set-up, raises it before the program runs (as FANUC's stroke check before movement, No. 1301#3, would for an
  end point).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from .blocks import Arc, Block, Linear, Rapid, Vec3
from .errors import GCodeError, NCParameterError, fmt_length

#: Overshoot below this is not an overtravel (m): rounding of offsets added in floating point.
STROKE_TOLERANCE = 1e-9
_AXES = "XYZ"


@dataclass(frozen=True)
class StrokeLimits:
    """Stored stroke limits per axis, machine coordinates (m); None: that axis is not checked.

    Attributes
    ----------
    x, y, z : tuple of (float, float) or None
        ``(minimum, maximum)`` of the axis (FANUC No. 1321, No. 1320), minimum < maximum.
    """

    x: tuple[float, float] | None = None
    y: tuple[float, float] | None = None
    z: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        for letter, pair in zip(_AXES, self.axes):
            if pair is None:
                continue
            lo, hi = pair
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise NCParameterError(f"stroke limits of {letter} must be finite with minimum < maximum, "
                                       f"got ({lo!r}, {hi!r}) m")

    @property
    def axes(self) -> tuple[tuple[float, float] | None, ...]:
        """The limits of X, Y, Z in order."""
        return (self.x, self.y, self.z)

    @property
    def active(self) -> bool:
        """Whether any axis is checked."""
        return any(p is not None for p in self.axes)


def arc_extremes(arc: Arc) -> list[Vec3]:
    """The points of an arc where an in-plane axis is extreme inside its sweep (quarter points, m).

    The radius is the larger of the start and end radius (an arc may be a slight spiral); on a helix the
    normal-axis coordinate of these points is the one at their angle.
    """
    i, j, k = arc.axes
    r = max(arc.radius_start, arc.radius_end)
    a0, sweep = arc.start_angle, arc.sweep
    out: list[Vec3] = []
    for quarter in range(4):
        target = quarter * 0.5 * math.pi
        # angle from the start to the quarter point in the direction of travel
        delta = (target - a0) % (2.0 * math.pi) if sweep > 0 else -((a0 - target) % (2.0 * math.pi))
        if abs(delta) > abs(sweep):
            continue
        p = list(arc.center)
        p[i] = arc.center[i] + r * math.cos(target)
        p[j] = arc.center[j] + r * math.sin(target)
        p[k] = arc.start[k] + arc.helix * (delta / sweep)
        out.append((p[0], p[1], p[2]))
    return out


def _points(block: Block) -> list[Vec3]:
    if isinstance(block, Arc):
        return [block.end, *arc_extremes(block)]
    if isinstance(block, (Rapid, Linear)):
        return [block.end]
    return []


def check_stroke(blocks: Sequence[Block], initial: Vec3, limits: StrokeLimits, file: str = "<text>",
                 lines: Sequence[str] = (), machine_zero: Vec3 = (0.0, 0.0, 0.0)) -> None:
    """Raise the overtravel alarm at the first block whose path leaves the stroke limits.

    Parameters
    ----------
    blocks : sequence of Block
        Interpreted blocks, axis frame (m).
    initial : Vec3
        Position before the program, axis frame (m).
    limits : StrokeLimits
    file : str
        Program name for the message.
    lines : sequence of str
        Source lines (quoted in the message; may be empty).
    machine_zero : Vec3
        Where machine zero sits in the axis frame (m): machine coordinates = axis frame - machine_zero.

    Raises
    ------
    GCodeError
        OT0500/OT0501: the axis, the machine position and the limit in mm, the line of the block.
    """
    if not limits.active:
        return
    lo = [-math.inf if p is None else p[0] - STROKE_TOLERANCE for p in limits.axes]
    hi = [math.inf if p is None else p[1] + STROKE_TOLERANCE for p in limits.axes]
    z0, z1, z2 = machine_zero

    def machine(p: Vec3) -> Vec3:
        return (p[0] - z0, p[1] - z1, p[2] - z2)

    def outside(p: Vec3) -> bool:
        m = machine(p)
        return not (lo[0] <= m[0] <= hi[0] and lo[1] <= m[1] <= hi[1] and lo[2] <= m[2] <= hi[2])

    if outside(initial):
        _alarm(machine(initial), 0, limits, file, "", "the machine position before the program")
    for block in blocks:
        for point in _points(block):
            if outside(point):  # the message only for the first point beyond a limit
                text = lines[block.line - 1].strip() if 0 < block.line <= len(lines) else ""
                _alarm(machine(point), block.line, limits, file, text, _what(block))


def _what(block: Block) -> str:
    if isinstance(block, Arc):
        return "the arc"
    if isinstance(block, Rapid):
        return "the rapid move"
    return "the feed move"


def _alarm(point: Vec3, line: int, limits: StrokeLimits, file: str, text: str, what: str) -> None:
    """Raise the alarm of the first axis of ``point`` (machine coordinates, m) beyond its limit (none: nothing)."""
    for axis, (letter, pair) in enumerate(zip(_AXES, limits.axes)):
        if pair is None:
            continue
        lo, hi = pair
        value = point[axis]
        if value > hi + STROKE_TOLERANCE:
            side, limit, alarm, key, number = "+", hi, "OT0500", "stroke_max_mm", 1320
        elif value < lo - STROKE_TOLERANCE:
            side, limit, alarm, key, number = "-", lo, "OT0501", "stroke_min_mm", 1321
        else:
            continue
        raise GCodeError(
            file, line, letter,
            f"{letter} within [{fmt_length(lo, 1e3)}, {fmt_length(hi, 1e3)}] mm in machine coordinates "
            "(check the work offset, the tool length and the program's coordinates)",
            f"{alarm} {side} OVERTRAVEL (SOFT 1): {what} takes {letter} to {fmt_length(value, 1e3)} mm in machine "
            f"coordinates (work offset and tool length included), beyond the {side} stroke limit "
            f"{fmt_length(limit, 1e3)} mm ([axis.{letter.lower()}] {key}, FANUC No. {number})",
            text)
