"""Feed of a block: the F word under G94 (feed per minute) or G95 (feed per revolution) → path feed in m/s.

Conventions
-----------
* G95 feed per revolution (G94 returns to feed per minute): F is in mm/rev
  (in/rev under G20) and the path feed of a G95 block is F x the commanded
  spindle speed in effect (S in rev/min / 60). FANUC measures the speed with
  the position coder; the twin's cutting feed already waits for the spindle
  speed arrival, so the commanded S is the steady speed. S above the
  machine's ``spindle_max_speed`` is clamped on the spindle but not in this
  feed. A G95 feed move (or canned cycle) with the spindle stopped (M5, no
  M3/M4 yet) or at S0 is an error naming the line, and so is a feed move
  whose modal F was given in the other feed mode (switching G94/G95 needs a
  new F). Per-line overrides: a spindle override rescales G95 feeds; a G95
  F word is overridden in m/rev (``feed_per_rev``, :mod:`.overrides`), not
  by a feed override in m/s; the writer writes G95 F words in mm/rev
  (in/rev), and ``optimize`` writes F = feed gene / S on G95 cutting lines.
* The G94/G95 code of a block applies to the block's own F word.
"""
from __future__ import annotations

import math

from .codes import GWords, ValueWords
from .errors import ErrorFactory
from .modal import ModalState


def read_feed_words(st: ModalState, gs: GWords, vals: ValueWords, line: int, err: ErrorFactory) -> None:
    """Set the feed mode (G94/G95) and the modal F of ``line`` (m/s under G94, m/rev under G95).

    Raises the error of ``err`` for F <= 0.
    """
    if "feed mode" in gs:
        st.per_rev = gs["feed mode"][0] == 95
    if "F" in vals:
        f = vals["F"].value
        if f <= 0.0:
            raise err("F" + vals["F"].text, f"feed rate F{vals['F'].text} is not positive", "F > 0")
        st.feed = f * st.scale if st.per_rev else f * st.scale / 60.0  # m/rev (G95) or m/s (G94)
        st.feed_per_rev = st.per_rev
        st.feed_line = line


def block_feed(st: ModalState, err: ErrorFactory, word: str, what: str) -> tuple[float, float]:
    """Path feed (m/s) of a feed block and its feed per revolution (m/rev; 0.0 under G94).

    G95: the feed is F (m/rev) x the commanded spindle speed in effect (rev/s); the cutting feed already waits
    for the spindle speed arrival, so the commanded S is the steady speed FANUC's position coder measures.

    Parameters
    ----------
    st : ModalState
        Modal feed, feed mode and spindle.
    err : ErrorFactory
        Builds the error for this block.
    word, what : str
        The word an error names (``"G1"``) and what the block does (``"G1 feed move"``).
    """
    if st.feed is None:
        raise err(word, f"{what} with no feed rate (F was never set)", "an F word on this or an earlier block")
    mode = "G95" if st.per_rev else "G94"
    if st.feed_per_rev != st.per_rev:
        given = "per revolution (G95)" if st.feed_per_rev else "per minute (G94)"
        raise err(word, f"{what} in {mode} but the modal F (line {st.feed_line}) is {given}",
                  f"an F word after switching to {mode} (F in {'mm/rev' if st.per_rev else 'mm/min'})")
    if not st.per_rev:
        return st.feed, 0.0
    if st.direction == 0 or not st.speed > 0.0:
        why = "the spindle is stopped (M5, or no M3/M4 yet)" if st.direction == 0 else "the spindle speed is S0"
        raise err(word, f"feed per revolution G95 {what} while {why}: the axes would not move",
                  "S > 0 and M3/M4 before a G95 feed move")
    return st.feed * st.speed / (2.0 * math.pi), st.feed
