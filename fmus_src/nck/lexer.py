"""Lexer: one source line → words with their columns (shared by interpreter and writer).

Rules (FANUC milling dialect):

* ``( ... )`` comments anywhere on the line (several allowed, not nested);
  ``;`` starts a comment running to the end of the line.
* A line starting with ``%`` is a tape start/end marker; the rest of the line (``%O1000``, ``% (comment)``,
  as some posts and DNC senders write it) is not read.
* A ``/`` as first non-blank character marks a block-delete block.
* A ``:`` as first non-blank character (after a ``/``) is the ISO program number address, read as ``O``
  (FANUC: ``:1000`` is ``O1000``; messages show it as ``O1000``).
* A word is a letter (either case) followed by a number; blanks between the
  letter and the number are allowed. Numbers: optional sign, digits with an
  optional decimal point (``10``, ``10.``, ``-.5``).
* Optional chamfer / corner R words (FANUC): a comma, ``C`` or ``R`` and a number (``,C1.``, ``, R 2``,
  also right after a number: ``X10,C1``) are one word with the letter ``",C"`` / ``",R"``. A comma before
  any other letter is an error; a comma before no letter is an unexpected character.
* Lines end at LF, CRLF or CR only (form feed, U+2028 etc. stay in the line
  and are rejected as unexpected characters), so line numbers match editors.
* A DOS end-of-file mark (Ctrl-Z, ``\x1a``) that old editors and DNC programs append ends the text
  (:func:`without_dos_eof`); a Ctrl-Z followed by more than blanks and Ctrl-Z is an unexpected character.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

_COMMENT = re.compile(r"\([^()]*\)")
_TOKEN = re.compile(r"([A-Za-z])[ \t]*([^A-Za-z \t(;/]*)|([ \t]+)|(.)", re.ASCII | re.DOTALL)
# ASCII digits only (``\d`` would accept e.g. Arabic-Indic digits); unambiguous, so a long run of
# digits followed by a bad character fails in linear time (``\d+\.?\d*`` backtracks quadratically)
_NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)\Z", re.ASCII)
#: Line endings of a program: LF, CRLF, CR (nothing else, unlike :meth:`str.splitlines`).
_EOL = re.compile(r"\r\n|\r|\n")
#: An optional chamfer / corner R word (FANUC ``,C1.``, ``,R2.``): comma, letter, number (checked later).
_COMMA_WORD = re.compile(r",[ \t]*([A-Za-z])[ \t]*([^A-Za-z \t(;/,]*)", re.ASCII)
#: Letters a comma word may have: chamfer C, corner R (:mod:`.corners`).
COMMA_LETTERS = ("C", "R")
#: Longest number accepted in a word, characters (FANUC accepts at most 8 digits plus sign and point).
MAX_NUMBER_CHARS = 32


@dataclass(frozen=True, slots=True)
class Word:
    """One word of a block.

    Attributes
    ----------
    letter : str
        Upper-case address letter.
    text : str
        The number as written (``"-12.5"``).
    value : float
        The number.
    start, end : int
        Column span ``[start, end)`` of the whole word in the source line.
    variable : bool
        The value came from a Custom Macro B variable or expression (``X#24``): a real value, never a count of
        least input increments (:mod:`.decimal_input`).
    """

    letter: str
    text: str
    value: float
    start: int
    end: int
    variable: bool = False

    @property
    def has_point(self) -> bool:
        """True when the number was written with a decimal point."""
        return "." in self.text


@dataclass(frozen=True, slots=True)
class LexedLine:
    """Result of lexing one line.

    Attributes
    ----------
    words : tuple of Word
        Words in source order.
    percent : bool
        The line is a ``%`` marker.
    block_delete : bool
        The line starts with ``/``.
    text : str
        The block text without line ending, stripped (used in messages).
    """

    words: tuple[Word, ...]
    percent: bool
    block_delete: bool
    text: str


class LexError(ValueError):
    """Raised by :func:`lex_line`; the caller turns it into a :class:`GCodeError`."""

    def __init__(self, word: str, problem: str, expected: str) -> None:
        super().__init__(problem)
        self.word = word
        self.problem = problem
        self.expected = expected


def clip(text: str, limit: int = 60) -> str:
    """``text`` cut to ``limit`` characters (with ``...`` and the total length) for messages."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text)} characters)"


def lex_line(raw: str) -> LexedLine:
    """Split one source line (without its line ending) into words.

    Parameters
    ----------
    raw : str
        The line as in the file.

    Returns
    -------
    LexedLine

    Raises
    ------
    LexError
        Unclosed or unopened comment, a word without a value, a malformed
        number, or a character that starts no word.
    """
    text = raw.strip()
    if text.startswith("%"):
        return LexedLine((), True, False, text)
    code = raw
    if "(" in code or ")" in code:
        code = _COMMENT.sub(lambda m: " " * len(m.group(0)), code)
        if "(" in code.split(";", 1)[0]:
            raise LexError("(", "comment '(' is not closed", "a ')' closing the comment on the same line")
        if ")" in code.split(";", 1)[0]:
            raise LexError(")", "')' without an opening '('", "comments written as ( ... )")
    semi = code.find(";")
    if semi >= 0:
        code = code[:semi]
    block_delete = False
    stripped = code.lstrip()
    if stripped.startswith("/"):
        block_delete = True
        col = len(code) - len(stripped)
        code = code[:col] + " " + code[col + 1 :]
    stripped = code.lstrip()
    if stripped.startswith(":"):  # ISO program number ":1000" = O1000 (FANUC), same column
        col = len(code) - len(stripped)
        code = code[:col] + "O" + code[col + 1 :]
    code, words = _comma_words(code)
    for m in _TOKEN.finditer(code):
        letter = m.group(1)
        if letter is None:
            if m.group(4) is not None:
                bad = m.group(4)
                raise LexError(bad, f"unexpected character {bad!r}", "words made of a letter and a number")
            continue
        num = m.group(2)
        if not num:
            raise LexError(letter.upper(), f"word {letter.upper()!r} has no value", f"a number after {letter.upper()}")
        if not _NUMBER.match(num):
            word = clip(letter.upper() + num)
            raise LexError(word, f"malformed number {clip(num)!r} in word {word}", "a number like 12, -3.5 or .25")
        if len(num) > MAX_NUMBER_CHARS:
            raise LexError(clip(letter.upper() + num), f"number in word {letter.upper()} has {len(num)} characters",
                           f"at most {MAX_NUMBER_CHARS} characters (FANUC accepts at most 8 digits)")
        words.append(Word(letter.upper(), num, float(num), m.start(), m.end(2)))
    words.sort(key=lambda w: w.start)
    return LexedLine(tuple(words), False, block_delete, text)


def _comma_words(code: str) -> tuple[str, list[Word]]:
    """The ``,C``/``,R`` words of a line, and the line with them blanked (columns kept) for the other words."""
    if "," not in code:
        return code, []
    words: list[Word] = []
    for m in _COMMA_WORD.finditer(code):
        name, num = "," + m.group(1).upper(), m.group(2)
        if name[1] not in COMMA_LETTERS:
            raise LexError(clip(name + num), f"comma word {name} is not supported",
                           "',C' (chamfer) or ',R' (corner R) followed by a number")
        if not num:
            raise LexError(name, f"word {name!r} has no value", f"a number after {name}")
        if not _NUMBER.match(num) or len(num) > MAX_NUMBER_CHARS:
            word = clip(name + num)
            raise LexError(word, f"malformed number {clip(num)!r} in word {word}",
                           f"a number like 12, -3.5 or .25 of at most {MAX_NUMBER_CHARS} characters")
        words.append(Word(name, num, float(num), m.start(), m.end(2)))
    return _COMMA_WORD.sub(lambda m: " " * len(m.group(0)), code), words


def split_lines(text: str, keepends: bool = False) -> list[str]:
    """Split a program into source lines at LF, CRLF or CR only.

    :meth:`str.splitlines` also splits at form feed, vertical tab, NEL,
    U+2028 etc.; editors and the NC count only LF/CRLF/CR, so line numbers
    in messages would disagree with the file. Such characters stay inside a
    line (and are then reported as unexpected characters).

    Parameters
    ----------
    text : str
        Program source.
    keepends : bool
        Keep the line endings (as :meth:`str.splitlines`).

    Returns
    -------
    list of str
        Lines; a final line ending does not start an empty line (as :meth:`str.splitlines`).
    """
    out: list[str] = []
    pos = 0
    for m in _EOL.finditer(text):
        out.append(text[pos : m.end() if keepends else m.start()])
        pos = m.end()
    if pos < len(text):
        out.append(text[pos:])
    return out


#: DOS end-of-file mark (Ctrl-Z, ASCII SUB).
DOS_EOF = "\x1a"


def without_dos_eof(text: str) -> str:
    """``text`` without a trailing DOS end-of-file mark (Ctrl-Z) and what follows it (blanks, line ends).

    Parameters
    ----------
    text : str
        Program source.

    Returns
    -------
    str
        The text up to the first Ctrl-Z when only blanks, line ends and Ctrl-Z follow it; else ``text``
        unchanged (a Ctrl-Z inside the program stays an unexpected character). The lines before it keep
        their numbers.
    """
    at = text.find(DOS_EOF)
    if at < 0 or text[at:].replace(DOS_EOF, "").strip():
        return text
    return text[:at]
