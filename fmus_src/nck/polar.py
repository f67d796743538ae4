"""Programmed end points of a block: Cartesian X/Y/Z words, or G16 polar coordinates (FANUC 0i-MF / 30i-MB).

Conventions (the manual's "polar coordinate command"; the twin's reading where noted)
-------------------------------------------------------------------------------------
* ``G16`` (modal until ``G15``): in the G17/G18/G19 plane the first axis word is the radius, the second the
  angle in degrees, counter-clockwise from the first axis (G17: X radius, Y angle; G18: Z radius, X angle;
  G19: Y radius, Z angle). The normal axis stays Cartesian; I/J/K and R of an arc stay Cartesian.
* Radius under G90: from the origin of the work (or G52 local) coordinate system; under G91: the polar origin
  is the current position and the radius the distance from it.
* Angle under G90: absolute; under G91: added to the angle of the current position about the work origin.
* Radius omitted: the distance of the current position from the work origin (origin = work origin); angle
  omitted: the angle of the current position about the work origin (0 at the origin) — FANUC/Mitsubishi.
  The first move after G16 must give the radius (the current position was not reached in polar
  coordinates): an error naming the word otherwise (the twin's rule).
* Polar moves are absolute end points for the transforms (:mod:`.transforms`); G16 under G68 is allowed
  (polar in the rotated system), G68 under G16 is an error.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from .blocks import AXIS_INDEX, PLANE_AXES
from .codes import ValueWords
from .errors import ErrorFactory

if TYPE_CHECKING:
    from .modal import ModalState


def program_targets(st: ModalState, vals: ValueWords, err: ErrorFactory, letters: str = "XYZ"
                    ) -> tuple[dict[int, float], bool]:
    """Programmed coordinates (m) of the axes the block names among ``letters``.

    Parameters
    ----------
    st : ModalState
        Modal state (distance mode, plane, G16, current programmed position).
    vals : ValueWords
        The block's words.
    err : ErrorFactory
        Builds the error for this block.
    letters : str
        The axis letters to read (``"XY"`` for a canned-cycle hole).

    Returns
    -------
    targets : dict of int to float
        Axis index -> programmed coordinate (m); both plane axes for a polar point.
    absolute : bool
        The end point is absolute (G90, or a polar point).
    """
    targets: dict[int, float] = {}
    scale = st.scale
    absolute = st.absolute
    if st.xf.polar:
        polar = _polar_point(st, vals, err)
        if polar is not None:
            targets.update(polar)
            absolute = True
    for a in letters:
        i = AXIS_INDEX[a]
        if a in vals and i not in targets:
            v = vals[a].value * scale
            targets[i] = v if st.absolute else st.prog[i] + v
    return targets, absolute


def _polar_point(st: ModalState, vals: ValueWords, err: ErrorFactory) -> dict[int, float] | None:
    """The plane point of a G16 block, or None when it names no plane axis."""
    i1, i2, _ = PLANE_AXES[st.plane]
    ra, aa = "XYZ"[i1], "XYZ"[i2]
    if ra not in vals and aa not in vals:
        return None
    xf = st.xf
    if ra not in vals and not xf.polar_started:
        w = vals[aa]
        raise err(aa + w.text, f"polar coordinate command G16: the first move gives no radius {ra}",
                  f"{ra} (radius) and {aa} (angle in degrees) on the first move after G16")
    cur = (st.prog[i1], st.prog[i2])
    origin = (0.0, 0.0)
    if ra in vals:
        radius = vals[ra].value * st.scale
        if not st.absolute:
            origin = cur
    else:
        radius = math.hypot(*cur)
    here = math.degrees(math.atan2(cur[1], cur[0])) if math.hypot(*cur) > 0.0 else 0.0
    if aa in vals:
        angle = vals[aa].value if st.absolute else here + vals[aa].value
    else:
        angle = here
    a = math.radians(angle)
    xf.polar_started = True
    return {i1: origin[0] + radius * math.cos(a), i2: origin[1] + radius * math.sin(a)}
