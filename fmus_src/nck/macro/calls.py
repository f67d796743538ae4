"""G65 simple macro call: ``G65 P<n> [L<k>] <arguments>`` (argument specification I, FANUC 0i-MF/31i-B).

Conventions
-----------
* P is the program O<n> (1..9999) in the same file, found as M98 finds subprograms
  (:mod:`..subprograms`); L the repeat count (1..9999, default 1). Each repetition starts with a fresh local
  level holding the arguments.
* Argument specification I: A #1, B #2, C #3, I #4, J #5, K #6, D #7, E #8, F #9, H #11, M #13, Q #17, R #18,
  S #19, T #20, U #21, V #22, W #23, X #24, Y #25, Z #26; an argument's value is a real value as written (no
  rounding to an address increment); a vacant one leaves its variable vacant. Argument specification II
  (I, J, K repeated) is an error, and so are other G codes, O, and an address given twice in the block.
* G65 calls nest at most :data:`MAX_MACRO_NESTING` levels (4, the limit of the FANUC manuals the brief cites);
  M98 and G65 calls together at most :data:`..subprograms.MAX_NESTING` (10).
* G66 (modal macro call) stays an error: it calls the macro after every move block until G67, which the
  twin does not implement (write the G65 call in each block instead).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

from ..subprograms import MAX_CALL_REPEAT, MAX_PROGRAM_NUMBER
from .variables import Fail

#: Argument address -> local variable number (argument specification I).
ARGUMENTS = {"A": 1, "B": 2, "C": 3, "I": 4, "J": 5, "K": 6, "D": 7, "E": 8, "F": 9, "H": 11, "M": 13, "Q": 17,
             "R": 18, "S": 19, "T": 20, "U": 21, "V": 22, "W": 23, "X": 24, "Y": 25, "Z": 26}
#: Deepest nesting of G65 macro calls.
MAX_MACRO_NESTING = 4
_FORM = "G65 P<program> [L<count>] with arguments A B C D E F H I J K M Q R S T U V W X Y Z"


@dataclass(frozen=True)
class MacroCall:
    """A G65 call: program ``number``, ``repeats`` times, local variables ``arguments`` (#n -> value)."""

    number: int
    repeats: int
    arguments: dict[int, float]


def read_macro_call(words: Sequence[tuple[str, float | None, str]], fail: Fail) -> MacroCall:
    """The call of a G65 block from its words ``(letter, value or None if vacant, text as shown)``.

    Raises
    ------
    GCodeError
        No P, P or L not an integer in range, another G code, O, an address twice (spec II), an argument that
        is no address of specification I.
    """
    number: int | None = None
    repeats = 1
    arguments: dict[int, float] = {}
    seen: set[str] = set()
    for letter, value, shown in words:
        up = letter.upper()
        if up == "G":
            if value != 65.0:
                raise fail(shown, f"{shown} in a G65 block", f"{_FORM} alone in its block")
            continue
        if up in seen and up != "N":
            raise fail(shown, f"address {up} twice in a G65 block (argument specification II is not supported)",
                       f"{_FORM}, each address once")
        seen.add(up)
        if up == "N":
            continue
        if up == "O":
            raise fail(shown, "O in a G65 block", _FORM)
        if up in ("P", "L"):
            top = MAX_PROGRAM_NUMBER if up == "P" else MAX_CALL_REPEAT
            if value is None or value != int(value) or not 1 <= value <= top:
                what = "program number" if up == "P" else "repeat count"
                raise fail(shown, f"G65 {shown}: the {what} is not an integer in 1..{top}", _FORM)
            if up == "P":
                number = int(value)
            else:
                repeats = int(value)
            continue
        if up not in ARGUMENTS:
            raise fail(shown, f"{up} is not an argument address of G65", _FORM)
        if value is not None:
            arguments[ARGUMENTS[up]] = value
    if number is None:
        raise fail("G65", "G65 without P (the macro program to call)", _FORM)
    return MacroCall(number, repeats, arguments)
