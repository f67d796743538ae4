"""Decimal point input (FANUC No. 3401#0 DPI): what a number written without a decimal point means.

Conventions
-----------
* ``"calculator"`` (DPI = 1, pocket-calculator type, the default): ``X10`` is 10 mm (10 in under G20), as the
  rest of the NC kernel reads numbers. Nothing is changed here.
* ``"increment"`` (DPI = 0): a number without a decimal point at an address that takes one is a count of least
  input increments (increment system IS-B): 0.001 mm under G21, 0.0001 in under G20, 0.001 deg for angles.
  ``X10`` is 0.010 mm, ``X10.`` is 10 mm. Affected, as listed by the FANUC 0i-MF/31i-B manuals (addresses that
  accept a decimal point):

  - X Y Z (positions, centres of G51/G51.1/G68, G10 offset values, G52/G92 shifts, G28/G30 intermediate
    points), I J K of an arc centre, R (arc radius, R level of a canned cycle, G10 L10-L13 offset value), Q
    (peck depth, G76/G87 shift), ``,C`` and ``,R``: the length increment;
  - R of G68 (rotation angle) and the angle word of G16 polar coordinates: 0.001 deg.

  Not affected: P (dwell in ms, program and offset numbers, the G51 magnification, always integers), the G51
  magnifications I J K (0.001 units anyway), K as the repeat count of a canned cycle, L, H, D, T, S, M, N, O, G;
  G4 X without a decimal point is read in ms (0.001 s, the time increment) by :mod:`.dwell` (in s under
  ``"calculator"``).
* F without a decimal point under G94 and G21 is in mm/min in either setting (the F increment of feed per
  minute in mm is 1 mm/min). Under G20 or G95 its increment differs (inch/min, mm/rev); the twin does not
  model those and rejects an F without a decimal point there under ``"increment"`` (write ``F.05``, ``F20.``).
* A word whose value comes from a macro variable or expression (``X#24``) is a real value in mm (in), never
  a count of increments, as on FANUC.
* Applied after the block's G20/G21 is read, so ``G20 X10`` is 0.0010 in.
"""
from __future__ import annotations

import dataclasses

from .blocks import PLANE_AXES
from .codes import GWords, ValueWords
from .errors import ErrorFactory
from .lexer import Word

#: The settings of FANUC No. 3401#0: ``"calculator"`` (DPI = 1), ``"increment"`` (DPI = 0).
DECIMAL_INPUTS = ("calculator", "increment")
#: Least input increments (IS-B) in the program's unit: mm, inch, and degrees for angles.
INCREMENT_MM = 0.001
INCREMENT_INCH = 0.0001
INCREMENT_DEG = 0.001
_PLANE_OF_G = {17: "XY", 18: "ZX", 19: "YZ"}


def _scaled(w: Word, factor: float) -> Word:
    if w.has_point or w.variable:
        return w
    return dataclasses.replace(w, value=w.value * factor)


def decimal_input_words(vals: ValueWords, gs: GWords, inch: bool, plane: str, polar: bool, in_cycle: bool,
                        per_rev: bool, err: ErrorFactory) -> ValueWords:
    """The block's words with the numbers written without a decimal point read as least input increments.

    Called only under ``"increment"`` (DPI = 0); see the module conventions.

    Parameters
    ----------
    vals : ValueWords
        The block's value words.
    gs : GWords
        The block's G codes (G4, G10, G16/G15, G17-G19, G51, G68, canned cycles, G94/G95).
    inch : bool
        G20 in effect for this block (its own G20/G21 included).
    plane : str
        The plane before the block (a G17/G18/G19 in it wins).
    polar : bool
        G16 in effect before the block (a G16/G15 in it wins).
    in_cycle : bool
        A canned cycle is modal before the block.
    per_rev : bool
        G95 in effect before the block (a G94/G95 in it wins).
    err : ErrorFactory
        Builds the error of this block.

    Returns
    -------
    ValueWords
        A new mapping; words with a decimal point or from a variable are the same objects.

    Raises
    ------
    GCodeError
        An F without a decimal point under G20 or G95.
    """
    length = INCREMENT_INCH if inch else INCREMENT_MM
    non_modal = gs.get("non-modal", (None, None))[0]
    cycle = gs.get("canned cycle", (None, None))[0]
    motion = "motion" in gs
    if "plane" in gs:
        plane = _PLANE_OF_G[gs["plane"][0]]
    pol = gs.get("polar coordinates", (None, None))[0]
    polar = (polar or pol == 16) and pol != 15
    if "feed mode" in gs:
        per_rev = gs["feed mode"][0] == 95
    scaling_on = gs.get("scaling", (None, None))[0] == 51
    rotation_on = gs.get("coordinate rotation", (None, None))[0] == 68
    cycle_block = cycle not in (None, 80) or (in_cycle and cycle is None and not motion and non_modal is None)
    angle_axis = "XYZ"[PLANE_AXES[plane][1]] if polar and not rotation_on and non_modal is None else None
    out: ValueWords = {}
    for letter, w in vals.items():
        if letter in "XYZ" and len(letter) == 1:
            if non_modal == 4:  # G4 X: a time, read in ms without a decimal point by .dwell
                out[letter] = w
            else:
                out[letter] = _scaled(w, INCREMENT_DEG if letter == angle_axis else length)
        elif letter in ("I", "J", "K"):
            if scaling_on or (letter == "K" and cycle_block):  # G51 magnifications, the cycle repeat count
                out[letter] = w
            else:
                out[letter] = _scaled(w, length)
        elif letter == "R":
            out[letter] = _scaled(w, INCREMENT_DEG if rotation_on else length)
        elif letter in ("Q", ",C", ",R"):
            out[letter] = _scaled(w, length)
        elif letter == "F" and not (w.has_point or w.variable) and (inch or per_rev):
            mode = "G95 (feed per revolution)" if per_rev else "G20 (inch)"
            raise err("F" + w.text, f"F{w.text} without a decimal point under {mode} with decimal point input "
                      "= \"increment\" (FANUC No. 3401#0 DPI = 0): its least input increment is not modelled",
                      "F with a decimal point (F.05, F20.)")
        else:
            out[letter] = w
    return out
