"""Machine-position moves of a block: G28/G30 reference position return and G53 machine coordinates.

Conventions
-----------
* G28 (FANUC 0i-MF/31i-B, "reference position return"): non-modal, rapid
  traverse, only the named axes move: first to the intermediate point, which
  is programmed like a G0 end point in the current G90/G91 mode (``G28 G91
  Z0`` has its intermediate point at the current position, so Z goes straight
  up to the reference; ``G28 G90 X0 Y0`` goes via work X0 Y0), then to the
  reference position :attr:`InterpreterSettings.reference`, a machine position
  (FANUC No. 1240): neither work offset nor tool length is added to it. After
  G28 Z the tool-length vector is no longer in the Z position (as FANUC
  cancels it at the reference position); G43/G44 stay modal and the next Z
  move applies the offset again. The programmed position of a returned axis
  is reference - work offset (Z: - the tool length still contained, i.e.
  none), so following G90/G91 moves are consistent. G28 without an axis word,
  and G28/G30/G53 in canned-cycle mode are errors. G29 is rejected.
* G30 P2/P3/P4 (2nd/3rd/4th reference position return; P omitted = P2): as
  G28 (intermediate point, only the named axes, rapid), to
  :attr:`InterpreterSettings.reference2`/``3``/``4`` (FANUC No. 1241-1243;
  not set: the 1st reference position). Other P values are errors.
* G53 (machine coordinate positioning): non-modal, rapid traverse whatever
  the G0/G1 mode (FANUC moves G53 at rapid), machine coordinates without work
  offset or tool length (the tool-length vector is left out as after G28).
  FANUC ignores G53 under G91; the twin rejects it (G90 required) so that a
  program cannot silently do something else than it reads.
* Frames: the reference positions and G53 values are machine coordinates; the blocks are in the axis frame, so
  each is moved by :attr:`InterpreterSettings.machine_zero` (:meth:`InterpreterSettings.machine_to_axis`). On
  the default machine machine zero is the G28 reference position: ``G53 Z0`` goes to the top of the Z travel,
  as on a FANUC or Haas VMC.
* M6 Z retract (:func:`tool_change_retract`, :attr:`InterpreterSettings.tool_change_retract`): on a vertical
  machining center the tool change first moves Z to the tool-change position at rapid, as the builder's M6
  macro does with ``G91 G28 Z0`` or ``G91 G30 Z0``: "G28" goes to the 1st reference Z, "G30" to the 2nd
  (No. 1241); "off" (the default) models M6 as the tool change time alone. Only Z moves, straight up from
  where the tool is, without work offset or tool length (the tool-length vector is left out as after G28).
  Under a programmable transform, in canned-cycle mode or under G41/G42 with a nonzero radius it is an error
  naming M6 (FANUC's G28/G30 are not allowed there either).
"""
from __future__ import annotations

from .blocks import AXIS_INDEX, Block, Rapid, Vec3
from .codes import ValueWords
from .compensation import RADIUS_ZERO
from .errors import ErrorFactory
from .lexer import Word
from .modal import ModalState
from .motion import SAME_POINT


def machine_move(st: ModalState, code: int, vals: ValueWords, line: int, err: ErrorFactory, out: list[Block]) -> None:
    """G28/G30 (reference position return via the intermediate point) or G53 (machine coordinates); see the
    module docstring for the FANUC behaviour followed.

    Parameters
    ----------
    st : ModalState
        Modal state; the named axes end at the reference (machine) position.
    code : int
        28, 30 or 53.
    vals : ValueWords
        The block's words (X Y Z; P of G30).
    line : int
        1-based source line of the block.
    err : ErrorFactory
        Builds the error for this block.
    out : list of Block
        The program's blocks so far; the :class:`Rapid` moves are appended.
    """
    gname = f"G{code}"
    for a in ("IJKRQ" if code == 30 else "IJKRPQ"):
        if a in vals:
            raise err(a + vals[a].text, f"word {a} in a {gname} block",
                      "G30 with P2/P3/P4 and X, Y, Z words only" if code == 30 else f"{gname} with X, Y, Z words only")
    number = reference_number(vals.get("P"), err) if code == 30 else 1
    axes = [AXIS_INDEX[a] for a in "XYZ" if a in vals]
    if not axes:
        raise err(gname, f"{gname} without an axis word",
                  "the axes to move named by X/Y/Z, e.g. G28 G91 Z0. or G90 G53 Z0.")
    start: Vec3 = tuple(st.machine)  # type: ignore[assignment]
    scale = st.scale
    if code == 53:
        if not st.absolute:
            raise err("G53", "G53 in incremental mode G91 (FANUC ignores it there)", "G90 with G53")
        for i in axes:  # machine coordinates -> the axis frame of the blocks
            st.machine[i] = st.settings.machine_to_axis(i, vals["XYZ"[i]].value * scale)
        if 2 in axes:
            st.applied_tool = 0.0
        st.sync_prog(axes)
        out.append(Rapid(line, start, tuple(st.machine)))  # type: ignore[arg-type]
        return
    off = st.work_offset()
    tool = st.tool_length()
    for i in axes:  # intermediate point: as a G0 end point in the current G90/G91 mode
        v = vals["XYZ"[i]].value * scale
        st.prog[i] = v if st.absolute else st.prog[i] + v
        st.machine[i] = st.prog[i] + off[i] + (tool if i == 2 else 0.0)
    if 2 in axes:
        st.applied_tool = tool
    mid: Vec3 = tuple(st.machine)  # type: ignore[assignment]
    if max(abs(mid[i] - start[i]) for i in range(3)) > SAME_POINT:
        out.append(Rapid(line, start, mid))
    ref = st.settings.reference_position(number)
    for i in axes:
        st.machine[i] = st.settings.machine_to_axis(i, ref[i])
    if 2 in axes:
        st.applied_tool = 0.0  # the reference position is a machine position: no tool length in it
    st.sync_prog(axes)
    out.append(Rapid(line, mid, tuple(st.machine)))  # type: ignore[arg-type]


def reference_number(p: Word | None, err: ErrorFactory) -> int:
    """Which reference position G30 returns to: P2, P3 or P4 (omitted: 2)."""
    if p is None:
        return 2
    if p.has_point or p.value not in (2.0, 3.0, 4.0):
        raise err("P" + p.text, f"G30 P{p.text} is not a reference position number",
                  "G30 P2, P3 or P4 (2nd/3rd/4th reference position; P omitted = P2)")
    return int(p.value)


def tool_change_retract(st: ModalState, line: int, err: ErrorFactory, out: list[Block]) -> None:
    """The Z move of an M6 to the tool-change position (see the module docstring); nothing when "off".

    Parameters
    ----------
    st : ModalState
        Modal state; Z ends at the reference position of ``st.settings.tool_change_retract``.
    line : int
        1-based source line of the M6 block.
    err : ErrorFactory
        Builds the error for this block.
    out : list of Block
        The program's blocks so far; the :class:`Rapid` is appended (none when Z is already there).
    """
    mode = st.settings.tool_change_retract
    if mode == "off":
        return
    why = None
    if st.xf.active:
        why = f"{st.xf.codes()} is on"
    elif st.cycle is not None:
        why = f"canned cycle G{st.cycle} is modal"
    elif st.comp != 40 and abs(st.tool_radius()) > RADIUS_ZERO:
        why = f"cutter compensation G{st.comp} is on with a nonzero radius"
    if why is not None:
        raise err("M6", f"M6 with the Z retract to the tool-change position ({mode} Z) while {why}",
                  "G69/G50/G50.1, G80 and G40 (as active) before M6")
    start: Vec3 = tuple(st.machine)  # type: ignore[assignment]
    st.machine[2] = st.settings.machine_to_axis(2, st.settings.reference_position(1 if mode == "G28" else 2)[2])
    st.applied_tool = 0.0
    st.sync_prog([2])
    if abs(st.machine[2] - start[2]) > SAME_POINT:
        out.append(Rapid(line, start, tuple(st.machine)))  # type: ignore[arg-type]
