"""The G and M codes and addresses the interpreter knows: modal groups, rejections, and the words of one block.

Accepted as no-ops, because they cancel features that are never switched on
(CAM posts emit them in safe-start lines): G67 (macro modal call cancel), G13.1 (polar interpolation
cancel). G50 (scaling cancel; a mill: G50 with X/Y/Z/S, the lathe meaning, is an error), G50.1 (mirror
image cancel), G69 (rotation cancel) and G15 (polar coordinates cancel) do nothing when their feature is
off; G51/G50, G51.1/G50.1, G68/G69 and G16/G15: :mod:`.transforms` and :mod:`.polar`.
Rejected with a :class:`GCodeError`: the codes switching the other features on
(G66, G12.1), G65 outside its own block (G65 calls: :mod:`.macro.calls`), what
cutter compensation G41/G42 with a
nonzero radius does not simulate (see :mod:`.compensation`), G88 (boring with a manual operation),
G29, and every other G/M code or address.

Haas words: G187 (accuracy control, accepted without effect: :mod:`.lookahead_codes`; its E word is read only
in a G187 block), G103 (block buffering limit: :mod:`.block_buffering`), G154 P1..P99 and G110..G129 (additional
work offsets: :mod:`.offsets`).

Rotary axis words at zero (``A0.``, ``B0.``, ``C0.``; any G90/G91 block, G10, G28 intermediate points) are
accepted and dropped: 4-axis-ready posts for 3-axis machines write them (Mastercam "Generic Fanuc 3X Mill"
``G0 G90 G54 X.. Y.. A0. S.. M3``, ``G28 X0. Y0. A0.``, ``G10 L2 P1 ... B0.``), and an axis that the program
keeps at 0 deg does not change the tool path. A nonzero rotary word and every U V W word are errors naming the
word. Macro lines (``A#1``) still take only the dialect's addresses.

Machine builders' M codes (M13, M48, M88, ...): the machine file's aliases (:mod:`.m_aliases`), passed to
:func:`group_words`; each expands to the standard codes it stands for on its block, so M13 M5 is a conflict
as M3 M5 is. M97 P<n> (Haas local subprogram call): :mod:`.subprograms`.

Conventions
-----------
* Decimal G codes (``G50.1``, ``G13.1``) are single codes; the lexer reads
  them as one number.
* At most one G code of each modal group and one M code of each kind per block; every other address at most
  once per block.
"""
from __future__ import annotations

from typing import Mapping, Sequence

from .cycles import CYCLES
from .errors import ErrorFactory
from .lexer import Word

#: The G words of a block by modal group: group -> (code, word).
GWords = dict[str, tuple[int, Word]]
#: The M words of a block by kind: kind -> (code, word).
MWords = dict[str, tuple[int, Word]]
#: The other words of a block by address letter.
ValueWords = dict[str, Word]

# G code -> modal group
G_GROUP: dict[int | float, str] = {
    0: "motion", 1: "motion", 2: "motion", 3: "motion",
    4: "non-modal", 28: "non-modal", 30: "non-modal", 53: "non-modal",
    10: "non-modal",
    52: "non-modal", 92: "non-modal", 92.1: "non-modal", 92.2: "non-modal", 92.3: "non-modal",  # coordinate_shifts
    9: "exact stop",
    17: "plane", 18: "plane", 19: "plane",
    20: "units", 21: "units",
    40: "cutter compensation", 41: "cutter compensation", 42: "cutter compensation",
    43: "tool length", 44: "tool length", 49: "tool length",
    54: "work offset", 55: "work offset", 56: "work offset", 57: "work offset", 58: "work offset",
    59: "work offset", 54.1: "work offset",
    # Haas additional work offsets G154 P1..P99 and their aliases G110..G129 = G154 P1..P20 (see offsets)
    154: "work offset", **{c: "work offset" for c in range(110, 130)},
    61: "path mode", 64: "path mode", 61.1: "path mode",  # G61.1: Mazak geometry compensation (path_blending)
    80: "canned cycle", **{c: "canned cycle" for c in CYCLES},
    90: "distance", 91: "distance",
    90.1: "arc centre", 91.1: "arc centre",  # LinuxCNC: I/J/K absolute / incremental (see motion)
    94: "feed mode", 95: "feed mode",
    # look-ahead / contour-control modes (accepted, see lookahead_codes)
    5.1: "look-ahead", 8: "look-ahead", 5: "look-ahead",
    # Haas accuracy control G187 (accepted, see lookahead_codes) and block buffering limit G103 (block_buffering)
    187: "accuracy control", 103: "block buffering",
    98: "return level", 99: "return level",
    # programmable transforms and polar coordinates (see transforms, polar)
    15: "polar coordinates", 16: "polar coordinates", 50: "scaling", 51: "scaling",
    50.1: "mirror image", 51.1: "mirror image", 68: "coordinate rotation", 69: "coordinate rotation",
    # cancel codes of features never switched on: accepted as no-ops
    67: "macro modal call", 13.1: "polar interpolation",
}
#: Known G codes the twin does not execute -> why.
G_REJECT: dict[int | float, str] = {
    88: "boring cycle G88 is not supported: it stops at the hole bottom for a manual operation (the operator "
        "jogs the tool out), which the twin cannot do (use G76, G85, G86 or G89)",
    65: "macro call G65 with other G codes or from a variable (write G65 P<n> <arguments> alone in its block)",
    66: "macro modal call G66 is not supported (only its cancel G67): it would call the macro after every move "
        "block until G67; write G65 P<n> <arguments> at each position instead",
    12.1: "polar coordinate interpolation G12.1 is not supported (only its cancel G13.1)",
    29: "return from the reference position G29 is not supported (program the move back with G0)",
}
# M code -> kind
M_GROUP: dict[int, str] = {
    0: "stop", 1: "stop", 2: "end", 30: "end", 3: "spindle", 4: "spindle", 5: "spindle", 19: "spindle",
    6: "tool change",
    7: "coolant", 8: "coolant", 9: "coolant", 97: "subprogram", 98: "subprogram", 99: "subprogram",
    29: "rigid tapping",
}
SUPPORTED_G = ("G0 G1 G2 G3 G4 G5 G5.1 G8 G9 G10 G13.1 G15 G16 G17 G18 G19 G20 G21 G28 G30 G40 G41 G42 G43 G44 "
               "G49 G50 G50.1 G51 G51.1 G52 G53 G54-G59 G54.1 G61 G61.1 G64 G67 G68 G69 G73 G74 G76 G80 G81 G82 G83 G84 "
               "G85 G86 G87 G89 G90 G90.1 G91 G91.1 G92 G92.1 G92.2 G92.3 G94 G95 G98 G99 G103 G110-G129 G154 G187")
SUPPORTED_M = "M0 M1 M2 M3 M4 M5 M6 M7 M8 M9 M19 M29 M30 M97 M98 M99"
#: Address letters of the dialect.
LETTERS = set("GMXYZIJKRFSTHDPQNOL") | {",C", ",R"}  # ,C / ,R: optional chamfer / corner R (see .corners)
#: Address letters read only in a block with one of these G codes: E (corner rounding) of Haas G187.
BLOCK_LETTERS: dict[str, int | float] = {"E": 187}
#: What each block letter means there, and why it is refused elsewhere (quoted in the error).
_BLOCK_LETTER_USE = {"E": "the Haas corner rounding; E in other blocks, e.g. the Haas rapid rate in percent of "
                          "G0 ... E, or the FANUC thread lead, would change the motion and is not modelled"}
#: Axis addresses of machines with more axes than the twin's X Y Z (rotary A B C, parallel U V W), as in
#: ``G0 G90 G54 X-5. Y-5. A0.`` of 4-axis posts; named as such in the error.
_EXTRA_AXES = {"A": "rotary axis about X", "B": "rotary axis about Y", "C": "rotary axis about Z",
               "U": "parallel axis to X", "V": "parallel axis to Y", "W": "parallel axis to Z"}
#: Rotary axes whose word is accepted at 0 (deg) and then has no effect: 4-axis-ready 3-axis posts write ``A0.``
#: on every positioning line, in ``G10 L2 ... B0.`` and ``G28 X0. Y0. A0.``; the twin's machine has no rotary
#: table, i.e. one that never leaves its 0 deg home (see :func:`group_words`).
ROTARY_AT_HOME = ("A", "B", "C")


def g_code(w: Word) -> int | float | None:
    """The code of a G word: an int (``G01``, ``G1.``), a one-decimal float (``G50.1``), else None."""
    if w.value < 0:
        return None
    if w.value == int(w.value):
        return int(w.value)
    tenths = round(w.value * 10.0)
    if abs(w.value * 10.0 - tenths) < 1e-9:
        return tenths / 10.0
    return None


def integer_code(w: Word) -> int | None:
    """The code number of a G/M word if it is a non-negative integer (``G01``, ``G1.``), else None."""
    if w.value < 0 or w.value != int(w.value):
        return None
    return int(w.value)


def describe_m_codes(m_codes: Mapping[int, Sequence[int]]) -> str:
    """M-code aliases as quoted in messages: ``"M13 (M3 M8), M48 (no effect)"``; ``"none"`` when empty."""
    if not m_codes:
        return "none"
    return ", ".join(f"M{c} (" + (" ".join(f"M{m}" for m in m_codes[c]) or "no effect") + ")" for c in sorted(m_codes))


def _m_name(code: int, w: Word) -> str:
    """``M3``, or ``M13 (= M3)`` when the standard code came from the alias word ``w``."""
    return f"M{code}" if integer_code(w) == code else f"M{w.text} (= M{code})"


def group_words(words: Sequence[Word], err: ErrorFactory, m_codes: Mapping[int, Sequence[int]] | None = None,
                ) -> tuple[GWords, MWords, ValueWords]:
    """Sort the words of a block into G codes by modal group, M codes by kind and the other words by letter.

    Parameters
    ----------
    words : sequence of Word
        The block's words.
    err : ErrorFactory
        Builds the error for this block.
    m_codes : mapping int -> sequence of int, optional
        The machine file's M-code aliases (:mod:`.m_aliases`): an alias word enters the standard codes it
        stands for (each under its kind, with the alias word), an empty one nothing.

    Raises the error of ``err`` for an unknown address, an unsupported or rejected G/M code, two codes of one
    group or kind (also through an alias) and an address given twice.
    """
    aliases = m_codes or {}
    codes = {g_code(w) for w in words if w.letter == "G"} - {None}  # for BLOCK_LETTERS
    gs: GWords = {}
    ms: MWords = {}
    vals: ValueWords = {}
    for w in words:
        if w.letter not in LETTERS and BLOCK_LETTERS.get(w.letter) not in codes:
            if w.letter in ROTARY_AT_HOME and w.value == 0.0:
                continue  # the rotary axis stays at its 0 deg home: no motion, no offset (module docstring)
            if w.letter in _EXTRA_AXES:
                at_home = (f"; {w.letter}0 is accepted (the axis kept at 0 deg, as 3-axis posts write it), "
                           f"{w.letter}{w.text} would turn it" if w.letter in ROTARY_AT_HOME else "")
                raise err(w.letter + w.text, f"axis word {w.letter}{w.text} is not supported: {w.letter} is "
                          f"a {_EXTRA_AXES[w.letter]} (4th/5th axis), and the machine has only X, Y and Z"
                          + at_home, "a 3-axis program (post-process it for a 3-axis machine, without "
                          f"{w.letter} words{', or with ' + w.letter + '0 only' if at_home else ''})")
            only_in = (f" here ({w.letter} is read only in a G{BLOCK_LETTERS[w.letter]} block: "
                       f"{_BLOCK_LETTER_USE[w.letter]})" if w.letter in BLOCK_LETTERS else "")
            raise err(w.letter + w.text, f"address {w.letter} is not supported{only_in}",
                      "one of the addresses " + " ".join(sorted(LETTERS)))
        if w.letter == "G":
            code = g_code(w)
            if code is None or (code not in G_GROUP and code not in G_REJECT):
                raise err("G" + w.text, f"G code G{w.text} is not supported", f"one of {SUPPORTED_G}")
            if code in G_REJECT:
                raise err("G" + w.text, G_REJECT[code], f"one of {SUPPORTED_G}")
            group = G_GROUP[code]
            if group in gs and gs[group][0] != code:
                raise err("G" + w.text, f"G{gs[group][0]} and G{code} are both in modal group '{group}'",
                          "at most one G code of each modal group per block")
            gs[group] = (code, w)  # type: ignore[assignment]
        elif w.letter == "M":
            mcode = integer_code(w)
            if mcode is not None and mcode in aliases:
                standard: Sequence[int] = aliases[mcode]
            elif mcode is not None and mcode in M_GROUP:
                standard = (mcode,)
            else:
                raise err("M" + w.text, f"M code M{w.text} is not supported",
                          f"one of {SUPPORTED_M} or the machine file's aliases: {describe_m_codes(aliases)} "
                          "(a machine builder's M code: add it under [nck.m_codes] of the machine file, e.g. "
                          "13 = { means = [3, 8], source = \"...\" })")
            for code in standard:
                kind = M_GROUP[code]
                if kind in ms and ms[kind][0] != code:
                    raise err("M" + w.text, f"{_m_name(*ms[kind])} and {_m_name(code, w)} conflict in one block",
                              f"at most one M code of each kind ({kind}) per block")
                ms[kind] = (code, w)
        else:
            if w.letter in vals:
                raise err(w.letter + w.text, f"word {w.letter} appears twice", f"at most one {w.letter} word per block")
            vals[w.letter] = w
    return gs, ms, vals


def check_stray_words(gs: GWords, vals: ValueWords, err: ErrorFactory, cycle_mode: bool = False) -> None:
    """L outside M98/G10 and G50 with X/Y/Z/I/J/K/P/S (the lathe's G50) are errors; call after M98 took its P/L.

    ``cycle_mode``: a canned cycle is modal before the block; an L there (or in a cycle block) is the repeat
    count as a Haas reads it (Haas mill manual, G81 ``L``: number of repeats; also the older FANUC format, and
    ``L0`` stores the cycle without drilling): it becomes the block's K word (an L with a K is an error).
    """
    if "L" in vals and gs.get("non-modal", (None,))[0] != 10:
        cycle = gs.get("canned cycle", (None,))[0]
        if (cycle_mode or cycle is not None) and cycle != 80 and "motion" not in gs:
            w = vals.pop("L")
            if "K" in vals:
                raise err("L" + w.text, "words K and L in one canned-cycle block: both are the repeat count "
                          "(K on the FANUC 0i/31i, L on a Haas and in the older FANUC format)",
                          "one repeat count, K<n> or L<n>")
            vals["K"] = Word("K", w.text, w.value, w.start, w.end, w.variable)  # Haas / older FANUC: L = K
            return
        raise err("L" + vals["L"].text, "word L outside an M98 block", "L only as the repeat count of M98 P<n> L<k>")
    if gs.get("scaling", (None,))[0] == 50:
        for a in "XYZIJKPS":
            if a in vals:
                raise err(a + vals[a].text, f"word {a} with G50: on a mill G50 only cancels scaling "
                          "(G50 with X/Z/S is the lathe's coordinate setting or spindle clamp)", "G50 alone")


def check_sequence_words(vals: ValueWords, err: ErrorFactory) -> None:
    """N (sequence number) and O (program number) words must be non-negative integers."""
    for letter in ("N", "O"):
        if letter in vals and (vals[letter].has_point or vals[letter].value < 0):
            w = vals[letter]
            raise err(letter + w.text, f"{letter}{w.text} is not a non-negative integer",
                      f"{letter} followed by digits")
