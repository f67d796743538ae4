"""The jump structure of one program (main program or ``O<n>``): sequence numbers for GOTO, DO/END pairs.

Conventions
-----------
* ``GOTO n`` jumps to the block ``N n`` of the program running it (the main program, or the subprogram or
  macro it is in): the search runs forward from the GOTO to the program's end, then from the program's top
  (FANUC searches the same way; the first block found wins). ``n`` is rounded to an integer and must be in
  1..99999; a missing N is an error naming the line.
* ``WHILE [...] DO m`` ... ``END m`` (and ``DO m`` ... ``END m``, an endless loop left by GOTO): the pairs of a
  program are matched once, when it first runs a loop statement or a GOTO: an ``END m`` closes the innermost
  open ``DO m``. Loops nest at most 3 deep; the same m inside its own loop, crossing loops (DO1 DO2 END1 END2),
  an END without DO and a DO without END are errors naming the lines, even in parts that never run, and so
  is a malformed line anywhere in that program. A GOTO
  from outside a loop into its body is an error (FANUC alarm); out of a loop is allowed.
"""
from __future__ import annotations

from bisect import bisect_right
from dataclasses import dataclass, field
from typing import Callable

from ..errors import GCodeError
from ..lexer import LexError
from .statements import Loop, MacroLine, scan_line

#: Deepest nesting of DO loops (FANUC: 3).
MAX_LOOP_NESTING = 3
#: Largest sequence number N (5 digits).
MAX_SEQUENCE = 99999


@dataclass
class ProgramIndex:
    """Sequence numbers and loops of the program on lines ``first..last`` (0-based, inclusive).

    Attributes
    ----------
    sequences : dict of int -> list of int
        N number -> 0-based indices of the lines holding it, ascending.
    do_end : dict of int -> int
        0-based index of a DO (WHILE) line -> its END line, and of an END line -> its DO line.
    loops : list of (int, int)
        (DO line, END line) pairs.
    """

    first: int
    last: int
    sequences: dict[int, list[int]] = field(default_factory=dict)
    do_end: dict[int, int] = field(default_factory=dict)
    loops: list[tuple[int, int]] = field(default_factory=list)

    def find(self, sequence: int, current: int) -> int | None:
        """0-based index of the block N<sequence>: forward from line ``current``, then from the top."""
        where = self.sequences.get(sequence)
        if not where:
            return None
        k = bisect_right(where, current)
        return where[k] if k < len(where) else where[0]

    def entering(self, source: int, target: int) -> tuple[int, int] | None:
        """A loop whose body a jump from ``source`` to ``target`` enters from outside, if any."""
        for do, end in self.loops:
            if do < target <= end and not do <= source <= end:
                return do, end
        return None


def index_program(lines: list[str], first: int, last: int, parse: Callable[[int], MacroLine | None],
                  block_delete: bool, file: str) -> ProgramIndex:
    """Build the :class:`ProgramIndex` of lines ``first..last``.

    Parameters
    ----------
    lines : list of str
        The file's lines.
    first, last : int
        0-based line range of the program.
    parse : callable index -> MacroLine or None
        The (cached) macro parse of a line; raises :class:`LexError` for a malformed macro line.
    block_delete : bool
        Block delete switch: ``/`` lines are skipped when True, as in execution.
    file : str
        Name used in error messages.

    Raises
    ------
    GCodeError
        Crossing, too deep, reused-while-open, unmatched DO or END.
    """
    index = ProgramIndex(first, last)
    open_loops: list[tuple[int, int]] = []  # (loop id, line index)
    for i in range(first, last + 1):
        try:
            parsed = parse(i)
            lexed = parsed.static if parsed is not None else scan_line(lines[i])
        except LexError as exc:  # the program's jumps cannot be known past a malformed line
            raise GCodeError(file, i + 1, exc.word, exc.expected, exc.problem, lines[i].strip()) from None
        if lexed.block_delete and block_delete:
            continue
        seq = parsed.label if parsed is not None and not parsed.is_block else None
        if seq is None:
            seq = next((int(w.value) for w in lexed.words if w.letter == "N" and not w.has_point), None)
        if seq is not None:
            index.sequences.setdefault(seq, []).append(i)
        if parsed is None or not isinstance(parsed.statement, Loop):
            continue
        loop = parsed.statement
        name = f"END{loop.loop_id}" if loop.end else f"DO{loop.loop_id}"
        fail = _line_error(file, i, name, lines[i])
        if not loop.end:
            if any(m == loop.loop_id for m, _ in open_loops):
                other = next(j for m, j in open_loops if m == loop.loop_id)
                raise fail(f"DO{loop.loop_id} inside the loop DO{loop.loop_id} of line {other + 1}",
                           "another identification number (1, 2, 3) for a nested loop")
            if len(open_loops) >= MAX_LOOP_NESTING:
                raise fail(f"a loop nested {len(open_loops) + 1} deep (lines "
                           f"{', '.join(str(j + 1) for _, j in open_loops)})",
                           f"DO loops nested at most {MAX_LOOP_NESTING} deep (FANUC)")
            open_loops.append((loop.loop_id, i))
            continue
        if not open_loops or all(m != loop.loop_id for m, _ in open_loops):
            raise fail(f"END{loop.loop_id} without a DO{loop.loop_id} before it in this program",
                       f"WHILE [...] DO{loop.loop_id} ... END{loop.loop_id}")
        m, j = open_loops[-1]
        if m != loop.loop_id:
            mine = next(k for mm, k in open_loops if mm == loop.loop_id)
            raise fail(f"loops cross: DO{loop.loop_id} (line {mine + 1}) ends here while DO{m} (line {j + 1}) "
                       "is still open", f"END{m} before END{loop.loop_id} (inner loops end first)")
        open_loops.pop()
        index.do_end[j] = i
        index.do_end[i] = j
        index.loops.append((j, i))
    if open_loops:
        m, j = open_loops[-1]
        raise GCodeError(file, j + 1, f"DO{m}", f"END{m} closing the loop before the program ends (line {last + 1})",
                         f"DO{m} without END{m}", lines[j].strip())
    return index


def _line_error(file: str, i: int, word: str, raw: str) -> Callable[[str, str], GCodeError]:
    def fail(problem: str, expected: str) -> GCodeError:
        return GCodeError(file, i + 1, word, expected, problem, raw.strip())
    return fail


def main_program_last(lines: list[str], parse: Callable[[int], MacroLine | None], block_delete: bool) -> int:
    """0-based index of the main program's last line: its first M30/M2 or ``%`` after a block, else the file's
    last line (malformed lines are passed over)."""
    seen_block = False
    for i, raw in enumerate(lines):
        try:
            parsed = parse(i)
            lexed = parsed.static if parsed is not None else scan_line(raw)
        except LexError:
            seen_block = True
            continue
        if lexed.percent:
            if seen_block:
                return i
            continue
        if lexed.block_delete and block_delete:
            continue
        if lexed.words or parsed is not None:
            seen_block = True
        if any(w.letter == "M" and w.value in (2.0, 30.0) for w in lexed.words):
            return i
    return len(lines) - 1
