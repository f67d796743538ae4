"""Coordinate shifts of a block: G52 local coordinate system, G92 workpiece coordinate system setting, G92.1-G92.3.

None of them moves the tool: they change which machine position a programmed coordinate means (the next
absolute move goes to the shifted target) and the programmed coordinates of the current position.

Conventions (FANUC 0i-MF / 31i-B operator's manuals as the twin reads them; LinuxCNC where noted)
--------------------------------------------------------------------------------------------------
* Both shifts are added to every workpiece coordinate system (G54-G59, G54.1 Pn, with the external offset):
  a G54 -> G55 change keeps them. Machine positions (G53, the G28/G30 reference positions) are not shifted;
  the G28/G30 intermediate point is a workpiece position and is. They start at zero in every run (power-on).
  M30/M2 end the twin's program, so FANUC's cancel at reset (No. 1202#3 RLC / No. 3402#6 CLR) has nothing
  left to act on; a reference return does not cancel them (FANUC No. 1201#2 ZCL = 0 assumed).
* ``G52 X Y Z`` (group 00): the origin of the local coordinate system in the workpiece coordinate system;
  named axes only, the others keep their shift; ``G52 X0`` cancels on X. The twin requires G90: the
  manual gives G52 as the origin (an absolute value), and a G91 G52 is read differently by the controls
  (absolute, or added to the current shift), so the twin rejects it rather than guess.
* ``G92 X Y Z`` (group 00): every workpiece coordinate system is shifted so that the current position gets
  the given coordinates on the named axes. The current position is the programmed end point of the
  previous block *without* the tool length offset (the tool tip, FANUC's absolute position display): under
  G43 the next Z move still adds the length. Under G91 the given values are added to the current
  coordinates (FANUC: "the current tool position coincides with the previous coordinates plus the
  increment"; LinuxCNC ignores G91 here). G92 cancels the G52 shift of the named axes (FANUC, also Haas).
* ``G92.1 X0 Y0 Z0`` (FANUC 31i workpiece coordinate system preset): cancels the G92 and G52 shifts of the
  named axes (the values must be 0). ``G92.1`` without axes (LinuxCNC): cancels them on all axes.
  ``G92.2`` (LinuxCNC) suspends both shifts (zero, remembered); ``G92.3`` restores the remembered ones
  (nothing to restore: unchanged, as LinuxCNC's parameters then hold the active values). A G52/G92 after a
  G92.2 replaces the remembered shifts.
* Errors naming the word: no axis word (G52, G92), I/J/K/R/P/Q/,C/,R words, a G0-G3 code in the block, a
  canned-cycle mode, G52 under G91, G92.1 with a nonzero value, axis words with G92.2/G92.3, and G41/G42 with
  a nonzero radius (FANUC cancels the offset vector temporarily around a coordinate system change; not
  simulated: G40 first).
"""
from __future__ import annotations

from .blocks import AXIS_INDEX
from .codes import GWords, ValueWords
from .compensation import RADIUS_ZERO
from .errors import ErrorFactory
from .modal import ModalState

#: The codes of this module.
SHIFT_CODES = (52, 92, 92.1, 92.2, 92.3)


def coordinate_shift(st: ModalState, code: float, gs: GWords, vals: ValueWords, err: ErrorFactory) -> None:
    """Execute G52, G92, G92.1, G92.2 or G92.3 (see the module docstring); no motion.

    Parameters
    ----------
    st : ModalState
        Modal state; its shifts and the programmed coordinates of the current position change.
    code : float
        52, 92, 92.1, 92.2 or 92.3.
    gs : GWords
        The block's G codes by group.
    vals : ValueWords
        The block's other words (X, Y, Z in program units).
    err : ErrorFactory
        Builds the error for this block.
    """
    gname = "G" + gs["non-modal"][1].text
    _check_block(st, code, gname, gs, vals, err)
    axes = [AXIS_INDEX[a] for a in "XYZ" if a in vals]
    if code in (52, 92) and not axes:
        raise err(gname, f"{gname} without an axis word", f"{gname} with X, Y and/or Z (e.g. {gname} X0 Y0)")
    if code == 52:
        if not st.absolute:
            raise err(gname, "G52 in incremental mode G91 (controls read it either as the local origin or as an "
                      "increment of the current shift)", "G90 with G52 (the origin of the local coordinate system "
                      "in the workpiece coordinate system)")
        for i in axes:
            st.local_shift[i] = vals["XYZ"[i]].value * st.scale
        st.suspended_shifts = None
    elif code == 92:
        base = st.base_work_offset()
        for i in axes:
            v = vals["XYZ"[i]].value * st.scale
            wanted = v if st.absolute else st.prog[i] + v
            tip = st.machine[i] - (st.applied_tool if i == 2 else 0.0)
            st.local_shift[i] = 0.0
            st.g92_shift[i] = tip - base[i] - wanted
        st.suspended_shifts = None
    elif code == 92.1:
        for a in "XYZ":
            if a in vals and vals[a].value != 0.0:
                raise err(a + vals[a].text, f"G92.1 with {a}{vals[a].text} (the workpiece coordinate system "
                          "preset only cancels the shift)", "G92.1 X0 Y0 Z0 (the axes to preset, value 0), or "
                          "G92.1 alone for all axes")
        for i in (axes or [0, 1, 2]):
            st.local_shift[i] = st.g92_shift[i] = 0.0
        st.suspended_shifts = None
    elif code == 92.2:
        st.suspended_shifts = (tuple(st.local_shift), tuple(st.g92_shift))  # type: ignore[assignment]
        st.local_shift[:] = [0.0, 0.0, 0.0]
        st.g92_shift[:] = [0.0, 0.0, 0.0]
    else:  # 92.3
        if st.suspended_shifts is not None:
            loc, g92 = st.suspended_shifts
            st.local_shift[:], st.g92_shift[:] = list(loc), list(g92)
            st.suspended_shifts = None
    st.shift_work()


def _check_block(st: ModalState, code: float, gname: str, gs: GWords, vals: ValueWords, err: ErrorFactory) -> None:
    """The words and modes a coordinate-shift block may not have (see the module docstring)."""
    if "motion" in gs:
        raise err("G" + gs["motion"][1].text, f"{gname} and a motion G code in one block",
                  f"{gname} in a block without G0-G3 (it moves no axis)")
    if st.cycle is not None:
        raise err(gname, f"{gname} in canned-cycle mode G{st.cycle}", f"G80 (or G0) before {gname}")
    allowed = "XYZ" if code in (52, 92, 92.1) else ""
    for a in ("X", "Y", "Z", "I", "J", "K", "R", "P", "Q", ",C", ",R"):
        if a in vals and a not in allowed:
            raise err(a + vals[a].text, f"word {a} in a {gname} block",
                      f"{gname} with X, Y, Z words only" if allowed else f"{gname} alone (no axis words)")
    if st.comp != 40 and abs(st.tool_radius()) > RADIUS_ZERO:
        raise err(gname, f"{gname} while cutter compensation G{st.comp} is on with a nonzero radius (FANUC "
                  "cancels the offset vector temporarily around it; not simulated)",
                  f"G40 and its cancel move before {gname}")
