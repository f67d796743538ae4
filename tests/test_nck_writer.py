"""Writer: byte-identical round trip, only the changed F/S words differ, appended words, inch programs."""
from __future__ import annotations

import pytest

from fmus_src.nck import GCodeError, interpret, rewrite_program
from fmus_src.nck.lexer import lex_line

PROG = ("%\r\nO0100 (WRITER TEST)  \r\nG90 G21 G17\r\nS2000 M3\r\nG0 X0 Y0\r\n"
        "G1 Z-1. F150. (plunge)\r\nX40 ; cut  \r\nG2 X50 Y10 R10\r\nG1 Y40 f300\r\nM30\r\n%")


def test_unchanged_program_is_byte_identical():
    assert rewrite_program(PROG) == PROG
    assert rewrite_program(PROG, {}, {}) == PROG
    lf = PROG.replace("\r\n", "\n") + "\n"
    assert rewrite_program(lf, {}, {}) == lf


def test_changed_words_only():
    out = rewrite_program(PROG, feed_by_line={6: 220.5, 9: 275}, spindle_by_line={4: 3150.4})
    old, new = PROG.split("\r\n"), out.split("\r\n")
    assert len(old) == len(new) and out.count("\r\n") == PROG.count("\r\n")
    changed = [i + 1 for i, (a, b) in enumerate(zip(old, new)) if a != b]
    assert changed == [4, 6, 9]
    assert new[3] == "S3150 M3"
    assert new[5] == "G1 Z-1. F220.5 (plunge)"
    assert new[8] == "G1 Y40 f275"  # original letter case kept, no decimal point added
    for a, b in zip(old, new):  # every other word identical
        wa = [(w.letter, w.text) for w in lex_line(a).words if w.letter not in "FS"]
        wb = [(w.letter, w.text) for w in lex_line(b).words if w.letter not in "FS"]
        assert wa == wb


def test_missing_word_is_appended_before_the_comment():
    out = rewrite_program(PROG, feed_by_line={7: 180}, spindle_by_line={8: 2500})
    lines = out.split("\r\n")
    assert lines[6] == "X40 F180 ; cut  "
    assert lines[7] == "G2 X50 Y10 R10 S2500"


def test_inch_program_gets_inch_feed():
    out = rewrite_program("G20\nG1 X1 F10.\n", feed_by_line={2: 254.0})
    assert out == "G20\nG1 X1 F10.\n".replace("F10.", "F10.")
    out = rewrite_program("G20\nG1 X1 F10.\n", feed_by_line={2: 127.0})
    assert out == "G20\nG1 X1 F5.\n"


def test_rewritten_program_interprets_to_the_new_feed():
    out = rewrite_program(PROG, feed_by_line={6: 200})
    blocks = [b for b in interpret(out).blocks if hasattr(b, "feed")]
    assert blocks[0].feed == pytest.approx(200e-3 / 60) and blocks[1].feed == pytest.approx(200e-3 / 60)


@pytest.mark.parametrize("feeds, line", [({1: 100}, 1), ({99: 100}, 99), ({6: -5}, 6), ({3: float("nan")}, 3)])
def test_writer_errors(feeds, line):
    with pytest.raises(GCodeError) as info:
        rewrite_program(PROG, feeds, file="w.nc")
    assert info.value.line == line and str(info.value).startswith(f"w.nc:{line}:")
