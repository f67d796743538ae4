"""LinuxCNC path blending ``G64 P<tol> [Q<tol>]``: accepted as G64, the tolerances are not modelled.

LinuxCNC (G-code reference, "G64 Path Blending"): ``G64 P`` sets the path tolerance (how far the blended
path may deviate from the programmed one) and ``Q`` the naive-CAM tolerance (collinear short segments merged
within Q). FANUC G64 has no P/Q. The twin reads the block as FANUC G64 (cutting mode, cancels G61): its
look-ahead (:mod:`.lookahead`) always runs through the programmed corners at the speed the allowable
per-axis velocity difference gives (FANUC No. 1783) and stays on the programmed path before the
after-interpolation filter, so a blending tolerance changes nothing in the reference. P and Q must be
numbers >= 0 (program units); they are only allowed with G64, not in a G4 dwell or canned-cycle block.
"""
from __future__ import annotations

from .codes import GWords, ValueWords
from .errors import ErrorFactory


def blending_tolerance_words(gs: GWords, vals: ValueWords, in_cycle: bool, err: ErrorFactory) -> None:
    """Take the P/Q tolerances of a ``G64`` block out of ``vals`` after checking them.

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
