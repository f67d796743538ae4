"""Spindle, tool and coolant words of a block: S, T, M3/M4/M5/M19, M6, M7/M8/M9 → typed blocks.

Conventions
-----------
* S is the commanded spindle speed in rev/min (modal, kept through M5); M3/M4 start the spindle clockwise /
  counter-clockwise at it, M5 stops it; an S without M3/M4/M5 changes the speed in the current direction.
* M19 (spindle orientation, as posts write it before a tool change or a boring tool's retract): the spindle
  stops as with M5 and stays stopped until M3/M4; the orientation itself (a fraction of a revolution at the
  orientation speed, well under the ramp-down time) is not modelled.
* T selects a tool (0..:data:`.input_ranges.MAX_TOOL`), M6 changes to the selected one, after the Z retract to
  the tool-change position when the machine has one (:func:`.machine_moves.tool_change_retract`).
* M6 and the spindle (:attr:`.settings.InterpreterSettings.tool_change_spindle`): with "stop" (the default) the
  tool-change macro stops a turning spindle at the start of the M6 block (a :class:`SpindleStop`, M19 without
  the orientation's fraction of a revolution), while Z goes to the tool-change position when the machine has a
  retract (as ``G91 G28 Z0 M19``); the change itself (``tool_change_time``) starts when the axes are in position
  and the spindle is at rest (:attr:`ToolChange.at_rest`: a drawbar cannot release a turning tool), also after an
  M5 written before M6 whose ramp down is still running. The spindle stays stopped after M6 until M3/M4 (the S
  word stays in effect), as RS274/NGC's "when the tool change is complete, the spindle will be stopped". With
  "keep" the spindle turns on at its speed through the change (a macro that restarts it).
* M7/M8 switch the coolant on, M9 off.
* Order within a block: tool change, spindle, coolant (then the modes and the motion of the block).
"""
from __future__ import annotations

from .blocks import Block, Coolant, SpindleSpeed, SpindleStop, ToolChange
from .codes import MWords, ValueWords
from .errors import ErrorFactory
from .input_ranges import MAX_TOOL
from .machine_moves import tool_change_retract
from .modal import ModalState
from .settings import RPM


def read_speed_and_tool(st: ModalState, vals: ValueWords, line: int, err: ErrorFactory) -> None:
    """Set the modal spindle speed (S, rad/s) and the selected tool (T) of ``line``.

    Raises the error of ``err`` for a negative S and a T that is not an integer in 0..MAX_TOOL.
    """
    if "S" in vals:
        s = vals["S"].value
        if s < 0.0:
            raise err("S" + vals["S"].text, f"spindle speed S{vals['S'].text} is negative", "S >= 0 (rpm)")
        st.speed = s * RPM
        st.speed_line = line
    if "T" in vals:
        t = vals["T"]
        if t.has_point or t.value < 0 or t.value > MAX_TOOL:
            raise err("T" + t.text, f"tool number T{t.text} is not an integer in 0..{MAX_TOOL}", "T0, T1, T2, ...")
        st.tool_selected = int(t.value)


def auxiliary_blocks(st: ModalState, ms: MWords, vals: ValueWords, line: int, err: ErrorFactory,
                     out: list[Block]) -> None:
    """Append the :class:`ToolChange`, spindle and :class:`Coolant` blocks of ``line`` to ``out``.

    M6 on a machine with ``tool_change_spindle = "stop"`` appends a :class:`SpindleStop` first when the spindle
    turns and a :class:`ToolChange` that waits for it at rest (see the module docstring). Raises the error of
    ``err`` for M6 with no tool selected.
    """
    if "tool change" in ms:
        if st.tool_selected is None:
            raise err("M6", "M6 with no tool selected", "a T word on this or an earlier block")
        stop = st.settings.tool_change_spindle == "stop"
        if stop and st.direction != 0:
            st.direction = 0  # stopped with the retract (M19); stays stopped until M3/M4
            out.append(SpindleStop(line))
        tool_change_retract(st, line, err, out)  # Z to the tool-change position (machine setting)
        out.append(ToolChange(line, st.tool_selected, at_rest=stop))
    if "spindle" in ms:
        code = ms["spindle"][0]
        if code in (5, 19):
            st.direction = 0
            out.append(SpindleStop(line))
            if "S" in vals:
                out.append(SpindleSpeed(line, st.speed, 0, st.speed_line))
        else:
            st.direction = 1 if code == 3 else -1
            out.append(SpindleSpeed(line, st.speed, st.direction, st.speed_line))
    elif "S" in vals:
        out.append(SpindleSpeed(line, st.speed, st.direction, st.speed_line))
    if "coolant" in ms:
        out.append(Coolant(line, ms["coolant"][0] != 9))
