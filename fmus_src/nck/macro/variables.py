"""Custom Macro B variables: the vacant ``#0``, local ``#1``-``#33`` per macro call level, common variables.

Conventions
-----------
* ``#0`` is always vacant and cannot be assigned.
* Local variables ``#1``-``#33``: one set per G65 call level (the main program is level 0). A G65 call opens
  a new level holding its arguments, M99 closes it and the caller's locals are back; an M98 subprogram shares
  its caller's level (FANUC). Every level starts vacant (apart from the arguments).
* Common variables ``#100``-``#199`` and ``#500``-``#999``: shared by all levels. They start vacant at every
  run of a program (on the machine, #500-#999 keep their values through power-off; the twin knows none).
* System variables (``#1000`` and up) are read through a callback (:mod:`.system`); the other numbers
  (``#34``-``#99``, ``#200``-``#499``) are errors.
"""
from __future__ import annotations

from typing import Callable

from ..errors import GCodeError

#: Number of local variables per level (#1..#33).
N_LOCAL = 33
#: First system variable number.
FIRST_SYSTEM = 1000
#: Variable numbers the program may use, for messages.
RANGES = "#1..#33, #100..#199, #500..#999"

#: fail(expression, problem, expected) -> GCodeError, bound to the line.
Fail = Callable[[str, str, str], GCodeError]
#: read_system(number, text, fail) -> value of a system variable.
SystemReader = Callable[[int, str, Fail], "float | None"]


def is_common(n: int) -> bool:
    """True for #100..#199 and #500..#999."""
    return 100 <= n <= 199 or 500 <= n <= 999


class VariableStore:
    """The variables of one program run.

    Parameters
    ----------
    system : callable (number, text, fail) -> float or None
        Reads a system variable (raises the error of ``fail`` for one it does not know).

    Attributes
    ----------
    levels : list of list
        Local variables per call level, ``levels[k][n]`` for #n (index 0 unused); None is vacant.
    common : dict of int -> float
        Common variables that are set.
    system_read : bool
        A system variable was read: the program's control flow may depend on the machine state.
    """

    def __init__(self, system: SystemReader) -> None:
        self.levels: list[list[float | None]] = [[None] * (N_LOCAL + 1)]
        self.common: dict[int, float] = {}
        self.system = system
        self.system_read = False

    @property
    def depth(self) -> int:
        """Number of open G65 levels (0 in the main program)."""
        return len(self.levels) - 1

    def read(self, n: int, text: str, fail: Fail) -> float | None:
        """Value of ``#n`` (None: vacant)."""
        if n == 0:
            return None
        if n <= N_LOCAL:
            return self.levels[-1][n]
        if is_common(n):
            return self.common.get(n)
        if n >= FIRST_SYSTEM:
            self.system_read = True
            return self.system(n, text, fail)
        raise fail(text, f"#{n} is not a variable of Custom Macro B", f"{RANGES} or a system variable")

    def write(self, n: int, value: float | None, text: str, fail: Fail) -> None:
        """Set ``#n`` (None: make it vacant); system variables are the caller's business."""
        if n == 0:
            raise fail(text, "#0 is always vacant and cannot be assigned", f"a variable {RANGES}")
        if n <= N_LOCAL:
            self.levels[-1][n] = value
        elif is_common(n):
            if value is None:
                self.common.pop(n, None)
            else:
                self.common[n] = value
        elif n >= FIRST_SYSTEM:
            raise fail(text, f"system variable #{n} cannot be assigned (read-only or not supported)",
                       f"a variable {RANGES}, #3000 = <n> (MESSAGE) for an alarm, or #3006 = <n> (MESSAGE) for a stop")
        else:
            raise fail(text, f"#{n} is not a local or common variable", f"a variable {RANGES}")

    def push(self, arguments: dict[int, float]) -> None:
        """Open a G65 level holding ``arguments`` (#n -> value); the other locals are vacant."""
        level: list[float | None] = [None] * (N_LOCAL + 1)
        for n, v in arguments.items():
            level[n] = v
        self.levels.append(level)

    def pop(self) -> None:
        """Close the innermost G65 level (M99): the caller's locals are back."""
        self.levels.pop()

    def peek(self, n: int) -> float | None:
        """Value of the local (current level) or common ``#n`` without reading the machine; None when vacant or
        not such a variable."""
        if 1 <= n <= N_LOCAL:
            return self.levels[-1][n]
        return self.common.get(n) if is_common(n) else None

    def snapshot(self) -> tuple:
        """Every local and common value, hashable (two equal snapshots: the same program state)."""
        return tuple(tuple(level) for level in self.levels), tuple(sorted(self.common.items()))
