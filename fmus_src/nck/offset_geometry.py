"""Plane geometry of cutter radius compensation (G17): programmed XY elements, their offsets and intersections.

An :class:`Element` is the XY projection of one programmed move: a line, or an arc with its centre and
direction. Its offset by a signed distance ``s`` (m; positive to the left of the direction of travel, i.e.
G41 with a positive radius) is the parallel line, or the concentric circle of radius ``R - s`` for a
counter-clockwise (G3) and ``R + s`` for a clockwise (G2) arc. Everything here is pure geometry in metres:
no G-code, no errors of the program (the caller, :mod:`.radius_offset`, turns an empty intersection or a
non-positive radius into a FANUC-style alarm).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from .blocks import Arc, Linear, Rapid

#: A point or vector of the XY plane (m).
Point = tuple[float, float]
#: Sine of the angle below which two directions are the same (tangent transition), or opposite.
TANGENT_SIN = 1e-9
#: Distance within which a line touches a circle, or two circles touch (tangent intersection), m.
TOUCH = 1e-9


@dataclass(frozen=True)
class Element:
    """XY projection of a programmed move.

    Attributes
    ----------
    start, end : Point
        Programmed start and end point (m).
    centre : Point or None
        Arc centre (m); None for a line.
    ccw : bool
        Arc direction: True for G3 (counter-clockwise), False for G2.
    """

    start: Point
    end: Point
    centre: Point | None = None
    ccw: bool = True

    @property
    def is_arc(self) -> bool:
        """True for an arc."""
        return self.centre is not None

    @property
    def sense(self) -> float:
        """+1 for a counter-clockwise arc, -1 for a clockwise one (1 for a line, unused)."""
        return 1.0 if self.ccw else -1.0

    def radius(self, at_end: bool) -> float:
        """Programmed arc radius at the start or end point (m; I/J/K arcs may differ by 0.002 mm, 0.002 in under G20)."""
        assert self.centre is not None
        p = self.end if at_end else self.start
        return math.hypot(p[0] - self.centre[0], p[1] - self.centre[1])

    def tangent(self, at_end: bool) -> Point:
        """Unit direction of travel at the start or end point."""
        if self.centre is None:
            dx, dy = self.end[0] - self.start[0], self.end[1] - self.start[1]
            n = math.hypot(dx, dy)
            return (dx / n, dy / n)
        p = self.end if at_end else self.start
        ux, uy = p[0] - self.centre[0], p[1] - self.centre[1]
        n = math.hypot(ux, uy)
        return (-self.sense * uy / n, self.sense * ux / n)

    def offset_radius(self, s: float, at_end: bool) -> float:
        """Radius of the offset circle for the signed offset ``s`` (m): ``R - s`` (G3), ``R + s`` (G2)."""
        return self.radius(at_end) - self.sense * s

    def offset_point(self, s: float, at_end: bool) -> Point:
        """The start or end point moved by ``s`` along the left normal of the direction of travel."""
        p = self.end if at_end else self.start
        n = left_normal(self.tangent(at_end))
        return (p[0] + s * n[0], p[1] + s * n[1])


def element_of(block: Rapid | Linear | Arc) -> Element:
    """The XY element of a move block (an arc must be in the XY plane)."""
    start, end = (block.start[0], block.start[1]), (block.end[0], block.end[1])
    if isinstance(block, Arc):
        return Element(start, end, (block.center[0], block.center[1]), not block.clockwise)
    return Element(start, end)


def xy_length(block: Rapid | Linear | Arc) -> float:
    """Length of the XY motion of a move block (m): the chord of a line, the arc length of an arc."""
    if isinstance(block, Arc):
        return abs(block.sweep) * block.radius_start
    return math.hypot(block.end[0] - block.start[0], block.end[1] - block.start[1])


def left_normal(t: Point) -> Point:
    """The unit vector 90 deg counter-clockwise from ``t``."""
    return (-t[1], t[0])


def cross(a: Point, b: Point) -> float:
    """z component of a x b (positive: b turns left from a)."""
    return a[0] * b[1] - a[1] * b[0]


def dot(a: Point, b: Point) -> float:
    """Scalar product."""
    return a[0] * b[0] + a[1] * b[1]


def distance(a: Point, b: Point) -> float:
    """Distance between two points (m)."""
    return math.hypot(a[0] - b[0], a[1] - b[1])


def offset_intersections(a: Element, sa: float, b: Element, sb: float) -> list[Point]:
    """Intersections of the offset of ``a`` (by ``sa``, near its end) and the offset of ``b`` (by ``sb``, near its
    start): line-line, line-arc, arc-line and arc-arc, lines taken as infinite and arcs as full circles.

    Returns
    -------
    list of Point
        0, 1 or 2 points; a tangent touch within :data:`TOUCH` gives one point. Parallel lines and concentric
        circles give none.
    """
    if not a.is_arc and not b.is_arc:
        pa, ta = a.offset_point(sa, True), a.tangent(True)
        pb, tb = b.offset_point(sb, False), b.tangent(False)
        det = cross(ta, tb)
        if abs(det) <= TANGENT_SIN:
            return []
        u = cross((pb[0] - pa[0], pb[1] - pa[1]), tb) / det
        return [(pa[0] + u * ta[0], pa[1] + u * ta[1])]
    if a.is_arc and b.is_arc:
        assert a.centre is not None and b.centre is not None
        return _circle_circle(a.centre, a.offset_radius(sa, True), b.centre, b.offset_radius(sb, False))
    if a.is_arc:
        assert a.centre is not None
        return _line_circle(b.offset_point(sb, False), b.tangent(False), a.centre, a.offset_radius(sa, True))
    assert b.centre is not None
    return _line_circle(a.offset_point(sa, True), a.tangent(True), b.centre, b.offset_radius(sb, False))


def _line_circle(p: Point, t: Point, c: Point, r: float) -> list[Point]:
    """Intersections of the line p + u t (t unit) with the circle (c, r)."""
    w = (c[0] - p[0], c[1] - p[1])
    u0 = dot(w, t)  # foot of the perpendicular from c
    foot = (p[0] + u0 * t[0], p[1] + u0 * t[1])
    d = distance(foot, c)
    if d > r + TOUCH:
        return []
    h = math.sqrt(max(r * r - d * d, 0.0))
    if h <= TOUCH:
        return [foot]
    return [(foot[0] - h * t[0], foot[1] - h * t[1]), (foot[0] + h * t[0], foot[1] + h * t[1])]


def _circle_circle(c1: Point, r1: float, c2: Point, r2: float) -> list[Point]:
    """Intersections of the circles (c1, r1) and (c2, r2)."""
    d = distance(c1, c2)
    if d <= TOUCH or d > r1 + r2 + TOUCH or d < abs(r1 - r2) - TOUCH:
        return []
    x = (d * d + r1 * r1 - r2 * r2) / (2.0 * d)  # from c1 along c1->c2
    h = math.sqrt(max(r1 * r1 - x * x, 0.0))
    ex, ey = (c2[0] - c1[0]) / d, (c2[1] - c1[1]) / d
    m = (c1[0] + x * ex, c1[1] + x * ey)
    if h <= TOUCH:
        return [m]
    return [(m[0] - h * ey, m[1] + h * ex), (m[0] + h * ey, m[1] - h * ex)]


def nearest(points: list[Point], target: Point) -> Point:
    """The point of a non-empty list closest to ``target``."""
    return min(points, key=lambda p: distance(p, target))
