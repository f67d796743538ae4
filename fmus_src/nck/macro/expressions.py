"""Custom Macro B expressions: tokenizer, recursive-descent parser and evaluator (FANUC 0i-MF/31i-B).

Conventions
-----------
* Operators by precedence, highest first (FANUC): functions and ``[ ]`` brackets; ``*`` ``/`` ``AND`` ``MOD``;
  ``+`` ``-`` ``OR`` ``XOR``; comparisons ``EQ NE GT GE LT LE`` (not chained: ``[#1 EQ 1 EQ 2]`` is an error).
  A sign ``-``/``+`` binds to the operand after it (``-#1*2`` is ``[-#1]*2``). Operators of one level run left
  to right. Keywords may be written in either case.
* Values: a number, *vacant* (a variable never set, or ``#0``), or a condition (the result of a comparison).
  A bare reference ``#i``, ``[#i]`` or ``-#i`` of a vacant variable stays vacant; in every other arithmetic a
  vacant value is 0. ``EQ``/``NE`` tell vacant from 0 (``#1 EQ #0`` is true only when #1 is vacant); ``GT GE
  LT LE`` read vacant as 0 (FANUC's rule). Comparisons are exact (FANUC advises GE/LE with a tolerance for
  computed values).
* ``AND OR XOR`` of two conditions combine them (``[[#1 EQ 1] AND [#2 GT 0]]``); of two numbers they act on
  the bits of non-negative integers. ``MOD`` rounds both operands to integers (half away from zero); the
  remainder has the sign of the dividend.
* Functions, angles in degrees: ``SIN COS TAN ASIN ACOS ATAN``; ``ATAN[a]/[b]`` and ``ATAN[a,b]`` is the angle
  of the point (b, a) in 0 <= angle < 360; ``ASIN`` gives 270..360 and 0..90, ``ACOS`` 0..180 (parameter No.
  6004#0 NAT = 0, the default). ``SQRT ABS LN EXP``; ``ROUND`` (half away from zero; inside an address
  expression it rounds to the address's least input increment, 0.001 mm / 0.0001 in, as FANUC), ``FIX``
  (towards zero), ``FUP`` (away from zero); ``BIN`` (BCD to binary), ``BCD`` (binary to BCD). SIN/COS/TAN of
  a multiple of 90 degrees are exact.
* Errors (FANUC macro alarms): division by zero, ``MOD 0``, SQRT of a negative number, LN of a number <= 0,
  ASIN/ACOS outside [-1, 1], TAN at 90 + k 180 degrees, ATAN[0]/[0], a result that is not finite, BIN/BCD
  of a value that is not a non-negative integer (or not BCD), a condition used as a number and a number used
  as a condition: a :class:`~fmus_src.nck.errors.GCodeError` naming the line and the expression.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from decimal import ROUND_HALF_UP, Decimal
from typing import Protocol

from ..errors import GCodeError
from ..lexer import LexError

#: A value: a number, None (vacant) or a condition (bool).
Value = float | bool | None

_TOKEN = re.compile(r"[ \t]*(?:(?P<num>[0-9]+\.?[0-9]*|\.[0-9]+)|(?P<word>[A-Za-z]+)|(?P<op>[#\[\],+\-*/=]))",
                    re.ASCII)
#: Longest number literal accepted in a macro expression, characters (as the lexer's words).
MAX_LITERAL_CHARS = 32
#: Deepest nesting of brackets, function brackets included (FANUC: 5 levels).
MAX_BRACKET_NESTING = 5
#: Most tokens of one macro line (keeps the recursive parser and evaluator shallow; FANUC blocks are short).
MAX_TOKENS = 256
FUNCTIONS = ("SIN", "COS", "TAN", "ASIN", "ACOS", "ATAN", "SQRT", "ABS", "ROUND", "FIX", "FUP", "LN", "EXP",
             "BIN", "BCD")
COMPARISONS = ("EQ", "NE", "GT", "GE", "LT", "LE")
_MUL = ("*", "/", "AND", "MOD")
_ADD = ("+", "-", "OR", "XOR")
_FORMS = "a number, #<n>, #[<expr>], [<expr>] or a function such as SIN[<expr>]"


@dataclass(frozen=True, slots=True)
class Token:
    """One token: ``kind`` is ``num``, ``word`` (upper-cased letters), an operator character, or ``end``."""

    kind: str
    text: str
    pos: int


def tokenize(code: str, start: int = 0, stop: int | None = None) -> list[Token]:
    """Tokens of ``code[start:stop]`` (positions are columns of ``code``), ending with an ``end`` token.

    Raises
    ------
    LexError
        A character that starts no token, or a number longer than :data:`MAX_LITERAL_CHARS`.
    """
    stop = len(code) if stop is None else stop
    out: list[Token] = []
    pos = start
    while True:
        while pos < stop and code[pos] in " \t":
            pos += 1
        if pos >= stop:
            break
        m = _TOKEN.match(code, pos, stop)
        if m is None:
            bad = code[pos]
            raise LexError(bad, f"unexpected character {bad!r} in a macro statement",
                           "numbers, #<n>, [ ], + - * /, = and keywords such as EQ, SIN, GOTO")
        if m.group("num") is not None:
            if len(m.group("num")) > MAX_LITERAL_CHARS:
                raise LexError(m.group("num")[:40], f"number with {len(m.group('num'))} characters",
                               f"at most {MAX_LITERAL_CHARS} characters")
            out.append(Token("num", m.group("num"), m.start("num")))
        elif m.group("word") is not None:
            out.append(Token("word", m.group("word").upper(), m.start("word")))
        else:
            out.append(Token(m.group("op"), m.group("op"), m.start("op")))
        pos = m.end()
    if len(out) > MAX_TOKENS:
        raise LexError(code[start:start + 40], f"a macro line of {len(out)} tokens",
                       f"at most {MAX_TOKENS} tokens (numbers, operators, brackets) per block")
    depth = 0
    for t in out:
        depth += (t.kind == "[") - (t.kind == "]")
        if depth > MAX_BRACKET_NESTING:
            raise LexError("[", f"brackets nested more than {MAX_BRACKET_NESTING} deep",
                           f"at most {MAX_BRACKET_NESTING} levels of [ ] (FANUC), function brackets included")
    out.append(Token("end", "", stop))
    return out


# ----------------------------------------------------------------------------------------------------- nodes
@dataclass(frozen=True, slots=True)
class Num:
    """A number literal."""

    value: float
    text: str


@dataclass(frozen=True, slots=True)
class Var:
    """A variable reference ``#n`` (``index`` a literal int) or ``#[<expr>]`` (``index`` a node)."""

    index: object
    text: str


@dataclass(frozen=True, slots=True)
class Sign:
    """``-x`` or ``+x``."""

    negative: bool
    operand: object
    text: str


@dataclass(frozen=True, slots=True)
class Binary:
    """``left op right`` for the arithmetic, logical and comparison operators."""

    op: str
    left: object
    right: object
    text: str


@dataclass(frozen=True, slots=True)
class Function:
    """``NAME[arg]`` (``ATAN`` with two arguments)."""

    name: str
    args: tuple
    text: str


class Context(Protocol):
    """What evaluation needs: variable reads, errors, and the address rounding of ROUND."""

    increment: float | None

    def read(self, number: int, text: str) -> float | None:
        """Value of variable ``number`` (None: vacant); ``text`` is the reference as written."""

    def fail(self, expression: str, problem: str, expected: str) -> GCodeError:
        """The error of this line for ``expression``."""


# ---------------------------------------------------------------------------------------------------- parser
class Parser:
    """Recursive-descent parser over the tokens of one line.

    Parameters
    ----------
    code : str
        The line's code (comments blanked); node texts are slices of it.
    tokens : list of Token
        From :func:`tokenize`.
    """

    def __init__(self, code: str, tokens: list[Token]) -> None:
        self.code = code
        self.tokens = tokens
        self.i = 0

    @property
    def tok(self) -> Token:
        """The current token."""
        return self.tokens[self.i]

    def take(self) -> Token:
        """The current token; advance."""
        t = self.tokens[self.i]
        if t.kind != "end":
            self.i += 1
        return t

    def expect(self, kind: str, what: str) -> Token:
        """Take a token of ``kind`` or raise a :class:`LexError` saying ``what`` was expected."""
        t = self.tok
        if t.kind != kind:
            raise LexError(t.text or "end of block", f"{self._seen(t)} where {what} was expected", what)
        return self.take()

    def keyword(self, word: str) -> bool:
        """Take the keyword ``word`` if it is the current token."""
        if self.tok.kind == "word" and self.tok.text == word:
            self.take()
            return True
        return False

    def _seen(self, t: Token) -> str:
        return "end of block" if t.kind == "end" else repr(t.text)

    def _text(self, start: int) -> str:
        end = self.tokens[self.i - 1].pos + len(self.tokens[self.i - 1].text) if self.i > 0 else start
        return self.code[start:end].strip()

    def expression(self) -> object:
        """expression := sum [comparison sum]."""
        start = self.tok.pos
        left = self.sum()
        if self.tok.kind == "word" and self.tok.text in COMPARISONS:
            op = self.take().text
            right = self.sum()
            node = Binary(op, left, right, self._text(start))
            if self.tok.kind == "word" and self.tok.text in COMPARISONS:
                raise LexError(self.tok.text, f"comparisons chained in '{node.text} {self.tok.text} ...'",
                               "one comparison per bracket: [[#1 EQ 1] AND [#2 EQ 2]]")
            return node
        return left

    def sum(self) -> object:
        """sum := product {(+ | - | OR | XOR) product}."""
        start = self.tok.pos
        node = self.product()
        while self.tok.text in _ADD and self.tok.kind in ("+", "-", "word"):
            op = self.take().text
            node = Binary(op, node, self.product(), self._text(start))
        return node

    def product(self) -> object:
        """product := signed {(* | / | AND | MOD) signed}."""
        start = self.tok.pos
        node = self.signed()
        while self.tok.text in _MUL and self.tok.kind in ("*", "/", "word"):
            op = self.take().text
            node = Binary(op, node, self.signed(), self._text(start))
        return node

    def signed(self) -> object:
        """signed := (+ | -) signed | primary."""
        start = self.tok.pos
        if self.tok.kind in ("+", "-"):
            negative = self.take().kind == "-"
            if self.tok.kind in ("+", "-"):
                raise LexError(self.tok.text, "two signs in a row", "at most one + or - before a value")
            operand = self.primary()
            return Sign(negative, operand, self._text(start))
        return self.primary()

    def primary(self) -> object:
        """primary := number | variable | [ expression ] | function."""
        t = self.tok
        if t.kind == "num":
            self.take()
            return Num(float(t.text), t.text)
        if t.kind == "#":
            return self.variable()
        if t.kind == "[":
            self.take()
            inner = self.expression()
            self.expect("]", "']' closing the bracket")
            return inner
        if t.kind == "word" and t.text in FUNCTIONS:
            return self.function()
        if t.kind == "word":
            raise LexError(t.text, f"unknown word {t.text!r} in an expression",
                           f"{_FORMS}; functions: {' '.join(FUNCTIONS)}")
        raise LexError(t.text or "end of block", f"{self._seen(t)} where a value was expected", _FORMS)

    def variable(self) -> object:
        """variable := # integer | # [ expression ]."""
        start = self.take().pos
        t = self.tok
        if t.kind == "num":
            self.take()
            if "." in t.text:
                raise LexError("#" + t.text, f"variable number #{t.text} has a decimal point",
                               "#<integer>, e.g. #1, #100, #500")
            return Var(int(t.text), "#" + t.text)
        if t.kind == "[":
            self.take()
            inner = self.expression()
            self.expect("]", "']' closing the variable number #[...]")
            return Var(inner, self._text(start))
        raise LexError("#" + t.text, f"'#' followed by {self._seen(t)}", "a variable #<n> or #[<expression>]")

    def function(self) -> object:
        """function := NAME [ expression ] ; ATAN [ a ] / [ b ] ; ATAN [ a , b ]."""
        start = self.tok.pos
        name = self.take().text
        self.expect("[", f"'[' after {name} ({name}[<expression>])")
        args = [self.expression()]
        if name == "ATAN" and self.tok.kind == ",":
            self.take()
            args.append(self.expression())
        self.expect("]", f"']' closing {name}[...]")
        if name == "ATAN" and len(args) == 1:
            if self.tok.kind != "/" or self.tokens[self.i + 1].kind != "[":
                raise LexError("ATAN", "ATAN with one argument", "ATAN[a]/[b] or ATAN[a,b] (the angle of b, a)")
            self.take()
            self.take()
            args.append(self.expression())
            self.expect("]", "']' closing the second argument of ATAN[a]/[b]")
        return Function(name, tuple(args), self._text(start))


def parse_expression(code: str, start: int = 0, stop: int | None = None) -> object:
    """Parse ``code[start:stop]`` as one whole expression.

    Raises
    ------
    LexError
        A syntax error, or words left over after the expression.
    """
    parser = Parser(code, tokenize(code, start, stop))
    node = parser.expression()
    if parser.tok.kind != "end":
        raise LexError(parser.tok.text, f"{parser.tok.text!r} after the expression '{node_text(node)}'",
                       "an operator (+ - * / AND OR ...) or the end of the block")
    return node


def node_text(node: object) -> str:
    """The source text of a node."""
    return getattr(node, "text")


# ------------------------------------------------------------------------------------------------ evaluation
def evaluate(node: object, ctx: Context) -> Value:
    """Value of ``node``: a float, None (vacant) or a bool (a condition)."""
    if isinstance(node, Num):
        return node.value
    if isinstance(node, Var):
        return ctx.read(variable_number(node, ctx), node.text)
    if isinstance(node, Sign):
        v = evaluate(node.operand, ctx)
        if v is None:
            return None
        x = _number(v, node.operand, ctx)
        return -x if node.negative else x
    if isinstance(node, Binary):
        if node.op in COMPARISONS:
            return _compare(node, ctx)
        return _binary(node, ctx)
    if isinstance(node, Function):
        return _function(node, ctx)
    raise TypeError(f"not an expression node: {node!r}")


def variable_number(node: Var, ctx: Context) -> int:
    """The number of the variable a :class:`Var` names (its ``#[<expr>]`` evaluated)."""
    if isinstance(node.index, int):
        return node.index
    v = evaluate(node.index, ctx)
    if v is None or isinstance(v, bool):
        raise ctx.fail(node.text, f"the variable number of {node.text} is {'vacant' if v is None else 'a condition'}",
                       "a number in #[<expression>]")
    n = round(v)
    if abs(v - n) > 1e-9 or n < 0:
        raise ctx.fail(node.text, f"the variable number of {node.text} is {v:.6g}", "a non-negative integer")
    return int(n)


def condition(node: object, ctx: Context, text: str) -> bool:
    """The truth of the condition ``node`` (a comparison, or comparisons joined by AND/OR/XOR)."""
    v = evaluate(node, ctx)
    if not isinstance(v, bool):
        raise ctx.fail(text, f"[{text}] is a number, not a condition",
                       "a comparison such as [#1 EQ 0] or [#2 GT 5.]")
    return v


def _number(v: Value, node: object, ctx: Context) -> float:
    if isinstance(v, bool):
        raise ctx.fail(node_text(node), f"the condition [{node_text(node)}] used as a number",
                       "a number (comparisons only in IF/WHILE conditions)")
    return 0.0 if v is None else v


def _finite(x: float, node: object, ctx: Context) -> float:
    if not math.isfinite(x):
        raise ctx.fail(node_text(node), f"{node_text(node)} overflows (|value| too large)", "a finite result")
    return x


def _integer(x: float, node: object, ctx: Context, what: str) -> int:
    if x < 0 or x != int(x):
        raise ctx.fail(node_text(node), f"{what} of {x:.6g} in {node_text(node)}: not a non-negative integer",
                       "non-negative integers")
    return int(x)


def round_half_away(x: float, increment: float = 1.0) -> float:
    """``x`` rounded to a multiple of ``increment`` (1, 0.001, 0.0001), half away from zero, decimally."""
    if not abs(x) < 1e15:  # already a multiple of every increment at this size (and beyond any address range)
        return x
    step = Decimal(repr(increment)).normalize()  # 1.0 -> 1 (not a step of 0.1)
    return float(Decimal(repr(x)).quantize(step, rounding=ROUND_HALF_UP))


def _compare(node: Binary, ctx: Context) -> bool:
    a, b = evaluate(node.left, ctx), evaluate(node.right, ctx)
    if isinstance(a, bool) or isinstance(b, bool):
        raise ctx.fail(node.text, f"a condition compared in [{node.text}]", "numbers on both sides of EQ NE GT ...")
    if node.op in ("EQ", "NE"):
        same = (a is None and b is None) or (a is not None and b is not None and a == b)
        return same if node.op == "EQ" else not same
    x, y = (0.0 if a is None else a), (0.0 if b is None else b)
    return {"GT": x > y, "GE": x >= y, "LT": x < y, "LE": x <= y}[node.op]


def _binary(node: Binary, ctx: Context) -> Value:
    a, b = evaluate(node.left, ctx), evaluate(node.right, ctx)
    if node.op in ("AND", "OR", "XOR") and (isinstance(a, bool) or isinstance(b, bool)):
        if not (isinstance(a, bool) and isinstance(b, bool)):
            raise ctx.fail(node.text, f"{node.op} of a condition and a number in {node.text}",
                           f"two conditions ([#1 EQ 1] {node.op} [#2 EQ 2]) or two integers")
        return {"AND": a and b, "OR": a or b, "XOR": a != b}[node.op]
    x, y = _number(a, node.left, ctx), _number(b, node.right, ctx)
    if node.op == "+":
        return _finite(x + y, node, ctx)
    if node.op == "-":
        return _finite(x - y, node, ctx)
    if node.op == "*":
        return _finite(x * y, node, ctx)
    if node.op == "/":
        if y == 0.0:
            raise ctx.fail(node.text, f"division by zero in {node.text} (FANUC alarm)", "a divisor that is not 0")
        return _finite(x / y, node, ctx)
    if node.op == "MOD":
        i, k = round_half_away(x), round_half_away(y)
        if k == 0.0:
            raise ctx.fail(node.text, f"{node.text}: MOD by 0 (FANUC alarm)", "a divisor that is not 0")
        return math.fmod(i, k)
    i, k = _integer(x, node.left, ctx, node.op), _integer(y, node.right, ctx, node.op)
    return float({"AND": i & k, "OR": i | k, "XOR": i ^ k}[node.op])


def _exact_trig(name: str, degrees: float) -> float | None:
    """SIN/COS/TAN at a multiple of 90 degrees, exactly (None elsewhere, or for TAN at 90 + k 180)."""
    if degrees % 90.0 != 0.0:
        return None
    quarter = int(degrees % 360.0 // 90.0)
    sin, cos = (0.0, 1.0, 0.0, -1.0)[quarter], (1.0, 0.0, -1.0, 0.0)[quarter]
    if name == "SIN":
        return sin
    if name == "COS":
        return cos
    return None if cos == 0.0 else sin / cos


def _function(node: Function, ctx: Context) -> float:
    vals = [_number(evaluate(a, ctx), a, ctx) for a in node.args]
    x = vals[0]
    name = node.name

    def fail(problem: str, expected: str) -> GCodeError:
        return ctx.fail(node.text, f"{node.text}: {problem} (FANUC alarm)", expected)

    if name in ("SIN", "COS", "TAN"):
        exact = _exact_trig(name, x)
        if exact is not None:
            return exact
        if name == "TAN" and x % 180.0 == 90.0:
            raise fail(f"TAN of {x:.6g} degrees is infinite", "an angle other than 90 + k*180 degrees")
        return {"SIN": math.sin, "COS": math.cos, "TAN": math.tan}[name](math.radians(x))
    if name in ("ASIN", "ACOS"):
        if not -1.0 <= x <= 1.0:
            raise fail(f"{name} of {x:.6g} is outside [-1, 1]", "an argument in [-1, 1]")
        if name == "ACOS":
            return math.degrees(math.acos(x))
        angle = math.degrees(math.asin(x))
        return angle + 360.0 if angle < 0.0 else angle
    if name == "ATAN":
        a, b = vals
        if a == 0.0 and b == 0.0:
            raise fail("ATAN[0]/[0] has no angle", "a point other than (0, 0)")
        angle = math.degrees(math.atan2(a, b))
        return angle + 360.0 if angle < 0.0 else angle
    if name == "SQRT":
        if x < 0.0:
            raise fail(f"square root of the negative number {x:.6g}", "an argument >= 0")
        return math.sqrt(x)
    if name == "ABS":
        return abs(x)
    if name == "LN":
        if x <= 0.0:
            raise fail(f"logarithm of {x:.6g}", "an argument > 0")
        return math.log(x)
    if name == "EXP":
        if x > 709.0:
            raise fail(f"EXP of {x:.6g} overflows", "an argument <= 709")
        return math.exp(x)
    if name == "ROUND":
        return round_half_away(x, ctx.increment or 1.0)
    if name == "FIX":
        return float(math.trunc(x))
    if name == "FUP":
        return float(math.trunc(x)) if x == math.trunc(x) else float(math.trunc(x) + math.copysign(1.0, x))
    if name == "BCD":
        n = _integer(x, node, ctx, "BCD")
        if n > 99999999:
            raise fail(f"{n} has more than 8 decimal digits", "0..99999999")
        return float(int(str(n), 16))
    n = _integer(x, node, ctx, "BIN")
    digits = f"{n:x}"
    if any(d not in "0123456789" for d in digits):
        raise fail(f"{n} is not a BCD number (hex {digits})", "a value whose 4-bit groups are 0..9")
    return float(int(digits))
