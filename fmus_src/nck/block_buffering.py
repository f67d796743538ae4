"""Haas G103 P<n> (limit block buffering): the look-ahead window of the feed blocks read after it.

Conventions
-----------
* ``G103 P<n>`` (Haas mill operator's manual, G103, group 00; n = 0..15) limits
  the look-ahead to n blocks: while a block executes, the control has read and
  prepared at most the n blocks after it. ``G103`` and ``G103 P0`` remove the
  limit. The Autodesk Haas posts write ``G103 P1 (LOOKAHEAD OFF)`` before
  probing / surface-inspection moves and ``G103 P0 (LOOKAHEAD ON)`` after them.
* Mapping to the twin's look-ahead (:mod:`.lookahead`), whose window
  ``lookahead_blocks`` counts the executing block: under ``G103 P<n>`` the
  window is ``min(lookahead_blocks, n + 1)`` (the executing block and the n
  read beyond it), so the path must be able to stop at the end of the n-th
  block after the executing one. ``G103 P1`` thus lets the tool enter a block
  only as fast as it can stop at the end of the next one. Without a limit the
  window is ``lookahead_blocks`` (the machine file's, as before).
* The limit is modal: each feed block carries the one in effect when it was
  read (:attr:`.blocks.Linear.lookahead_limit`), and its own window applies to
  the stop-within-window constraint at its end. The windows count the feed
  blocks of a chain (G1/G2/G3; a G103 line itself is no block of the chain).
* ``G103 [P<n>]`` is read alone in its block (an N number allowed), as the Haas
  posts write it. P must be an integer 0..15 written without a decimal point.
"""
from __future__ import annotations

from typing import Sequence

from .errors import ErrorFactory
from .lexer import Word
from .lookahead_codes import alone_in_block
from .modal import ModalState

#: Largest block count of G103 P (Haas: 0..15).
MAX_G103_BLOCKS = 15
G103_FORMS = f"G103 (no limit), G103 P0 (no limit) or G103 P1..P{MAX_G103_BLOCKS} (blocks read ahead)"


def block_buffering(st: ModalState, gw: Word, words: Sequence[Word], err: ErrorFactory) -> None:
    """Set the G103 look-ahead limit of the feed blocks read from now on (``st.lookahead_limit``, 0: none).

    Parameters
    ----------
    st : ModalState
        Modal state; ``lookahead_limit`` is set to n of ``G103 P<n>`` (0 for ``G103`` / ``G103 P0``).
    gw : Word
        The block's G103 word.
    words : sequence of Word
        All words of the block.
    err : ErrorFactory
        Builds the error for this block.
    """
    alone_in_block(gw, words, "P", G103_FORMS, err)
    limit = 0
    for w in words:
        if w.letter == "P":
            if w.has_point or w.value != int(w.value) or not 0 <= w.value <= MAX_G103_BLOCKS:
                raise err("P" + w.text, f"G103 P{w.text} is not a number of blocks 0..{MAX_G103_BLOCKS}",
                          f"{G103_FORMS} (an integer without a decimal point)")
            limit = int(w.value)
    st.lookahead_limit = limit
