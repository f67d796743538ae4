"""Modal interpreter of the FANUC milling dialect → typed blocks: the driver of the program and of one block.

Supported: G0 G1 G2 G3 (arcs by R, negative R for > 180 deg, or by I/J/K incl.
full circles), G4 (dwell), G9 (exact stop, one block), G17/G18/G19, G20/G21,
G28/G30 (1st/2nd-4th reference position return), G40/G41/G42 with D (cutter radius
compensation, see :mod:`.compensation` and :mod:`.radius_offset`), G43/G44/G49 with H, G53
(machine coordinates), G52 (local coordinate system), G92/G92.1/G92.2/G92.3 (workpiece coordinate
system setting), G54-G59, G54.1 P1-P48 (also written G54 Pn), Haas G154 P1-P99 and G110-G129, G10
L2/L20/L10-L13 (programmable data input), G5.1 Q0/Q1, G8 P0/P1, G5
P0/P10000 and Haas G187 (look-ahead and accuracy modes, accepted), Haas G103 P0-P15 (look-ahead limit),
G61/G64 (exact stop mode / cutting
mode; LinuxCNC G64 P Q, see :mod:`.path_blending`), canned cycles G73 G74 G76 G81-G87 G89
with G98/G99 and G80 (see :mod:`.cycles`; tapping and M29: :mod:`.tapping`), G90/G91,
G90.1/G91.1 (arc centre I/J/K absolute/incremental), G94/G95, G51.1/G50.1 (programmable mirror image),
G51/G50 (scaling), G68/G69 (coordinate rotation), G16/G15 (polar coordinates); M0 M1 M2 M3 M4 M5 M6 M7 M8 M9
M19 M29 M30 and the machine builder's M codes of the machine file (:mod:`.m_aliases`); subprograms
M98/M99 in the same file and Haas M97 local subprograms (see :mod:`.subprograms`); Custom Macro B variables, IF/WHILE/GOTO and
G65 calls (see :mod:`.macro`); F S T H D P Q N O L words
(K: arc centre, or repeat count in a canned cycle; L: repeat count of M98);
``,C``/``,R`` optional chamfer and corner R between G1 blocks; ``( )`` and ``;`` comments, ``%`` lines,
block delete ``/``.
Accepted as no-ops and rejected codes: :mod:`.codes`.

Conventions (each topic in the module that implements it)
---------------------------------------------------------
* Decimal input, program units, the machine data: :mod:`.settings`.
* Power-on modes, when an offset change takes effect: :mod:`.modal`.
* Decimal G codes, modal groups, no-op and rejected codes: :mod:`.codes`.
* Comments, ``%``, block delete marks, line endings: :mod:`.lexer`.
* Input ranges of the numbers: :mod:`.input_ranges`; G4 dwell: :mod:`.dwell`.
* G94/G95 feed (feed per revolution): :mod:`.feed`.
* S, T, M3-M9 (spindle, tool, coolant): :mod:`.auxiliary_functions`.
* G54-G59, G54.1 Pn, Haas G154 Pn and G110-G129, the external offset, G10 data input: :mod:`.offsets`.
* G43/G44/G49 tool length, G40/G41/G42 cutter radius compensation: :mod:`.compensation`.
* G5.1/G8/G5 look-ahead mode codes and Haas G187 accuracy control: :mod:`.lookahead_codes`; Haas G103 block
  buffering limit: :mod:`.block_buffering`.
* G0-G3 motion, G61/G9 exact stop: :mod:`.motion`.
* G28/G30 reference position return, G53 machine coordinates: :mod:`.machine_moves`.
* G52 local coordinate system, G92/G92.1/G92.2/G92.3 workpiece coordinate system setting:
  :mod:`.coordinate_shifts`.
* ``,C``/``,R`` optional chamfer and corner R: :mod:`.corners`.
* G51.1/G50.1 mirror, G51/G50 scaling, G68/G69 rotation (order, centres, what they apply to):
  :mod:`.transforms`; G16/G15 polar coordinates: :mod:`.polar`.
* Canned cycles: the modal data :mod:`.cycle_mode`, the moves of a hole :mod:`.cycles`.
* M98/M99 subprograms: run time :mod:`.call_stack`, the file's programs :mod:`.subprograms`.
* Custom Macro B (variables, expressions, IF/WHILE/GOTO, G65 calls): :mod:`.macro`.

Kept here, as the driver implements them:

* M0 (program stop) and M1 (optional stop): the twin does not wait for an
  operator (and its optional-stop switch is off), so neither adds time, but
  the axes come to rest and are in position (like an exact stop): FANUC does
  not pre-read the block after M00/M01/M02/M30 (buffering is suppressed), so
  the path decelerates to rest there even with the switch off. The spindle
  and coolant keep their state.
* Block delete ``/``: honoured when ``block_delete=True`` (the block is not
  executed), otherwise the block is executed (switch off, the default).
* Execution stops at M30/M2 or at a second ``%``; lines after it are not
  read, except the subprograms ``O<n>`` ... ``M99`` written there (indexed
  at the first M98, see :mod:`.subprograms`). End of file without M30/M2
  also ends the program (``ProgramEnd`` with reason ``"end of file"``).
* Order of the words of one block: units, feed, spindle speed and tool, tool change, spindle, coolant, the
  modes (plane, distance, work offset, tool length, cutter compensation, path mode, return level), then the
  dwell, machine-position move, canned cycle or motion, then M0/M1, M30/M2 and last the M98/M99 call or return.
"""
from __future__ import annotations

from .auxiliary_functions import auxiliary_blocks, read_speed_and_tool
from .block_buffering import block_buffering
from .blocks import Block, Program, ProgramEnd, ProgramStop
from .call_stack import Frame, called_subprogram, return_target, subprogram_words
from .codes import check_sequence_words, check_stray_words, group_words
from .compensation import RADIUS_ZERO, check_compensation_move, cutter_compensation, tool_length_words
from .coordinate_shifts import SHIFT_CODES, coordinate_shift
from .corners import check_no_open_corner, close_corner, corner_word, open_corner
from .cycle_mode import canned_cycle_block
from .decimal_input import decimal_input_words
from .dwell import dwell_block
from .errors import GCodeError
from .feed import read_feed_words
from .input_ranges import check_coordinates
from .lexer import LexedLine, LexError, Word, lex_line, split_lines, without_dos_eof
from .lookahead_codes import check_accuracy_control, check_look_ahead
from .macro.calls import MacroCall
from .macro.runtime import Jump, MacroRuntime
from .machine_moves import machine_move
from .modal import ModalState
from .motion import programmed_move
from .offsets import program_data, select_work_offset
from .radius_offset import RadiusOffset
from .path_blending import blending_tolerance_words
from .settings import (
    DEFAULT_REFERENCE, EXTERNAL_OFFSET, INCH, MM, RPM, InterpreterSettings, additional_offset_key,
)
from .subprograms import MAX_CALLED_LINES, Call, Return, Subprogram, index_subprograms, next_program_start
from .tapping import end_cycle_mode, rigid_tapping_word
from .transforms import check_plane_change, check_transform_block, transform_modes

# re-exported for importers of the former single-module interpreter (their homes: settings, compensation)
__all__ = [
    "DEFAULT_REFERENCE", "EXTERNAL_OFFSET", "INCH", "MM", "RADIUS_ZERO", "RPM", "InterpreterSettings",
    "additional_offset_key", "interpret",
]
#: Plane of G17/G18/G19.
_PLANE_OF_G = {17: "XY", 18: "ZX", 19: "YZ"}


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
    st = ModalState(settings)
    radius = RadiusOffset(file)  # cutter radius compensation: the tool-centre path, after the program
    out: list[Block] = []
    lines = split_lines(without_dos_eof(text))
    seen_percent = False
    subs: dict[int, Subprogram] | None = None  # indexed at the first M98
    stack: list[Frame] = []
    segments: list[tuple[int, int]] = []
    seg_blocks: list[int] = []  # blocks of each run of segments
    seg_start = 1
    called_lines = 0
    macro = MacroRuntime(lines, file, settings.block_delete, st)  # Custom Macro B: variables, jumps, G65
    pc = 0  # 0-based index of the next line

    def done(number: int, end: ProgramEnd) -> Program:
        out.append(end)
        return finished(number)

    run_total = 0  # blocks of the closed runs (a running sum: macro loops close millions of runs)
    macro_lines = 0  # macro lines run (a subprogram pass without one repeats exactly)

    def too_many_called_lines(projection: str) -> GCodeError:
        top = stack[0]
        return GCodeError(file, top.call_line, f"M98 P{top.sub.number}", f"at most {MAX_CALLED_LINES} lines "
                          "executed in subprograms (smaller repeat counts L)",
                          f"the subprogram calls execute more than {MAX_CALLED_LINES} lines{projection}",
                          lines[top.call_line - 1].strip())

    def close_run(number: int) -> None:
        nonlocal run_total
        segments.append((seg_start, number))
        seg_blocks.append(len(out) - run_total)
        run_total = len(out)

    def finished(number: int) -> Program:
        check_no_open_corner(st, file)
        close_run(number)
        blocks, runs = radius.apply(out, seg_blocks)
        return Program(file, tuple(blocks), tuple(settings.initial), tuple(segments),  # type: ignore[arg-type]
                       tuple(runs))

    while pc < len(lines):
        number = pc + 1
        raw = lines[pc]
        pc += 1
        statement = macro.parse(number)  # a Custom Macro B line, or None for a plain line (see .macro)
        try:
            lexed = lex_line(raw) if statement is None else statement.static
        except LexError as exc:
            raise GCodeError(file, number, exc.word, exc.expected, exc.problem, raw.strip()) from None
        if lexed.percent:  # never inside a subprogram: its M99 comes first (see index_subprograms)
            if seen_percent or out:
                return done(number, ProgramEnd(number, "%"))
            seen_percent = True
            continue
        if (not lexed.words and statement is None) or (lexed.block_delete and settings.block_delete):
            continue
        if stack:
            called_lines += 1
            if called_lines > MAX_CALLED_LINES:
                raise too_many_called_lines("")
        if statement is not None:
            macro_lines += 1
        macro.count(number)
        step = macro.execute(number, statement, lexed, stack)
        if not isinstance(step, LexedLine):  # a macro statement ran: nothing, a jump or a G65 call
            if isinstance(step, Jump):
                close_run(number)
                pc = step.target
                seg_start = pc + 1
            elif isinstance(step, MacroCall):
                if subs is None:
                    subs = index_subprograms(lines, number - 1, file, settings.block_delete)
                sub = called_subprogram(Call(step.number, step.repeats), subs, stack, number, lexed.text, file, "G65")
                macro.enter(step, stack, number)
                close_run(number)
                stack.append(Frame(sub, number, pc, step.repeats, step, (called_lines, macro_lines)))
                pc = sub.start
                seg_start = pc + 1
            continue
        lexed = step
        first = len(out)
        action = _block(st, lexed.words, number, lexed.text, file, out)
        radius.record(st, number, lexed.text, first)
        if action is None:
            continue
        if action == _END:
            return finished(number)
        close_run(number)
        if isinstance(action, Call):
            if subs is None:
                subs = index_subprograms(lines, number - 1, file, settings.block_delete)
            sub = called_subprogram(action, subs, stack, number, lexed.text, file, lines=lines,
                                    block_delete=settings.block_delete)  # lines: M97's block N<n>
            stack.append(Frame(sub, number, pc, action.repeats, pass_start=(called_lines, macro_lines)))
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
                lines_before, macro_before = frame.pass_start
                per_pass = called_lines - lines_before
                if macro_lines == macro_before and called_lines + per_pass * frame.remaining > MAX_CALLED_LINES:
                    raise too_many_called_lines(
                        f": O{frame.sub.number} (called at line {frame.call_line}) ran {per_pass} lines in a pass "
                        f"without a macro statement, so its {frame.remaining} passes still to come run "
                        f"{per_pass * frame.remaining} more")
                frame.pass_start = (called_lines, macro_lines)
                pc = frame.sub.start
                macro.repeat(frame)
            else:
                stack.pop()
                macro.leave(frame)
                pc = frame.return_pc
                if isinstance(action, Return) and action.sequence is not None:
                    pc = return_target(action.sequence, lines, stack, subs, frame, number, lexed.text, file,
                                       settings.block_delete, macro.return_jumps())
        seg_start = pc + 1
    return done(len(lines), ProgramEnd(len(lines), "end of file"))



#: What :func:`_block` returns at a program end (M30/M2).
_END = "end"


def _block(st: ModalState, words: tuple[Word, ...], line: int, text: str, file: str,
           out: list[Block]) -> str | Call | Return | None:
    """Execute one block; return :data:`_END` at M30/M2, a :class:`Call` at M98, a :class:`Return` at M99."""

    def err(word: str, problem: str, expected: str) -> GCodeError:
        return GCodeError(file, line, word, expected, problem, text)

    gs, ms, vals = group_words(words, err, st.settings.m_codes)  # m_codes: the machine builder's M codes
    begin = len(out)  # index of this block's first typed block
    if "look-ahead" in gs or "accuracy control" in gs or "block buffering" in gs:
        if "look-ahead" in gs:
            check_look_ahead(gs["look-ahead"], words, err)
        elif "accuracy control" in gs:
            check_accuracy_control(gs["accuracy control"][1], words, err)  # Haas G187: no effect on the plan
        else:
            block_buffering(st, gs["block buffering"][1], words, err)  # Haas G103: the look-ahead window
        close_corner(st, out, begin, line, text, file)  # no move after a ,C/,R block: error
        return None
    if st.settings.decimal_input == "increment":  # FANUC No. 3401#0 DPI = 0: X10 is 0.010 mm (see .decimal_input)
        inch = gs["units"][0] == 20 if "units" in gs else st.scale == INCH
        vals = decimal_input_words(vals, gs, inch, st.plane, st.xf.polar, st.cycle is not None, st.per_rev, err)
    corner = corner_word(vals, err)  # ,C / ,R: optional chamfer / corner R (see .corners)
    moved = False
    call, ret = subprogram_words(gs, ms, vals, err)
    check_stray_words(gs, vals, err, st.cycle is not None)

    # 1. units first: they apply to every number of the block
    if "units" in gs:
        st.scale = INCH if gs["units"][0] == 20 else MM
    unit_name = "in" if st.scale == INCH else "mm"
    # 2. feed (G94/G95 first: the F word of the block is read in the block's feed mode)
    read_feed_words(st, gs, vals, line, err)
    # 3. spindle speed, tool select
    read_speed_and_tool(st, vals, line, err)
    check_sequence_words(vals, err)
    # 4.-6. tool change, spindle, coolant
    rigid_tapping_word(st, ms, vals, line, err, out)  # M29: spindle stop, then the S word below
    auxiliary_blocks(st, ms, vals, line, err, out)
    # 7. modes
    if "plane" in gs:
        plane = _PLANE_OF_G[gs["plane"][0]]
        check_plane_change(st, plane, gs, err)
        if plane != st.plane and st.comp != 40:
            raise err("G" + gs["plane"][1].text, f"G{gs['plane'][0]} changes the plane while cutter compensation "
                      f"G{st.comp} is on (FANUC alarm PS0037)", "G40 and its cancel move before changing the plane")
        st.plane = plane
    if "distance" in gs:
        st.absolute = gs["distance"][0] == 90
    consumed = transform_modes(st, gs, vals, err)  # G15/G16, G69/G68, G50/G51, G50.1/G51.1 (see .transforms)
    check_transform_block(st, gs, err)
    if "work offset" in gs:
        select_work_offset(st, gs, vals, None if call is None else "M97" if call.local else "M98", err)
    tool_length_words(st, gs, vals, err)
    cutter_compensation(st, gs, vals, err, unit_name)
    if "path mode" in gs:
        st.exact_stop = gs["path mode"][0] == 61
        st.path_code = float(gs["path mode"][0])
        blending_tolerance_words(gs, vals, st.cycle is not None or "canned cycle" in gs or "non-modal" in gs, err)
    if "arc centre" in gs:
        st.arc_centre_absolute = gs["arc centre"][0] == 90.1
    if "return level" in gs:
        st.return_initial = gs["return level"][0] == 98
    # 8. dwell, reference return, machine coordinates (non-modal), canned cycles, motion
    non_modal = gs["non-modal"][0] if "non-modal" in gs else None
    cycle = gs["canned cycle"][0] if "canned cycle" in gs else None
    if cycle not in (None, 80) and ("motion" in gs or non_modal is not None):
        other = gs["motion"][1] if "motion" in gs else gs["non-modal"][1]
        raise err("G" + other.text, f"G{other.text} and the canned cycle G{cycle} in one block",
                  "a canned cycle block without G0-G3, G4, G28, G30 or G53 (G80 or G0-G3 cancel the cycle)")
    if consumed:  # the axis words were the centre / mirror positions of G51.1, G50.1, G51 or G68: no move
        check_coordinates(vals, unit_name, err)
        if cycle == 80:
            end_cycle_mode(st, "G80", err)
    elif non_modal == 4:
        out.append(dwell_block(gs, vals, line, err, st.settings.decimal_input == "calculator"))
    else:
        # in a canned-cycle block K is the repeat count (checked by the cycle), not an arc centre
        cycle_block = cycle not in (None, 80) or (
            st.cycle is not None and cycle is None and "motion" not in gs and non_modal is None)
        check_coordinates(vals, unit_name, err, "XYZIJRQ" if cycle_block else "XYZIJKRQ")
        if "motion" in gs:
            st.motion = gs["motion"][0]
            end_cycle_mode(st, "G" + gs["motion"][1].text, err)  # a group 01 code cancels the canned cycle
        if cycle == 80:
            end_cycle_mode(st, "G80", err)
        if non_modal == 10:
            if st.cycle is not None:
                raise err("G10", f"G10 in canned-cycle mode G{st.cycle}", "G80 (or G0) before G10")
            program_data(st, gs, vals, err)
        elif non_modal in SHIFT_CODES:
            coordinate_shift(st, non_modal, gs, vals, err)
        elif non_modal is not None:
            if st.cycle is not None:
                raise err(f"G{non_modal}", f"G{non_modal} in canned-cycle mode G{st.cycle}",
                          f"G80 (or G0) before G{non_modal}")
            st.comp_pending = None  # a rapid move: start-up/cancel done
            machine_move(st, non_modal, vals, line, err, out)
        elif st.cycle is not None or cycle not in (None, 80):
            if any(a in vals for a in "XYZR"):
                st.comp_pending = None  # positioning at rapid: start-up/cancel done
            canned_cycle_block(st, vals, cycle, line, err, out)
        else:
            for a in "PQ":
                if a in vals:
                    raise err(a + vals[a].text, f"word {a} outside a G4 dwell or canned-cycle block",
                              "P only with G4 or a canned cycle, Q only with a canned cycle")
            check_compensation_move(st, vals, gs, err)
            programmed_move(st, vals, "exact stop" in gs, line, err, unit_name, out)
            moved = True
    # 8b. optional chamfer / corner R: the previous block's corner, then this block's (see .corners)
    close_corner(st, out, begin, line, text, file)
    open_corner(st, corner, moved, ms, out, begin, line, text, err)
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
