"""Modal interpreter of the FANUC milling dialect → typed blocks.

Supported: G0 G1 G2 G3 (arcs by R, negative R for > 180 deg, or by I/J/K incl.
full circles), G4 (dwell), G9 (exact stop, one block), G17/G18/G19, G20/G21,
G28/G30 (1st/2nd-4th reference position return), G40/G41/G42 with D (cutter radius
compensation with a zero radius only, see below), G43/G44/G49 with H, G53
(machine coordinates), G54-G59, G54.1 P1-P48 (also written G54 Pn), G10
L2/L20/L10-L13 (programmable data input), G5.1 Q0/Q1, G8 P0/P1, G5
P0/P10000 (look-ahead modes, accepted), G61/G64 (exact stop mode / cutting
mode), canned drilling cycles G73 G81 G82 G83 G85 G86 G89 with G98/G99 and G80 (see
:mod:`.cycles`), G90/G91, G94/G95; M0 M1 M2 M3 M4 M5 M6 M7 M8 M9 M30; subprograms
M98/M99 in the same file (see :mod:`.subprograms`); F S T H D P Q N O L words
(K: arc centre, or repeat count in a canned cycle; L: repeat count of M98);
``( )`` and ``;`` comments, ``%`` lines, block delete ``/``.
Accepted as no-ops, because they cancel features that are never switched on
(CAM posts emit them in safe-start lines): G15 (polar coordinates cancel),
G50 (scaling cancel; a mill: G50 with X/Y/Z/S, the lathe meaning, is an
error), G50.1 (programmable mirror image cancel), G69 (coordinate rotation
cancel), G67 (macro modal call cancel), G13.1 (polar interpolation cancel).
Rejected with a :class:`GCodeError`: the codes switching those features on
(G16, G51, G51.1, G68, G66, G65, G12.1), cutter compensation G41/G42 with a
nonzero radius, tapping cycles G74/G84, G76/G87/G88,
G29, and every other G/M code or address.

Conventions
-----------
* Calculator-type decimal input (FANUC No. 3401#0 DPI = 1): ``X10`` is 10 mm.
* Power-on modes: G0, G17, G21, G40, G49, G54, G64, G80, G90, G94, G98; H0, D0.
* Decimal G codes (``G50.1``, ``G13.1``) are single codes; the lexer reads
  them as one number.
* G28 (FANUC 0i-MF/31i-B, "reference position return"): non-modal, rapid
  traverse, only the named axes move: first to the intermediate point, which
  is programmed like a G0 end point in the current G90/G91 mode (``G28 G91
  Z0`` has its intermediate point at the current position, so Z goes straight
  up to the reference; ``G28 G90 X0 Y0`` goes via work X0 Y0), then to the
  reference position :attr:`InterpreterSettings.reference`, a machine position
  (FANUC No. 1240): neither work offset nor tool length is added to it. After
  G28 Z the tool-length vector is no longer in the Z position (as FANUC
  cancels it at the reference position); G43/G44 stay modal and the next Z
  move applies the offset again. The programmed position of a returned axis
  is reference - work offset (Z: - the tool length still contained, i.e.
  none), so following G90/G91 moves are consistent. G28 without an axis word,
  and G28/G30/G53 in canned-cycle mode are errors. G29 is rejected.
* G30 P2/P3/P4 (2nd/3rd/4th reference position return; P omitted = P2): as
  G28 (intermediate point, only the named axes, rapid), to
  :attr:`InterpreterSettings.reference2`/``3``/``4`` (FANUC No. 1241-1243;
  not set: the 1st reference position). Other P values are errors.
* G53 (machine coordinate positioning): non-modal, rapid traverse whatever
  the G0/G1 mode (FANUC moves G53 at rapid), machine coordinates without work
  offset or tool length (the tool-length vector is left out as after G28).
  FANUC ignores G53 under G91; the twin rejects it (G90 required) so that a
  program cannot silently do something else than it reads.
* G61 (modal) and G9 (one block): the feed block decelerates to rest at its
  end and the next block starts after the in-position check; G64 cancels G61.
  Rapids always end with an exact stop.
* M0 (program stop) and M1 (optional stop): the twin does not wait for an
  operator (and its optional-stop switch is off), so neither adds time, but
  the axes come to rest and are in position (like an exact stop): FANUC does
  not pre-read the block after M00/M01/M02/M30 (buffering is suppressed), so
  the path decelerates to rest there even with the switch off. The spindle
  and coolant keep their state.
* G4: a value with a decimal point is in seconds (``G4 X1.5``, ``G4 P1.5``),
  without it in milliseconds (``G4 P1500`` as FANUC).
* An offset change takes effect on the next move of the axis: the machine
  target of a programmed axis is programmed value + work offset (+ tool length
  on Z); axes not programmed do not move. A work-offset change shifts the
  programmed coordinates of the current position (as FANUC's absolute
  position display); a tool-length change is applied by the next Z move, also
  in G91 (as FANUC).
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
* Additional work coordinate systems (FANUC 0i-MF/31i-B option):
  ``G54.1 P<n>`` and its alternate form ``G54 P<n>``, n = 1..48, select a
  work offset like G54-G59 (modal, group 14); its value is
  ``work_offsets[additional_offset_key(n)]`` (key 1000 + n, zero when
  missing). G54.1 without P, P outside 1..48 or with a decimal point, and
  G54.1 in a block where P means something else (G4, G10, M98, a canned
  cycle) are errors (FANUC takes G54.1 without P as P1; the twin asks for
  it). ``G54 P<n>`` in such a block is plain G54 (P keeps its meaning there).
* External workpiece zero point offset (``work_offsets[EXTERNAL_OFFSET]``,
  key 0, set by ``G10 L2 P0``): added to every work coordinate system
  (G54-G59 and G54.1 Pn), never to G53/G28 machine positions.
* G10 programmable data input (non-modal, no motion; tool offset memory C):
  ``G10 L2 P<p> X Y Z`` sets the work offset G54..G59 (p = 1..6) or the
  external offset (p = 0); ``G10 L20 P<n> X Y Z`` sets G54.1 Pn;
  ``G10 L10/L11 P<n> R`` the geometry/wear of tool length offset Hn and
  ``G10 L12/L13 P<n> R`` the geometry/wear of tool radius offset Dn (the
  offset used is geometry + wear; :attr:`InterpreterSettings.tool_lengths`
  and ``tool_radii`` are the geometry, the wear starts at 0). Under G90 the
  given values are set, under G91 added; axes not given keep their value;
  values in the unit in effect (G20/G21). The change takes effect like the
  other offset changes: a changed active work offset shifts the programmed
  coordinates of the current position, a changed tool length is applied by
  the next Z move, and a D radius made nonzero is an error when G41/G42 uses
  it (also in the G10 block itself if G41/G42 is on with that D). Other L,
  a missing P or data word, P out of range, words of the other form, a
  motion G code in the block and G10 in canned-cycle mode are errors.
* Look-ahead / contour-control modes: ``G5.1 Q1`` / ``G5.1 Q0`` (AI contour
  control, also ``G5.1 Q1 R<level>`` with level 1..10 as Fusion 360 posts
  write it), ``G8 P1`` / ``G8 P0`` (advanced preview control), ``G5 P10000``
  / ``G5 P0`` (high-precision contour control) are accepted alone in their
  block (an N number allowed), as the FANUC manuals ask. They change
  nothing in the simulation: the twin always plans with its own look-ahead
  (``lookahead_blocks``) and the machine file's acc/dec before and after
  interpolation, i.e. as if the mode were on all the time; the separate
  parameter sets a control switches to in AICC/HPCC (the AICC variants of
  No. 1660/1772 etc.) and the machining quality levels R are not modelled.
  Other Q/P values (e.g. nano smoothing ``G5.1 Q3``) and other words in the
  block are errors.
* G95 feed per revolution (G94 returns to feed per minute): F is in mm/rev
  (in/rev under G20) and the path feed of a G95 block is F x the commanded
  spindle speed in effect (S in rev/min / 60). FANUC measures the speed with
  the position coder; the twin's cutting feed already waits for the spindle
  speed arrival, so the commanded S is the steady speed. S above the
  machine's ``spindle_max_speed`` is clamped on the spindle but not in this
  feed. A G95 feed move (or canned cycle) with the spindle stopped (M5, no
  M3/M4 yet) or at S0 is an error naming the line, and so is a feed move
  whose modal F was given in the other feed mode (switching G94/G95 needs a
  new F). Per-line overrides: a spindle override rescales G95 feeds; a feed
  override (m/s) cannot govern a G95 block (:mod:`.overrides`), the writer
  does not rewrite a G95 F word and ``optimize`` refuses G95 cutting lines
  naming the file and line.
* Block delete ``/``: honoured when ``block_delete=True`` (the block is not
  executed), otherwise the block is executed (switch off, the default).
* Input ranges (FANUC IS-B, 8 digits): X Y Z I J K R within +-99999.999 mm
  (G21) or +-9999.9999 in (G20); dwell at most 99999.999 s; T at most
  99999999; a number has at most 32 characters (ASCII digits only). Beyond
  them: :class:`GCodeError` (a 1e400 would otherwise become ``inf``).
* Lines end at LF, CRLF or CR only (form feed, U+2028 etc. stay in the line
  and are rejected as unexpected characters), so line numbers match editors.
* Execution stops at M30/M2 or at a second ``%``; lines after it are not
  read, except the subprograms ``O<n>`` ... ``M99`` written there (indexed
  at the first M98, see :mod:`.subprograms`). End of file without M30/M2
  also ends the program (``ProgramEnd`` with reason ``"end of file"``).
* Subprograms (FANUC 0i-MF/31i-B): ``M98 P1001``, ``M98 P1001 L2`` and
  ``M98 P21001`` (twice) call O1001; other words of the M98 block (a move)
  run first, then the call. M99 returns to the block after the M98 (or runs
  the subprogram again while repeats remain); ``M99 P<seq>`` returns to the
  caller's block N<seq> instead. The modal state is one: a
  subprogram that switches to G91 must switch back itself, and its F, S,
  offsets and canned cycle carry over to the caller. Calls nest at most 10
  levels (31i-B); deeper (e.g. a subprogram calling itself), a missing
  program, M99 in the main program (FANUC: an endless restart), M99 P<seq>
  without that N in the caller or making the program endless, and M98 with
  G4/G28/G30/G53 or a canned-cycle code are errors. Blocks from a subprogram carry the
  subprogram's own source lines; :attr:`Program.segments` gives the order in
  which lines ran.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Mapping, Sequence

from .blocks import (
    PLANE_AXES, Arc, Block, Coolant, Dwell, Linear, Program, ProgramEnd, ProgramStop, Rapid, SpindleSpeed,
    SpindleStop, ToolChange, Vec3,
)
from .cycles import CYCLES, MAX_CYCLE_MOVES, CycleError, CycleMachine, Hole, LevelWord, cycle_levels, expand_hole
from .errors import GCodeError
from .lexer import LexError, Word, lex_line, split_lines
from .subprograms import (
    MAX_CALLED_LINES, MAX_NESTING, Call, Return, Subprogram, find_sequence, index_subprograms, next_program_start,
    main_program_end, read_call, read_return,
)

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
#: A tool radius offset with an absolute value up to this is zero (cutter compensation accepted), m.
RADIUS_ZERO = 1e-9
#: Largest repeat count K of a canned cycle (FANUC: 4 digits).
MAX_REPEAT = 9999
#: Reference position (G28) of the default machine, machine coordinates (m): ``reference_*_mm`` of
#: models/machines/default.toml (assumption, see there).
DEFAULT_REFERENCE: Vec3 = (0.380, 0.225, 0.300)

# G code -> modal group
_G_GROUP: dict[int | float, str] = {
    0: "motion", 1: "motion", 2: "motion", 3: "motion",
    4: "non-modal", 28: "non-modal", 30: "non-modal", 53: "non-modal",
    10: "non-modal",
    9: "exact stop",
    17: "plane", 18: "plane", 19: "plane",
    20: "units", 21: "units",
    40: "cutter compensation", 41: "cutter compensation", 42: "cutter compensation",
    43: "tool length", 44: "tool length", 49: "tool length",
    54: "work offset", 55: "work offset", 56: "work offset", 57: "work offset", 58: "work offset",
    59: "work offset", 54.1: "work offset",
    61: "path mode", 64: "path mode",
    80: "canned cycle", **{c: "canned cycle" for c in CYCLES},
    90: "distance", 91: "distance",
    94: "feed mode", 95: "feed mode",
    # look-ahead / contour-control modes (accepted, see the module docstring)
    5.1: "look-ahead", 8: "look-ahead", 5: "look-ahead",
    98: "return level", 99: "return level",
    # cancel codes of features never switched on: accepted as no-ops
    15: "polar coordinates", 50: "scaling", 50.1: "mirror image", 69: "coordinate rotation",
    67: "macro modal call", 13.1: "polar interpolation",
}
_G_REJECT: dict[int | float, str] = {
    74: "tapping cycle G74 is not supported (needs rigid tapping with the feed per revolution)",
    84: "tapping cycle G84 is not supported (needs rigid tapping with the feed per revolution)",
    76: "fine boring cycle G76 is not supported (needs spindle orientation and a tool shift)",
    87: "back boring cycle G87 is not supported (needs spindle orientation and a tool shift)",
    88: "boring cycle G88 is not supported (needs a manual operation at the hole bottom)",
    16: "polar coordinate command G16 is not supported (only its cancel G15)",
    51: "scaling G51 is not supported (only its cancel G50)",
    51.1: "programmable mirror image G51.1 is not supported (only its cancel G50.1)",
    68: "coordinate rotation G68 is not supported (only its cancel G69)",
    65: "macro call G65 is not supported",
    66: "macro modal call G66 is not supported (only its cancel G67)",
    12.1: "polar coordinate interpolation G12.1 is not supported (only its cancel G13.1)",
    29: "return from the reference position G29 is not supported (program the move back with G0)",
}
_M_GROUP: dict[int, str] = {
    0: "stop", 1: "stop", 2: "end", 30: "end", 3: "spindle", 4: "spindle", 5: "spindle", 6: "tool change",
    7: "coolant", 8: "coolant", 9: "coolant", 98: "subprogram", 99: "subprogram",
}
_SUPPORTED_G = ("G0 G1 G2 G3 G4 G5 G5.1 G8 G9 G10 G13.1 G15 G17 G18 G19 G20 G21 G28 G30 G40 G41 G42 G43 G44 G49 G50 "
                "G50.1 G53 G54-G59 G54.1 G61 G64 G67 G69 G73 G80 G81 G82 G83 G85 G86 G89 G90 G91 G94 G95 G98 G99")
_SUPPORTED_M = "M0 M1 M2 M3 M4 M5 M6 M7 M8 M9 M30 M98 M99"
_LETTERS = set("GMXYZIJKRFSTHDPQNOL")
_AXIS = {"X": 0, "Y": 1, "Z": 2}
_CENTRE = {"I": 0, "J": 1, "K": 2}
_PLANE_OF_G = {17: "XY", 18: "ZX", 19: "YZ"}
#: Key of the external workpiece zero point offset in :attr:`InterpreterSettings.work_offsets` (FANUC "EXT",
#: ``G10 L2 P0``): added to every work coordinate system.
EXTERNAL_OFFSET = 0
#: Number of additional work coordinate systems G54.1 P1..P48 (FANUC 0i-MF/31i-B option).
N_ADDITIONAL_OFFSETS = 48
#: Allowed modes of the look-ahead / contour-control codes: G code -> (address, values).
_LOOK_AHEAD = {5.1: ("Q", (0, 1)), 8: ("P", (0, 1)), 5: ("P", (0, 10000))}
#: G10 L numbers: L -> what it sets.
_G10_L = {2: "work offset G54-G59 (P1-P6) or the external offset (P0)", 20: "additional work offset G54.1 Pn",
          10: "tool length geometry H", 11: "tool length wear H", 12: "tool radius geometry D",
          13: "tool radius wear D"}


def additional_offset_key(n: int) -> int:
    """Key of G54.1 P``n`` in :attr:`InterpreterSettings.work_offsets`: ``1000 + n`` (1001..1048).

    Parameters
    ----------
    n : int
        Number of the additional work coordinate system, 1..48.
    """
    if not 1 <= n <= N_ADDITIONAL_OFFSETS:
        raise ValueError(f"G54.1 P{n}: expected P1..P{N_ADDITIONAL_OFFSETS}")
    return 1000 + n


def _work_name(key: int) -> str:
    """``G54``, ``G54.1 P7`` or ``EXT`` for a work-offset key."""
    if key == EXTERNAL_OFFSET:
        return "EXT"
    return f"G54.1 P{key - 1000}" if key > 1000 else f"G{key}"


@dataclass(frozen=True)
class InterpreterSettings:
    """Machine data the interpreter needs (SI).

    Attributes
    ----------
    initial : Vec3
        Machine position before the program (m).
    work_offsets : Mapping[int, Vec3]
        Work offset → (x, y, z) (m). Keys: 54..59 for G54..G59, :func:`additional_offset_key` ``(n)`` = 1000 + n
        for G54.1 Pn (n = 1..48), :data:`EXTERNAL_OFFSET` = 0 for the external workpiece zero point offset,
        which is added to every work coordinate system. Missing keys are zero. ``G10 L2``/``G10 L20`` in the
        program change a copy (these stay untouched).
    tool_lengths : Sequence[float]
        Tool length offsets (m) for H1..Hn (index 0 is H1). H0 is always zero. They are the geometry values
        of ``G10 L10``; the wear values (``G10 L11``) start at zero.
    tool_radii : Sequence[float]
        Tool radius offsets (m) for D1..Dn (index 0 is D1; FANUC's radius, geometry + wear). D0 is always zero.
        Geometry of ``G10 L12``; the wear (``G10 L13``) starts at zero.
        G41/G42 are accepted only while the active one is zero (see the module docstring).
    block_delete : bool
        Block delete switch: True skips blocks starting with ``/``.
    reference : Vec3
        G28 reference position (m, machine coordinates; FANUC No. 1240). Default: the default machine's.
    reference2, reference3, reference4 : Vec3 or None
        2nd/3rd/4th reference position of G30 P2/P3/P4 (m, machine coordinates; FANUC No. 1241-1243).
        None: the 1st reference position ``reference``.
    cycles : CycleMachine
        Return amount of G73 (No. 5114) and clearance of G83 (No. 5115).
    """

    initial: Vec3 = (0.0, 0.0, 0.0)
    work_offsets: Mapping[int, Vec3] = field(default_factory=dict)
    tool_lengths: Sequence[float] = ()
    tool_radii: Sequence[float] = ()
    block_delete: bool = False
    reference: Vec3 = DEFAULT_REFERENCE
    reference2: Vec3 | None = None
    reference3: Vec3 | None = None
    reference4: Vec3 | None = None
    cycles: CycleMachine = field(default_factory=CycleMachine)

    def reference_position(self, n: int) -> Vec3:
        """The n-th reference position (n = 1..4, m, machine coordinates); an unset 2nd-4th is the 1st."""
        other = {2: self.reference2, 3: self.reference3, 4: self.reference4}.get(n)
        return self.reference if other is None else other


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
        # G10 changes these copies: work offsets by key, tool offsets as (geometry, wear) per number
        self.offsets: dict[int, Vec3] = {int(k): tuple(v)  # type: ignore[misc]
                                         for k, v in settings.work_offsets.items()}
        self.lengths = [[float(v), 0.0] for v in settings.tool_lengths]
        self.radii = [[float(v), 0.0] for v in settings.tool_radii]
        self.per_rev = False  # G95 (True) / G94
        self.feed_per_rev = False  # the modal F was given under G95 (m/rev) rather than G94 (m/s)
        off = self.work_offset()
        self.prog = [self.machine[a] - off[a] for a in range(3)]
        self.exact_stop = False  # G61 (True) / G64
        self.return_initial = True  # G98 (True) / G99
        self.cycle: int | None = None  # active canned cycle, None under G80
        self.cycle_initial = 0.0  # initial level (work Z, m)
        self.cycle_r: LevelWord | None = None  # R word as programmed (G90 level / G91 from the initial level)
        self.cycle_bottom: LevelWord | None = None  # Z word as programmed (G90 level / G91 from the R point)
        self.cycle_q: float | None = None  # peck depth (m)
        self.cycle_dwell = 0.0  # s
        self.comp = 40  # cutter compensation G40/G41/G42
        self.d = 0  # tool radius offset number (modal)
        self.comp_pending: str | None = None  # "start-up"/"cancel" until the next move block

    def sync_prog(self, axes: Sequence[int]) -> None:
        """Programmed position of ``axes`` from the machine position (after a machine-coordinate move)."""
        off = self.work_offset()
        for i in axes:
            self.prog[i] = self.machine[i] - off[i] - (self.applied_tool if i == 2 else 0.0)

    def work_offset(self) -> Vec3:
        """Active work offset + external offset (m)."""
        zero = (0.0, 0.0, 0.0)
        own, ext = self.offsets.get(self.work, zero), self.offsets.get(EXTERNAL_OFFSET, zero)
        return (own[0] + ext[0], own[1] + ext[1], own[2] + ext[2])

    def shift_work(self) -> None:
        """Programmed coordinates of the current position after a work-offset change (as FANUC's display)."""
        off = self.work_offset()
        self.prog = [self.machine[a] - off[a] for a in range(3)]
        self.prog[2] -= self.applied_tool

    def tool_length(self) -> float:
        if self.tool_sign == 0 or self.h == 0:
            return 0.0
        return self.tool_sign * sum(self.lengths[self.h - 1])

    def tool_radius(self) -> float:
        """Radius of the active tool radius offset D (m, geometry + wear; D0 = 0)."""
        return 0.0 if self.d == 0 else sum(self.radii[self.d - 1])


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
    lines = split_lines(text)
    seen_percent = False
    subs: dict[int, Subprogram] | None = None  # indexed at the first M98
    stack: list[_Frame] = []
    segments: list[tuple[int, int]] = []
    seg_blocks: list[int] = []  # blocks of each run of segments
    seg_start = 1
    called_lines = 0
    jumps: set[tuple] = set()  # control states at M99 P<seq> returns (a repeat is an endless loop)
    pc = 0  # 0-based index of the next line

    def done(number: int, end: ProgramEnd) -> Program:
        out.append(end)
        return finished(number)

    def close_run(number: int) -> None:
        segments.append((seg_start, number))
        seg_blocks.append(len(out) - sum(seg_blocks))

    def finished(number: int) -> Program:
        close_run(number)
        return Program(file, tuple(out), tuple(settings.initial), tuple(segments),  # type: ignore[arg-type]
                       tuple(seg_blocks))

    while pc < len(lines):
        number = pc + 1
        raw = lines[pc]
        pc += 1
        try:
            lexed = lex_line(raw)
        except LexError as exc:
            raise GCodeError(file, number, exc.word, exc.expected, exc.problem, raw.strip()) from None
        if lexed.percent:  # never inside a subprogram: its M99 comes first (see index_subprograms)
            if seen_percent or out:
                return done(number, ProgramEnd(number, "%"))
            seen_percent = True
            continue
        if not lexed.words or (lexed.block_delete and settings.block_delete):
            continue
        if stack:
            called_lines += 1
            if called_lines > MAX_CALLED_LINES:
                top = stack[0]
                raise GCodeError(file, top.call_line, f"M98 P{top.sub.number}", f"at most {MAX_CALLED_LINES} "
                                 "lines executed in subprograms (smaller repeat counts L)",
                                 f"the subprogram calls execute more than {MAX_CALLED_LINES} lines",
                                 lines[top.call_line - 1].strip())
        action = _block(st, lexed.words, number, lexed.text, file, out)
        if action is None:
            continue
        if action == _END:
            return finished(number)
        close_run(number)
        if isinstance(action, Call):
            if subs is None:
                subs = index_subprograms(lines, number - 1, file, settings.block_delete)
            sub = _called(action, subs, stack, number, lexed.text, file)
            stack.append(_Frame(sub, number, pc, action.repeats))
            pc = sub.start
        else:  # M99
            if not stack:
                later = next_program_start(lines, number)
                if later is not None:
                    raise GCodeError(file, number, "M99", "the main program first, ending with M30/M2, then its "
                                     "subprograms O<n> ... M99 (as Fusion 360 and Mastercam post them)",
                                     f"M99 before program {lines[later].split()[0]} (line {later + 1}): subprograms "
                                     "written before the main program are not supported (the file runs from its "
                                     "first line)", lexed.text)
                raise GCodeError(file, number, "M99", "M99 only at the end of a subprogram O<n> called by M98, "
                                 "M30 at the end of the main program",
                                 "M99 in the main program (FANUC restarts the program: an endless loop)", lexed.text)
            frame = stack[-1]
            frame.remaining -= 1
            if frame.remaining > 0:
                pc = frame.sub.start
            else:
                stack.pop()
                pc = frame.return_pc
                if isinstance(action, Return) and action.sequence is not None:
                    pc = _return_target(action.sequence, lines, stack, subs, frame, number, lexed.text, file,
                                        settings.block_delete, jumps)
        seg_start = pc + 1
    return done(len(lines), ProgramEnd(len(lines), "end of file"))


@dataclass
class _Frame:
    """An active subprogram call: what runs, where it was called from, and how many runs remain."""

    sub: Subprogram
    call_line: int  # 1-based line of the M98 block
    return_pc: int  # 0-based index of the line after the M98 block
    remaining: int


def _return_target(sequence: int, lines: Sequence[str], stack: list[_Frame], subs: dict[int, Subprogram] | None,
                   frame: _Frame, line: int, text: str, file: str, block_delete: bool, jumps: set[tuple]) -> int:
    """0-based line index M99 P<sequence> returns to: the block N<sequence> of the caller (after ``stack.pop()``).

    Raises a :class:`GCodeError` when the caller has no such block, or when the same return with the same calls
    active happened before (the program has no conditions: it would repeat endlessly).
    """
    word = f"P{sequence}"
    if stack:
        caller = stack[-1].sub
        first, last, name = caller.start, caller.end, f"subprogram O{caller.number}"
    else:
        subs_start = min((s.start for s in (subs or {}).values()), default=len(lines))
        end = main_program_end(lines, frame.call_line - 1, file, block_delete)
        first, last, name = 0, min(subs_start - 1, len(lines) - 1 if end is None else end), "the main program"
    target = find_sequence(lines, first, last, sequence)
    if target is None:
        raise GCodeError(file, line, word, f"a block N{sequence} in {name} (lines {first + 1}-{last + 1}), "
                         "which called this subprogram", f"{name} has no block N{sequence} to return to", text)
    state = (target, tuple((f.sub.number, f.return_pc, f.remaining) for f in stack))
    if state in jumps:
        raise GCodeError(file, line, word, "a return that does not lead back to the same M98 call (an M30 or M2 "
                         "after N{0}, or M99 without P)".format(sequence),
                         f"returning to N{sequence} (line {target + 1}) repeats the program endlessly: the same "
                         f"calls run again from there (FANUC would loop forever)", text)
    jumps.add(state)
    return target


def _called(call: Call, subs: dict[int, Subprogram], stack: list[_Frame], line: int, text: str,
            file: str) -> Subprogram:
    """The subprogram an M98 block calls, or a :class:`GCodeError` (missing program, nesting too deep)."""
    word = f"M98 P{call.number}"
    if call.number not in subs:
        have = ", ".join(f"O{n} (line {s.start + 1})" for n, s in sorted(subs.items())) or "none"
        raise GCodeError(file, line, word, f"one of the subprograms after the main program's M30: {have}",
                         f"subprogram O{call.number} is not in the file", text)
    if len(stack) >= MAX_NESTING:
        active = " -> ".join(f"O{f.sub.number}" for f in stack)
        again = " (recursion: it is already running)" if any(f.sub.number == call.number for f in stack) else ""
        raise GCodeError(file, line, word, f"subprogram calls nested at most {MAX_NESTING} levels deep (FANUC 31i-B)",
                         f"calling O{call.number}{again} would nest {len(stack) + 1} levels ({active})", text)
    return subs[call.number]


def _fmt(value: float) -> str:
    return f"{value:.6g}"


#: What :func:`_block` returns at a program end (M30/M2).
_END = "end"


def _block(st: _State, words: tuple[Word, ...], line: int, text: str, file: str,
           out: list[Block]) -> str | Call | Return | None:
    """Execute one block; return :data:`_END` at M30/M2, a :class:`Call` at M98, a :class:`Return` at M99."""

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
            code = _g_code(w)
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
    if "look-ahead" in gs:
        _look_ahead(gs["look-ahead"], words, err)
        return None
    call: Call | None = None
    ret = Return()
    if "subprogram" in ms:
        code = ms["subprogram"][0]
        if "end" in ms:
            raise err(f"M{ms['end'][0]}", f"M{code} and M{ms['end'][0]} in one block",
                      f"M{code} and the program end M30/M2 in separate blocks")
        if code == 98:
            drill = "canned cycle" in gs and gs["canned cycle"][0] != 80
            if "non-modal" in gs or drill:
                other = (gs.get("non-modal") or gs["canned cycle"])[1]
                raise err("G" + other.text, f"G{other.text} and M98 in one block",
                          "M98 P<n> alone or with a G0-G3 move (the move runs first, then the call)")
            call = read_call(vals.pop("P", None), vals.pop("L", None), err)
        elif gs.get("non-modal", (None,))[0] not in (4, 10, 30):  # there P is the dwell, offset or reference no.
            ret = read_return(vals.pop("P", None), err)
    if "L" in vals and gs.get("non-modal", (None,))[0] != 10:
        raise err("L" + vals["L"].text, "word L outside an M98 block", "L only as the repeat count of M98 P<n> L<k>")
    if "scaling" in gs:
        for a in "XYZIJKPS":
            if a in vals:
                raise err(a + vals[a].text, f"word {a} with G50: on a mill G50 only cancels scaling "
                          "(G50 with X/Z/S is the lathe's coordinate setting or spindle clamp)", "G50 alone")

    # 1. units first: they apply to every number of the block
    if "units" in gs:
        st.scale = INCH if gs["units"][0] == 20 else MM
    unit_name = "in" if st.scale == INCH else "mm"
    # 2. feed (G94/G95 first: the F word of the block is read in the block's feed mode)
    if "feed mode" in gs:
        st.per_rev = gs["feed mode"][0] == 95
    if "F" in vals:
        f = vals["F"].value
        if f <= 0.0:
            raise err("F" + vals["F"].text, f"feed rate F{vals['F'].text} is not positive", "F > 0")
        st.feed = f * st.scale if st.per_rev else f * st.scale / 60.0  # m/rev (G95) or m/s (G94)
        st.feed_per_rev = st.per_rev
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
        plane = _PLANE_OF_G[gs["plane"][0]]
        if plane != st.plane and st.comp != 40:
            raise err("G" + gs["plane"][1].text, f"G{gs['plane'][0]} changes the plane while cutter compensation "
                      f"G{st.comp} is on (FANUC alarm PS0037)", "G40 and its cancel move before changing the plane")
        st.plane = plane
    if "distance" in gs:
        st.absolute = gs["distance"][0] == 90
    if "work offset" in gs:
        new = _work_key(st, gs, vals, call is not None, err)
        if new != st.work:
            st.work = new
            st.shift_work()
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
    _cutter_compensation(st, gs, vals, err, unit_name)
    if "path mode" in gs:
        st.exact_stop = gs["path mode"][0] == 61
    if "return level" in gs:
        st.return_initial = gs["return level"][0] == 98
    # 8. dwell, reference return, machine coordinates (non-modal), canned cycles, motion
    non_modal = gs["non-modal"][0] if "non-modal" in gs else None
    cycle = gs["canned cycle"][0] if "canned cycle" in gs else None
    if cycle not in (None, 80) and ("motion" in gs or non_modal is not None):
        other = gs["motion"][1] if "motion" in gs else gs["non-modal"][1]
        raise err("G" + other.text, f"G{other.text} and the canned cycle G{cycle} in one block",
                  "a canned cycle block without G0-G3, G4, G28, G30 or G53 (G80 or G0-G3 cancel the cycle)")
    if non_modal == 4:
        if "motion" in gs:
            raise err(f"G{gs['motion'][0]}", "G4 and a motion G code in one block", "G4 alone in its block")
        for a in ("Y", "Z", "I", "J", "K", "R", "Q"):
            if a in vals:
                raise err(a + vals[a].text, f"word {a} in a G4 dwell block", "G4 X<time> or G4 P<time>")
        if ("X" in vals) == ("P" in vals):
            raise err("G4", "G4 needs exactly one of X or P", "G4 X1.5 (s), G4 P1500 (ms)")
        out.append(Dwell(line, _dwell_seconds(vals.get("X") or vals["P"], err)))
    else:
        limit = MAX_COORDINATE[unit_name]
        for a in "XYZIJKRQ":
            if a in vals and abs(vals[a].value) > limit:
                raise err(a + vals[a].text, f"{a}{vals[a].text} is beyond the input range of {limit} {unit_name}",
                          f"|{a}| <= {limit} {unit_name}")
        if "motion" in gs:
            st.motion = gs["motion"][0]
            st.cycle = None  # a group 01 code cancels the canned cycle
        if cycle == 80:
            st.cycle = None
        if non_modal == 10:
            if st.cycle is not None:
                raise err("G10", f"G10 in canned-cycle mode G{st.cycle}", "G80 (or G0) before G10")
            _program_data(st, gs, vals, err)
        elif non_modal is not None:
            if st.cycle is not None:
                raise err(f"G{non_modal}", f"G{non_modal} in canned-cycle mode G{st.cycle}",
                          f"G80 (or G0) before G{non_modal}")
            st.comp_pending = None  # a rapid move: start-up/cancel done
            _machine_move(st, non_modal, vals, line, err, out)
        elif st.cycle is not None or cycle not in (None, 80):
            if any(a in vals for a in "XYZR"):
                st.comp_pending = None  # positioning at rapid: start-up/cancel done
            _canned_cycle(st, vals, cycle, line, err, out)
        else:
            for a in "PQ":
                if a in vals:
                    raise err(a + vals[a].text, f"word {a} outside a G4 dwell or canned-cycle block",
                              "P only with G4 or a canned cycle, Q only with a canned cycle")
            _check_compensation_move(st, vals, gs, err)
            _motion(st, vals, "exact stop" in gs, line, err, unit_name, out)
    # 9. program stop (after the motion of the block, as FANUC); no operator wait, but the path stops
    if "stop" in ms:
        out.append(ProgramStop(line, f"M{ms['stop'][0]}"))
    # 10. end
    if "end" in ms:
        out.append(ProgramEnd(line, f"M{ms['end'][0]}"))
        return _END
    # 11. subprogram call / return, after the motion of the block (FANUC)
    if call is not None:
        return call
    if "subprogram" in ms:
        return ret
    return None


def _cutter_compensation(st: _State, gs: dict[str, tuple[int, Word]], vals: dict[str, Word], err,
                         unit_name: str) -> None:
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
        raise err(word, f"cutter radius compensation with a nonzero radius (D{st.d} = {_fmt(radius * u)} {unit_name}) "
                  f"is not simulated",
                  "the tool-centre path posted by the CAM system ('wear' or 'computer' compensation) with D = 0, "
                  f"i.e. a tool radius offset of at most {_fmt(RADIUS_ZERO * 1e3)} mm")


def _check_compensation_move(st: _State, vals: dict[str, Word], gs: dict[str, tuple[int, Word]], err) -> None:
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


def _look_ahead(entry: tuple[int | float, Word], words: tuple[Word, ...], err) -> None:
    """Check a look-ahead / contour-control block: G5.1 Q0/Q1 (AI contour control, optional R level 1..10 with
    Q1), G8 P0/P1 (advanced preview control), G5 P0/P10000 (high-precision contour control), alone in the
    block (N allowed). They change nothing in the twin's plan (see the module docstring)."""
    code, gw = entry
    letter, allowed = _LOOK_AHEAD[code]
    gname = "G" + gw.text
    forms = ", ".join(f"G{code} {letter}{v}" for v in allowed)
    mode = None
    for w in words:
        if w is gw or w.letter == "N":
            continue
        if w.letter == letter and mode is None:
            if w.value not in allowed:
                raise err(letter + w.text, f"{gname} {letter}{w.text} is not a supported mode", forms)
            mode = int(w.value)
            continue
        if code == 5.1 and w.letter == "R" and mode == 1:
            if w.has_point or not 1 <= w.value <= 10:
                raise err("R" + w.text, f"{gname} Q1 R{w.text}: the level is not an integer in 1..10",
                          "G5.1 Q1 R1 .. R10 (machining quality level) or G5.1 Q1")
            continue
        word = (w.letter + w.text) if w.letter != "G" else "G" + w.text
        raise err(word, f"{word} in the {gname} block (FANUC: {gname} is specified alone in its block)",
                  f"{forms} alone in a block (an N number allowed)")
    if mode is None:
        raise err(gname, f"{gname} without {letter}", forms)


def _work_key(st: _State, gs: dict[str, tuple[int, Word]], vals: dict[str, Word], m98: bool, err) -> int:
    """Work-offset key selected by the block's G54-G59 / G54.1 Pn / G54 Pn (pops the P word it uses).

    ``G54 P<n>`` is the alternate form of ``G54.1 P<n>`` unless P belongs to G4, G10, M98 or a canned cycle in
    the block; G54.1 needs its P and may not share the block with them.
    """
    code, gw = gs["work offset"]
    other = None
    drill = "canned cycle" in gs and gs["canned cycle"][0] != 80
    cancel = "motion" in gs or gs.get("canned cycle", (None,))[0] == 80
    if "non-modal" in gs:
        other = "G" + gs["non-modal"][1].text
    elif m98:
        other = "M98"
    elif drill:
        other = "G" + gs["canned cycle"][1].text
    elif st.cycle is not None and not cancel:
        other = f"canned-cycle mode G{st.cycle}"
    if code == 54.1:
        if other is not None:
            raise err("G" + gw.text, f"G54.1 and {other} in one block (the P word would have two meanings)",
                      "G54.1 P<n> in a block without G4, G10, M98 or a canned cycle")
        if "P" not in vals:
            raise err("G" + gw.text, "G54.1 without P (the number of the additional work coordinate system)",
                      f"G54.1 P1 .. G54.1 P{N_ADDITIONAL_OFFSETS}")
    elif code != 54 or "P" not in vals or other is not None:
        return int(code)
    p = vals.pop("P")
    if p.has_point or not 1 <= p.value <= N_ADDITIONAL_OFFSETS:
        raise err("P" + p.text, f"additional work coordinate system P{p.text} does not exist",
                  f"P1..P{N_ADDITIONAL_OFFSETS} (integers) with G{gw.text}")
    return additional_offset_key(int(p.value))


def _program_data(st: _State, gs: dict[str, tuple[int, Word]], vals: dict[str, Word], err) -> None:
    """G10 programmable data input: L2/L20 work offsets, L10-L13 tool offsets (memory C); see the module
    docstring. G90 sets the values, G91 adds them."""
    if "motion" in gs:
        raise err("G" + gs["motion"][1].text, "G10 and a motion G code in one block",
                  "G10 with L, P and its data words only")
    forms = "G10 L2 P0-P6 X Y Z, G10 L20 P1-P48 X Y Z, G10 L10/L11/L12/L13 P<n> R"
    if "L" not in vals:
        raise err("G10", "G10 without L (which data to set)", forms)
    lw = vals["L"]
    if lw.has_point or lw.value not in _G10_L:
        raise err("L" + lw.text, f"G10 L{lw.text} is not supported", forms)
    ell = int(lw.value)
    if "P" not in vals:
        raise err(f"L{lw.text}", f"G10 L{ell} without P (the number of the {_G10_L[ell]})", forms)
    pw = vals["P"]
    work = ell in (2, 20)
    data = "XYZ" if work else "R"
    for a in "XYZIJKRQ":
        if a in vals and a not in data:
            raise err(a + vals[a].text, f"word {a} in a G10 L{ell} block", f"G10 L{ell} P<n> with {' '.join(data)}")
    given = [a for a in data if a in vals]
    if not given:
        raise err(f"L{lw.text}", f"G10 L{ell} without data", f"G10 L{ell} P<n> with {' or '.join(data)}")
    if ell == 2:
        top, first = 6, 0
    elif ell == 20:
        top, first = N_ADDITIONAL_OFFSETS, 1
    else:
        top, first = len(st.lengths if ell in (10, 11) else st.radii), 1
    if pw.has_point or not first <= pw.value <= top:
        raise err("P" + pw.text, f"G10 L{ell} P{pw.text}: {_G10_L[ell]} number P{pw.text} does not exist",
                  f"P{first}..P{top} (integers)")
    p = int(pw.value)
    if work:
        key = additional_offset_key(p) if ell == 20 else (EXTERNAL_OFFSET if p == 0 else 53 + p)
        xyz = list(st.offsets.get(key, (0.0, 0.0, 0.0)))
        for a in given:
            v = vals[a].value * st.scale
            xyz[_AXIS[a]] = v if st.absolute else xyz[_AXIS[a]] + v
        st.offsets[key] = tuple(xyz)  # type: ignore[assignment]
        if key in (st.work, EXTERNAL_OFFSET):
            st.shift_work()
        return
    table = st.lengths if ell in (10, 11) else st.radii
    part = 0 if ell in (10, 12) else 1  # geometry, wear
    v = vals["R"].value * st.scale
    table[p - 1][part] = v if st.absolute else table[p - 1][part] + v
    if ell in (12, 13) and st.comp != 40 and st.d == p and not abs(st.tool_radius()) <= RADIUS_ZERO:
        raise err("R" + vals["R"].text, f"G10 L{ell} gives the active D{p} a nonzero radius while cutter "
                  f"compensation G{st.comp} is on (the offset path is not simulated)",
                  "tool radius offsets that stay 0 while G41/G42 is on")


def _block_feed(st: _State, err, word: str, what: str) -> tuple[float, float]:
    """Path feed (m/s) of a feed block and its feed per revolution (m/rev; 0.0 under G94).

    G95: the feed is F (m/rev) x the commanded spindle speed in effect (rev/s); the cutting feed already waits
    for the spindle speed arrival, so the commanded S is the steady speed FANUC's position coder measures.
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


def _g_code(w: Word) -> int | float | None:
    """The code of a G word: an int (``G01``, ``G1.``), a one-decimal float (``G50.1``), else None."""
    if w.value < 0:
        return None
    if w.value == int(w.value):
        return int(w.value)
    tenths = round(w.value * 10.0)
    if abs(w.value * 10.0 - tenths) < 1e-9:
        return tenths / 10.0
    return None


def _dwell_seconds(w: Word, err) -> float:
    """Dwell of a P or X word (s): with a decimal point in s, without in ms (as FANUC G4 P)."""
    seconds = w.value if w.has_point else w.value * 1e-3
    if seconds < 0:
        raise err(w.letter + w.text, "negative dwell time", "a time >= 0")
    if seconds > MAX_DWELL:
        raise err(w.letter + w.text, f"dwell of {_fmt(seconds)} s is beyond the input range",
                  f"a dwell of at most {MAX_DWELL} s")
    return seconds


def _integer_code(w: Word) -> int | None:
    """The code number of a G/M word if it is a non-negative integer (``G01``, ``G1.``), else None."""
    if w.value < 0 or w.value != int(w.value):
        return None
    return int(w.value)


def _motion(st: _State, vals: dict[str, Word], g9: bool, line: int, err, unit_name: str,
            out: list[Block]) -> None:
    """G0-G3 of a block; ``g9``: one-shot exact stop in this block."""
    exact = g9 or st.exact_stop
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
    feed, per_rev = _block_feed(st, err, f"G{st.motion}", f"G{st.motion} feed move")
    if st.motion == 1:
        out.append(Linear(line, start, end, feed, st.feed_line, exact, per_rev))
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
        out.append(Arc(line, start, end, tuple(c), st.plane, clockwise, feed, st.feed_line,  # type: ignore[arg-type]
                       exact_stop=exact, feed_per_rev=per_rev))
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
    out.append(Arc(line, start, end, tuple(c), st.plane, clockwise, feed, st.feed_line,  # type: ignore[arg-type]
                   exact_stop=exact, feed_per_rev=per_rev))


def _machine_move(st: _State, code: int, vals: dict[str, Word], line: int, err, out: list[Block]) -> None:
    """G28/G30 (reference position return via the intermediate point) or G53 (machine coordinates); see the
    module docstring for the FANUC behaviour followed."""
    gname = f"G{code}"
    for a in ("IJKRQ" if code == 30 else "IJKRPQ"):
        if a in vals:
            raise err(a + vals[a].text, f"word {a} in a {gname} block",
                      "G30 with P2/P3/P4 and X, Y, Z words only" if code == 30 else f"{gname} with X, Y, Z words only")
    number = _reference_number(vals.get("P"), err) if code == 30 else 1
    axes = [_AXIS[a] for a in "XYZ" if a in vals]
    if not axes:
        raise err(gname, f"{gname} without an axis word",
                  "the axes to move named by X/Y/Z, e.g. G28 G91 Z0. or G90 G53 Z0.")
    start: Vec3 = tuple(st.machine)  # type: ignore[assignment]
    scale = st.scale
    if code == 53:
        if not st.absolute:
            raise err("G53", "G53 in incremental mode G91 (FANUC ignores it there)", "G90 with G53")
        for i in axes:
            st.machine[i] = vals["XYZ"[i]].value * scale
        if 2 in axes:
            st.applied_tool = 0.0
        st.sync_prog(axes)
        out.append(Rapid(line, start, tuple(st.machine)))  # type: ignore[arg-type]
        return
    off = st.work_offset()
    tool = st.tool_length()
    for i in axes:  # intermediate point: as a G0 end point in the current G90/G91 mode
        v = vals["XYZ"[i]].value * scale
        st.prog[i] = v if st.absolute else st.prog[i] + v
        st.machine[i] = st.prog[i] + off[i] + (tool if i == 2 else 0.0)
    if 2 in axes:
        st.applied_tool = tool
    mid: Vec3 = tuple(st.machine)  # type: ignore[assignment]
    if max(abs(mid[i] - start[i]) for i in range(3)) > SAME_POINT:
        out.append(Rapid(line, start, mid))
    ref = st.settings.reference_position(number)
    for i in axes:
        st.machine[i] = ref[i]
    if 2 in axes:
        st.applied_tool = 0.0  # the reference position is a machine position: no tool length in it
    st.sync_prog(axes)
    out.append(Rapid(line, mid, tuple(st.machine)))  # type: ignore[arg-type]


def _reference_number(p: Word | None, err) -> int:
    """Which reference position G30 returns to: P2, P3 or P4 (omitted: 2)."""
    if p is None:
        return 2
    if p.has_point or p.value not in (2.0, 3.0, 4.0):
        raise err("P" + p.text, f"G30 P{p.text} is not a reference position number",
                  "G30 P2, P3 or P4 (2nd/3rd/4th reference position; P omitted = P2)")
    return int(p.value)


def _canned_cycle(st: _State, vals: dict[str, Word], code: int | None, line: int, err, out: list[Block]) -> None:
    """A block in canned-cycle mode: store the drilling data and drill the hole(s) (see :mod:`.cycles`).

    FANUC semantics: the initial level is the Z position when the cycle mode starts; R (G91: from the initial
    level) and Z (G91: from the R point) stay modal as programmed and the levels are derived per hole
    (:func:`.cycles.cycle_levels`); Q, P are modal; K (repeat count, not modal) repeats the hole, moving by the
    X/Y increments each time under G91; a hole is drilled when the block holds X, Y, Z or R; K0 stores the
    data only.
    """
    if code is not None:
        if st.cycle is None:
            st.cycle_initial = st.prog[2]
        st.cycle = code
    gname = f"G{st.cycle}"
    for a in "IJ":
        if a in vals:
            raise err(a + vals[a].text, f"word {a} in canned cycle {gname}", "X Y Z R Q P K F words in a cycle block")
    scale = st.scale
    if "R" in vals:
        st.cycle_r = LevelWord(vals["R"].value * scale, not st.absolute)
    if "Z" in vals:
        st.cycle_bottom = LevelWord(vals["Z"].value * scale, not st.absolute)
    if "Q" in vals:
        q = vals["Q"]
        if q.value <= 0.0:
            raise err("Q" + q.text, f"peck depth Q{q.text} is not positive", "Q > 0 (depth of each peck)")
        st.cycle_q = q.value * scale
    if "P" in vals:
        st.cycle_dwell = _dwell_seconds(vals["P"], err)
    repeat = 1
    if "K" in vals:
        k = vals["K"]
        if k.has_point or k.value < 0 or k.value > MAX_REPEAT:
            raise err("K" + k.text, f"repeat count K{k.text} is not an integer in 0..{MAX_REPEAT}",
                      "K0 (store the data only), K1 (default), ... K9999")
        repeat = int(k.value)
    if repeat == 0 or not any(a in vals for a in "XYZR"):
        return
    if st.cycle_r is None:
        raise err(gname, f"canned cycle {gname} without an R point", "an R word on this or an earlier cycle block")
    if st.cycle_bottom is None:
        raise err(gname, f"canned cycle {gname} without a hole bottom Z", "a Z word on this or an earlier cycle block")
    u = 1.0 / scale
    unit_name = "in" if scale == INCH else "mm"
    r_level, bottom = cycle_levels(st.cycle_initial, st.cycle_r, st.cycle_bottom)
    if bottom >= r_level - SAME_POINT:
        word = "Z" + vals["Z"].text if "Z" in vals else ("R" + vals["R"].text if "R" in vals else gname)
        raise err(word, f"hole bottom Z {_fmt(bottom * u)} {unit_name} is not below the R point "
                  f"{_fmt(r_level * u)} {unit_name}", "Z below R (the cycles drill towards -Z; under G91 "
                  "R counts from the initial level and Z from the R point)")
    assert st.cycle is not None
    if st.cycle in (73, 83) and st.cycle_q is None:
        raise err(gname, f"{gname} without a peck depth Q", "Q > 0 on this or an earlier cycle block")
    feed, per_rev = _block_feed(st, err, gname, f"canned cycle {gname}")
    pecks = 1 if st.cycle not in (73, 83) else math.ceil((r_level - bottom) / st.cycle_q - 1e-9)
    moves = repeat * (3 * pecks + 4)
    if moves > MAX_CYCLE_MOVES:
        raise err("Q" + vals["Q"].text if "Q" in vals else gname,
                  f"the cycle would expand to {moves} moves ({repeat} holes x {pecks} pecks)",
                  f"at most {MAX_CYCLE_MOVES} moves per block (a larger Q or a smaller K)")
    off = st.work_offset()
    tool = st.tool_length()
    z_off = off[2] + tool
    levels = (st.cycle_initial + z_off, r_level + z_off, bottom + z_off)
    for _ in range(repeat):
        for a in "XY":
            if a in vals:
                i = _AXIS[a]
                v = vals[a].value * scale
                st.prog[i] = v if st.absolute else st.prog[i] + v
        hole = Hole(code=st.cycle, line=line, x=st.prog[0] + off[0], y=st.prog[1] + off[1], initial=levels[0],
                    r_level=levels[1], bottom=levels[2], return_to_initial=st.return_initial, feed=feed,
                    feed_line=st.feed_line, peck=st.cycle_q, dwell=st.cycle_dwell,
                    spindle=(st.speed, st.direction, st.speed_line))
        try:
            blocks, end = expand_hole(hole, tuple(st.machine), st.settings.cycles)  # type: ignore[arg-type]
        except CycleError as exc:
            raise err(exc.word, exc.problem, exc.expected) from None
        if per_rev:  # G95: the feed blocks keep their feed per revolution (spindle overrides rescale them)
            blocks = [replace(b, feed_per_rev=per_rev) if isinstance(b, Linear) else b for b in blocks]
        out.extend(blocks)
        st.machine = list(end)
        st.applied_tool = tool
        st.prog[2] = st.cycle_initial if st.return_initial else r_level
