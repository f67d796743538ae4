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
        # one printable line: a control character of the block (also inside the quoted word) is escaped
        super().__init__(escape_controls(f"{where}:{quoted} {problem}; expected {expected}"))


def escape_controls(text: str) -> str:
    r"""``text`` with every non-printable character (control characters, tab, DEL, U+2028...) as a Python escape.

    A block quoted in a one-line message must not carry a bell, a form feed or a terminal escape sequence
    into the user's terminal or log: a BEL between ``G1`` and ``X1`` is shown as ``G1\x07X1``.
    """
    if text.isprintable():
        return text
    return "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in text)


#: Builds the :class:`GCodeError` of one block from ``(word, problem, expected)``; the interpreter makes one per
#: block (file, line and block text bound) and passes it to the modules that check the block's words.
ErrorFactory = Callable[[str, str, str], GCodeError]


def fmt_number(value: float) -> str:
    """A number as quoted in messages: 6 significant digits (``0.5``, ``99999.9``, ``1e-06``)."""
    return f"{value:.6g}"


#: Resolution of a length quoted in messages, m (1 nm: far below the 0.001 mm least input increment).
LENGTH_RESOLUTION = 1e-9


def fmt_length(metres: float, per_metre: float) -> str:
    """A length (m) as quoted in messages in the program's unit, without floating-point noise.

    Parameters
    ----------
    metres : float
        The length, m.
    per_metre : float
        Program units per metre (1e3 for mm, 1/0.0254 for inch).

    Returns
    -------
    str
        :func:`fmt_number` of the length rounded to :data:`LENGTH_RESOLUTION` (``-6.9e-15`` mm is ``0``).
    """
    snapped = round(metres / LENGTH_RESOLUTION) * LENGTH_RESOLUTION
    return fmt_number(snapped * per_metre + 0.0)  # + 0.0: no "-0"


class NCParameterError(CncTwinError):
    """An NC kernel parameter or override is out of range or inconsistent across the batch."""
