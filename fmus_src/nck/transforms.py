"""Programmable coordinate transforms (FANUC 0i-MF / 30i-MB): G51.1/G50.1 mirror, G51/G50 scaling, G68/G69 rotation.

The transforms map a *programmed* point (work coordinates as written, after G52/G92 and the work offset are
taken out) to the *transformed* work point; the work offset, then the tool length on Z are added after them
(:mod:`.modal`), and cutter compensation (:mod:`.radius_offset`) offsets the transformed path, so the order of
application is the manual's: work offsets/G52/G92 -> mirror -> scaling -> rotation -> cutter compensation ->
tool length. G16 polar coordinates (:mod:`.polar`) make the programmed point before all of them.

Conventions (FANUC 0i-MF / 30i-MB operator's manuals; the twin's reading where noted)
------------------------------------------------------------------------------------
* Processing order mirror -> scaling -> rotation (the manual's "programmable mirror image, then scaling, then
  coordinate system rotation"); they must be switched on in that order and cancelled in the reverse one:
  G51.1/G50.1 under G51 or G68, G51 or G50 under G68 are errors naming the word. Each centre is a programmed
  point mapped through the transforms before it ("the rotation centre is also scaled, not the angle").
  With a uniform scale the result is the programmed part rotated about its programmed centre, scaled about
  its programmed centre, then mirrored about the programmed axes (mirror and scaling commute).
* ``G51.1 X_ Y_ Z_`` mirrors the named axes about the given positions (work coordinates, always absolute as
  the manual's format; also under G91); another G51.1 adds or moves axes. ``G50.1 X_ ..`` cancels the named
  axes (values ignored), ``G50.1`` alone all of them (the twin's reading). Mirror in one axis of the plane:
  G2 <-> G3, G41 <-> G42 and the G68 rotation direction reverse (the geometry is the mirror image of the
  whole program, rotation included).
* ``G51 X_ Y_ Z_ P_``: uniform scaling of X, Y and Z about the centre (absolute work coordinates; an omitted
  axis: the tool position on that axis). P is an integer in units of 0.001 (FANUC No. 5400#7 SCR = 1:
  P1000 = x1, P2000 = x2), 1..999999; P0, a negative P or a P with a decimal point are errors.
  ``G51 X_ Y_ Z_ I_ J_ K_`` (No. 5400#6 XSC = 1): a factor per axis in the same units, an omitted one x1;
  a negative factor mirrors the axis. P or I/J/K is required (No. 5411 is not modelled). Scaled: end points,
  arc centres and R, the ``,C``/``,R`` sizes, canned-cycle hole positions, R point, bottom and initial level.
  Not scaled (manual): D and H offsets, the peck Q and return d of G73/G83, the G76/G87 shift Q, feeds.
  G2/G3 and ``,C``/``,R`` under different factors of the two plane axes are errors (FANUC alarm; no ellipse).
* ``G68 a_ b_ R_`` (the two axes of the G17/G18/G19 plane): rotation by R degrees counter-clockwise about
  (a, b), absolute work coordinates (the manual's "absolute command", also under G91); an omitted centre
  axis: the tool position when G68 is given; R omitted: 0 deg (No. 5410 = 0). R is always absolute (No.
  5400#0 RIN = 0), |R| <= 360. A normal-axis or I/J/K word (3-D conversion), G68 in G68 (G69 first), G68
  under G16 (G15 first) and G17/G18/G19 changing the plane under G68 (alarm PS0037-style) are errors.
  G2/G3 are in the rotation plane (FANUC alarm 144). G69 may share its block with a move.
* Current position: the programmed coordinates are kept as programmed; an absolute move goes to the
  transformed point of its programmed end point (an axis left out keeps its programmed value, so under G68 a
  one-axis G90 move can move both plane axes, as FANUC). After a transform is switched on or off, incremental
  moves run by the transformed increment from where the tool is until the axis gets an absolute command (the
  manual: "the centre for an incremental command after G68 before an absolute command is the tool position").
* Under a transform (G51.1, G51, G68): G28/G30/G53, G52, G92/G92.x and work-offset changes (G54-G59,
  G54.1) are errors (manual: "cancel first"); G10 data input is allowed. Switching a transform on or off
  while G41/G42 is on with a nonzero radius, or in canned-cycle mode, is an error (G40/G80 first). Canned
  cycles need the drilling axis Z untouched by rotation and mirror (G68 in G17, no Z mirror).
* The transforms are part of the modal state: one for the main program and its subprograms/macros (they
  survive M98/M99, G65); a run starts with all of them off (power-on). M30/M2 end the twin's program, so
  FANUC's cancel at reset has nothing left to act on.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

from .blocks import AXIS_INDEX, PLANE_AXES
from .codes import GWords, ValueWords
from .errors import ErrorFactory, fmt_number
from .input_ranges import check_coordinates
from .lexer import Word
from .settings import INCH

if TYPE_CHECKING:
    from .modal import ModalState

#: Unit of the G51 magnification P / I / J / K (FANUC No. 5400#7 SCR = 1): 0.001.
MAGNIFICATION_UNIT = 1e-3
#: Largest G51 magnification word (x999.999).
MAX_MAGNIFICATION = 999999
#: Largest |R| of G68, degrees.
MAX_ANGLE = 360.0
#: Non-modal codes not allowed while a transform is on -> what they are.
_FORBIDDEN = {28: "reference position return", 30: "reference position return", 53: "machine coordinates",
              52: "local coordinate system", 92: "workpiece coordinate system setting",
              92.1: "workpiece coordinate system preset", 92.2: "coordinate shift suspend",
              92.3: "coordinate shift restore"}
#: Plane -> its G code, for messages.
_PLANE_G = {"XY": 17, "ZX": 18, "YZ": 19}


@dataclass(frozen=True)
class Rotation:
    """Coordinate rotation of G68.

    Attributes
    ----------
    plane : {"XY", "ZX", "YZ"}
        Plane of G17/G18/G19 when G68 was given.
    centre : tuple of float
        Centre in the two plane axes (first, second), after mirror and scaling, m.
    angle : float
        Effective angle counter-clockwise about the plane normal, rad (reversed under a one-axis mirror).
    degrees : float
        R as programmed, degrees.
    """

    plane: str
    centre: tuple[float, float]
    angle: float
    degrees: float


class Transforms:
    """Mirror, scaling and rotation in effect, G16 polar mode, and the axes awaiting an absolute command."""

    def __init__(self) -> None:
        self.mirror: list[float | None] = [None, None, None]  # mirror position per axis (programmed, m)
        self.factors = [1.0, 1.0, 1.0]  # scaling factor per axis
        self.scale_centre = [0.0, 0.0, 0.0]  # after the mirror, m
        self.scaling = False
        self.rotation: Rotation | None = None
        self.polar = False  # G16
        self.polar_started = False  # a polar move has been made since G16
        self.pending: set[int] = set()  # axes whose next incremental move starts from the tool (see module doc)

    @property
    def active(self) -> bool:
        """A mirror, scaling or rotation is on."""
        return self.scaling or self.rotation is not None or any(m is not None for m in self.mirror)

    @property
    def engaged(self) -> bool:
        """Moves need this module (a transform, G16, or axes awaiting an absolute command)."""
        return self.active or self.polar or bool(self.pending)

    def codes(self) -> str:
        """The active codes, for messages (``"G51.1 G68"``)."""
        names = [("G51.1", any(m is not None for m in self.mirror)), ("G51", self.scaling),
                 ("G68", self.rotation is not None)]
        return " ".join(n for n, on in names if on)

    def to_work(self, p: Sequence[float]) -> list[float]:
        """The transformed point of programmed point ``p`` (m), shape (3,)."""
        q = list(p)
        for i, m in enumerate(self.mirror):
            if m is not None:
                q[i] = 2.0 * m - q[i]
        if self.scaling:
            for i in range(3):
                q[i] = self.scale_centre[i] + self.factors[i] * (q[i] - self.scale_centre[i])
        if self.rotation is not None:
            r = self.rotation
            i1, i2, _ = PLANE_AXES[r.plane]
            d1, d2 = q[i1] - r.centre[0], q[i2] - r.centre[1]
            c, s = math.cos(r.angle), math.sin(r.angle)
            q[i1], q[i2] = r.centre[0] + c * d1 - s * d2, r.centre[1] + s * d1 + c * d2
        return q

    def to_program(self, w: Sequence[float]) -> list[float]:
        """Inverse of :meth:`to_work`: the programmed point of transformed point ``w`` (m)."""
        q = list(w)
        if self.rotation is not None:
            r = self.rotation
            i1, i2, _ = PLANE_AXES[r.plane]
            d1, d2 = q[i1] - r.centre[0], q[i2] - r.centre[1]
            c, s = math.cos(r.angle), math.sin(r.angle)
            q[i1], q[i2] = r.centre[0] + c * d1 + s * d2, r.centre[1] - s * d1 + c * d2
        if self.scaling:
            for i in range(3):
                q[i] = self.scale_centre[i] + (q[i] - self.scale_centre[i]) / self.factors[i]
        for i, m in enumerate(self.mirror):
            if m is not None:
                q[i] = 2.0 * m - q[i]
        return q

    def linear(self, v: Sequence[float]) -> list[float]:
        """The transformed vector of programmed vector ``v`` (the linear part of :meth:`to_work`)."""
        zero = self.to_work((0.0, 0.0, 0.0))
        q = self.to_work(v)
        return [q[i] - zero[i] for i in range(3)]

    def coupled(self, axes: Sequence[int]) -> list[int]:
        """The axes that move when ``axes`` are programmed (both plane axes of a rotation)."""
        moved = set(axes)
        if self.rotation is not None:
            i1, i2, _ = PLANE_AXES[self.rotation.plane]
            if moved & {i1, i2}:
                moved |= {i1, i2}
        return sorted(moved)

    def handedness(self, plane: str) -> int:
        """-1 when the transforms mirror the plane (one of its axes mirrored or negatively scaled), else +1."""
        i1, i2, _ = PLANE_AXES[plane]
        sign = 1
        for i in (i1, i2):
            if self.mirror[i] is not None:
                sign = -sign
            if self.scaling and self.factors[i] < 0.0:
                sign = -sign
        return sign

    def plane_factor(self, plane: str) -> float | None:
        """Length factor in ``plane`` (1 without scaling); None when its two axes are scaled differently."""
        if not self.scaling:
            return 1.0
        i1, i2, _ = PLANE_AXES[plane]
        k1, k2 = abs(self.factors[i1]), abs(self.factors[i2])
        return k1 if k1 == k2 else None


def advance(st: ModalState, targets: dict[int, float], absolute: bool) -> tuple[list[float], list[int]]:
    """Programmed end point ``targets`` (axis -> programmed coordinate, m): update ``st.prog`` and return the
    machine position it means and the axes that move (see the module docstring; ``st.machine`` is not changed).

    Parameters
    ----------
    st : ModalState
        Modal state.
    targets : dict of int to float
        Programmed coordinates (m) of the axes the block names.
    absolute : bool
        The block's end point is absolute (G90 or polar); else incremental moves of axes in
        :attr:`Transforms.pending` run by the transformed increment from the tool position.

    Returns
    -------
    machine : list of float
        Machine position (m), shape (3,).
    moved : list of int
        Axes whose machine position changed (both plane axes of a rotation).
    """
    xf = st.xf
    off = st.work_offset()
    tool = st.tool_length()
    step = [0.0, 0.0, 0.0]
    for i, v in targets.items():
        step[i] = v - st.prog[i]
        st.prog[i] = v
    moved = xf.coupled(list(targets))
    work = xf.to_work(st.prog)
    delta = xf.linear(step)
    machine = list(st.machine)
    for i in moved:
        length = tool if i == 2 else 0.0
        if not absolute and i in xf.pending:
            machine[i] = machine[i] - (st.applied_tool if i == 2 else 0.0) + delta[i] + length
        else:
            machine[i] = work[i] + off[i] + length
    if absolute:
        xf.pending -= set(moved)
    return machine, moved


def tool_position(st: ModalState) -> list[float]:
    """Programmed coordinates of the tool (m, without the tool length) under the transforms on, shape (3,)."""
    off = st.work_offset()
    w = [st.machine[i] - off[i] - (st.applied_tool if i == 2 else 0.0) for i in range(3)]
    return st.xf.to_program(w)


def check_transform_block(st: ModalState, gs: GWords, err: ErrorFactory) -> None:
    """Codes a block may not have while a transform is on (after the block's cancels): G28/G30/G53, G52,
    G92/G92.x and work-offset changes (FANUC: "cancel first")."""
    xf = st.xf
    if not xf.active:
        return
    code = gs.get("non-modal", (None,))[0]
    word = None
    if code in _FORBIDDEN:
        word, what = "G" + gs["non-modal"][1].text, _FORBIDDEN[code]  # type: ignore[index]
    elif "work offset" in gs:
        word, what = "G" + gs["work offset"][1].text, "work coordinate system selection"
    if word is not None:
        raise err(word, f"{word} ({what}) while {xf.codes()} is on (FANUC: not allowed in mirror image, "
                  "scaling or coordinate rotation mode)", f"G69, G50 and G50.1 (as active) before {word}")


def check_plane_change(st: ModalState, plane: str, gs: GWords, err: ErrorFactory) -> None:
    """G17/G18/G19 may not change the plane under G68 (unless the same block cancels it with G69)."""
    rot = st.xf.rotation
    if rot is None or plane == rot.plane or gs.get("coordinate rotation", (None,))[0] == 69:
        return
    word = "G" + gs["plane"][1].text
    raise err(word, f"{word} changes the plane while coordinate rotation G68 in G{_PLANE_G[rot.plane]} is on",
              "G69 before changing the plane (FANUC: no G17/G18/G19 in G68 mode)")


def transform_modes(st: ModalState, gs: GWords, vals: ValueWords, err: ErrorFactory) -> bool:
    """G15/G16, G69/G68, G50/G51, G50.1/G51.1 of a block (cancels first, in the reverse order of the switch-on).

    Returns
    -------
    bool
        The block's axis words were the data of G51.1/G50.1/G51/G68 (the block makes no move).

    Raises
    ------
    GCodeError
        Through ``err``, for the cases of the module docstring.
    """
    xf = st.xf
    pol = gs.get("polar coordinates", (None, None))[0]
    rot = gs.get("coordinate rotation", (None, None))[0]
    sca = gs.get("scaling", (None, None))[0]
    mir = gs.get("mirror image", (None, None))[0]
    takers = [("G" + gs[g][1].text) for g, c in (("mirror image", mir), ("scaling", sca),
                                                  ("coordinate rotation", rot)) if c in (50.1, 51.1, 51, 68)]
    if len(takers) > 1:
        raise err(takers[1], f"{takers[0]} and {takers[1]} in one block (both take the axis words)",
                  f"{takers[0]} and {takers[1]} in separate blocks")
    if takers:
        _check_data_block(st, takers[0], gs, err)
        check_coordinates(vals, "in" if st.scale == INCH else "mm", err)  # before the centres are read
    if pol == 15:
        xf.polar = False
    elif pol == 16:
        xf.polar, xf.polar_started = True, False
    changed = False
    if rot == 69 and xf.rotation is not None:
        _check_switch(st, "G" + gs["coordinate rotation"][1].text, err)
        xf.rotation = None
        changed = True
    if sca == 50 and xf.scaling:
        word = "G" + gs["scaling"][1].text
        _check_order(st, word, "scaling cancel", rotation=True, scaling=False, err=err)
        _check_switch(st, word, err)
        xf.scaling, xf.factors = False, [1.0, 1.0, 1.0]
        changed = True
    if mir == 50.1:
        changed |= _mirror_cancel(st, "G" + gs["mirror image"][1].text, vals, err)
    elif mir == 51.1:
        _mirror_on(st, "G" + gs["mirror image"][1].text, vals, err)
        changed = True
    if sca == 51:
        _scaling_on(st, "G" + gs["scaling"][1].text, vals, err)
        changed = True
    if rot == 68:
        _rotation_on(st, "G" + gs["coordinate rotation"][1].text, vals, err)
        changed = True
    if changed:
        xf.pending = {0, 1, 2}
    return bool(takers)


def _check_data_block(st: ModalState, word: str, gs: GWords, err: ErrorFactory) -> None:
    """A G51.1/G50.1/G51/G68 block has no motion, non-modal or canned-cycle code and is not in a cycle mode."""
    for group in ("motion", "non-modal"):
        if group in gs:
            other = "G" + gs[group][1].text
            raise err(other, f"{other} and {word} in one block ({word} takes the block's axis words)",
                      f"{word} in a block of its own, the move in the next block")
    cycle = gs.get("canned cycle", (None, None))[0]
    if cycle not in (None, 80):
        other = "G" + gs["canned cycle"][1].text
        raise err(other, f"{other} and {word} in one block", f"{word} before the canned cycle block")
    if st.cycle is not None and cycle != 80:
        raise err(word, f"{word} in canned-cycle mode G{st.cycle}", f"G80 (or G0) before {word}")


def _check_switch(st: ModalState, word: str, err: ErrorFactory) -> None:
    """A transform switched on or off: not while G41/G42 is on with a nonzero radius."""
    from .compensation import RADIUS_ZERO  # compensation imports modal, which imports this module
    if st.comp != 40 and abs(st.tool_radius()) > RADIUS_ZERO:
        raise err(word, f"{word} while cutter compensation G{st.comp} is on with a nonzero radius (FANUC: specify "
                  "the transforms before the cutter compensation mode)", f"G40 and its cancel move before {word}")


def _check_order(st: ModalState, word: str, what: str, *, rotation: bool, scaling: bool,
                 err: ErrorFactory) -> None:
    """Switch on G51.1 -> G51 -> G68, cancel G69 -> G50 -> G50.1 (FANUC)."""
    xf = st.xf
    later = [c for c, on in (("G68", rotation and xf.rotation is not None), ("G51", scaling and xf.scaling)) if on]
    if later:
        cancel = " and ".join({"G68": "G69", "G51": "G50"}[c] for c in later)
        raise err(word, f"{word} ({what}) while {' and '.join(later)} is on (FANUC order: G51.1, G51, G68 "
                  "on; G69, G50, G50.1 off)", f"{cancel} before {word}")


def _axis_words(vals: ValueWords, word: str, allowed: str, err: ErrorFactory) -> None:
    """Only the letters of ``allowed`` among the position and data words of a transform block."""
    for a in ("X", "Y", "Z", "I", "J", "K", "R", "P", "Q", ",C", ",R"):
        if a in vals and (len(a) > 1 or a not in allowed):
            raise err(a + vals[a].text, f"word {a} in a {word} block",
                      f"{word} with {' '.join(allowed)} words only" if allowed else f"{word} alone")


def _mirror_on(st: ModalState, word: str, vals: ValueWords, err: ErrorFactory) -> None:
    _axis_words(vals, word, "XYZ", err)
    axes = [a for a in "XYZ" if a in vals]
    if not axes:
        raise err(word, f"{word} without an axis word", f"{word} with the mirror position, e.g. {word} X50.")
    _check_order(st, word, "programmable mirror image", rotation=True, scaling=True, err=err)
    _check_switch(st, word, err)
    for a in axes:
        st.xf.mirror[AXIS_INDEX[a]] = vals[a].value * st.scale


def _mirror_cancel(st: ModalState, word: str, vals: ValueWords, err: ErrorFactory) -> bool:
    _axis_words(vals, word, "XYZ", err)
    axes = [AXIS_INDEX[a] for a in "XYZ" if a in vals] or [0, 1, 2]
    if all(st.xf.mirror[i] is None for i in axes):
        return False
    _check_order(st, word, "programmable mirror image cancel", rotation=True, scaling=True, err=err)
    _check_switch(st, word, err)
    for i in axes:
        st.xf.mirror[i] = None
    return True


def _magnification(w: Word, err: ErrorFactory, allow_negative: bool) -> float:
    if w.has_point or w.value != int(w.value):
        raise err(w.letter + w.text, f"magnification {w.letter}{w.text} has a decimal point",
                  f"an integer {w.letter} in units of 0.001 ({w.letter}1000 = x1, {w.letter}2000 = x2)")
    lo = -MAX_MAGNIFICATION if allow_negative else 1
    if w.value == 0 or not lo <= w.value <= MAX_MAGNIFICATION:
        rng = f"1..{MAX_MAGNIFICATION}" if not allow_negative else f"+-1..{MAX_MAGNIFICATION} (negative mirrors)"
        raise err(w.letter + w.text, f"scaling magnification {w.letter}{w.text} is "
                  f"{'zero' if w.value == 0 else 'out of range'}", f"{w.letter} in {rng}, units of 0.001")
    return w.value * MAGNIFICATION_UNIT


def _scaling_on(st: ModalState, word: str, vals: ValueWords, err: ErrorFactory) -> None:
    xf = st.xf
    _axis_words(vals, word, "XYZPIJK", err)
    if "P" in vals and any(a in vals for a in "IJK"):
        a = next(a for a in "IJK" if a in vals)
        raise err(a + vals[a].text, f"{word} with both P and {a}", f"{word} with P (uniform) or I/J/K (per axis)")
    if "P" not in vals and not any(a in vals for a in "IJK"):
        raise err(word, f"{word} without a magnification", f"{word} X_ Y_ Z_ P_ (P2000 = x2) or I_ J_ K_ per axis")
    if xf.rotation is not None:
        _check_order(st, word, "scaling", rotation=True, scaling=False, err=err)
    if xf.scaling:
        raise err(word, f"{word} while scaling G51 is on", f"G50 before {word}")
    _check_switch(st, word, err)
    if "P" in vals:
        factors = [_magnification(vals["P"], err, False)] * 3
    else:
        factors = [_magnification(vals[a], err, True) if a in vals else 1.0 for a in "IJK"]
    here = tool_position(st)  # G68 is off (order), G51 not yet on: through the mirror only
    centre = [vals[a].value * st.scale if a in vals else here[i] for i, a in enumerate("XYZ")]
    xf.scale_centre = xf.to_work(centre)  # scaling is off yet: the mirrored centre
    xf.factors = factors
    xf.scaling = True


def _rotation_on(st: ModalState, word: str, vals: ValueWords, err: ErrorFactory) -> None:
    xf = st.xf
    i1, i2, i3 = PLANE_AXES[st.plane]
    normal = "XYZ"[i3]
    if normal in vals:
        w = vals[normal]
        raise err(normal + w.text, f"{word} with {normal}, which is not an axis of the {st.plane} plane "
                  f"(G{_PLANE_G[st.plane]})", f"{word} {'XYZ'[i1]}_ {'XYZ'[i2]}_ R_ (the centre in the plane)")
    for a in "IJK":
        if a in vals:
            raise err(a + vals[a].text, f"{word} with {a} (three-dimensional coordinate conversion) is not "
                      "supported", f"{word} {'XYZ'[i1]}_ {'XYZ'[i2]}_ R_")
    _axis_words(vals, word, "XYZR", err)
    if xf.polar:
        raise err(word, f"{word} in polar coordinate mode G16", f"G15 before {word}")
    if xf.rotation is not None:
        raise err(word, f"{word} while coordinate rotation G68 is on", f"G69 before {word}")
    _check_switch(st, word, err)
    degrees = vals["R"].value if "R" in vals else 0.0
    if abs(degrees) > MAX_ANGLE:
        raise err("R" + vals["R"].text, f"rotation angle R{vals['R'].text} is beyond {fmt_number(MAX_ANGLE)} deg",
                  f"|R| <= {fmt_number(MAX_ANGLE)} (degrees, counter-clockwise)")
    here = tool_position(st)  # G68 is off yet: through the mirror and scaling
    centre = list(here)
    for i in (i1, i2):
        a = "XYZ"[i]
        if a in vals:
            centre[i] = vals[a].value * st.scale
    c = xf.to_work(centre)
    angle = math.radians(degrees) * xf.handedness(st.plane)
    xf.rotation = Rotation(st.plane, (c[i1], c[i2]), angle, degrees)


def check_arc(st: ModalState, plane: str, word: str, err: ErrorFactory) -> float:
    """Length factor of an arc in ``plane`` under the transforms (G2/G3 in the G68 plane, uniform scaling)."""
    xf = st.xf
    if xf.rotation is not None and xf.rotation.plane != plane:
        raise err(word, f"{word} in the {plane} plane under coordinate rotation in {xf.rotation.plane} (FANUC "
                  "alarm 144)", f"arcs in the plane of G68 (G{_PLANE_G[xf.rotation.plane]})")
    k = xf.plane_factor(plane)
    if k is None:
        i1, i2, _ = PLANE_AXES[plane]
        raise err(word, f"{word} under scaling with different factors on {'XYZ'[i1]} "
                  f"(x{fmt_number(xf.factors[i1])}) and {'XYZ'[i2]} (x{fmt_number(xf.factors[i2])}) (an ellipse; "
                  "FANUC alarm)", "the same magnification on both plane axes (G51 P_) for G2/G3")
    return k


def check_cycle(st: ModalState, word: str, err: ErrorFactory) -> None:
    """Canned cycles drill along Z: no G68 outside G17, no mirror or negative scale of Z, G16 only in G17."""
    xf = st.xf
    problem = None
    if xf.rotation is not None and xf.rotation.plane != "XY":
        problem = f"coordinate rotation G68 in the {xf.rotation.plane} plane turns the drilling axis Z"
    elif xf.mirror[2] is not None or (xf.scaling and xf.factors[2] < 0.0):
        problem = "the drilling axis Z is mirrored"
    elif xf.polar and st.plane != "XY":
        problem = f"polar coordinates G16 in the {st.plane} plane"
    if problem is not None:
        raise err(word, f"canned cycle {word}: {problem}", "canned cycles with G68/G16 in G17 and Z not mirrored")


def z_work(st: ModalState, z: float) -> float:
    """Transformed Z of programmed level ``z`` (m) for a canned cycle (Z not in a rotation, see check_cycle)."""
    return st.xf.to_work((0.0, 0.0, z))[2]
