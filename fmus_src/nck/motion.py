"""Motion G0-G3 of a block: rapid positioning, linear and circular interpolation → typed blocks.

Conventions
-----------
* G0 rapid, G1 linear, G2/G3 arcs (clockwise/counter-clockwise in the plane of G17/G18/G19) by R, negative R
  for > 180 deg, or by I/J/K (incremental from the start point) incl. full circles (end point = start point).
  The radii at start and end of an I/J/K arc may differ by at most :data:`ARC_RADIUS_TOLERANCE_INPUT` in the
  program's unit (0.002 mm or 0.002 in; FANUC No. 3410, alarm PS0020), and an R at most that much below half
  the chord.
* G90.1 (LinuxCNC, modal until G91.1): I/J/K are the centre in work coordinates (plus the work offset, and
  the tool length on Z, as an end point); both centre words of the plane are then required. G91.1 (the
  power-on mode, FANUC's only one): I/J/K are incremental from the start point.
* Under G16 the end point is polar, under G51.1/G51/G68 it is transformed (:mod:`.polar`, :mod:`.transforms`):
  the arc keeps its shape (centre I/J/K and R transformed, R times the plane's scale factor), G2 and G3
  exchange under a mirror of one plane axis.
* G61 (modal) and G9 (one block): the feed block decelerates to rest at its
  end and the next block starts after the in-position check; G64 cancels G61.
  Rapids always end with an exact stop.
"""
from __future__ import annotations

import math

from .blocks import AXIS_INDEX, PLANE_AXES, Arc, Block, Linear, Rapid, Vec3
from .codes import ValueWords
from .errors import ErrorFactory, fmt_number
from .feed import block_feed
from .modal import ModalState
from .polar import program_targets
from .settings import INCH, MM
from .transforms import advance, check_arc

#: Tolerance on the radius difference of an I/J/K arc in the program's input unit (FANUC No. 3410 "tolerance of
#: arc radius", whose unit is the input unit, mm or inch; alarm PS0020): 0.002 mm under G21, 0.002 in under G20.
#: Posts write inch programs with 4 decimals: rounding the end point and I/J to 0.0001 in alone makes the radii
#: differ by up to about 0.0002 in (0.005 mm), so a fixed 0.002 mm failed about one inch arc in six.
ARC_RADIUS_TOLERANCE_INPUT = 0.002
#: :data:`ARC_RADIUS_TOLERANCE_INPUT` under G21, m.
ARC_RADIUS_TOLERANCE = ARC_RADIUS_TOLERANCE_INPUT * MM
#: End points closer than this are the same point (full circle), m.
SAME_POINT = 1e-9
#: Index of an arc-centre word in a :data:`Vec3`.
CENTRE_INDEX = {"I": 0, "J": 1, "K": 2}


def programmed_move(st: ModalState, vals: ValueWords, g9: bool, line: int, err: ErrorFactory, unit_name: str,
                    out: list[Block]) -> None:
    """G0-G3 of a block (the modal motion ``st.motion``): append its :class:`Rapid`, :class:`Linear` or
    :class:`Arc` to ``out`` (nothing when the block names no axis).

    Parameters
    ----------
    st : ModalState
        Modal state; its programmed and machine positions move to the end point.
    vals : ValueWords
        The block's X Y Z I J K R words.
    g9 : bool
        One-shot exact stop G9 in this block.
    line : int
        1-based source line of the block.
    err : ErrorFactory
        Builds the error for this block.
    unit_name : str
        ``"mm"`` or ``"in"``, for messages.
    out : list of Block
        The program's blocks so far.
    """
    exact = g9 or st.exact_stop
    axes = [a for a in "XYZ" if a in vals]
    centre = [c for c in "IJK" if c in vals]
    has_r = "R" in vals
    is_arc = st.motion in (2, 3)
    if (centre or has_r) and not is_arc:
        w = vals[(centre or ["R"])[0]]
        raise err(w.letter + w.text, f"word {w.letter} without G2/G3", "I, J, K or R only in circular interpolation")
    if not axes and not (is_arc and centre):
        if has_r:
            raise err("R" + vals["R"].text, "R given without an end point", "X/Y/Z end point with R")
        return
    scale = st.scale
    start: Vec3 = tuple(st.machine)  # type: ignore[assignment]
    off = st.work_offset()
    tool = st.tool_length()
    xf = st.xf
    if xf.engaged:  # G16 polar point and/or G51.1/G51/G68 transforms
        targets, absolute = program_targets(st, vals, err)
        st.machine, moved = advance(st, targets, absolute)
        if 2 in moved:
            st.applied_tool = tool
    else:
        for a in axes:
            i = AXIS_INDEX[a]
            v = vals[a].value * scale
            st.prog[i] = v if st.absolute else st.prog[i] + v
            st.machine[i] = st.prog[i] + off[i] + (tool if i == 2 else 0.0)
            if i == 2:
                st.applied_tool = tool
    end: Vec3 = tuple(st.machine)  # type: ignore[assignment]
    if st.motion == 0:
        out.append(Rapid(line, start, end))
        return
    feed, per_rev = block_feed(st, err, f"G{st.motion}", f"G{st.motion} feed move")
    if st.motion == 1:
        out.append(Linear(line, start, end, feed, st.feed_line, exact, per_rev,
                          lookahead_limit=st.lookahead_limit))
        return
    i1, i2, i3 = PLANE_AXES[st.plane]
    plane_letters = {"XY": "IJ", "ZX": "KI", "YZ": "JK"}[st.plane]
    clockwise = st.motion == 2
    gname = f"G{st.motion}"
    factor = 1.0
    if xf.active:  # the arc of the transformed program: radius x factor, direction mirrored
        factor = check_arc(st, st.plane, gname, err)
        clockwise = clockwise != (xf.handedness(st.plane) < 0)
    u = 1.0 / (INCH if scale == INCH else MM)  # SI -> program units for messages
    tolerance = ARC_RADIUS_TOLERANCE_INPUT * scale  # No. 3410 is in the input unit
    d1, d2 = end[i1] - start[i1], end[i2] - start[i2]
    chord = math.hypot(d1, d2)
    if has_r:
        rw = vals["R"]
        r = rw.value * scale * factor
        if chord <= SAME_POINT:
            raise err("R" + rw.text, "an arc given by R cannot end at its start point",
                      "I/J/K for a full circle, or an end point different from the start")
        half = 0.5 * chord
        if abs(r) < half - tolerance:
            raise err("R" + rw.text, f"arc radius {fmt_number(abs(r) * u)} {unit_name} is smaller than half the chord "
                      f"({fmt_number(half * u)} {unit_name})", f"R >= {fmt_number(half * u)}")
        h = math.sqrt(max(r * r - half * half, 0.0))
        side = (1.0 if not clockwise else -1.0) * (1.0 if r > 0 else -1.0)
        c = [0.0, 0.0, 0.0]
        c[i1] = start[i1] + 0.5 * d1 - side * h * d2 / chord
        c[i2] = start[i2] + 0.5 * d2 + side * h * d1 / chord
        c[i3] = start[i3]
        out.append(Arc(line, start, end, tuple(c), st.plane, clockwise, feed, st.feed_line,  # type: ignore[arg-type]
                       exact_stop=exact, feed_per_rev=per_rev, lookahead_limit=st.lookahead_limit))
        return
    if not centre:
        raise err(gname, f"{gname} without R or I/J/K", f"R or {plane_letters[0]}/{plane_letters[1]} for the centre")
    for cl in centre:
        if cl not in plane_letters:
            raise err(cl + vals[cl].text, f"centre word {cl} is not in the {st.plane} plane",
                      f"{plane_letters[0]} and {plane_letters[1]} in G{ {'XY': 17, 'ZX': 18, 'YZ': 19}[st.plane]}")
    c = list(start)
    if st.arc_centre_absolute and len(centre) < 2:
        raise err(gname, f"{gname} under G90.1 without both centre words {plane_letters[0]} and {plane_letters[1]}",
                  f"{plane_letters[0]} and {plane_letters[1]} (the centre in work coordinates under G90.1)")
    if xf.active:
        given = [0.0, 0.0, 0.0]
        for cl in centre:
            given[CENTRE_INDEX[cl]] = vals[cl].value * scale
        if st.arc_centre_absolute:
            w = xf.to_work([given[i] if i in (i1, i2) else st.prog[i] for i in range(3)])
            for i in (i1, i2):
                c[i] = w[i] + off[i] + (st.applied_tool if i == 2 else 0.0)
        else:
            d = xf.linear(given)
            for i in (i1, i2):
                c[i] = start[i] + d[i]
    else:
        for cl in centre:
            i = CENTRE_INDEX[cl]
            v = vals[cl].value * scale
            c[i] = v + off[i] + (st.applied_tool if i == 2 else 0.0) if st.arc_centre_absolute else start[i] + v
    r1 = math.hypot(start[i1] - c[i1], start[i2] - c[i2])
    if r1 <= SAME_POINT:
        raise err(gname, "arc centre coincides with the start point", "a non-zero radius from I/J/K")
    if chord <= SAME_POINT:
        end_l = list(end)
        end_l[i1], end_l[i2] = start[i1], start[i2]
        end = tuple(end_l)  # type: ignore[assignment]
        st.machine[i1], st.machine[i2] = start[i1], start[i2]
    r2 = math.hypot(end[i1] - c[i1], end[i2] - c[i2])
    if abs(r2 - r1) > tolerance:
        raise err(gname, f"end point is {fmt_number(r2 * u)} {unit_name} from the centre but the start is "
                  f"{fmt_number(r1 * u)} {unit_name} (difference {fmt_number(abs(r2 - r1) * u)} {unit_name})",
                  f"start and end radii equal within {fmt_number(ARC_RADIUS_TOLERANCE_INPUT)} {unit_name} "
                  "(FANUC No. 3410, alarm PS0020)")
    out.append(Arc(line, start, end, tuple(c), st.plane, clockwise, feed, st.feed_line,  # type: ignore[arg-type]
                   exact_stop=exact, feed_per_rev=per_rev, lookahead_limit=st.lookahead_limit))
