"""Custom Macro B lines: telling them from plain NC blocks, and parsing them into statements.

Conventions
-----------
* A line is a macro line when its code (comments removed) holds ``#`` or ``[``, or starts (after an optional
  ``/`` and ``N<n>``) with ``IF``, ``WHILE``, ``GOTO``, ``DO`` or ``END``. Every other line goes to the plain
  lexer unchanged (:mod:`..lexer`), with its errors. None of these can start a valid plain block.
* Statements, each alone in its block, optionally after a sequence number ``N<n>``: ``#i = <expr>``
  (``#[<expr>] = <expr>`` too); ``GOTO <n>`` (a number, ``#i`` or ``[<expr>]``); ``IF [<cond>] GOTO <n>``;
  ``IF [<cond>] THEN #i = <expr>``; ``WHILE [<cond>] DO m``; ``DO m``; ``END m`` (m = 1, 2 or 3).
* NC blocks with variables: a word's value may be ``#i``, ``#[<expr>]``, ``[<expr>]``, or one of them with a
  sign (``X-#24``, ``Z[#26+1.]``, ``F#9``, ``G#10``). Words with plain numbers are read by the plain lexer.
  A statement and NC words in one block (``G1 X1 #1=2``) are an error.
* ``#3000 = <n> (MESSAGE)``: the comment is the alarm message (:mod:`.runtime`).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from ..lexer import LexedLine, LexError, lex_line
from .expressions import Parser, Var, node_text, tokenize

_COMMENT = re.compile(r"\([^()]*\)")
_KEYWORDS = ("IF", "WHILE", "GOTO", "DO", "END")
_START = re.compile(r"[ \t]*/?[ \t]*(?:[Nn][ \t]*[0-9]+[ \t]*)?(?:IF|WHILE|GOTO|DO|END)(?![A-Za-z])",
                    re.IGNORECASE | re.ASCII)
_ANY = re.compile(r"IF|WHILE|GOTO|DO|END", re.IGNORECASE | re.ASCII)
_LABEL = re.compile(r"[ \t]*[Nn][ \t]*([0-9]+)", re.ASCII)
_LITERAL = re.compile(r"[^A-Za-z \t(;/#\[\]]*", re.ASCII)
#: Loop identification numbers of DO/END (FANUC: 1, 2, 3).
LOOP_IDS = (1, 2, 3)


@dataclass(frozen=True)
class Assign:
    """``#i = <expr>``: ``target`` a :class:`~.expressions.Var`, ``value`` an expression node."""

    target: Var
    value: object


@dataclass(frozen=True)
class Goto:
    """``GOTO <n>`` (``condition`` None) or ``IF [<cond>] GOTO <n>``."""

    target: object
    condition: object | None = None


@dataclass(frozen=True)
class IfThen:
    """``IF [<cond>] THEN #i = <expr>``."""

    condition: object
    assign: Assign


@dataclass(frozen=True)
class Loop:
    """``WHILE [<cond>] DO m`` (``condition`` set), ``DO m`` (None) or ``END m`` (``end`` True)."""

    loop_id: int
    condition: object | None = None
    end: bool = False


@dataclass(frozen=True)
class AddressValue:
    """A word whose value is an expression: ``letter`` as written, ``node``, columns ``[start, end)`` and the
    ``source`` text of the word (``F[#9 * 2]``)."""

    letter: str
    node: object
    start: int
    end: int
    source: str


@dataclass(frozen=True)
class NCBlock:
    """An NC block with variable words: ``pieces`` are source text (str) and :class:`AddressValue` in order."""

    pieces: tuple

    @property
    def values(self) -> tuple[AddressValue, ...]:
        """The words whose value is an expression."""
        return tuple(p for p in self.pieces if isinstance(p, AddressValue))


Statement = Assign | Goto | IfThen | Loop | NCBlock


@dataclass(frozen=True)
class MacroLine:
    """One parsed macro line.

    Attributes
    ----------
    statement : Statement
    label : int or None
        Sequence number N of a statement line (an NC block keeps its N word among its pieces).
    block_delete : bool
        The line starts with ``/``.
    text : str
        The line, stripped (quoted in messages).
    comment : str
        The text of its first ``( )`` comment ("" without), the message of ``#3000``.
    static : LexedLine
        The words with plain numbers (a statement: its N word only), for scans that need no values (program
        ends, M99, sequence numbers, G20/G95 modes).
    """

    statement: Statement
    label: int | None
    block_delete: bool
    text: str
    comment: str
    static: LexedLine

    @property
    def is_block(self) -> bool:
        """True for an NC block (not a statement)."""
        return isinstance(self.statement, NCBlock)

    @property
    def is_call(self) -> bool:
        """True for a G65 block (a literal G65 word)."""
        return self.is_block and any(w.letter == "G" and w.value == 65.0 for w in self.static.words)


def _code(raw: str) -> str | None:
    """The line's code: comments blanked, ``;`` and after dropped; None for unbalanced comments (the plain
    lexer reports them) and ``%`` lines."""
    if raw.lstrip().startswith("%"):
        return None
    code = _COMMENT.sub(lambda m: " " * len(m.group(0)), raw) if "(" in raw or ")" in raw else raw
    semi = code.find(";")
    if semi >= 0:
        code = code[:semi]
    if "(" in code or ")" in code:
        return None
    return code


def is_macro_line(raw: str) -> bool:
    """True when ``raw`` is a Custom Macro B line (see the module conventions)."""
    if "#" not in raw and "[" not in raw and not _START.match(raw) and not ("(" in raw and _ANY.search(raw)):
        return False
    code = _code(raw)
    return code is not None and ("#" in code or "[" in code or _START.match(code) is not None)


def parse_line(raw: str) -> MacroLine | None:
    """Parse a macro line; None for a plain line (see :func:`is_macro_line`).

    Raises
    ------
    LexError
        A malformed statement or expression.
    """
    if not is_macro_line(raw):
        return None
    code = _code(raw)
    assert code is not None
    comment_match = _COMMENT.search(raw)
    comment = comment_match.group(0)[1:-1].strip() if comment_match else ""
    text = raw.strip()
    stripped = code.lstrip()
    block_delete = stripped.startswith("/")
    if block_delete:
        col = len(code) - len(stripped)
        code = code[:col] + " " + code[col + 1:]
    label_match = _LABEL.match(code)
    rest = label_match.end() if label_match else 0
    after = code[rest:].lstrip()
    first = re.match(r"[A-Za-z]+", after)
    if after.startswith("#") or (first and first.group(0).upper() in _KEYWORDS):
        label = int(label_match.group(1)) if label_match else None
        statement = _statement(code, rest)
        static = LexedLine(() if label_match is None else lex_line(code[:rest]).words, False, block_delete, text)
        return MacroLine(statement, label, block_delete, text, comment, static)
    block = _nc_block(code)
    literal = "".join(p if isinstance(p, str) else " " * (p.end - p.start) for p in block.pieces)
    static = LexedLine(lex_line(literal).words, False, block_delete, text)
    return MacroLine(block, None, block_delete, text, comment, static)


def _statement(code: str, start: int) -> Statement:
    p = Parser(code, tokenize(code, start))
    t = p.tok
    if t.kind == "#":
        statement: Statement = _assign(p)
    else:
        word = p.take().text
        if word == "GOTO":
            statement = Goto(_goto_target(p))
        elif word == "IF":
            cond = _condition(p, "IF")
            if p.keyword("GOTO"):
                statement = Goto(_goto_target(p), cond)
            elif p.keyword("THEN"):
                if p.tok.kind != "#":
                    raise LexError(p.tok.text or "THEN", "THEN without an assignment",
                                   "IF [<condition>] THEN #<n> = <expression>")
                statement = IfThen(cond, _assign(p))
            else:
                raise LexError(p.tok.text or "IF", f"IF [{node_text(cond)}] without GOTO or THEN",
                               "IF [<condition>] GOTO <n> or IF [<condition>] THEN #<n> = <expression>")
        elif word == "WHILE":
            cond = _condition(p, "WHILE")
            if not p.keyword("DO"):
                raise LexError(p.tok.text or "WHILE", f"WHILE [{node_text(cond)}] without DO",
                               "WHILE [<condition>] DO1 (DO2, DO3)")
            statement = Loop(_loop_id(p, "DO"), cond)
        elif word == "DO":
            statement = Loop(_loop_id(p, "DO"))
        else:  # END
            statement = Loop(_loop_id(p, "END"), end=True)
    if p.tok.kind != "end":
        raise LexError(p.tok.text, f"{p.tok.text!r} after the statement",
                       "one macro statement per block, alone (no NC words with it)")
    return statement


def _assign(p: Parser) -> Assign:
    target = p.variable()
    assert isinstance(target, Var)
    p.expect("=", f"'=' after {target.text} (an assignment {target.text} = <expression>)")
    if p.tok.kind == "end":
        raise LexError(target.text, f"nothing after '{target.text} ='", f"{target.text} = <expression>")
    return Assign(target, p.expression())


def _condition(p: Parser, keyword: str) -> object:
    if p.tok.kind != "[":
        raise LexError(keyword, f"{keyword} without a bracketed condition", f"{keyword} [<condition>], e.g. "
                       f"{keyword} [#1 LT 10]")
    p.take()
    cond = p.expression()
    p.expect("]", f"']' closing the condition of {keyword}")
    return cond


def _goto_target(p: Parser) -> object:
    if p.tok.kind == "end":
        raise LexError("GOTO", "GOTO without a sequence number", "GOTO <n>, GOTO #<i> or GOTO [<expression>]")
    return p.signed()


def _loop_id(p: Parser, keyword: str) -> int:
    t = p.tok
    if t.kind != "num" or "." in t.text or int(t.text) not in LOOP_IDS:
        shown = keyword + (t.text if t.kind != "end" else "")
        raise LexError(shown, f"{shown}: the loop identification number is not 1, 2 or 3",
                       f"{keyword}1, {keyword}2 or {keyword}3")
    p.take()
    return int(t.text)


def _nc_block(code: str) -> NCBlock:
    pieces: list = []
    i, n = 0, len(code)
    while i < n:
        c = code[i]
        if c.isascii() and c.isalpha():
            k = i + 1
            while k < n and code[k] in " \t":
                k += 1
            sign_then = k + 1 < n and code[k] in "+-" and code[k + 1:].lstrip(" \t")[:1] in ("#", "[")
            if k < n and (code[k] in "#[" or sign_then):
                p = Parser(code, tokenize(code, k))
                node = p.signed()
                end = p.tokens[p.i - 1].pos + len(p.tokens[p.i - 1].text)
                pieces.append(AddressValue(c, node, i, end, code[i:end]))
                i = end
                continue
            m = _LITERAL.match(code, k)
            pieces.append(code[i:m.end()])
            i = m.end()
            continue
        if c == "#":
            raise LexError("#", "a macro statement and NC words in one block",
                           "#<n> = <expression> alone in its block, or a variable as the value of a word (X#1)")
        if c == "[":
            raise LexError("[", "'[' not after an address letter",
                           "an expression as the value of a word: X[#1+2.], or a statement such as IF [...]")
        pieces.append(c)
        i += 1
    return NCBlock(tuple(pieces))


def scan_line(raw: str) -> LexedLine:
    """The words of a line with plain numbers, for scans that need no variable values.

    A plain line is :func:`..lexer.lex_line`; a macro line gives its literal words (a statement: its N word).

    Raises
    ------
    LexError
        As :func:`..lexer.lex_line`, or a malformed macro line.
    """
    parsed = parse_line(raw)
    return lex_line(raw) if parsed is None else parsed.static

