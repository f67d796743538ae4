"""The words of an NC block with variables: expression values rounded to the address, as FANUC does.

Conventions
-----------
* A word whose value is vacant (``X#1`` with #1 vacant, also ``X-#1`` and ``X[#1]``) is left out of the block:
  ``G90 X#1`` is ``G90``. Any arithmetic makes a vacant value 0 (``X[#1+0]`` is ``X0``).
* The value is rounded (half away from zero) to the address's least input increment: 0.001 mm (0.0001 in under
  G20) for X Y Z I J K R Q F (and the other real-valued letters); the nearest integer for M S T H D N O P L; one
  decimal for G (``G#10`` with #10 = 54.1 is G54.1). ``ROUND[...]`` inside the word rounds to the same increment.
* A variable's value is a real value: X, Y, Z, I, J, R and F words from variables have a decimal point, so
  ``X#1`` with #1 = 10 is 10 mm and ``G4 X#1`` dwells #1 seconds (the twin reads numbers without a point in mm
  anyway, calculator-type input). K and Q get a point only when not integral (K is also a repeat count).
* The resulting text goes through the plain lexer (:func:`..lexer.lex_line`), so a block with variables is
  read exactly as the same block written with those numbers; the words from expressions are marked
  (:attr:`..lexer.Word.variable`), so that decimal point input DPI = 0 (:mod:`..decimal_input`) leaves them real.
"""
from __future__ import annotations

import dataclasses

from ..lexer import LexedLine, LexError, lex_line
from .expressions import Context, evaluate, round_half_away
from .statements import AddressValue, NCBlock

#: Least input increment of a length, mm (G21) and inch (G20) programs.
INCREMENT_MM = 0.001
INCREMENT_INCH = 0.0001
#: Addresses holding integers (rounded to the nearest integer, written without a point).
INTEGER_ADDRESSES = "MSTHDNOPL"
#: Addresses that are a length or a count (a point only when the value is not integral).
COUNT_OR_LENGTH = "KQ"


def address_increment(letter: str, inch: bool) -> float:
    """The rounding step of an address's value: 0.1 for G, 1 for integer addresses, else the length increment."""
    letter = letter.upper()
    if letter == "G":
        return 0.1
    if letter in INTEGER_ADDRESSES:
        return 1.0
    return INCREMENT_INCH if inch else INCREMENT_MM


def address_text(letter: str, value: float, inch: bool) -> str:
    """The number written for ``value`` in a word of ``letter`` (see the module conventions)."""
    up = letter.upper()
    v = round_half_away(value, address_increment(up, inch))
    if up in INTEGER_ADDRESSES:
        return str(int(v))
    if up == "G":
        return f"{v:.1f}".removesuffix(".0")
    text = f"{v:.{4 if inch else 3}f}".rstrip("0")
    if up in COUNT_OR_LENGTH and text.endswith("."):
        text = text[:-1]
    return text


def block_inch(block: NCBlock, inch: bool) -> bool:
    """Whether the block's numbers are in inch: a literal G20/G21 in the block, else the mode ``inch``."""
    for piece in block.pieces:
        if isinstance(piece, str) and piece[:1] in "Gg":
            try:
                words = lex_line(piece).words
            except LexError:
                continue
            if words and words[0].value in (20.0, 21.0):
                return words[0].value == 20.0
    return inch


def value_of(piece: AddressValue, ctx: Context, inch: bool) -> float | None:
    """The value of an expression word (None: vacant), ROUND inside it rounding to the address increment."""
    ctx.increment = address_increment(piece.letter, inch)
    try:
        v = evaluate(piece.node, ctx)
    finally:
        ctx.increment = None
    if isinstance(v, bool):
        shown = piece.source
        raise ctx.fail(shown, f"the word {shown} has a condition as its value",
                       "a number: comparisons only in IF/WHILE conditions")
    return v


def evaluate_block(block: NCBlock, ctx: Context, inch: bool, block_delete: bool, text: str) -> LexedLine:
    """The block's words with the expression values written in (vacant words left out).

    Parameters
    ----------
    block : NCBlock
    ctx : Context
        Variables and errors of the line.
    inch : bool
        G20 in effect before the block.
    block_delete, text : bool, str
        Of the source line (``text`` is quoted in messages).

    Raises
    ------
    LexError
        The resulting block is malformed (as the plain lexer says).
    GCodeError
        An expression cannot be evaluated.
    """
    inch = block_inch(block, inch)
    parts: list[str] = []
    starts: set[int] = set()  # columns where a word from an expression starts
    column = 0
    for piece in block.pieces:
        if isinstance(piece, str):
            parts.append(piece)
            column += len(piece)
            continue
        v = value_of(piece, ctx, inch)
        if v is not None:
            starts.add(column + 1)
        written = " " if v is None else f" {piece.letter}{address_text(piece.letter, v, inch)} "
        parts.append(written)
        column += len(written)
    lexed = lex_line("".join(parts))
    words = tuple(dataclasses.replace(w, variable=True) if w.start in starts else w for w in lexed.words)
    return LexedLine(words, False, block_delete, text)
