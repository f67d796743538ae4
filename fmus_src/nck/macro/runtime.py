"""Running Custom Macro B lines inside the interpreter: statements, jumps, G65 calls and runaway guards.

The interpreter (:func:`..interpreter.interpret`) asks :class:`MacroRuntime` for every line: a plain line is
lexed as before (a G65 in it becomes a :class:`~.calls.MacroCall`); a macro line becomes nothing (an
assignment), a :class:`Jump` (GOTO, WHILE/END), a call, or the block's words with the values written in.

Conventions
-----------
* Every jump (GOTO, a WHILE that exits, END back to its WHILE/DO) starts a new run of
  :attr:`..blocks.Program.segments`, so a line run 5 times in a loop is one source line run 5 times, for
  recordings and per-line overrides (as subprogram lines are).
* Runaway programs: every executed line counts; beyond the file's length + :data:`MAX_LOOP_LINES` lines the
  run stops with an error naming the last backward jump and the cap. An endless loop is found sooner when it
  repeats exactly: a backward jump taken a second time with every local and common variable and every active
  call as before cannot end (conditions depend on variables only). Once a system variable (modal codes,
  positions) has been read, only the cap applies. ``M99 P<seq>`` returns count as repeats only with equal
  variables too. A loop that changes other variables (``#2 = #2 + 1`` under a ``WHILE [#1 LT 10]`` that never
  counts #1) is found at its second pass too: the variables that decide its branches (its *slice*,
  :mod:`.loop_slice`) are as in the pass before, and only the loop's own lines ran in between.
* ``#3000 = n (MESSAGE)`` stops the program with a :class:`~..errors.GCodeError` naming the line, n and the
  message (FANUC macro alarm 3000 + n).
* ``#3006 = n (MESSAGE)`` (stop with message, as hand-written programs ask the operator to turn the part over)
  is a program stop: the line runs as the block ``M0`` (the axes come to rest, no operator wait is added).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from ..codes import LETTERS
from ..errors import GCodeError
from ..lexer import LexedLine, LexError, Word, lex_line
from ..modal import ModalState
from ..settings import INCH
from ..subprograms import MAX_CALLED_LINES
from .calls import MAX_MACRO_NESTING, MacroCall, read_macro_call

#: FANUC system variable of the stop with message (the program stops as at M00 and shows the message).
STOP_WITH_MESSAGE = 3006

#: Letters of a G65 block read as integers (not affected by decimal point input): G, P (program), L (count), and
#: the addresses H D M S T whose arguments FANUC passes as written.
INTEGER_ARGUMENTS = "GPLHDMST"
from .expressions import condition, evaluate, node_text, round_half_away, variable_number
from .loop_slice import loop_slice
from .loops import MAX_SEQUENCE, ProgramIndex, index_program, main_program_last
from .statements import Assign, Goto, IfThen, Loop, MacroLine, NCBlock, parse_line
from .system import read_system
from .variables import VariableStore
from .words import evaluate_block

#: Lines a program may execute beyond one pass over its file (loops, jumps), as for subprogram calls.
MAX_LOOP_LINES = MAX_CALLED_LINES
_UNPARSED = object()


@dataclass(frozen=True)
class Jump:
    """Continue at the 0-based line index ``target``."""

    target: int


class LineContext:
    """Evaluation context of one line: its variables, its errors, and the address rounding of ROUND."""

    def __init__(self, store: VariableStore, file: str, line: int, text: str) -> None:
        self.store = store
        self.file = file
        self.line = line
        self.text = text
        self.increment: float | None = None

    def read(self, number: int, text: str) -> float | None:
        """Value of ``#number`` (None: vacant)."""
        return self.store.read(number, text, self.fail)

    def fail(self, expression: str, problem: str, expected: str) -> GCodeError:
        """The error of this line."""
        return GCodeError(self.file, self.line, expression, expected, problem, self.text)


class MacroRuntime:
    """The macro state of one interpreter run.

    Parameters
    ----------
    lines : list of str
        The program's lines.
    file : str
        Name used in error messages.
    block_delete : bool
        Block delete switch.
    st : ModalState
        The interpreter's modal state (system variables read it).
    """

    def __init__(self, lines: list[str], file: str, block_delete: bool, st: ModalState) -> None:
        self.lines = lines
        self.file = file
        self.block_delete = block_delete
        self.st = st
        self.store = VariableStore(lambda n, text, fail: read_system(st, n, text, fail))
        self._parsed: list[object] = [_UNPARSED] * len(lines)
        self._programs: dict[tuple[int, int], ProgramIndex] = {}
        self._main_last: int | None = None
        self._states: set[int] = set()
        self._returns: dict[tuple, set[tuple]] = {}
        self.executed = 0
        self.limit = len(lines) + MAX_LOOP_LINES
        self.last_jump: tuple[int, int] | None = None  # (line, target line) of the last backward jump
        self._slices: dict[tuple[int, int], frozenset[int] | None] = {}
        # loops watched for a repeat: key -> (first line, last line, slice values at the last pass)
        self._watched: dict[tuple, tuple[int, int, tuple]] = {}
        self._lo, self._hi = math.inf, -math.inf  # lines run since the last backward jump

    # ------------------------------------------------------------------------------------------- parsing
    def parse(self, number: int) -> MacroLine | None:
        """The parsed macro line ``number`` (1-based; cached), None for a plain line.

        Raises
        ------
        GCodeError
            A malformed macro line.
        """
        cached = self._parsed[number - 1]
        if cached is not _UNPARSED:
            return cached  # type: ignore[return-value]
        try:
            return self._parse(number - 1)
        except LexError as exc:
            raise GCodeError(self.file, number, exc.word, exc.expected, exc.problem,
                             self.lines[number - 1].strip()) from None

    def _parse(self, index: int) -> MacroLine | None:
        cached = self._parsed[index]
        if cached is _UNPARSED:
            cached = parse_line(self.lines[index])
            self._parsed[index] = cached
        return cached  # type: ignore[return-value]

    # ------------------------------------------------------------------------------------------ counting
    def count(self, number: int) -> None:
        """Count one executed line; raise past the cap (naming the loop that does not end)."""
        self.executed += 1
        if number < self._lo:
            self._lo = number
        if number > self._hi:
            self._hi = number
        if self.executed <= self.limit:
            return
        line, target = self.last_jump or (number, number)
        raise GCodeError(self.file, line, self.lines[line - 1].strip(),
                         "a loop that ends (a condition that becomes false, a counter that grows)",
                         f"more than {self.limit} lines executed ({len(self.lines)} lines in the file + "
                         f"{self.limit - len(self.lines)} by loops and calls): the loop at line {line} (back to "
                         f"line {target}) does not end", self.lines[line - 1].strip())

    # ------------------------------------------------------------------------------------------ executing
    def execute(self, number: int, parsed: MacroLine | None, lexed: LexedLine | None,
                stack: Sequence) -> Jump | MacroCall | LexedLine | None:
        """Run line ``number``.

        Parameters
        ----------
        number : int
            1-based line.
        parsed : MacroLine or None
            :meth:`parse` of the line (None: a plain line, ``lexed`` given).
        lexed : LexedLine or None
            The plain line's words.
        stack : sequence of Frame
            Active M98/G65 calls (:class:`..call_stack.Frame`).

        Returns
        -------
        Jump, MacroCall, LexedLine or None
            Where to continue, a G65 call, the NC block to execute, or nothing (a statement was executed).
        """
        if parsed is None:  # a plain line: only a G65 call concerns the macro machinery
            assert lexed is not None
            if "65" not in lexed.text or not any(w.letter == "G" and w.value == 65.0 for w in lexed.words):
                return lexed
        ctx = LineContext(self.store, self.file, number, self.lines[number - 1].strip())
        if parsed is None:
            self._check_arguments(lexed.words, ctx)
            return read_macro_call([(w.letter, w.value, w.letter + w.text) for w in lexed.words], ctx.fail)
        s = parsed.statement
        if isinstance(s, NCBlock):
            return self._block(parsed, s, ctx)
        if isinstance(s, Assign):
            return self._assign(s, ctx, parsed)
        if isinstance(s, IfThen):
            if condition(s.condition, ctx, node_text(s.condition)):
                return self._assign(s.assign, ctx, parsed)
            return None
        if isinstance(s, Goto):
            if s.condition is None or condition(s.condition, ctx, node_text(s.condition)):
                return self._goto(number, s, ctx, stack)
            return None
        assert isinstance(s, Loop)
        index = self._program(stack)
        here = number - 1
        if s.end:
            return self._jump(number, index.do_end[here], stack)
        if s.condition is None or condition(s.condition, ctx, node_text(s.condition)):
            return None
        return Jump(index.do_end[here] + 1)

    def _check_arguments(self, words: Sequence[Word], ctx: LineContext) -> None:
        """Under decimal point input DPI = 0 (:mod:`..decimal_input`), a G65 argument written without a decimal
        point at an address that takes one is an error: FANUC passes it in least input increments of that
        address, which the twin does not model for arguments."""
        if self.st.settings.decimal_input != "increment":
            return
        for w in words:
            if w.letter not in INTEGER_ARGUMENTS and not w.has_point:
                shown = w.letter + w.text
                raise ctx.fail(shown, f"G65 argument {shown} without a decimal point under decimal point input "
                               "\"increment\" (FANUC No. 3401#0 DPI = 0: passed in least input increments, not "
                               "modelled for arguments)", f"the argument with a decimal point ({w.letter}{w.text}.)")

    def _block(self, parsed: MacroLine, s: NCBlock, ctx: LineContext) -> MacroCall | LexedLine:
        if parsed.is_call:
            self._check_arguments(parsed.static.words, ctx)
            items: list[tuple[str, float | None, str]] = [(w.letter, w.value, w.letter + w.text)
                                                          for w in parsed.static.words]
            for piece in s.values:
                v = evaluate(piece.node, ctx)
                shown = piece.source
                if isinstance(v, bool):
                    raise ctx.fail(shown, f"the argument {shown} is a condition", "a number")
                items.append((piece.letter.upper(), v, shown))
            return read_macro_call(items, ctx.fail)
        before = ""
        for piece in s.pieces:  # checked before a vacant value drops the word
            if isinstance(piece, str):
                before = (before + piece).rstrip(" \t")[-1:]
                continue
            name = ("," if before == "," else "") + piece.letter.upper()
            before = ""
            if name not in LETTERS:
                shown = piece.source
                raise ctx.fail(shown, f"address {name} is not supported outside a G65 call",
                               "one of the addresses " + " ".join(sorted(LETTERS)))
        try:
            lexed = evaluate_block(s, ctx, self.st.scale == INCH, parsed.block_delete, parsed.text)
        except LexError as exc:
            raise ctx.fail(exc.word, f"{exc.problem} (after writing in the variables' values)", exc.expected) \
                from None
        for w in lexed.words:
            if w.letter == "G" and w.value in (65.0, 66.0):
                raise ctx.fail("G" + w.text, f"G{w.text} from a variable", f"G{w.text} written as a number")
        return lexed

    def _assign(self, s: Assign, ctx: LineContext, parsed: MacroLine) -> LexedLine | None:
        """Run an assignment; ``#3006 = n (MESSAGE)`` is a program stop: the block ``M0`` to execute."""
        n = variable_number(s.target, ctx)
        v = evaluate(s.value, ctx)
        if isinstance(v, bool):
            raise ctx.fail(node_text(s.value), f"a condition [{node_text(s.value)}] assigned to #{n}",
                           "a number (comparisons only in IF/WHILE conditions)")
        if n == 3000:
            shown = "vacant" if v is None else f"{v:g}"
            raise ctx.fail("#3000", f"macro alarm #3000 = {shown}: {parsed.comment or '(no message)'}",
                           "a program that does not raise its alarm (the program stopped it on purpose)")
        if n == STOP_WITH_MESSAGE:  # FANUC: the program stops as at M00 and shows the message; cycle start resumes
            return LexedLine(lex_line("M0").words, False, parsed.block_delete, parsed.text)
        self.store.write(n, v, s.target.text, ctx.fail)
        return None

    def _goto(self, number: int, s: Goto, ctx: LineContext, stack: Sequence) -> Jump:
        v = evaluate(s.target, ctx)
        shown = "GOTO " + node_text(s.target)
        if v is None or isinstance(v, bool):
            raise ctx.fail(shown, f"{shown}: the sequence number is {'vacant' if v is None else 'a condition'}",
                           f"a sequence number 1..{MAX_SEQUENCE}")
        n = round_half_away(v)
        if not 1 <= n <= MAX_SEQUENCE:
            raise ctx.fail(shown, f"{shown}: sequence number {v:g} is not in 1..{MAX_SEQUENCE}",
                           f"GOTO 1..{MAX_SEQUENCE}")
        index = self._program(stack)
        here = number - 1
        target = index.find(int(n), here)
        if target is None:
            name = f"subprogram O{stack[-1].sub.number}" if stack else "the main program"
            raise ctx.fail(shown, f"{name} (lines {index.first + 1}-{index.last + 1}) has no block N{int(n)}",
                           f"a block N{int(n)} in the program running the GOTO (searched forward, then from its "
                           "top)")
        entered = index.entering(here, target)
        if entered is not None:
            raise ctx.fail(shown, f"{shown} jumps into the loop of lines {entered[0] + 1}-{entered[1] + 1} "
                           "from outside it (FANUC alarm)", "GOTO within a loop, out of it, or outside loops")
        return self._jump(number, target, stack)

    def _jump(self, number: int, target: int, stack: Sequence) -> Jump:
        if target < number:  # backward (or to itself): a loop
            if not self.store.system_read:
                calls = tuple((f.sub.number, f.return_pc, f.remaining) for f in stack)
                key = hash((number, target, calls, self.store.snapshot()))
                if key in self._states:
                    text = self.lines[number - 1].strip()
                    raise GCodeError(self.file, number, text, "a loop whose condition changes (a counter such "
                                     "as #1 = #1 + 1 inside it) or a GOTO out of it",
                                     f"endless loop: jumping back to line {target + 1} again with every variable "
                                     "and call as in an earlier pass, so the program never ends", text)
                self._states.add(key)
            self._check_slice(number, target, stack)
            self.last_jump = (number, target + 1)
        return Jump(target)

    def _check_slice(self, number: int, target: int, stack: Sequence) -> None:
        """Raise when the loop of lines ``target + 1 .. number`` passes its back jump with its slice as at the
        previous pass and only its own lines ran in between (see the module conventions)."""
        lo, hi = self._lo, self._hi
        self._lo, self._hi = math.inf, -math.inf
        self._watched = {key: w for key, w in self._watched.items() if w[0] <= lo and hi <= w[1]}
        first = target + 1
        span = (first, number)
        if span not in self._slices:
            self._slices[span] = loop_slice(self.parse, first, number)
        sliced = self._slices[span]
        if sliced is None:
            return
        names = sorted(sliced)
        values = tuple(self.store.peek(n) for n in names)
        key = (number, target, tuple((f.sub.number, f.return_pc, f.remaining) for f in stack))
        seen = self._watched.get(key)
        if seen is not None and seen[2] == values:
            text = self.lines[number - 1].strip()
            if names:
                shown = ", ".join(f"#{n} = {'vacant' if v is None else f'{v:g}'}" for n, v in zip(names, values))
                why = (f"again with {shown} as in the pass before; these decide every condition of lines "
                       f"{first}-{number} and nothing in the loop changes them")
            else:
                why = f"again: lines {first}-{number} have no condition and no GOTO that could leave the loop"
            raise GCodeError(self.file, number, text, "a loop whose condition changes (a counter such as #1 = #1 + 1 "
                             "inside it) or a GOTO out of it",
                             f"endless loop: jumping back to line {first} {why}, so the program never ends", text)
        self._watched[key] = (first, number, values)

    def _program(self, stack: Sequence) -> ProgramIndex:
        if stack:
            first, last = stack[-1].sub.start, stack[-1].sub.end
        else:
            if self._main_last is None:
                self._main_last = main_program_last(self.lines, self._parse, self.block_delete)
            first, last = 0, self._main_last
        key = (first, last)
        if key not in self._programs:
            self._programs[key] = index_program(self.lines, first, last, self._parse, self.block_delete, self.file)
        return self._programs[key]

    # ------------------------------------------------------------------------------------------ G65 levels
    def enter(self, call: MacroCall, stack: Sequence, number: int) -> None:
        """Open the local level of a G65 call (after the program was found); raise beyond the nesting limit."""
        active = [f for f in stack if getattr(f, "macro", None) is not None]
        if len(active) >= MAX_MACRO_NESTING:
            text = self.lines[number - 1].strip()
            chain = " -> ".join(f"O{f.sub.number}" for f in active)
            raise GCodeError(self.file, number, f"G65 P{call.number}", f"G65 macro calls nested at most "
                             f"{MAX_MACRO_NESTING} levels deep", f"calling O{call.number} would nest "
                             f"{len(active) + 1} macro levels ({chain})", text)
        self.store.push(call.arguments)

    def repeat(self, frame: object) -> None:
        """A G65 ... L<k> call runs again: a fresh local level with the same arguments."""
        call = getattr(frame, "macro", None)
        if call is not None:
            self.store.pop()
            self.store.push(call.arguments)

    def leave(self, frame: object) -> None:
        """M99 of a G65 call: the caller's locals are back."""
        if getattr(frame, "macro", None) is not None:
            self.store.pop()

    def return_jumps(self) -> set[tuple]:
        """The set of ``M99 P<seq>`` return states for the current variables (see :func:`..call_stack.return_target`).

        Equal variables: a repeated return is endless. After a system variable was read: a fresh set (the
        line cap guards instead).
        """
        if self.store.system_read:
            return set()
        return self._returns.setdefault(self.store.snapshot(), set())
