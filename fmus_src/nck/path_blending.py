"""LinuxCNC path blending ``G64 P<tol> [Q<tol>]``: accepted as G64, the tolerances are not modelled.

LinuxCNC (G-code reference, "G64 Path Blending"): ``G64 P`` sets the path tolerance (how far the blended
path may deviate from the programmed one) and ``Q`` the naive-CAM tolerance (collinear short segments merged
within Q). FANUC G64 has no P/Q. The twin reads the block as FANUC G64 (cutting mode, cancels G61): its
look-ahead (:mod:`.lookahead`) always runs through the programmed corners at the speed the allowable
per-axis velocity difference gives (FANUC No. 1783) and stays on the programmed path before the
after-interpolation filter, so a blending tolerance changes nothing in the reference. P and Q must be
numbers >= 0 (program units); they are only allowed with G64, not in a G4 dwell or canned-cycle block.

Mazak EIA ``G61.1 [P<level>]`` (geometry compensation / high-accuracy mode, cancelled by G64 or G61; the Mazak
posts, e.g. the Keycult fork of Autodesk's mazak.cps, write ``G61.1 P0`` rough ... ``G61.1 P3`` accurate before an
operation and ``G64`` after it) is read the same way: a continuous cutting mode on the programmed path, planned
with the machine file's acc/dec; the level P (an integer 0..3 without a decimal point) is not modelled. LinuxCNC
gives G61.1 another meaning (exact stop); the twin reads it as Mazak's.
"""
from __future__ import annotations

from .codes import GWords, ValueWords
from .errors import ErrorFactory


#: Machining-mode levels of Mazak ``G61.1 P<level>`` (0 rough, 1 semi-rough, 2 smooth, 3 accurate).
G61_1_LEVELS = (0, 1, 2, 3)


def blending_tolerance_words(gs: GWords, vals: ValueWords, in_cycle: bool, err: ErrorFactory) -> None:
    """Take the P/Q tolerances of a ``G64`` block (and the level P of ``G61.1``) out of ``vals`` after checking them.

    Parameters
    ----------
    gs : GWords
        The block's G codes.
    vals : ValueWords
        The block's other words; P and Q are removed when the block has G64.
    in_cycle : bool
        The block is a G4 dwell or in canned-cycle mode (where P/Q are the cycle's words).
    err : ErrorFactory
        Builds the error for this block.
    """
    if gs.get("path mode", (None,))[0] == 61.1 and "P" in vals:
        w = vals["P"]
        if in_cycle:
            raise err("P" + w.text, f"G61.1 P{w.text} in a dwell or canned-cycle block: P would be read twice",
                      "G61.1 P<level> in a block of its own")
        if w.has_point or w.value not in G61_1_LEVELS:
            raise err("P" + w.text, f"G61.1 P{w.text} is not a machining-mode level (Mazak: P0 rough, P1 "
                      "semi-rough, P2 smooth, P3 accurate)", "G61.1, or G61.1 P0 .. P3 (an integer without a "
                      "decimal point)")
        del vals["P"]
        return
    if gs.get("path mode", (None,))[0] != 64 or not ("P" in vals or "Q" in vals):
        return
    if in_cycle:
        w = vals["P"] if "P" in vals else vals["Q"]
        raise err(w.letter + w.text, f"G64 {w.letter}{w.text} in a dwell or canned-cycle block: "
                  f"{w.letter} would be read twice", "G64 P<tol> [Q<tol>] in a block of its own")
    for a in "PQ":
        if a in vals:
            w = vals.pop(a)
            if w.value < 0.0:
                raise err(a + w.text, f"G64 blending tolerance {a}{w.text} is negative",
                          "G64 P<tol> [Q<tol>] with tolerances >= 0")
