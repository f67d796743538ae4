"""Tapping lines (G84/G74) in the optimiser: F is tied to S (F = pitch x S), so they are never optimised.

Rules (documented for machinists)
---------------------------------
* A tapping line (a G84/G74 block, or a line continuing such a cycle; its feed blocks carry
  :attr:`fmus_src.nck.blocks.Linear.tap_pitch`) is never a cutting line: its F and S stay as written,
  whatever material it removes in the reference run (:func:`.context.classify_lines`). When its F is modal
  (G94, the F word on an earlier line), its original F is written on it (a pin), so that an F the optimiser
  writes on a cutting line in between cannot reach it.
* The optimiser refuses the program, naming the tapping line, when an S word it writes for a cutting line
  would still be in effect at a tapping hole (:func:`check_tapping_spindle`): the tap would run at a new S
  with the old F, cutting a wrong pitch. Write the tapping tool's own S (``S.. M3`` or ``M29 S..``) after the
  last cutting line before it, as CAM posts do at every tool change.
"""
from __future__ import annotations

from typing import Iterable

from fmus_src.nck.blocks import Block, Linear, Program, SpindleSpeed
from fmus_src.nck.overrides import apply_overrides

from .errors import OptimizeError

#: A spindle speed no S word has (rad/s): marks the blocks an optimiser S word would govern.
_MARK = 1.0e9


def tapping_lines(blocks: Iterable[Block]) -> set[int]:
    """Source lines holding tapping feed blocks (G84/G74, conventional or rigid)."""
    return {b.line for b in blocks if isinstance(b, Linear) and b.tap_pitch > 0.0}


def check_tapping_spindle(program: Program, spindle_lines: Iterable[int], file: str) -> None:
    """Refuse when an S word written on ``spindle_lines`` would govern a tapping hole.

    Parameters
    ----------
    program : Program
        The interpreted original program.
    spindle_lines : iterable of int
        Lines where the optimiser writes S words (:attr:`.context.ProblemContext.spindle_lines`).
    file : str
        Program file, for the message.

    Raises
    ------
    OptimizeError
        Naming the first tapping line whose spindle speed would come from an optimiser S word.
    """
    lines = sorted(set(int(x) for x in spindle_lines))
    if not lines or not tapping_lines(program.blocks):
        return
    blocks, _, speeds = apply_overrides(program, 1, None, {line: _MARK for line in lines})
    governed = None  # the optimiser line whose S is in effect, None for a program S word
    for i, b in enumerate(blocks):
        if isinstance(b, SpindleSpeed):
            governed = True if speeds[0, i] == _MARK else None
        elif isinstance(b, Linear) and b.tap_pitch > 0.0 and governed:
            raise OptimizeError(
                f"{file}:{b.line}: tapping line (G84/G74, F = pitch x S) would run at the spindle speed the "
                f"optimiser writes for a cutting line (S words on lines {', '.join(map(str, lines))}); expected "
                "the tapping tool's own S word (S.. M3/M4 or M29 S..) after the last cutting line before it")
