"""Custom Macro B system variables the twin provides (read-only), from the interpreter's modal state.

Conventions
-----------
* ``#4001``-``#4022``: the G code of modal group 1..22 in effect before the block (FANUC M series groups):
  4001 G0-G3, 4002 G17-G19, 4003 G90/G91, 4005 G94/G95, 4006 G20/G21, 4007 G40-G42, 4008 G43/G44/G49,
  4009 the canned cycle or G80, 4010 G98/G99, 4014 the work offset code as written (54-59; 54.1 for G54.1 Pn
  and G54 Pn, as FANUC; 154 for Haas G154 Pn and 110-129 for G110-G129, the codes a Haas reports), 4015
  G61/G64 (61.1 under Mazak's G61.1). Groups of
  features that are never on read their cancel code: 4012 G67, 4013 G97; 4011 G50/G51, 4016 G68/G69,
  4017 G15/G16, 4022 G50.1/G51.1 (:mod:`..transforms`). Groups 4, 18-21 are errors (the twin does not track
  them).
* ``#4107`` D, ``#4109`` F (in the program's unit: mm/min, in/min, or mm/rev under G95), ``#4111`` H,
  ``#4119`` S (rpm), ``#4120`` T (vacant before the first T or F).
* ``#5001``-``#5003``: end point X, Y, Z of the last block in work coordinates (programmed position, without
  tool length, in the program's unit).
* ``#3000``: writing it is a macro alarm (handled by :mod:`.runtime`); reading it, and any other system
  variable, is an error naming the variable.
"""
from __future__ import annotations

from ..modal import ModalState
from ..settings import INCH, RPM
from .variables import Fail

#: Modal group (4000 + k) -> the code the twin always has there (features it never switches on).
_FIXED = {4012: 67.0, 4013: 97.0}
#: What the twin provides, for messages.
PROVIDED = ("#4001-#4003, #4005-#4017, #4022 (modal G codes), #4107 D, #4109 F, #4111 H, #4119 S, #4120 T, "
            "#5001-#5003 (end point X Y Z)")


def read_system(st: ModalState, n: int, text: str, fail: Fail) -> float | None:
    """Value of system variable ``#n`` from the modal state ``st``.

    Raises
    ------
    GCodeError
        A system variable the twin does not provide (the message lists those it does).
    """
    if n in _FIXED:
        return _FIXED[n]
    modal = {
        4001: lambda: float(st.motion),
        4002: lambda: {"XY": 17.0, "ZX": 18.0, "YZ": 19.0}[st.plane],
        4003: lambda: 90.0 if st.absolute else 91.0,
        4005: lambda: 95.0 if st.per_rev else 94.0,
        4006: lambda: 20.0 if st.scale == INCH else 21.0,
        4007: lambda: float(st.comp),
        4008: lambda: {1: 43.0, -1: 44.0, 0: 49.0}[st.tool_sign],
        4009: lambda: float(st.cycle) if st.cycle is not None else 80.0,
        4010: lambda: 98.0 if st.return_initial else 99.0,
        4014: lambda: st.work_code,
        4015: lambda: st.path_code,
        4011: lambda: 51.0 if st.xf.scaling else 50.0,
        4016: lambda: 68.0 if st.xf.rotation is not None else 69.0,
        4017: lambda: 16.0 if st.xf.polar else 15.0,
        4022: lambda: 51.1 if any(m is not None for m in st.xf.mirror) else 50.1,
        4107: lambda: float(st.d),
        4111: lambda: float(st.h),
        4109: lambda: _feed(st),
        4119: lambda: st.speed / RPM,
        4120: lambda: None if st.tool_selected is None else float(st.tool_selected),
        5001: lambda: st.prog[0] / st.scale,
        5002: lambda: st.prog[1] / st.scale,
        5003: lambda: st.prog[2] / st.scale,
    }
    if n in modal:
        return modal[n]()
    raise fail(text, f"system variable #{n} is not available in the twin", f"one of {PROVIDED}")


def _feed(st: ModalState) -> float | None:
    if st.feed is None:
        return None
    return st.feed / st.scale if st.feed_per_rev else st.feed * 60.0 / st.scale
