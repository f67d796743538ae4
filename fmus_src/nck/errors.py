"""Errors of the NC kernel (dependency-free, shipped inside FMUs)."""
from __future__ import annotations

from typing import Callable

from ..errors import CncTwinError


#: Longest block text quoted in a message, characters.
_QUOTE_LIMIT = 120


class GCodeError(CncTwinError):
    """A G-code program cannot be interpreted (or rewritten).

    Parameters
    ----------
    file : str
        Program file name as given by the user (``"<text>"`` for programs passed as text).
    line : int
        1-based source line number (0 when the problem is not tied to a line).
    word : str
        The offending word or block text (e.g. ``"R0.5"``, ``"G95"``).
    expected : str
        What would have been accepted.
    problem : str
        What is wrong.
    block : str
        The source text of the block (stripped), quoted in the message.

    Attributes
    ----------
    file, line, word, expected, problem, block
        As given.

    Examples
    --------
    ``part.nc:12: 'G2 X10 R0.5': arc radius 0.5 mm is smaller than half the chord (5.0 mm); expected R >= 5.0``
    """

    def __init__(self, file: str, line: int, word: str, expected: str, problem: str, block: str = "") -> None:
        self.file = file
        self.line = line
        self.word = word
        self.expected = expected
        self.problem = problem
        self.block = block
        where = f"{file}:{line}" if line else file
        if len(block) > _QUOTE_LIMIT:  # a 1 MB line must not become a 1 MB message
            block = f"{block[:_QUOTE_LIMIT]}... ({len(block)} characters)"
        quoted = f" '{block}':" if block else ""
        super().__init__(f"{where}:{quoted} {problem}; expected {expected}")


#: Builds the :class:`GCodeError` of one block from ``(word, problem, expected)``; the interpreter makes one per
#: block (file, line and block text bound) and passes it to the modules that check the block's words.
ErrorFactory = Callable[[str, str, str], GCodeError]


def fmt_number(value: float) -> str:
    """A number as quoted in messages: 6 significant digits (``0.5``, ``99999.9``, ``1e-06``)."""
    return f"{value:.6g}"


class NCParameterError(CncTwinError):
    """An NC kernel parameter or override is out of range or inconsistent across the batch."""
