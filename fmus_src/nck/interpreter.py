"""Modal interpreter of the FANUC milling dialect → typed blocks.

Supported: G0 G1 G2 G3 (arcs by R, negative R for > 180 deg, or by I/J/K incl.
full circles), G4 (dwell), G17/G18/G19, G20/G21, G40, G43/G44/G49 with H,
G54-G59, G64, G80, G90/G91, G94; M2 M3 M4 M5 M6 M7 M8 M9 M30; F S T H N O
words; ``( )`` and ``;`` comments, ``%`` lines, block delete ``/``.
Rejected with a :class:`GCodeError`: cutter compensation G41/G42, feed per
revolution G95, canned cycles and every other G/M code or address.

Conventions
-----------
* Calculator-type decimal input (FANUC No. 3401#0 DPI = 1): ``X10`` is 10 mm.
* Power-on modes: G0, G17, G21, G40, G49, G54, G64, G80, G90, G94.
* G4: a value with a decimal point is in seconds (``G4 X1.5``, ``G4 P1.5``),
  without it in milliseconds (``G4 P1500`` as FANUC).
* An offset change takes effect on the next move of the axis: the machine
  target of a programmed axis is programmed value + work offset (+ tool length
  on Z); axes not programmed do not move. A work-offset change shifts the
  programmed coordinates of the current position (as FANUC's absolute
  position display); a tool-length change is applied by the next Z move, also
  in G91 (as FANUC).
* Block delete ``/``: honoured when ``block_delete=True`` (the block is not
  executed), otherwise the block is executed (switch off, the default).
* Input ranges (FANUC IS-B, 8 digits): X Y Z I J K R within +-99999.999 mm
  (G21) or +-9999.9999 in (G20); dwell at most 99999.999 s; T at most
  99999999; a number has at most 32 characters (ASCII digits only). Beyond
  them: :class:`GCodeError` (a 1e400 would otherwise become ``inf``).
* Lines end at LF, CRLF or CR only (form feed, U+2028 etc. stay in the line
  and are rejected as unexpected characters), so line numbers match editors.
* Execution stops at M30/M2 or at a second ``%``; lines after it are not
  read. End of file without M30/M2 also ends the program (``ProgramEnd`` with
  reason ``"end of file"``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

from .blocks import (
    PLANE_AXES, Arc, Block, Coolant, Dwell, Linear, Program, ProgramEnd, Rapid, SpindleSpeed, SpindleStop,
    ToolChange, Vec3,
)
from .errors import GCodeError
from .lexer import LexError, Word, lex_line, split_lines

MM = 1e-3
INCH = 25.4e-3
RPM = 2.0 * math.pi / 60.0
#: Tolerance on the radius difference of an I/J/K arc (FANUC alarm PS0020 style), m.
ARC_RADIUS_TOLERANCE = 0.002e-3
#: End points closer than this are the same point (full circle), m.
SAME_POINT = 1e-9
#: Input range of X Y Z I J K R words (FANUC IS-B, 8 digits): mm under G21, inch under G20.
MAX_COORDINATE = {"mm": 99999.999, "in": 9999.9999}
#: Longest dwell, s (FANUC: 8 digits of P in ms).
MAX_DWELL = 99999.999
#: Largest tool number (FANUC: 8 digits).
MAX_TOOL = 99999999

# G code -> modal group
_G_GROUP: dict[int, str] = {
    0: "motion", 1: "motion", 2: "motion", 3: "motion",
    4: "non-modal",
    17: "plane", 18: "plane", 19: "plane",
    20: "units", 21: "units",
    40: "cutter compensation",
    43: "tool length", 44: "tool length", 49: "tool length",
    54: "work offset", 55: "work offset", 56: "work offset", 57: "work offset", 58: "work offset",
    59: "work offset",
    64: "path mode",
    80: "canned cycle",
    90: "distance", 91: "distance",
    94: "feed mode",
}
_G_REJECT: dict[int, str] = {
    41: "cutter radius compensation G41 is not supported (program the tool-centre path and use G40)",
    42: "cutter radius compensation G42 is not supported (program the tool-centre path and use G40)",
    95: "feed per revolution G95 is not supported",
    **{c: f"canned cycle G{c} is not supported" for c in (73, 74, 76, 81, 82, 83, 84, 85, 86, 87, 88, 89)},
}
_M_GROUP: dict[int, str] = {
    2: "end", 30: "end", 3: "spindle", 4: "spindle", 5: "spindle", 6: "tool change",
    7: "coolant", 8: "coolant", 9: "coolant",
}
_SUPPORTED_G = "G0 G1 G2 G3 G4 G17 G18 G19 G20 G21 G40 G43 G44 G49 G54-G59 G64 G80 G90 G91 G94"
_SUPPORTED_M = "M2 M3 M4 M5 M6 M7 M8 M9 M30"
_LETTERS = set("GMXYZIJKRFSTHPNO")
_AXIS = {"X": 0, "Y": 1, "Z": 2}
_CENTRE = {"I": 0, "J": 1, "K": 2}
_PLANE_OF_G = {17: "XY", 18: "ZX", 19: "YZ"}


@dataclass(frozen=True)
class InterpreterSettings:
    """Machine data the interpreter needs (SI).

    Attributes
    ----------
    initial : Vec3
        Machine position before the program (m).
    work_offsets : Mapping[int, Vec3]
        G54..G59 → (x, y, z) offset (m). Missing numbers are zero.
    tool_lengths : Sequence[float]
        Tool length offsets (m) for H1..Hn (index 0 is H1). H0 is always zero.
    block_delete : bool
        Block delete switch: True skips blocks starting with ``/``.
    """

    initial: Vec3 = (0.0, 0.0, 0.0)
    work_offsets: Mapping[int, Vec3] = field(default_factory=dict)
    tool_lengths: Sequence[float] = ()
    block_delete: bool = False


class _State:
    """Modal state of the interpreter."""

    def __init__(self, settings: InterpreterSettings) -> None:
        self.motion = 0
        self.plane = "XY"
        self.scale = MM
        self.absolute = True
        self.work = 54
        self.tool_sign = 0  # +1 G43, -1 G44, 0 G49
        self.h = 0
        self.feed: float | None = None
        self.feed_line = 0
        self.speed = 0.0
        self.speed_line = 0
        self.direction = 0
        self.tool_selected: int | None = None
        self.machine = list(settings.initial)
        self.applied_tool = 0.0  # tool length contained in machine[2]
        self.settings = settings
        off = self.work_offset()
        self.prog = [self.machine[a] - off[a] for a in range(3)]

    def work_offset(self) -> Vec3:
        return tuple(self.settings.work_offsets.get(self.work, (0.0, 0.0, 0.0)))  # type: ignore[return-value]

    def tool_length(self) -> float:
        if self.tool_sign == 0 or self.h == 0:
            return 0.0
        return self.tool_sign * self.settings.tool_lengths[self.h - 1]


def interpret(text: str, file: str = "<text>", settings: InterpreterSettings | None = None) -> Program:
    """Interpret a G-code program into typed blocks.

    Parameters
    ----------
    text : str
        Program source (any line endings).
    file : str
        Name used in error messages.
    settings : InterpreterSettings, optional
        Initial position, work offsets, tool lengths (all zero by default).

    Returns
    -------
    Program
        Blocks in execution order ending with :class:`ProgramEnd`.

    Raises
    ------
    GCodeError
        For every unsupported, malformed or impossible block (never skipped silently).
    """
    settings = settings or InterpreterSettings()
    st = _State(settings)
    out: list[Block] = []
    seen_percent = False
    last_line = 0
    for number, raw in enumerate(split_lines(text), start=1):
        last_line = number
        try:
            lexed = lex_line(raw)
        except LexError as exc:
            raise GCodeError(file, number, exc.word, exc.expected, exc.problem, raw.strip()) from None
        if lexed.percent:
            if seen_percent or out:
                out.append(ProgramEnd(number, "%"))
                return Program(file, tuple(out), tuple(settings.initial))  # type: ignore[arg-type]
            seen_percent = True
            continue
        if not lexed.words or (lexed.block_delete and settings.block_delete):
            continue
        end = _block(st, lexed.words, number, lexed.text, file, out)
        if end:
            return Program(file, tuple(out), tuple(settings.initial))  # type: ignore[arg-type]
    out.append(ProgramEnd(last_line, "end of file"))
    return Program(file, tuple(out), tuple(settings.initial))  # type: ignore[arg-type]


def _fmt(value: float) -> str:
    return f"{value:.6g}"


def _block(st: _State, words: tuple[Word, ...], line: int, text: str, file: str, out: list[Block]) -> bool:
    """Execute one block; return True at program end."""

    def err(word: str, problem: str, expected: str) -> GCodeError:
        return GCodeError(file, line, word, expected, problem, text)

    gs: dict[str, tuple[int, Word]] = {}
    ms: dict[str, tuple[int, Word]] = {}
    vals: dict[str, Word] = {}
    for w in words:
        if w.letter not in _LETTERS:
            raise err(w.letter + w.text, f"address {w.letter} is not supported",
                      "one of the addresses " + " ".join(sorted(_LETTERS)))
        if w.letter == "G":
            code = _integer_code(w)
            if code is None or (code not in _G_GROUP and code not in _G_REJECT):
                raise err("G" + w.text, f"G code G{w.text} is not supported", f"one of {_SUPPORTED_G}")
            if code in _G_REJECT:
                raise err("G" + w.text, _G_REJECT[code], f"one of {_SUPPORTED_G}")
            group = _G_GROUP[code]
            if group in gs and gs[group][0] != code:
                raise err("G" + w.text, f"G{gs[group][0]} and G{code} are both in modal group '{group}'",
                          "at most one G code of each modal group per block")
            gs[group] = (code, w)
        elif w.letter == "M":
            code = _integer_code(w)
            if code is None or code not in _M_GROUP:
                raise err("M" + w.text, f"M code M{w.text} is not supported", f"one of {_SUPPORTED_M}")
            group = _M_GROUP[code]
            if group in ms and ms[group][0] != code:
                raise err("M" + w.text, f"M{ms[group][0]} and M{code} conflict in one block",
                          "at most one M code of each kind per block")
            ms[group] = (code, w)
        else:
            if w.letter in vals:
                raise err(w.letter + w.text, f"word {w.letter} appears twice", f"at most one {w.letter} word per block")
            vals[w.letter] = w

    # 1. units first: they apply to every number of the block
    if "units" in gs:
        st.scale = INCH if gs["units"][0] == 20 else MM
    unit_name = "in" if st.scale == INCH else "mm"
    # 2. feed
    if "F" in vals:
        f = vals["F"].value
        if f <= 0.0:
            raise err("F" + vals["F"].text, f"feed rate F{vals['F'].text} is not positive", "F > 0")
        st.feed = f * st.scale / 60.0
        st.feed_line = line
    # 3. spindle speed, tool select
    if "S" in vals:
        s = vals["S"].value
        if s < 0.0:
            raise err("S" + vals["S"].text, f"spindle speed S{vals['S'].text} is negative", "S >= 0 (rpm)")
        st.speed = s * RPM
        st.speed_line = line
    if "T" in vals:
        t = vals["T"]
        if t.has_point or t.value < 0 or t.value > MAX_TOOL:
            raise err("T" + t.text, f"tool number T{t.text} is not an integer in 0..{MAX_TOOL}", "T0, T1, T2, ...")
        st.tool_selected = int(t.value)
    for letter in ("N", "O"):
        if letter in vals and (vals[letter].has_point or vals[letter].value < 0):
            w = vals[letter]
            raise err(letter + w.text, f"{letter}{w.text} is not a non-negative integer", f"{letter} followed by digits")
    # 4. tool change
    if "tool change" in ms:
        if st.tool_selected is None:
            raise err("M6", "M6 with no tool selected", "a T word on this or an earlier block")
        out.append(ToolChange(line, st.tool_selected))
    # 5. spindle
    if "spindle" in ms:
        code = ms["spindle"][0]
        if code == 5:
            st.direction = 0
            out.append(SpindleStop(line))
            if "S" in vals:
                out.append(SpindleSpeed(line, st.speed, 0, st.speed_line))
        else:
            st.direction = 1 if code == 3 else -1
            out.append(SpindleSpeed(line, st.speed, st.direction, st.speed_line))
    elif "S" in vals:
        out.append(SpindleSpeed(line, st.speed, st.direction, st.speed_line))
    # 6. coolant
    if "coolant" in ms:
        out.append(Coolant(line, ms["coolant"][0] != 9))
    # 7. modes
    if "plane" in gs:
        st.plane = _PLANE_OF_G[gs["plane"][0]]
    if "distance" in gs:
        st.absolute = gs["distance"][0] == 90
    if "work offset" in gs:
        new = gs["work offset"][0]
        if new != st.work:
            st.work = new
            off = st.work_offset()
            st.prog = [st.machine[a] - off[a] for a in range(3)]
            st.prog[2] -= st.applied_tool
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
            raise err(f"G{code}", f"G{code} without an H word", f"G{code} H<n> with n in 1..{len(st.settings.tool_lengths)}")
    # 8. dwell (non-modal)
    if "non-modal" in gs:
        if "motion" in gs:
            raise err(f"G{gs['motion'][0]}", "G4 and a motion G code in one block", "G4 alone in its block")
        for a in ("Y", "Z", "I", "J", "K", "R"):
            if a in vals:
                raise err(a + vals[a].text, f"word {a} in a G4 dwell block", "G4 X<time> or G4 P<time>")
        if ("X" in vals) == ("P" in vals):
            raise err("G4", "G4 needs exactly one of X or P", "G4 X1.5 (s), G4 P1500 (ms)")
        w = vals.get("X") or vals["P"]
        seconds = w.value if w.has_point else w.value * 1e-3
        if seconds < 0:
            raise err(w.letter + w.text, "negative dwell time", "a time >= 0")
        if seconds > MAX_DWELL:
            raise err(w.letter + w.text, f"dwell of {_fmt(seconds)} s is beyond the input range",
                      f"a dwell of at most {MAX_DWELL} s")
        out.append(Dwell(line, seconds))
    elif "P" in vals:
        raise err("P" + vals["P"].text, "word P outside a G4 dwell block", "P only with G4")
    else:
        limit = MAX_COORDINATE[unit_name]
        for a in "XYZIJKR":
            if a in vals and abs(vals[a].value) > limit:
                raise err(a + vals[a].text, f"{a}{vals[a].text} is beyond the input range of {limit} {unit_name}",
                          f"|{a}| <= {limit} {unit_name}")
        if "motion" in gs:
            st.motion = gs["motion"][0]
        _motion(st, vals, "motion" in gs, line, err, unit_name, out)
    # 9. end
    if "end" in ms:
        out.append(ProgramEnd(line, f"M{ms['end'][0]}"))
        return True
    return False


def _integer_code(w: Word) -> int | None:
    """The code number of a G/M word if it is a non-negative integer (``G01``, ``G1.``), else None."""
    if w.value < 0 or w.value != int(w.value):
        return None
    return int(w.value)


def _motion(st: _State, vals: dict[str, Word], motion_word: bool, line: int, err, unit_name: str,
            out: list[Block]) -> None:
    axes = [a for a in "XYZ" if a in vals]
    centre = [c for c in "IJK" if c in vals]
    has_r = "R" in vals
    is_arc = st.motion in (2, 3)
    if (centre or has_r) and not is_arc:
        w = vals[(centre or ["R"])[0]]
        raise err(w.letter + w.text, f"word {w.letter} without G2/G3", "I, J, K or R only in circular interpolation")
    if not axes and not (is_arc and centre):
        if has_r:
            raise err("R" + vals["R"].text, "R given without an end point", "X/Y/Z end point with R")
        return
    scale = st.scale
    start: Vec3 = tuple(st.machine)  # type: ignore[assignment]
    off = st.work_offset()
    tool = st.tool_length()
    for a in axes:
        i = _AXIS[a]
        v = vals[a].value * scale
        st.prog[i] = v if st.absolute else st.prog[i] + v
        st.machine[i] = st.prog[i] + off[i] + (tool if i == 2 else 0.0)
        if i == 2:
            st.applied_tool = tool
    end: Vec3 = tuple(st.machine)  # type: ignore[assignment]
    if st.motion == 0:
        out.append(Rapid(line, start, end))
        return
    if st.feed is None:
        raise err(f"G{st.motion}", f"G{st.motion} feed move with no feed rate (F was never set)",
                  "an F word on this or an earlier block")
    if st.motion == 1:
        out.append(Linear(line, start, end, st.feed, st.feed_line))
        return
    i1, i2, i3 = PLANE_AXES[st.plane]
    plane_letters = {"XY": "IJ", "ZX": "KI", "YZ": "JK"}[st.plane]
    clockwise = st.motion == 2
    gname = f"G{st.motion}"
    u = 1.0 / (INCH if scale == INCH else MM)  # SI -> program units for messages
    d1, d2 = end[i1] - start[i1], end[i2] - start[i2]
    chord = math.hypot(d1, d2)
    if has_r:
        rw = vals["R"]
        r = rw.value * scale
        if chord <= SAME_POINT:
            raise err("R" + rw.text, "an arc given by R cannot end at its start point",
                      "I/J/K for a full circle, or an end point different from the start")
        half = 0.5 * chord
        if abs(r) < half - ARC_RADIUS_TOLERANCE:
            raise err("R" + rw.text, f"arc radius {_fmt(abs(r) * u)} {unit_name} is smaller than half the chord "
                      f"({_fmt(half * u)} {unit_name})", f"R >= {_fmt(half * u)}")
        h = math.sqrt(max(r * r - half * half, 0.0))
        side = (1.0 if not clockwise else -1.0) * (1.0 if r > 0 else -1.0)
        c = [0.0, 0.0, 0.0]
        c[i1] = start[i1] + 0.5 * d1 - side * h * d2 / chord
        c[i2] = start[i2] + 0.5 * d2 + side * h * d1 / chord
        c[i3] = start[i3]
        out.append(Arc(line, start, end, tuple(c), st.plane, clockwise, st.feed, st.feed_line))  # type: ignore[arg-type]
        return
    if not centre:
        raise err(gname, f"{gname} without R or I/J/K", f"R or {plane_letters[0]}/{plane_letters[1]} for the centre")
    for cl in centre:
        if cl not in plane_letters:
            raise err(cl + vals[cl].text, f"centre word {cl} is not in the {st.plane} plane",
                      f"{plane_letters[0]} and {plane_letters[1]} in G{ {'XY': 17, 'ZX': 18, 'YZ': 19}[st.plane]}")
    c = list(start)
    for cl in centre:
        c[_CENTRE[cl]] = start[_CENTRE[cl]] + vals[cl].value * scale
    r1 = math.hypot(start[i1] - c[i1], start[i2] - c[i2])
    if r1 <= SAME_POINT:
        raise err(gname, "arc centre coincides with the start point", "a non-zero radius from I/J/K")
    if chord <= SAME_POINT:
        end_l = list(end)
        end_l[i1], end_l[i2] = start[i1], start[i2]
        end = tuple(end_l)  # type: ignore[assignment]
        st.machine[i1], st.machine[i2] = start[i1], start[i2]
    r2 = math.hypot(end[i1] - c[i1], end[i2] - c[i2])
    if abs(r2 - r1) > ARC_RADIUS_TOLERANCE:
        raise err(gname, f"end point is {_fmt(r2 * u)} {unit_name} from the centre but the start is "
                  f"{_fmt(r1 * u)} {unit_name} (difference {_fmt(abs(r2 - r1) * u)} {unit_name})",
                  f"start and end radii equal within {_fmt(ARC_RADIUS_TOLERANCE * u)} {unit_name}")
    out.append(Arc(line, start, end, tuple(c), st.plane, clockwise, st.feed, st.feed_line))  # type: ignore[arg-type]
