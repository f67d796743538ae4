"""Which variables decide whether a macro loop ends: the loop's *slice* (for the endless-loop guard).

A backward jump from line ``last`` to line ``first`` (a GOTO back, an END back to its WHILE/DO) closes a loop
whose lines are ``first .. last``. Every branch taken inside it is decided by its conditions (IF, WHILE) and
computed GOTO targets. Their variables, closed under the assignments inside the loop that set them
(``#2 = #2 + #3`` adds #2 and #3 once #2 counts), are the slice ``S``: while execution stays inside the loop
(no line outside it, so no call and no jump out and back), the values of ``S`` at one pass over the back jump
fix every later branch. Two passes over the back jump with equal ``S`` values and only loop lines run in
between therefore repeat forever (:class:`.runtime.MacroRuntime` checks this).

NC blocks only read variables, and so do conditions; variables outside ``S`` may change freely (a counter
that drives X but not the WHILE condition does not end the loop). The analysis gives up (None: only the line
cap applies) where the slice cannot be known from the text: a system variable (``#1000`` and up: positions,
clocks and modal states change without an assignment) or an indirect variable ``#[...]`` in the slice, an
indirect assignment anywhere in the loop, or a line that does not parse (it may never run).
"""
from __future__ import annotations

from typing import Callable

from ..errors import GCodeError
from .expressions import Binary, Function, Sign, Var
from .statements import Assign, Goto, IfThen, Loop, MacroLine
from .variables import FIRST_SYSTEM


def variables_read(node: object) -> set[int] | None:
    """Numbers of the variables an expression reads; None when one is indirect (``#[...]``) or a system variable.

    Parameters
    ----------
    node : expression node
        A node of :mod:`.expressions` (Num, Var, Sign, Binary, Function).

    Returns
    -------
    set of int or None
    """
    out: set[int] = set()
    stack = [node]
    while stack:
        n = stack.pop()
        if isinstance(n, Var):
            if not isinstance(n.index, int) or n.index >= FIRST_SYSTEM:
                return None
            if n.index != 0:  # #0 is always vacant
                out.add(n.index)
        elif isinstance(n, Sign):
            stack.append(n.operand)
        elif isinstance(n, Binary):
            stack.extend((n.left, n.right))
        elif isinstance(n, Function):
            stack.extend(n.args)
    return out


def loop_slice(parse: Callable[[int], MacroLine | None], first: int, last: int) -> frozenset[int] | None:
    """The slice of the loop of lines ``first .. last`` (1-based, inclusive); None when it cannot be known.

    Parameters
    ----------
    parse : callable (line) -> MacroLine or None
        Parsed macro line (None: a plain NC line); may raise :class:`~..errors.GCodeError`.
    first, last : int
        The back jump's target line and the back jump's line.

    Returns
    -------
    frozenset of int or None
        Variable numbers (locals of the current call level, commons) whose values decide every branch.
    """
    roots: set[int] = set()
    assigns: list[tuple[int, object]] = []  # (target, value) of every assignment in the loop
    for number in range(first, last + 1):
        try:
            parsed = parse(number)
        except GCodeError:
            return None
        if parsed is None:
            continue
        s = parsed.statement
        decides: list[object] = []
        if isinstance(s, Goto):
            decides = [s.target] + ([s.condition] if s.condition is not None else [])
        elif isinstance(s, Loop) and s.condition is not None:
            decides = [s.condition]
        elif isinstance(s, IfThen):
            decides = [s.condition]
            s = s.assign
        if isinstance(s, Assign):
            if not isinstance(s.target.index, int):
                return None
            assigns.append((s.target.index, s.value))
        for node in decides:
            read = variables_read(node)
            if read is None:
                return None
            roots |= read
    sliced = set(roots)
    grown = True
    while grown:
        grown = False
        for target, value in assigns:
            if target not in sliced:
                continue
            read = variables_read(value)
            if read is None:
                return None
            if not read <= sliced:
                sliced |= read
                grown = True
    return frozenset(sliced)
