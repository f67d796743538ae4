"""The look-ahead / contour-control mode codes G5.1, G8 and G5: checked, accepted, without effect on the plan.

Conventions
-----------
* Look-ahead / contour-control modes: ``G5.1 Q1`` / ``G5.1 Q0`` (AI contour
  control, also ``G5.1 Q1 R<level>`` with level 1..10 as Fusion 360 posts
  write it), ``G8 P1`` / ``G8 P0`` (advanced preview control), ``G5 P10000``
  / ``G5 P0`` (high-precision contour control) are accepted alone in their
  block (an N number allowed), as the FANUC manuals ask. They change
  nothing in the simulation: the twin always plans with its own look-ahead
  (``lookahead_blocks``) and the machine file's acc/dec before and after
  interpolation, i.e. as if the mode were on all the time; the separate
  parameter sets a control switches to in AICC/HPCC (the AICC variants of
  No. 1660/1772 etc.) and the machining quality levels R are not modelled.
  Other Q/P values (e.g. nano smoothing ``G5.1 Q3``) and other words in the
  block are errors.
"""
from __future__ import annotations

from typing import Sequence

from .errors import ErrorFactory
from .lexer import Word

#: Allowed modes of the look-ahead / contour-control codes: G code -> (address, values).
LOOK_AHEAD_MODES = {5.1: ("Q", (0, 1)), 8: ("P", (0, 1)), 5: ("P", (0, 10000))}


def check_look_ahead(entry: tuple[int | float, Word], words: Sequence[Word], err: ErrorFactory) -> None:
    """Check a look-ahead / contour-control block: G5.1 Q0/Q1 (AI contour control, optional R level 1..10 with
    Q1), G8 P0/P1 (advanced preview control), G5 P0/P10000 (high-precision contour control), alone in the
    block (N allowed). They change nothing in the twin's plan (see the module docstring).

    Parameters
    ----------
    entry : (code, word)
        The block's look-ahead G code and its word.
    words : sequence of Word
        All words of the block.
    err : ErrorFactory
        Builds the error for this block.
    """
    code, gw = entry
    letter, allowed = LOOK_AHEAD_MODES[code]
    gname = "G" + gw.text
    forms = ", ".join(f"G{code} {letter}{v}" for v in allowed)
    mode = None
    for w in words:
        if w is gw or w.letter == "N":
            continue
        if w.letter == letter and mode is None:
            if w.value not in allowed:
                raise err(letter + w.text, f"{gname} {letter}{w.text} is not a supported mode", forms)
            mode = int(w.value)
            continue
        if code == 5.1 and w.letter == "R" and mode == 1:
            if w.has_point or not 1 <= w.value <= 10:
                raise err("R" + w.text, f"{gname} Q1 R{w.text}: the level is not an integer in 1..10",
                          "G5.1 Q1 R1 .. R10 (machining quality level) or G5.1 Q1")
            continue
        word = (w.letter + w.text) if w.letter != "G" else "G" + w.text
        raise err(word, f"{word} in the {gname} block (FANUC: {gname} is specified alone in its block)",
                  f"{forms} alone in a block (an N number allowed)")
    if mode is None:
        raise err(gname, f"{gname} without {letter}", forms)
