"""Tool compensation words of a block: tool length (H, G43/G44/G49) and cutter radius (D, G40/G41/G42).

Conventions
-----------
* Tool length offset G43/G44 H<n> (+/- the length of Hn, geometry + wear), G49 cancels; H is modal, G43/G44
  without an H need an earlier nonzero H. The length is applied by the next Z move (:mod:`.modal`).
* Cutter radius compensation G41/G42 (FANUC 0i-MF/31i-B, cutter compensation
  C), as CAM posts write it in "wear" mode (Fusion 360, Mastercam): the
  posted path is already the tool-centre path and ``G41 D1`` ... ``G40`` only
  lets the operator add a wear value. D selects the tool radius offset
  :attr:`InterpreterSettings.tool_radii` (D0 = 0); D is modal and G41/G42
  without D uses the previous one (D0 at power-on), as FANUC. While the
  active radius is zero within :data:`RADIUS_ZERO`, the path is the
  programmed one, start-up and cancel blocks included, which is FANUC's
  result with a zero offset; G41/G42 are accepted in G17, G18 and G19 alike
  and canned cycles, G28 and G53 under G41/G42 are executed as programmed
  (with a zero radius an offset could not move them; no alarm is mirrored).
  A nonzero radius (in the G41/G42 block, or a D change while G41/G42 is
  on) is a :class:`GCodeError` naming the D word (or G41/G42): the offset
  path is not simulated. Also errors, as FANUC alarms: the start-up block
  (first move after G41/G42 from G40) or the cancel block (first move after
  G40) in G2/G3 (PS0034), and G17/G18/G19 changing the plane while G41/G42
  is on (PS0037).
"""
from __future__ import annotations

from .codes import GWords, ValueWords
from .errors import ErrorFactory, fmt_number
from .modal import ModalState
from .settings import INCH, MM

#: A tool radius offset with an absolute value up to this is zero (cutter compensation accepted), m.
RADIUS_ZERO = 1e-9


def tool_length_words(st: ModalState, gs: GWords, vals: ValueWords, err: ErrorFactory) -> None:
    """H word and G43/G44/G49 of a block.

    Raises the error of ``err`` for an H number outside 0..n and for G43/G44 with no H (this or an earlier one).
    """
    if "H" in vals:
        h = vals["H"]
        n_tools = len(st.settings.tool_lengths)
        if h.has_point or h.value < 0 or h.value > n_tools:
            raise err("H" + h.text, f"tool length offset number H{h.text} does not exist",
                      f"H0..H{n_tools} (integers)")
        st.h = int(h.value)
    if "tool length" in gs:
        code = gs["tool length"][0]
        st.tool_sign = {43: 1, 44: -1, 49: 0}[code]
        if code != 49 and "H" not in vals and st.h == 0:
            raise err(f"G{code}", f"G{code} without an H word",
                      f"G{code} H<n> with n in 1..{len(st.settings.tool_lengths)}")


def cutter_compensation(st: ModalState, gs: GWords, vals: ValueWords, err: ErrorFactory, unit_name: str) -> None:
    """D word and G40/G41/G42 of a block (FANUC cutter compensation C, zero radius only; see the module docstring).

    Raises the GCodeError of ``err`` for a D number outside 0..n and for G41/G42 with a nonzero radius.
    """
    if "D" in vals:
        d = vals["D"]
        n_radii = len(st.settings.tool_radii)
        if d.has_point or d.value < 0 or d.value > n_radii:
            raise err("D" + d.text, f"tool radius offset number D{d.text} does not exist", f"D0..D{n_radii} (integers)")
        st.d = int(d.value)
    if "cutter compensation" in gs:
        code = gs["cutter compensation"][0]
        if code == 40 and st.comp != 40:
            st.comp_pending = None if st.comp_pending == "start-up" else "cancel"
        elif code != 40 and st.comp == 40:
            st.comp_pending = None if st.comp_pending == "cancel" else "start-up"
        st.comp = code
    if st.comp == 40 or ("cutter compensation" not in gs and "D" not in vals):
        return
    radius = st.tool_radius()
    if not abs(radius) <= RADIUS_ZERO:  # also NaN
        word = "D" + vals["D"].text if "D" in vals else "G" + gs["cutter compensation"][1].text
        u = 1.0 / (INCH if st.scale == INCH else MM)
        raise err(word, f"cutter radius compensation with a nonzero radius (D{st.d} = {fmt_number(radius * u)} "
                  f"{unit_name}) is not simulated",
                  "the tool-centre path posted by the CAM system ('wear' or 'computer' compensation) with D = 0, "
                  f"i.e. a tool radius offset of at most {fmt_number(RADIUS_ZERO * 1e3)} mm")


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
