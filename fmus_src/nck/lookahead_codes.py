"""The look-ahead / contour-control mode codes G5.1, G8, G5 and Haas G187: checked, accepted, no effect on the plan.

Conventions
-----------
* Look-ahead / contour-control modes: ``G5.1 Q1`` / ``G5.1 Q0`` (AI contour
  control, also ``G5.1 Q1 R<level>`` with level 1..10 as Fusion 360 posts
  write it), ``G8 P1`` / ``G8 P0`` (advanced preview control), ``G5 P10000``
  / ``G5 P0`` (high-precision contour control; ``G5 P2``, Mazak EIA's high-speed machining mode as the Mazak
  posts write it around an operation, is read the same way) are accepted alone in their
  block (an N number allowed), as the FANUC manuals ask. They change
  nothing in the simulation: the twin always plans with its own look-ahead
  (``lookahead_blocks``) and the machine file's acc/dec before and after
  interpolation, i.e. as if the mode were on all the time; the separate
  parameter sets a control switches to in AICC/HPCC (the AICC variants of
  No. 1660/1772 etc.) and the machining quality levels R are not modelled.
  Other Q/P values (e.g. nano smoothing ``G5.1 Q3``) and other words in the
  block are errors.
* Haas accuracy control ``G187 [P1|P2|P3] [E<tol>]`` (Haas mill operator's
  manual, G187, group 00): P sets the smoothness level (1 rough, 2 medium,
  3 finish; overrides Setting 191), E the largest corner rounding in the
  program's unit (overrides Setting 85), ``G187`` alone returns to the
  settings. The Autodesk Haas posts write ``G187 P<level>`` (some forks
  ``G187 P<level> E<tol>``) before each operation and ``G187`` after it.
  Accepted alone in its block (an N number allowed), without effect on the
  plan, for the reason above: the twin always keeps the programmed path and
  plans with the machine file's acc/dec. P must be an integer 1..3 written
  without a decimal point and E a number >= 0; anything else in the block is
  an error. The E word is read only in a G187 block (:data:`.codes.BLOCK_LETTERS`).
"""
from __future__ import annotations

from typing import Sequence

from .errors import ErrorFactory
from .lexer import Word

#: Allowed modes of the look-ahead / contour-control codes: G code -> (address, values).
LOOK_AHEAD_MODES = {5.1: ("Q", (0, 1)), 8: ("P", (0, 1)), 5: ("P", (0, 2, 10000))}
#: Smoothness levels of Haas G187 P (1 rough, 2 medium, 3 finish).
G187_LEVELS = (1, 2, 3)
G187_FORMS = "G187, G187 P1/P2/P3, G187 E<corner rounding >= 0> or G187 P<level> E<corner rounding>"


def alone_in_block(gw: Word, words: Sequence[Word], letters: str, forms: str, err: ErrorFactory) -> None:
    """Raise the error of ``err`` for a word other than ``gw``, N and the addresses ``letters`` in the block.

    Parameters
    ----------
    gw : Word
        The block's G word that must stand alone (with its own addresses).
    words : sequence of Word
        All words of the block.
    letters : str
        The addresses that belong to ``gw`` (e.g. ``"PE"``).
    forms : str
        The accepted forms, quoted in the message.
    err : ErrorFactory
        Builds the error for this block.
    """
    gname = "G" + gw.text
    for w in words:
        if w is gw or w.letter == "N" or w.letter in letters:
            continue
        word = w.letter + w.text
        raise err(word, f"{word} in the {gname} block (the twin reads {gname} alone in its block, as the Haas "
                  "posts write it)", f"{forms} alone in a block (an N number allowed)")


def check_accuracy_control(gw: Word, words: Sequence[Word], err: ErrorFactory) -> None:
    """Check a Haas ``G187 [P1|P2|P3] [E<tol>]`` block (accuracy control); it changes nothing in the plan.

    Parameters
    ----------
    gw : Word
        The block's G187 word.
    words : sequence of Word
        All words of the block.
    err : ErrorFactory
        Builds the error for this block.
    """
    alone_in_block(gw, words, "PE", G187_FORMS, err)
    for w in words:
        if w.letter == "P" and (w.has_point or w.value not in G187_LEVELS):
            raise err("P" + w.text, f"G187 P{w.text} is not a smoothness level (Haas: P1 rough, P2 medium, "
                      "P3 finish)", "P1, P2 or P3 (an integer without a decimal point)")
        if w.letter == "E" and w.value < 0.0:
            raise err("E" + w.text, f"G187 E{w.text}: the corner rounding is negative",
                      "E >= 0 (the largest corner rounding, in the program's unit)")


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
