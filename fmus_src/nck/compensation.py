"""Tool compensation words of a block: tool length (H, G43/G44/G49) and cutter radius (D, G40/G41/G42).

Conventions
-----------
* Tool length offset G43/G44 H<n> (+/- the length of Hn, geometry + wear), G49 cancels; H is modal, G43/G44
  without an H need an earlier nonzero H. The length is applied by the next Z move (:mod:`.modal`).
* Cutter radius compensation G41/G42 (FANUC 0i-MF/31i-B, cutter compensation C). D selects the tool
  radius offset :attr:`InterpreterSettings.tool_radii` (geometry, plus the wear of ``G10 L13``; D0 = 0);
  D is modal and G41/G42 without D use the previous one (D0 at power-on), as FANUC. This module reads the
  words and checks the block; the tool-centre path is computed after the program by
  :mod:`.radius_offset` (G17, lines and arcs, start-up, corners, cancel).
* Zero radius (within :data:`RADIUS_ZERO`): CAM posts in "wear" mode (Fusion 360, Mastercam) write the
  tool-centre path and ``G41 D1`` ... ``G40`` only so that the operator can enter a wear value; with the
  register at 0 the path is the programmed one, start-up and cancel blocks included (FANUC's result with a
  zero offset). G41/G42 are then accepted in G17, G18 and G19 alike, and canned cycles, G28 and G53 under
  G41/G42 run as programmed (a zero offset could not move them; no alarm is mirrored).
* Nonzero radius (negative swaps G41 and G42, as FANUC): the offset path is simulated in G17 only. These
  are :class:`GCodeError` naming the word, as they are not simulated: G41/G42 in G18/G19, G41 and G42
  switched directly into each other (FANUC's change of offset direction), a canned cycle, G28/G30 or G53
  while G41/G42 is on. A radius that is not a finite number is an error.
* FANUC alarms also mirrored for any radius: the start-up block (first move after G41/G42 from G40) or the
  cancel block (first move after G40) in G2/G3 (PS0034), and G17/G18/G19 changing the plane while G41/G42
  is on (PS0037).
"""
from __future__ import annotations

import math

from .codes import GWords, ValueWords
from .errors import ErrorFactory, fmt_number
from .modal import ModalState
from .settings import INCH, MM, TWIN_OFFSET_REGISTERS

#: A tool radius offset with an absolute value up to this is zero (the programmed path is the tool centre), m.
RADIUS_ZERO = 1e-9


def _register_note(kind: str, setting: str, n: int) -> str:
    """The part of the message saying that no register of ``kind`` is set (empty when some are)."""
    if n:
        return ""
    return f" (no {kind} offsets are set: InterpreterSettings.{setting} is empty, so only the zero register 0 exists)"


def _register_range(letter: str, setting: str, n: int) -> str:
    """What a register word may be: ``H0..H200 (integers)``, or with no registers set, how to set them."""
    if n:
        return f"{letter}0..{letter}{n} (integers)"
    return (f"{letter}0, or the offsets given in InterpreterSettings.{setting} ({letter}1 is index 0; "
            f"the NCKernel component and cnctwin simulate have {TWIN_OFFSET_REGISTERS})")


def tool_length_words(st: ModalState, gs: GWords, vals: ValueWords, err: ErrorFactory) -> None:
    """H word and G43/G44/G49 of a block.

    Raises the error of ``err`` for an H number outside 0..n and for G43/G44 with no H (this or an earlier one).
    """
    if "H" in vals:
        h = vals["H"]
        n_tools = len(st.settings.tool_lengths)
        if h.has_point or h.value < 0 or h.value > n_tools:
            raise err("H" + h.text, f"tool length offset number H{h.text} does not exist"
                      + _register_note("tool length", "tool_lengths", n_tools),
                      _register_range("H", "tool_lengths", n_tools))
        st.h = int(h.value)
    if "tool length" in gs:
        code = gs["tool length"][0]
        st.tool_sign = {43: 1, 44: -1, 49: 0}[code]
        if code != 49 and "H" not in vals and st.h == 0:
            n_tools = len(st.settings.tool_lengths)
            raise err(f"G{code}", f"G{code} without an H word",
                      f"G{code} H<n> with n in 1..{n_tools}" if n_tools else
                      f"G{code} H<n>, with the tool lengths given in InterpreterSettings.tool_lengths")


def cutter_compensation(st: ModalState, gs: GWords, vals: ValueWords, err: ErrorFactory, unit_name: str) -> None:
    """D word and G40/G41/G42 of a block, and the checks of a nonzero radius (see the module docstring).

    Raises the GCodeError of ``err`` for a D number outside 0..n, a radius that is not finite, and the
    cases a nonzero radius does not simulate (other plane, G41/G42 switch, canned cycle, G28/G30/G53).
    """
    if "D" in vals:
        d = vals["D"]
        n_radii = len(st.settings.tool_radii)
        if d.has_point or d.value < 0 or d.value > n_radii:
            raise err("D" + d.text, f"tool radius offset number D{d.text} does not exist"
                      + _register_note("tool radius", "tool_radii", n_radii),
                      _register_range("D", "tool_radii", n_radii))
        st.d = int(d.value)
    switched = False
    if "cutter compensation" in gs:
        code = gs["cutter compensation"][0]
        if code == 40 and st.comp != 40:
            st.comp_pending = None if st.comp_pending == "start-up" else "cancel"
        elif code != 40 and st.comp == 40:
            st.comp_pending = None if st.comp_pending == "cancel" else "start-up"
        switched = code != 40 and st.comp not in (40, code)
        st.comp = code
    if st.comp == 40:
        return
    radius = st.tool_radius()

    def word() -> str:
        if "D" in vals:
            return "D" + vals["D"].text
        return "G" + gs["cutter compensation"][1].text if "cutter compensation" in gs else f"D{st.d}"

    u = 1.0 / (INCH if st.scale == INCH else MM)
    if not math.isfinite(radius):
        raise err(word(), f"tool radius offset D{st.d} = {radius} is not a number", "a finite tool radius offset")
    if abs(radius) <= RADIUS_ZERO:
        return
    value = f"D{st.d} = {fmt_number(radius * u)} {unit_name}"
    if switched:
        g = gs["cutter compensation"][1]
        raise err("G" + g.text, f"G{st.comp} switches the offset side directly while cutter compensation is on "
                  f"with a nonzero radius ({value}); the change of offset direction is not simulated",
                  f"G40 and its cancel move before G{st.comp}")
    if st.plane != "XY":
        raise err(word(), f"cutter radius compensation with a nonzero radius ({value}) in the {st.plane} plane "
                  "is not simulated", "G17 (XY plane) for a nonzero radius, or D = 0 (CAM 'wear' mode)")
    other = None
    if gs.get("non-modal", (None,))[0] in (28, 30, 53):
        other = "G" + gs["non-modal"][1].text
    cycle = gs.get("canned cycle", (None,))[0]
    if cycle not in (None, 80):
        other = "G" + gs["canned cycle"][1].text
    elif st.cycle is not None and cycle != 80 and "motion" not in gs:
        other = f"canned-cycle mode G{st.cycle}"
    if other is not None:
        raise err(other if other.startswith("G") else word(), f"{other} while cutter compensation "
                  f"G{st.comp} is on with a nonzero radius ({value}) is not simulated",
                  f"G40 and its cancel move before {other}")


def check_compensation_move(st: ModalState, vals: ValueWords, gs: GWords, err: ErrorFactory) -> None:
    """The first move after G41/G42 (start-up) or G40 (cancel) must be G0/G1 (FANUC alarm PS0034)."""
    if st.comp_pending is None:
        return
    arc = st.motion in (2, 3)
    if not (any(a in vals for a in "XYZ") or (arc and any(c in vals for c in "IJK"))):
        return  # no move: start-up/cancel waits for the next move block
    if arc:
        word = "G" + gs["motion"][1].text if "motion" in gs else f"G{st.motion}"
        which = "start-up after G41/G42" if st.comp_pending == "start-up" else "cancel after G40"
        raise err(word, f"cutter compensation {which} in circular interpolation G{st.motion} (FANUC alarm PS0034)",
                  "the first move after G41/G42 or G40 in G0 or G1")
    st.comp_pending = None
