"""Dwell: the G4 block and the dwell time of a P or X word (also P of the canned cycles G82/G89).

Conventions
-----------
* G4: a value with a decimal point is in seconds (``G4 X1.5``, ``G4 P1.5``),
  without it in milliseconds (``G4 P1500`` as FANUC).
"""
from __future__ import annotations

from .blocks import Dwell
from .codes import GWords, ValueWords
from .errors import ErrorFactory, fmt_number
from .input_ranges import MAX_DWELL
from .lexer import Word


def dwell_seconds(w: Word, err: ErrorFactory) -> float:
    """Dwell of a P or X word (s): with a decimal point in s, without in ms (as FANUC G4 P)."""
    seconds = w.value if w.has_point else w.value * 1e-3
    if seconds < 0:
        raise err(w.letter + w.text, "negative dwell time", "a time >= 0")
    if seconds > MAX_DWELL:
        raise err(w.letter + w.text, f"dwell of {fmt_number(seconds)} s is beyond the input range",
                  f"a dwell of at most {MAX_DWELL} s")
    return seconds


def dwell_block(gs: GWords, vals: ValueWords, line: int, err: ErrorFactory) -> Dwell:
    """The :class:`Dwell` of a G4 block: G4 X<time> or G4 P<time>, alone with its time word."""
    if "motion" in gs:
        raise err(f"G{gs['motion'][0]}", "G4 and a motion G code in one block", "G4 alone in its block")
    for a in ("Y", "Z", "I", "J", "K", "R", "Q"):
        if a in vals:
            raise err(a + vals[a].text, f"word {a} in a G4 dwell block", "G4 X<time> or G4 P<time>")
    if ("X" in vals) == ("P" in vals):
        raise err("G4", "G4 needs exactly one of X or P", "G4 X1.5 (s), G4 P1500 (ms)")
    return Dwell(line, dwell_seconds(vals.get("X") or vals["P"], err))
