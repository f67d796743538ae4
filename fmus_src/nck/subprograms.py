"""Subprograms in the same file (FANUC M98/M99): finding the ``O<n>`` programs and reading an M98 call.

CAM posts (Fusion 360's FANUC post with "use subprograms", Mastercam transforms) write the main program, its
M30, and then the subprograms, each ``O<n>`` ... ``M99``, before the closing ``%``. FANUC loads every
``O<n>`` of such a file as a program of its own; the twin does the same, for one file:

* The main program ends at its first M30/M2 (a block-deleted one is skipped when the switch is on) or at a
  ``%``. After it, every line starting with an ``O<n>`` word opens subprogram ``n`` (1..9999), which runs up to
  and including the first line holding M99 (a block-deleted ``/M99`` is skipped when the switch is on, as
  in execution), or the last such line before the next ``O`` line, ``%`` or the end of the file when there
  are several (a macro returning early: ``IF [...] GOTO 9`` ... ``M99`` ... ``N9 M99``). Lines between such
  programs are not read (comments, stray text).
  A ``%`` ends the file's programs.
* Inside a subprogram every line must be well formed; an ``O`` line, ``%`` or the end of the file before its
  M99 is an error, and so is a program number defined twice.
* ``M98 P<n>`` calls O<n> once, ``M98 P<n> L<k>`` k times (1..9999), and the FANUC packed form ``M98
  P<kkkk><nnnn>`` (more than 4 digits: the last 4 are the program number, the leading ones the repeat count;
  ``P21001`` calls O1001 twice). L together with a packed P is an error.
* ``M99`` returns to the block after the M98; ``M99 P<seq>`` (FANUC) to the block with the sequence number
  ``N<seq>`` in the calling program (the main program up to its end, or the calling subprogram): the first
  such block from the top of that program. While repeats of an ``M98 ... L<k>`` remain, M99 (with or
  without P) runs the subprogram again; P takes effect at the last return. A missing N<seq> is an error, and
  so is a jump that makes the program endless (the same return with the same calls active again: the program
  has no conditions, so it would repeat forever).
* ``M97 P<n>`` (Haas mill: local subprogram call) runs the block N<n> of the *same* program (the main program
  including the lines after its M30, up to the first ``O<n>`` subprogram; or the running subprogram) up to its
  M99, which returns to the block after the M97; ``L<k>`` repeats it k times (1..9999). P is a sequence
  number 1..99999 (no packed repeat count). The first N<n> from the top of that program is the target; a
  missing N<n>, or an M30/M2/``%`` before the M99 after it, is an error. M97 and M98 calls nest together
  (:data:`MAX_NESTING`).
* Subprograms written *before* the main program (``O2000 ... M99`` then ``O1000 ... M30``) are not
  supported: the CAM posts the twin reads (Fusion 360's FANUC post, Mastercam) write the main program first
  and its subprograms after M30, and a file is executed from its first line, so such a file stops at the
  first subprogram's M99 with an error saying where the subprograms must go.
* Custom Macro B lines (``#1 = 2``, ``IF [...] GOTO 5``, ``X#24``) are read by their plain words here
  (:func:`.macro.statements.scan_line`): M99, M30 and N numbers written as plain numbers count; the same
  O<n> programs are the macros of G65 calls.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

from .errors import GCodeError
from .lexer import LexedLine, LexError, Word
from .macro.statements import scan_line

#: Deepest nesting of subprogram calls (FANUC 31i-B: 10 levels).
MAX_NESTING = 10
#: Largest program number O<n> (4 digits).
MAX_PROGRAM_NUMBER = 9999
#: Largest repeat count of an M98 call (FANUC: 4 digits of L, or of the packed P).
MAX_CALL_REPEAT = 9999
#: Most source lines executed inside subprograms per program (guards against L9999 nested 10 deep).
MAX_CALLED_LINES = 2_000_000
#: Largest sequence number N of an M99 P<seq> jump (FANUC: 5 digits).
MAX_SEQUENCE = 99999


@dataclass(frozen=True)
class Subprogram:
    """One ``O<n>`` ... ``M99`` program of the file.

    Or a local subprogram of an M97 call: the lines from the block N<number> on.

    Attributes
    ----------
    number : int
        Program number n (a local subprogram: the sequence number N<n> it starts at).
    start : int
        0-based index of the ``O<n>`` line (its 1-based line number is ``start + 1``); a local subprogram: of
        the N<n> line (where a run starts).
    end : int
        0-based index of the line holding M99; a local subprogram: the last line of the program holding it.
    scope_start : int or None
        A local subprogram: 0-based first line of the program holding it (its block N<n> is searched there);
        None for an ``O<n>`` program.
    """

    number: int
    start: int
    end: int
    scope_start: int | None = None

    @property
    def name(self) -> str:
        """``O1001``, or ``N100 (M97)`` for a local subprogram, as quoted in messages."""
        return f"O{self.number}" if self.scope_start is None else f"N{self.number} (M97)"

    @property
    def first(self) -> int:
        """0-based first line of the program this runs in (``start`` for an ``O<n>`` program)."""
        return self.start if self.scope_start is None else self.scope_start


@dataclass(frozen=True)
class Call:
    """An M98 call read from a block: program ``number``, called ``repeats`` times; ``local``: an M97 call of the
    block N<number> of the same program."""

    number: int
    repeats: int
    local: bool = False


@dataclass(frozen=True)
class Return:
    """An M99 block: back to the block after the M98, or (``sequence`` set) to the caller's block N<sequence>."""

    sequence: int | None = None


def _has_m(words: Sequence[Word], codes: tuple[float, ...]) -> bool:
    return any(w.letter == "M" and w.value in codes for w in words)


def index_subprograms(lines: Sequence[str], first: int, file: str, block_delete: bool) -> dict[int, Subprogram]:
    """Find the subprograms that follow the main program's end.

    Parameters
    ----------
    lines : sequence of str
        The program's source lines (without line endings).
    first : int
        0-based index of a main-program line (the first M98 call) to start looking for the main program's
        M30/M2 from.
    file : str
        Name used in error messages.
    block_delete : bool
        Block delete switch (a ``/M30`` block is skipped when True, as by the interpreter).

    Returns
    -------
    dict of int -> Subprogram
        By program number; empty when the main program has no end or nothing follows it.

    Raises
    ------
    GCodeError
        A malformed main-program line before its end, a malformed line inside a subprogram, an ``O`` line, a
        ``%`` or the end of the file before a subprogram's M99, an invalid or repeated program number.
    """
    n = len(lines)
    end = main_program_end(lines, first, file, block_delete)
    if end is None:
        return {}
    i = end + 1
    found: dict[int, Subprogram] = {}
    while i < n:
        try:
            lexed = scan_line(lines[i])
        except LexError:  # a line outside any program is not read
            i += 1
            continue
        if lexed.percent:
            break
        if not lexed.words or lexed.words[0].letter != "O":
            i += 1
            continue
        number = _program_number(lexed.words[0], i, file, lexed.text)
        if number in found:
            raise GCodeError(file, i + 1, "O" + lexed.words[0].text, "each program number once in the file",
                             f"program O{number} is defined twice (first at line {found[number].start + 1})",
                             lexed.text)
        start = i
        i += 1
        while True:
            if i >= n:
                raise GCodeError(file, start + 1, f"O{number}", "M99 at the end of every subprogram",
                                 f"subprogram O{number} has no M99 before the end of the file", lines[start].strip())
            body = _lex(lines[i], i, file)
            if body.percent or (body.words and body.words[0].letter == "O"):
                raise GCodeError(file, start + 1, f"O{number}", "M99 at the end of every subprogram",
                                 f"subprogram O{number} has no M99 before line {i + 1}", lines[start].strip())
            i += 1
            if _has_m(body.words, (99.0,)) and not (body.block_delete and block_delete):
                break
        end = _last_return(lines, i - 1, block_delete)
        found[number] = Subprogram(number, start, end)
        i = end + 1
    return found


def _last_return(lines: Sequence[str], first: int, block_delete: bool) -> int:
    """0-based index of the last M99 line from ``first`` (an M99 line) up to the next ``O`` line, ``%`` or the end
    of the file: a macro may return early (``IF [...] GOTO 9`` ... ``M99`` ... ``N9 M99``)."""
    end = first
    for j in range(first + 1, len(lines)):
        try:
            more = scan_line(lines[j])
        except LexError:
            continue
        if more.percent or (more.words and more.words[0].letter == "O"):
            break
        if _has_m(more.words, (99.0,)) and not (more.block_delete and block_delete):
            end = j
    return end


def main_program_end(lines: Sequence[str], first: int, file: str, block_delete: bool) -> int | None:
    """0-based index of the main program's end: its first M30/M2 block or ``%`` at or after line ``first``.

    Parameters
    ----------
    lines : sequence of str
        The program's source lines.
    first : int
        0-based index of a main-program line to start from.
    file : str
        Name used in error messages.
    block_delete : bool
        Block delete switch (a ``/M30`` block is skipped when True).

    Returns
    -------
    int or None
        None when the file ends without M30/M2 or ``%``.

    Raises
    ------
    GCodeError
        A malformed line before the end.
    """
    for i in range(first, len(lines)):
        lexed = _lex(lines[i], i, file)
        if lexed.percent:
            return i
        if _has_m(lexed.words, (2.0, 30.0)) and not (lexed.block_delete and block_delete):
            return i
    return None


def next_program_start(lines: Sequence[str], first: int) -> int | None:
    """0-based index of the first ``O<n>`` line at or after line ``first``, if it comes before any M30/M2 or
    ``%`` (lines that do not lex are passed over): after an M99 of the main program, it means that subprograms
    were written before the main program."""
    for i in range(max(first, 0), len(lines)):
        try:
            lexed = scan_line(lines[i])
        except LexError:
            continue
        if lexed.percent or _has_m(lexed.words, (2.0, 30.0)):
            return None
        if lexed.words and lexed.words[0].letter == "O":
            return i
    return None


def find_sequence(lines: Sequence[str], first: int, last: int, sequence: int) -> int | None:
    """0-based index of the first line in ``lines[first:last + 1]`` whose block has the word N<sequence>.

    Lines that do not lex are passed over (they raise their own error if they are executed).
    """
    for i in range(max(first, 0), min(last, len(lines) - 1) + 1):
        try:
            lexed = scan_line(lines[i])
        except LexError:
            continue
        if any(w.letter == "N" and not w.has_point and w.value == sequence for w in lexed.words):
            return i
    return None


def read_return(p: Word | None, err: Callable[[str, str, str], GCodeError]) -> Return:
    """The return of an M99 block: plain, or ``M99 P<seq>`` to the caller's block N<seq>.

    Raises
    ------
    GCodeError
        A P that is not a sequence number 0..99999 (an integer).
    """
    if p is None:
        return Return()
    if p.has_point or p.value < 0 or p.value > MAX_SEQUENCE:
        raise err("P" + p.text, f"M99 P{p.text}: P is not a sequence number",
                  f"M99 P<n> with an integer n in 0..{MAX_SEQUENCE} (return to the caller's block N<n>) or M99 alone")
    return Return(int(p.value))


def _lex(raw: str, i: int, file: str) -> LexedLine:
    try:
        return scan_line(raw)
    except LexError as exc:
        raise GCodeError(file, i + 1, exc.word, exc.expected, exc.problem, raw.strip()) from None


def _program_number(w: Word, i: int, file: str, text: str) -> int:
    if w.has_point or w.value < 1 or w.value > MAX_PROGRAM_NUMBER:
        raise GCodeError(file, i + 1, "O" + w.text, f"O1..O{MAX_PROGRAM_NUMBER} (an integer)",
                         f"program number O{w.text} is not an integer in 1..{MAX_PROGRAM_NUMBER}", text)
    return int(w.value)


def read_call(p: Word | None, l_word: Word | None, err: Callable[[str, str, str], GCodeError]) -> Call:
    """The program number and repeat count of an M98 block (FANUC 0i-MF/31i-B forms).

    Parameters
    ----------
    p, l_word : Word or None
        The block's P and L words.
    err : callable (word, problem, expected) -> GCodeError
        Builds the error for this block.

    Raises
    ------
    GCodeError
        No P, a P or L that is not a positive integer, L with a packed P, L0, numbers out of range.
    """
    forms = "M98 P1001 (once), M98 P1001 L2 or M98 P21001 (twice)"
    if p is None:
        raise err("M98", "M98 without a P word (the program to call)", forms)
    if p.has_point or p.value < 1 or p.value > 99999999:
        raise err("P" + p.text, f"P{p.text} is not a program number", forms)
    value = int(p.value)
    if l_word is not None:
        if l_word.has_point or l_word.value < 1 or l_word.value > MAX_CALL_REPEAT:
            raise err("L" + l_word.text, f"repeat count L{l_word.text} is not an integer in 1..{MAX_CALL_REPEAT}",
                      "L1..L9999 (the number of calls)")
        if value > MAX_PROGRAM_NUMBER:
            raise err("P" + p.text, f"P{p.text} packs a repeat count and L{l_word.text} gives one too",
                      "either M98 P<program> L<count> or M98 P<count><program 4 digits>")
        return Call(value, int(l_word.value))
    repeats, number = divmod(value, 10000) if value > MAX_PROGRAM_NUMBER else (1, value)
    if number == 0:
        raise err("P" + p.text, f"P{p.text} calls program O0", "a program number 1..9999 in the last 4 digits of P")
    return Call(number, repeats)


def read_local_call(p: Word | None, l_word: Word | None, err: Callable[[str, str, str], GCodeError]) -> Call:
    """The sequence number and repeat count of an M97 block (Haas: ``M97 P<n> [L<k>]``).

    Raises
    ------
    GCodeError
        No P, a P that is not an integer 1..99999, an L that is not an integer 1..9999.
    """
    forms = f"M97 P<n> (a block N<n> of this program, n = 1..{MAX_SEQUENCE}) or M97 P<n> L<k> (k times)"
    if p is None:
        raise err("M97", "M97 without a P word (the sequence number N to call)", forms)
    if p.has_point or p.value < 1 or p.value > MAX_SEQUENCE:
        raise err("P" + p.text, f"M97 P{p.text}: P is not a sequence number", forms)
    repeats = 1
    if l_word is not None:
        if l_word.has_point or l_word.value < 1 or l_word.value > MAX_CALL_REPEAT:
            raise err("L" + l_word.text, f"repeat count L{l_word.text} is not an integer in 1..{MAX_CALL_REPEAT}",
                      "L1..L9999 (the number of calls)")
        repeats = int(l_word.value)
    return Call(int(p.value), repeats, local=True)


def local_subprogram(sequence: int, first: int, last: int, lines: Sequence[str], file: str, block_delete: bool,
                     name: str, line: int, text: str) -> Subprogram:
    """The local subprogram an ``M97 P<sequence>`` block calls: from the first N<sequence> in ``lines[first:last
    + 1]`` (the program ``name`` holding the M97) to its M99.

    Raises
    ------
    GCodeError
        No block N<sequence> there, or an M30/M2/``%`` or the program's end before an M99 after it.
    """
    word = f"M97 P{sequence}"
    target = find_sequence(lines, first, last, sequence)
    if target is None:
        raise GCodeError(file, line, word, f"a block N{sequence} in {name} (lines {first + 1}-{last + 1}), "
                         "ending with M99", f"{name} has no block N{sequence} to call", text)
    for i in range(target, min(last, len(lines) - 1) + 1):
        try:
            lexed = scan_line(lines[i])
        except LexError:  # raised when executed
            continue
        if lexed.block_delete and block_delete:
            continue
        if _has_m(lexed.words, (99.0,)):
            return Subprogram(sequence, target, last, first)
        if lexed.percent or _has_m(lexed.words, (2.0, 30.0)):
            raise GCodeError(file, line, word, f"M99 at the end of the local subprogram N{sequence}",
                             f"the local subprogram from N{sequence} (line {target + 1}) reaches "
                             f"'{lexed.text or '%'}' (line {i + 1}) before an M99", text)
    raise GCodeError(file, line, word, f"M99 at the end of the local subprogram N{sequence}",
                     f"the local subprogram from N{sequence} (line {target + 1}) has no M99 before the end of "
                     f"{name} (line {last + 1})", text)
