"""FANUC Custom Macro B in the NC kernel: expected numbers derived by hand from the 0i-MF/31i-B rules."""
from __future__ import annotations

import math

import numpy as np
import pytest

import fmus_src.nck.macro.runtime as macro_runtime
from fmus_src.nck.blocks import Linear, Rapid, SpindleSpeed
from fmus_src.nck.errors import GCodeError
from fmus_src.nck.interpreter import interpret
from fmus_src.nck.lexer import LexError
from fmus_src.nck.macro.expressions import evaluate, parse_expression
from fmus_src.nck.overrides import apply_overrides
from fmus_src.nck.writer import rewrite_program

MPM = 1e-3 / 60.0  # mm/min -> m/s
RPM = 2.0 * np.pi / 60.0


class _Ctx:
    """A stand-in evaluation context: variables from a dict (missing = vacant), errors as GCodeError."""

    def __init__(self, **variables: float) -> None:
        self.vars = {int(k[1:]): v for k, v in variables.items()}
        self.increment = None

    def read(self, number, text):
        return self.vars.get(number)

    def fail(self, expression, problem, expected):
        return GCodeError("<expr>", 1, expression, expected, problem)


def value(expression: str, **variables: float):
    return evaluate(parse_expression(expression), _Ctx(**variables))


def _mm(p):
    return [round(v * 1e3, 9) for v in p]


def _moves(program, kind=(Rapid, Linear)):
    return [(b.line, _mm(b.end)) for b in program.blocks if isinstance(b, kind)]


def _error(text: str) -> GCodeError:
    with pytest.raises(GCodeError) as info:
        interpret(text, file="m.nc")
    return info.value


# --------------------------------------------------------------------------------------------- expressions
@pytest.mark.parametrize("expression, expected", [
    ("2 + 3 * 4", 14.0),          # * before +
    ("[2 + 3] * 4", 20.0),
    ("2 * 3 + 4 * 5", 26.0),
    ("10 - 2 - 3", 5.0),          # left to right
    ("8 / 4 / 2", 1.0),
    ("-2 * 3", -6.0),
    ("1 + 2 AND 3", 3.0),         # AND is on the level of *: 1 + [2 AND 3] = 1 + 2
    ("5 AND 3", 1.0), ("5 OR 3", 7.0), ("5 XOR 3", 6.0),
    ("7 MOD 3", 1.0), ("-7 MOD 3", -1.0), ("7.4 MOD 2.6", 1.0),  # operands rounded: 7 MOD 3
    ("ATAN[1]/[1]", 45.0), ("ATAN[1,1]", 45.0), ("ATAN[-1]/[1]", 315.0), ("ATAN[0]/[-1]", 180.0),
    ("SIN[90]", 1.0), ("COS[90]", 0.0), ("COS[180]", -1.0), ("TAN[45]", 1.0),
    ("ASIN[1]", 90.0), ("ASIN[-1]", 270.0), ("ACOS[-1]", 180.0), ("ACOS[0.5]", 60.0),
    ("SQRT[16]", 4.0), ("ABS[-3.5]", 3.5), ("LN[EXP[2]]", 2.0),
    ("ROUND[1.5]", 2.0), ("ROUND[2.5]", 3.0), ("ROUND[-1.5]", -2.0),  # half away from zero, not to even
    ("FIX[1.2]", 1.0), ("FIX[-1.2]", -1.0), ("FUP[1.2]", 2.0), ("FUP[-1.2]", -2.0), ("FUP[3]", 3.0),
    ("BCD[12]", 18.0), ("BIN[18]", 12.0), ("BCD[1234]", 4660.0),  # 0x12 = 18, 0x1234 = 4660
    ("sin[30] * 2", 1.0),  # keywords in either case
])
def test_operators_and_functions_follow_fanuc(expression, expected):
    assert value(expression) == pytest.approx(expected, abs=1e-12)


def test_vacant_is_zero_in_arithmetic_but_not_for_eq():
    # #1 vacant, #2 = 0
    assert value("#1") is None and value("[#1]") is None and value("-#1") is None
    assert value("#1 + 5") == 5.0 and value("#1 * 5") == 0.0
    assert value("#1 EQ 0", **{"#2": 0.0}) is False and value("#1 NE 0") is True
    assert value("#1 EQ #0") is True and value("#2 EQ #0", **{"#2": 0.0}) is False
    assert value("#2 EQ 0", **{"#2": 0.0}) is True
    assert value("#1 GE 0") is True and value("#1 LT 0") is False  # GT GE LT LE read vacant as 0
    assert value("[#1 EQ #0] AND [#2 GT 1]", **{"#2": 3.0}) is True
    assert value("#[#1 + 100]", **{"#1": 5.0, "#105": 7.5}) == 7.5  # indirect


@pytest.mark.parametrize("expression, needle", [
    ("5 / #1", "division by zero in 5 / #1"), ("SQRT[-4]", "square root of the negative number -4"),
    ("LN[0]", "logarithm of 0"), ("ASIN[2]", "outside [-1, 1]"), ("TAN[90]", "is infinite"),
    ("ATAN[0]/[0]", "ATAN[0]/[0]"), ("5 MOD 0", "MOD by 0"), ("BIN[10]", "not a BCD number"),
    ("1.5 AND 1", "not a non-negative integer"), ("[1 EQ 1] + 2", "used as a number"),
    ("EXP[1000]", "overflows"),
])
def test_arithmetic_alarms_name_the_expression(expression, needle):
    with pytest.raises(GCodeError) as info:
        value(expression)
    assert needle in str(info.value)


@pytest.mark.parametrize("expression", ["2 +", "[1 + 2", "ATAN[1]", "#1.5", "1 EQ 1 EQ 1", "FOO[1]", "2 $ 3",
                                        "[[[[[[1]]]]]]", "--#1", "1" + "+1" * 200])
def test_malformed_expressions_are_lex_errors(expression):
    with pytest.raises(LexError):
        parse_expression(expression)


# ------------------------------------------------------------------------------------------ words, vacant
def test_vacant_variable_drops_its_address_and_values_round_to_the_increment():
    text = ("G90 G0 X0 Y0 Z0\n"
            "G90 X#1 Y5.\n"                      # #1 vacant: Y only
            "#1 = 12.3456\n"
            "X#1\n"                              # 12.346 mm (0.001 mm increment, half away from zero)
            "#2 = -2.\n"
            "Y-#2 Z[#2 * 2]\n"                   # Y 2, Z -4
            "#19 = 1000.6\n"
            "S#19 M3\n"                          # S is an integer address: 1001 rpm
            "M30\n")
    program = interpret(text)
    assert _moves(program) == [(1, [0, 0, 0]), (2, [0, 5, 0]), (4, [12.346, 5, 0]), (6, [12.346, 2, -4])]
    speeds = [b.speed / RPM for b in program.blocks if isinstance(b, SpindleSpeed)]
    assert speeds == [pytest.approx(1001.0, rel=1e-12)]


def test_round_in_an_address_rounds_to_the_least_input_increment_fanuc_example():
    # FANUC manual: #1 = 1.2345, #2 = 2.3456; G91 X-#1 moves -1.235, X-#2 -2.346 (values rounded per word);
    # X[#1 + #2] would move +3.580 (3.5801 rounded) and miss the start by 0.001; X[ROUND[#1] + ROUND[#2]]
    # moves 1.235 + 2.346 = 3.581 and returns exactly
    for back, end in (("X[ROUND[#1] + ROUND[#2]]", 0.0), ("X[#1 + #2]", -0.001)):
        text = f"G90 G0 X0 Y0 Z0\n#1 = 1.2345\n#2 = 2.3456\nG91 G0 X-#1\nG1 X-#2 F300\nG0 {back}\nM30\n"
        assert _moves(interpret(text))[-1][1][0] == pytest.approx(end, abs=1e-9)


def test_variables_have_a_decimal_point_dwell_in_seconds_and_g_codes_from_variables():
    text = "#1 = 2\nG4 X#1\n#10 = 1\n#11 = 91\nG#11 G#10 X1. F100\nM30\n"
    program = interpret(text)
    assert program.blocks[0].seconds == 2.0  # X#1 = X2. : seconds (so is a literal G4 X2 under calculator input)
    assert _moves(program) == [(5, [1, 0, 0])]  # G91 G1


# ------------------------------------------------------------------------------------------ control flow
def test_while_loop_gives_four_roughing_plunges_at_half_mm_steps():
    text = ("G90 G0 X0 Y0 Z5.\n"
            "#1 = 1\n"
            "WHILE [#1 LE 4] DO1\n"
            "G1 Z[-0.5 * #1] F100\n"
            "G0 Z5.\n"
            "#1 = #1 + 1\n"
            "END1\n"
            "M30\n")
    program = interpret(text)
    plunges = [(b.line, b.end[2] * 1e3) for b in program.blocks if isinstance(b, Linear)]
    assert plunges == [(4, pytest.approx(-0.5 * i, abs=1e-12)) for i in (1, 2, 3, 4)]
    # lines 3-7 run 4 times, then WHILE (line 3) exits to line 8: the runs of the source lines
    assert program.segments == ((1, 7), (3, 7), (3, 7), (3, 7), (3, 3), (8, 8))


def test_nested_loops_and_if_then():
    # 3 x 2 grid; IF THEN skips nothing but counts the corner holes in #100 (x = 0 or 20, y = 0 or 10)
    text = ("G90 G0 X0 Y0 Z0\n#1 = 0\nWHILE [#1 LT 3] DO1\n#2 = 0\nWHILE [#2 LT 2] DO2\n"
            "G0 X[#1 * 10] Y[#2 * 10]\n"
            "IF [[#1 NE 1] AND [#2 GE 0]] THEN #100 = #100 + 1\n"
            "#2 = #2 + 1\nEND2\n#1 = #1 + 1\nEND1\nG0 Z#100\nM30\n")
    moves = _moves(interpret(text))
    assert [m[1][:2] for m in moves[1:-1]] == [[x, y] for x in (0, 10, 20) for y in (0, 10)]
    assert moves[-1][1][2] == 4.0  # #100 started vacant (0 in arithmetic): 4 holes with x != 10


def test_goto_searches_forward_then_from_the_top():
    text = ("G90 G0 X0 Y0 Z0\n"
            "N10 X1.\n"          # 2: the N10 from the top
            "#1 = #1 + 1\n"
            "IF [#1 GE 3] GOTO 99\n"
            "GOTO 10\n"          # 5: forward finds line 6 first
            "N10 Y#1\n"          # 6
            "GOTO 10\n"          # 7: nothing forward: from the top, line 2
            "N99 Z7.\n"
            "M30\n")
    moves = _moves(interpret(text))
    assert moves == [(1, [0, 0, 0]), (2, [1, 0, 0]), (6, [1, 1, 0]), (2, [1, 1, 0]), (6, [1, 2, 0]),
                     (2, [1, 2, 0]), (8, [1, 2, 7])]


def test_early_return_and_m99_p_loop_driven_by_a_variable():
    # O7 returns early by GOTO to its second M99; M99 P5 jumps back to N5 of the main program while #1 < 3:
    # the same return with the same calls comes 3 times, but with #1 = 1, 2: not endless
    text = ("G90 G0 X0 Y0 Z0\nN5 #1 = #1 + 1\nG0 X#1\nM98 P7\nG0 Y9.\nM30\n"
            "O7\nIF [#1 GE 3] GOTO 9\nM99 P5\nN9 M99\n")
    assert _moves(interpret(text)) == [(1, [0, 0, 0]), (3, [1, 0, 0]), (3, [2, 0, 0]), (3, [3, 0, 0]),
                                       (5, [3, 9, 0])]


def test_block_delete_and_inch_increment():
    from fmus_src.nck.settings import InterpreterSettings

    text = "G90 G0 X0 Y0 Z0\n#1 = 1.23456\n/#1 = 2.\nG20 X#1\nM30\n"
    # switch off: #1 = 2 runs (X 2 in = 50.8 mm); switch on: X#1 rounds to 0.0001 in, 1.2346 in = 31.35884 mm
    assert _moves(interpret(text))[-1][1][0] == pytest.approx(50.8, abs=1e-9)
    on = interpret(text, settings=InterpreterSettings(block_delete=True))
    assert _moves(on)[-1][1][0] == pytest.approx(1.2346 * 25.4, abs=1e-9)


def test_do_without_while_is_left_by_goto():
    text = "G90 G0 X0 Y0 Z0\nDO1\n#1 = #1 + 2\nIF [#1 GT 5] GOTO 5\nEND1\nN5 X#1\nM30\n"
    # 2, 4, 6: the loop is left when #1 = 6 > 5 (GOTO out of a loop is allowed)
    assert _moves(interpret(text))[-1] == (6, [6, 0, 0])


def test_endless_while_names_the_line():
    err = _error("G90 G0 X0\nWHILE [1 EQ 1] DO1\nG91 G1 X1. F100\nEND1\nM30\n")
    assert err.line == 4 and "endless loop" in str(err) and "line 2" in str(err)


def test_runaway_loop_stops_at_the_line_cap(monkeypatch):
    # the counter decides the condition and changes every pass, so only the cap of executed lines ends it:
    # 4 lines + 1000 beyond the file
    monkeypatch.setattr(macro_runtime, "MAX_LOOP_LINES", 1000)
    err = _error("#1 = 0\nN1 #1 = #1 + 1\nIF [#1 GT -1] GOTO 1\nM30\n")
    assert err.line == 3 and "more than 1004 lines executed" in str(err) and "back to line 2" in str(err)


@pytest.mark.parametrize("text, line, shown", [
    # the WHILE tests #1, the body counts #2 (which drives X): #1 never changes
    ("#1 = 0\n#2 = 0\nWHILE [#1 LT 10] DO1\n#2 = #2 + 1\nG91 G1 X#2 F100\nEND1\nM30\n", 6, "#1 = 0"),
    # a GOTO loop whose exit tests #1 through #3, while #2 grows
    ("#1 = 1\nN5 #3 = #1 * 2\n#2 = #2 + 1\nIF [#3 LT 10] GOTO 5\nM30\n", 4, "#1 = 1, #3 = 2"),
    # no condition at all: DO without WHILE and no GOTO out, a counter inside
    ("DO1\n#2 = #2 + 1\nEND1\nM30\n", 3, "lines 1-3 have no condition and no GOTO that could leave"),
])
def test_loop_whose_deciding_variables_never_change_is_endless_at_its_second_pass(monkeypatch, text, line, shown):
    # other variables change every pass, so the whole state never repeats; the variables that decide the
    # branches (the loop's slice) do not change, so the second pass over the back jump is the proof
    monkeypatch.setattr(macro_runtime, "MAX_LOOP_LINES", 50)  # found long before the cap
    err = _error(text)
    assert err.line == line and "endless loop" in str(err) and shown in str(err)


@pytest.mark.parametrize("text, x_ends", [
    # nested loops, the outer condition's variable changed in the inner loop
    ("#1 = 0\nWHILE [#1 LT 2] DO1\n#2 = 0\nWHILE [#2 LT 2] DO2\n#2 = #2 + 1\n#1 = #1 + 0.5\n"
     "G90 G1 X[#1 * 10] F100\nEND2\nEND1\nM30\n", [5.0, 10.0, 15.0, 20.0]),
    # the condition's variable is counted by a subprogram the loop calls (lines outside the loop run)
    ("#100 = 0\nWHILE [#100 LT 3] DO1\nM98 P200\nEND1\nM30\nO200\n#100 = #100 + 1\nG90 G1 X#100 F100\n"
     "M99\n", [1.0, 2.0, 3.0]),
    # the condition reads a system variable (the end point X), which only the NC blocks move
    ("G90 G0 X0\nWHILE [#5001 LT 3.] DO1\nG91 G1 X1. F100\nEND1\nM30\n", [0.0, 1.0, 2.0, 3.0]),
    # the condition's variable is counted through an indirect assignment #[#1]
    ("#1 = 2\n#2 = 0\nWHILE [#2 LT 3] DO1\n#[#1] = #2 + 1\nG90 G1 X#2 F100\nEND1\nM30\n", [1.0, 2.0, 3.0]),
])
def test_loops_that_end_are_not_called_endless(text, x_ends):
    program = interpret(text, file="m.nc")
    assert [p[0] for _, p in _moves(program)] == x_ends


@pytest.mark.parametrize("text, line, needle", [
    ("G0 X0\nGOTO 50\nM30\n", 2, "has no block N50"),
    ("DO1\nDO2\nEND1\nEND2\nM30\n", 3, "loops cross"),
    ("END1\nM30\n", 1, "END1 without a DO1"),
    ("WHILE [#1 LT 3] DO1\nM30\n", 1, "DO1 without END1"),
    ("DO1\nDO2\nDO3\nDO1\nEND1\nEND3\nEND2\nEND1\nM30\n", 4, "DO1 inside the loop DO1"),
    ("DO1\nDO2\nDO3\nWHILE [1 EQ 1] DO4\nM30\n", 4, "not 1, 2 or 3"),
    ("GOTO 5\nWHILE [#1 LT 2] DO1\nN5 #1 = #1 + 1\nEND1\nM30\n", 1, "into the loop of lines 2-4"),
    ("#34 = 1\nM30\n", 1, "#34 is not a local or common variable; expected a variable #1..#33, #100..#199"),
    ("#1 = #250\nM30\n", 1, "#250 is not a variable"),
    ("#0 = 1\nM30\n", 1, "#0 is always vacant"),
    ("#1 = #2001\nM30\n", 1, "system variable #2001 is not available"),
    ("#4001 = 1\nM30\n", 1, "cannot be assigned"),
    ("G0 X0\n#3000 = 12 (TOOL BROKEN)\nM30\n", 2, "macro alarm #3000 = 12: TOOL BROKEN"),
    ("#1 = 1 / 0\nM30\n", 1, "division by zero"),
    ("G1 X1 #1 = 2\nM30\n", 1, "a macro statement and NC words in one block"),
    ("G1 X1 E#1 F100\nM30\n", 1, "address E is not supported outside a G65 call"),  # even when vacant
    ("G1 X1 E5 F100\nM30\n", 1, "address E is not supported"),
    ("G66 P1\nM30\n", 1, "G66 is not supported"),
    ("IF [#1 EQ 1] #2 = 3\nM30\n", 1, "without GOTO or THEN"),
    ("#1 = 2\nIF [#1] GOTO 5\nN5 M30\n", 2, "is a number, not a condition"),
    ("G0 X[#1 EQ 1]\nM30\n", 1, "has a condition as its value"),
    ("G0 X1 $\nM30\n", 1, "unexpected character '$'"),  # plain lines: the lexer's errors as before
])
def test_macro_errors_name_the_line(text, line, needle):
    err = _error(text)
    assert err.line == line and err.file == "m.nc", str(err)
    assert needle in str(err)


def test_system_variables_read_the_modal_state():
    text = ("G90 G0 X0 Y0 Z0\nG91 G1 X3. Y4. F250\n"
            "#1 = #5001 + #5002\n"   # 3 + 4 = 7 (work coordinates of the last block's end)
            "#2 = #4001 * 1000 + #4003\n"  # G1, G91: 1091
            "#3 = #4109\n"           # F 250 mm/min
            "G90 G0 X#1 Y#2 Z#3\nM30\n")
    assert _moves(interpret(text))[-1][1] == [7, 1091, 250]


# ----------------------------------------------------------------------------------------------- G65 calls
BOLT_CIRCLE = """G90 G17 G21 G0 X0 Y0 Z10.
#1 = 7.
G65 P9010 R20. A0 B60. H6 Z-3. F100
G80 G0 X#1 Z50.
M30
O9010 (BOLT CIRCLE: R radius, A start angle, B step, H holes, Z depth, F feed)
#10 = 0
WHILE [#10 LT #11] DO1
#12 = #1 + #10 * #2
G98 G81 X[#18 * COS[#12]] Y[#18 * SIN[#12]] Z#26 R2. F#9
#10 = #10 + 1
END1
M99
"""


def test_bolt_circle_by_g65_drills_six_holes_and_restores_the_callers_locals():
    program = interpret(BOLT_CIRCLE)
    bottoms = [(b.line, _mm(b.end)) for b in program.blocks if isinstance(b, Linear)]
    # hole k at 20 (cos 60k, sin 60k) mm, each coordinate rounded to the 0.001 mm increment of X/Y (FANUC rounds
    # a variable's value to the address's least input increment: 17.3205... -> 17.321)
    expected = [(10, [round(20 * math.cos(math.radians(60 * k)), 3), round(20 * math.sin(math.radians(60 * k)), 3),
                      -3.0]) for k in range(6)]
    assert len(bottoms) == 6
    for (line, got), (eline, want) in zip(bottoms, expected):
        assert line == eline and got == pytest.approx(want, abs=1e-9)
    # the macro's #1 was A0: after M99 the main program's #1 = 7 is back
    assert _moves(program, Rapid)[-1] == (4, [7, -17.321, 50])  # Y stays at the last hole
    feeds = [b.feed / MPM for b in program.blocks if isinstance(b, Linear)]
    assert feeds == pytest.approx([100.0] * 6, rel=1e-12)  # F#9 from the argument F100


def test_g65_argument_specification_one_and_repeats():
    letters = {"A": 1, "B": 2, "C": 3, "I": 4, "J": 5, "K": 6, "D": 7, "E": 8, "F": 9, "H": 11, "M": 13, "Q": 17,
               "R": 18, "S": 19, "T": 20, "U": 21, "V": 22, "W": 23, "X": 24, "Y": 25, "Z": 26}
    args = " ".join(f"{a}{n}" for a, n in letters.items())
    checks = "".join(f"IF [#{n} NE {n}] THEN #3000 = {n} (ARGUMENT {a})\n" for a, n in letters.items())
    text = (f"G90 G0 X0 Y0 Z0\nG65 P100 L3 {args}\nG0 X#100\nM30\n"
            f"O100\n{checks}IF [#10 NE #0] THEN #3000 = 10 (#10 NOT VACANT)\n#10 = 5\n#100 = #100 + #1\nM99\n")
    # every repetition starts with the arguments (and #10 vacant again): #100 = 3 x A1 = 3
    assert _moves(interpret(text))[-1] == (3, [3, 0, 0])


def test_m98_shares_the_callers_locals_g65_does_not():
    text = ("G90 G0 X0 Y0 Z0\n#1 = 5\nM98 P2\nG65 P3 A1\nG0 X#1 Y#100\nM30\n"
            "O2\n#1 = #1 + 1\nM99\n"          # M98: the main program's #1 becomes 6
            "O3\n#100 = #1\n#1 = 100\nM99\n")  # G65: its own #1 (A1), the main program's #1 untouched
    assert _moves(interpret(text))[-1] == (5, [6, 1, 0])


def test_g65_errors():
    deep = "G65 P1\nM30\n" + "".join(f"O{k}\nG65 P{k + 1}\nM99\n" for k in range(1, 5)) + "O5\nM99\n"
    err = _error(deep)
    assert err.line == 13 and "would nest 5 macro levels (O1 -> O2 -> O3 -> O4)" in str(err)
    err = _error("G65 P77 A1\nM30\nO1\nM99\n")
    assert err.line == 1 and "G65 P77" in str(err) and "O77 is not in the file" in str(err)
    err = _error("G65 P1 I1 I2\nM30\nO1\nM99\n")
    assert "argument specification II is not supported" in str(err)
    err = _error("G65 G1 P1\nM30\nO1\nM99\n")
    assert "G1 in a G65 block" in str(err)
    err = _error("#5 = 1.5\nG65 P#5\nM30\nO1\nM99\n")
    assert "program number is not an integer" in str(err)


# ------------------------------------------------------------------------------------------------ optimiser
LOOP_FEEDS = """G90 G0 X0 Y0 Z0
S1000 M3
#9 = 200.
#1 = 0
WHILE [#1 LT 3] DO1
G1 X[#1 + 1] F#9
Y[#1 + 1]
#9 = #9 + 100.
#1 = #1 + 1
END1
G65 P5 F150. X1.
M30
O5
G1 X0 F[#9 * 2]
Y0
M99
"""


@pytest.mark.parametrize("feed_lines, spindle_lines", [({6: 77.0}, {}), ({7: 55.0}, {}), ({14: 66.0, 6: 44.0}, {}),
                                                       ({15: 33.0}, {7: 1500.0}), ({}, {14: 2000.0})])
def test_overrides_of_loop_and_macro_lines_equal_rewriting_the_file(feed_lines, spindle_lines):
    # independent reference: the writer puts plain numbers in place of F#9 / F[#9*2] (or appends F/S) and the
    # interpreter runs the file again; the overrides act on the original program's runs of the lines
    program = interpret(LOOP_FEEDS)
    rewritten_text = rewrite_program(LOOP_FEEDS, feed_lines, spindle_lines)
    rewritten = interpret(rewritten_text)
    blocks, feeds, speeds = apply_overrides(program, 1, {k: v * MPM for k, v in feed_lines.items()},
                                            {k: v * RPM for k, v in spindle_lines.items()})
    assert [(type(b), b.line) for b in blocks] == [(type(b), b.line) for b in rewritten.blocks]
    for i, b in enumerate(rewritten.blocks):
        if isinstance(b, Linear):
            assert feeds[0, i] == pytest.approx(b.feed, rel=1e-12), (feed_lines, i, b)
        elif isinstance(b, SpindleSpeed):
            assert speeds[0, i] == pytest.approx(b.speed, rel=1e-12), (spindle_lines, b)


def test_writer_replaces_expression_feeds_and_refuses_macro_statements_and_g65():
    out = rewrite_program(LOOP_FEEDS, {6: 123.0, 14: 45.5})
    lines = out.splitlines()
    assert lines[5] == "G1 X[#1 + 1] F123" and lines[13] == "G1 X0 F45.5"
    with pytest.raises(GCodeError, match=r"<text>:11: .*G65 macro call: its F and S words are the macro's"):
        rewrite_program(LOOP_FEEDS, {11: 100.0})
    with pytest.raises(GCodeError, match=r"<text>:8: .*cannot put an F or S word on a macro statement"):
        rewrite_program(LOOP_FEEDS, {8: 100.0})


# ---------------------------------------------------------------------------------------------- end to end
UNROLLED = """G90 G17 G21 G0 X0 Y0 Z5.
S3000 M3
G1 Z-1. F200
X10. F400
G0 Z5.
X0
G1 Z-2. F200
X10. F400
G0 Z5.
X0
M30
"""
MACRO = """G90 G17 G21 G0 X0 Y0 Z5.
S3000 M3
#1 = 1
WHILE [#1 LE 2] DO1
G65 P20 Z-#1 F400.
#1 = #1 + 1
END1
M30
O20
G1 Z#26 F[#9 / 2]
X10. F#9
G0 Z5.
X0
M99
"""


def test_simulated_macro_program_takes_as_long_as_the_unrolled_one(tmp_path):
    from orchestrator.simulate import simulate

    times = []
    for name, text in (("unrolled", UNROLLED), ("macro", MACRO)):
        folder = tmp_path / name
        folder.mkdir()
        (folder / "program.nc").write_text(text)
        (folder / "case.toml").write_text('program = "program.nc"\n[tool]\ndiameter_mm = 6.0\nflutes = 2\n'
                                          '[machine]\nparameters = "default"\n')
        result = simulate(case=folder, plot=False)
        assert result.success, result.message
        times.append(result.summary["cycle_time_s"])
    # the same moves at the same feeds: the same plan, sample for sample
    assert times[1] == pytest.approx(times[0], rel=1e-12)
    assert times[0] > 0.0
