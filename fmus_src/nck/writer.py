"""Program writer: change F and S words on given lines, every other character untouched.

Rules
-----
* Only the number of an existing F (S) word changes (letter case, blanks
  before the number and everything else on the line, e.g. ``,C1.``/``,R2`` corner words, are kept).
* A line without an F (S) word gets one appended right after its last word,
  separated by one blank, i.e. before any comment and trailing blanks; in lower case
  when every word of the line is written in lower case (``x45. f500``).
* Feeds are given in mm/min and written in the program's unit at that line
  (mm/min under G21, in/min under G20) with at most 3 (G21) or 4 (G20)
  decimals; a decimal point is kept when the original word had one.
  Spindle speeds are given in rpm and written as integers (FANUC S words
  are integers).
* Line endings (LF, CRLF, CR) and a missing final newline are preserved, so
  an empty change set returns the input byte for byte.
* A line that is not a block (empty, comment only, ``%``) cannot take a word:
  :class:`GCodeError`.
* Custom Macro B (:mod:`.macro`): an F (S) word whose value is a variable or an expression (``F#9``,
  ``F[#9*2]``) is replaced by the plain number (the optimiser gives one value per line, as a per-line override
  does for every run of the line). Macro statements (``#1 = ...``, IF, WHILE, GOTO) and G65 calls (whose F
  and S are the macro's arguments #9 and #19) cannot take a word: :class:`GCodeError`. G20/G95 written with
  a variable (``G#10``) are not seen by the writer's unit and feed-mode scan.
* An F word under G95 (feed per revolution) is not rewritten from a feed in
  mm/min: :class:`GCodeError` naming the line. It is given as a feed per
  revolution instead (``feed_per_rev_by_line``, mm/rev), written in mm/rev
  under G21 (at most 4 decimals) and in in/rev under G20 (at most 5
  decimals). The caller names the G95 lines (the NC kernel knows a
  subprogram's inherited feed mode; the writer's scan in file order does
  not). S words on G95 lines are rewritten as usual (the feed then follows
  the new S).
"""
from __future__ import annotations

import math
from typing import Mapping

from .errors import GCodeError
from .lexer import LexError, LexedLine, Word, lex_line, split_lines
from .macro.statements import parse_line, scan_line


#: Decimals of a written F word: mm/min under G21, in/min under G20.
FEED_DECIMALS_MM = 3
FEED_DECIMALS_INCH = 4
#: Decimals of a written F word under G95: mm/rev under G21, in/rev under G20.
FEED_PER_REV_DECIMALS_MM = 4
FEED_PER_REV_DECIMALS_INCH = 5
MM_PER_INCH = 25.4


def feed_word_value(feed_mm_per_min: float, inch: bool) -> float:
    """The number an F word written by :func:`rewrite_program` carries, as the lexer reads it back.

    Parameters
    ----------
    feed_mm_per_min : float
        Feed, mm/min.
    inch : bool
        G20 in effect on the line (the word is then in in/min).

    Returns
    -------
    float
        In/min under G20, else mm/min (``float`` of the written digits, so ``value * INCH / 60`` or
        ``value * MM / 60`` is the interpreter's feed bit for bit).
    """
    value = float(feed_mm_per_min) / MM_PER_INCH if inch else float(feed_mm_per_min)
    return float(_format(value, FEED_DECIMALS_INCH if inch else FEED_DECIMALS_MM, True))


def feed_per_rev_word_value(feed_mm_per_rev: float, inch: bool) -> float:
    """The number an F word written by :func:`rewrite_program` under G95 carries, as the lexer reads it back.

    Parameters
    ----------
    feed_mm_per_rev : float
        Feed per revolution, mm/rev.
    inch : bool
        G20 in effect on the line (the word is then in in/rev).

    Returns
    -------
    float
        In/rev under G20, else mm/rev (``float`` of the written digits, so ``value * INCH`` or ``value * MM``
        is the interpreter's feed per revolution bit for bit).
    """
    value = float(feed_mm_per_rev) / MM_PER_INCH if inch else float(feed_mm_per_rev)
    return float(_format(value, FEED_PER_REV_DECIMALS_INCH if inch else FEED_PER_REV_DECIMALS_MM, True))


def inch_lines(text: str, lines: list[int] | tuple[int, ...], file: str = "<text>") -> set[int]:
    """The given 1-based lines on which G20 (inch) is in effect (a G20/G21 on the line itself counts).

    Raises
    ------
    GCodeError
        A line up to the last one asked for is malformed.
    """
    targets = sorted(set(int(n) for n in lines))
    if not targets:
        return set()
    state = _inch_mode(split_lines(text, keepends=True), targets, file)
    return {n for n, inch in state.items() if inch}


def _format(value: float, decimals: int, point: bool) -> str:
    text = f"{value:.{decimals}f}".rstrip("0")
    if text.endswith("."):
        return text if point else text[:-1]
    return text


def rewrite_program(text: str, feed_by_line: Mapping[int, float] | None = None,
                    spindle_by_line: Mapping[int, float] | None = None, file: str = "<text>",
                    feed_per_rev_by_line: Mapping[int, float] | None = None) -> str:
    """Re-emit ``text`` with new F (mm/min or mm/rev) and S (rpm) values on the given 1-based lines.

    Parameters
    ----------
    text : str
        Program source.
    feed_by_line : mapping line -> feed (mm/min), optional
        F words of G94 lines.
    spindle_by_line : mapping line -> speed (rpm), optional
    file : str
        Name used in error messages.
    feed_per_rev_by_line : mapping line -> feed per revolution (mm/rev), optional
        F words of G95 lines (a line given here and in ``feed_by_line`` is an error).

    Returns
    -------
    str
        The program; byte-identical to ``text`` when nothing is changed.

    Raises
    ------
    GCodeError
        Line out of range, not a block, malformed, or a value that is not finite and positive.
    """
    feed_by_line = dict(feed_by_line or {})
    spindle_by_line = dict(spindle_by_line or {})
    per_rev_by_line = dict(feed_per_rev_by_line or {})
    if not feed_by_line and not spindle_by_line and not per_rev_by_line:
        return text
    lines = split_lines(text, keepends=True)
    targets = sorted(set(feed_by_line) | set(spindle_by_line) | set(per_rev_by_line))
    inch_at = _inch_mode(lines, targets, file) if (feed_by_line or per_rev_by_line) else {}
    per_rev = _per_rev_lines(lines, sorted(feed_by_line), file) if feed_by_line else set()
    for number in targets:
        if number < 1 or number > len(lines):
            raise GCodeError(file, number, "", f"a line number in 1..{len(lines)}", f"line {number} does not exist")
        full = lines[number - 1]
        body = full.rstrip("\r\n")
        eol = full[len(body):]
        lexed = _block_words(body, number, file)
        if not lexed.words:
            raise GCodeError(file, number, body.strip(), "a line holding a block",
                             "cannot put an F or S word on a line without a block", body.strip())
        edits: list[tuple[str, float, int, bool]] = []
        if number in feed_by_line:
            value = float(feed_by_line[number])
            _check(value, number, "F", file, body)
            if number in per_rev:
                raise GCodeError(file, number, "F", "an F word of a G94 line (feed per minute)",
                                 "the F word of this line is a feed per revolution (G95): a feed in mm/min "
                                 "cannot be written there", body.strip())
            inch = inch_at.get(number, False)
            edits.append(("F", value / MM_PER_INCH if inch else value,
                          FEED_DECIMALS_INCH if inch else FEED_DECIMALS_MM, True))
        if number in per_rev_by_line:
            value = float(per_rev_by_line[number])
            _check(value, number, "F", file, body)
            if number in feed_by_line:
                raise GCodeError(file, number, "F", "one F value per line",
                                 "the line is given a feed per minute and a feed per revolution", body.strip())
            inch = inch_at.get(number, False)
            edits.append(("F", value / MM_PER_INCH if inch else value,
                          FEED_PER_REV_DECIMALS_INCH if inch else FEED_PER_REV_DECIMALS_MM, True))
        if number in spindle_by_line:
            value = float(spindle_by_line[number])
            _check(value, number, "S", file, body, allow_zero=True)
            edits.append(("S", value, 0, False))
        for letter, value, decimals, keep_point in edits:
            body = _set_word(body, letter, value, decimals, keep_point, number, file)
        lines[number - 1] = body + eol
    return "".join(lines)


def _check(value: float, number: int, letter: str, file: str, body: str, allow_zero: bool = False) -> None:
    if not math.isfinite(value) or value < 0.0 or (value == 0.0 and not allow_zero):
        raise GCodeError(file, number, f"{letter}{value}", f"a finite {letter} value > 0",
                         f"new {letter} value {value!r} is not valid", body.strip())


def _lex(body: str, number: int, file: str) -> LexedLine:
    try:
        return scan_line(body)  # a Custom Macro B line: its words with plain numbers (see .macro.statements)
    except LexError as exc:
        raise GCodeError(file, number, exc.word, exc.expected, exc.problem, body.strip()) from None


def _block_words(body: str, number: int, file: str) -> LexedLine:
    """The words of a line to rewrite; a word whose value is a macro expression (``F#9``) has the value NaN and
    the expression as its text. Macro statements and G65 calls cannot take an F or S word."""
    try:
        parsed = parse_line(body)
        lexed = lex_line(body) if parsed is None else parsed.static
    except LexError as exc:
        raise GCodeError(file, number, exc.word, exc.expected, exc.problem, body.strip()) from None
    if parsed is not None and not parsed.is_block:
        raise GCodeError(file, number, body.strip(), "a line holding an NC block (G1 X... F...)",
                         "cannot put an F or S word on a macro statement (#i = ..., IF, WHILE, GOTO, DO, END)",
                         body.strip())
    if any(w.letter == "G" and w.value == 65.0 for w in lexed.words):
        raise GCodeError(file, number, "G65", "F and S words of move or spindle blocks",
                         "the line is a G65 macro call: its F and S words are the macro's arguments #9 and #19, "
                         "not the feed or speed of this line, so no number for them can be written", body.strip())
    if parsed is None:
        return lexed
    values = tuple(Word(v.letter.upper(), v.source[1:].lstrip(" \t"), math.nan, v.start, v.end)
                   for v in parsed.statement.values)  # type: ignore[union-attr]
    return LexedLine(tuple(sorted(lexed.words + values, key=lambda w: w.start)), False, lexed.block_delete,
                     lexed.text)


def _set_word(body: str, letter: str, value: float, decimals: int, keep_point: bool, number: int, file: str) -> str:
    lexed = _block_words(body, number, file)
    words = [w for w in lexed.words if w.letter == letter]
    if len(words) > 1:
        raise GCodeError(file, number, letter, f"at most one {letter} word", f"word {letter} appears twice",
                         body.strip())
    if words:
        w: Word = words[0]
        num = _format(value, decimals, keep_point and w.has_point) if decimals else str(int(round(value)))
        head = body[w.start : w.end - len(w.text)]  # letter (original case) and blanks
        return body[: w.start] + head + num + body[w.end :]
    num = _format(value, decimals, False) if decimals else str(int(round(value)))
    end = max(x.end for x in lexed.words)
    letters = [body[x.start] for x in lexed.words if body[x.start].isalpha()]
    if letters and all(c.islower() for c in letters):
        letter = letter.lower()  # a lower-case program gets lower-case words
    return body[:end] + f" {letter}{num}" + body[end:]


def _inch_mode(lines: list[str], targets: list[int], file: str) -> dict[int, bool]:
    """Whether G20 (inch) is active on each target line (G20/G21 on the line itself count)."""
    if not any(("G20" in ln.upper()) or ("G 20" in ln.upper()) for ln in lines):
        return {}
    state: dict[int, bool] = {}
    inch = False
    wanted = set(targets)
    for number, full in enumerate(lines, start=1):
        if number > targets[-1]:
            break
        body = full.rstrip("\r\n")
        for w in _lex(body, number, file).words:
            if w.letter == "G" and w.value in (20.0, 21.0):
                inch = w.value == 20.0
        if number in wanted:
            state[number] = inch
    return state


def per_revolution_lines(text: str, lines: list[int] | tuple[int, ...], file: str = "<text>") -> set[int]:
    """The given 1-based lines on which G95 (feed per revolution) is in effect (a G94/G95 on the line counts).

    Raises
    ------
    GCodeError
        A line up to the last one asked for is malformed.
    """
    targets = sorted(set(int(n) for n in lines))
    return _per_rev_lines(split_lines(text, keepends=True), targets, file) if targets else set()


def _per_rev_lines(lines: list[str], targets: list[int], file: str) -> set[int]:
    """Target lines under G95, in file order (as :func:`_inch_mode`; a subprogram inherits nothing here)."""
    if not targets or not any("95" in ln for ln in lines):
        return set()
    out: set[int] = set()
    per_rev = False
    wanted = set(targets)
    for number, full in enumerate(lines, start=1):
        if number > targets[-1]:
            break
        for w in _lex(full.rstrip("\r\n"), number, file).words:
            if w.letter == "G" and w.value in (94.0, 95.0):
                per_rev = w.value == 95.0
        if number in wanted and per_rev:
            out.add(number)
    return out
