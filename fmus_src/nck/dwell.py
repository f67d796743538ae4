"""Dwell: the G4 block and the dwell time of a P or X word (also P of the canned cycles G82/G89).

Conventions
-----------
* G4: a value with a decimal point is in seconds (``G4 X1.5``, ``G4 P1.5``),
  P without it in milliseconds (``G4 P1500`` as FANUC).
* G4 X without a decimal point follows decimal point input (FANUC No. 3401#0):
  seconds under calculator-type input (DPI = 1, ``G4 X2`` dwells 2 s, as
  ``X10`` is 10 mm there), milliseconds, the least time increment, under
  ``"increment"`` (DPI = 0).
"""
from __future__ import annotations

from .blocks import Dwell
from .codes import GWords, ValueWords
from .errors import ErrorFactory, fmt_number
from .input_ranges import MAX_DWELL
from .lexer import Word


def dwell_seconds(w: Word, err: ErrorFactory, whole_seconds: bool = False) -> float:
    """Dwell of a P or X word (s): with a decimal point in s, without in ms (as FANUC G4 P).

    ``whole_seconds``: a value without a decimal point is in s too (G4 X under calculator-type input).
    """
    seconds = w.value if (w.has_point or whole_seconds) else w.value * 1e-3
    if seconds < 0:
        raise err(w.letter + w.text, "negative dwell time", "a time >= 0")
    if seconds > MAX_DWELL:
        raise err(w.letter + w.text, f"dwell of {fmt_number(seconds)} s is beyond the input range",
                  f"a dwell of at most {MAX_DWELL} s")
    return seconds


def dwell_block(gs: GWords, vals: ValueWords, line: int, err: ErrorFactory, calculator: bool = True) -> Dwell:
    """The :class:`Dwell` of a G4 block: G4 X<time> or G4 P<time>, alone with its time word.

    ``calculator``: calculator-type decimal point input (FANUC No. 3401#0 DPI = 1), where ``G4 X2`` is 2 s.
    """
    if "motion" in gs:
        raise err(f"G{gs['motion'][0]}", "G4 and a motion G code in one block", "G4 alone in its block")
    for a in ("Y", "Z", "I", "J", "K", "R", "Q"):
        if a in vals:
            raise err(a + vals[a].text, f"word {a} in a G4 dwell block", "G4 X<time> or G4 P<time>")
    if ("X" in vals) == ("P" in vals):
        raise err("G4", "G4 needs exactly one of X or P", "G4 X1.5 (s), G4 P1500 (ms)")
    if "X" in vals:
        return Dwell(line, dwell_seconds(vals["X"], err, whole_seconds=calculator))
    return Dwell(line, dwell_seconds(vals["P"], err))
