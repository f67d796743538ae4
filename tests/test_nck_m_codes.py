"""Machine builders' M codes from the machine file ([nck.m_codes]) and Haas M97 local subprograms.

Expected values are derived by hand: S3000 = 3000 * 2 pi / 60 rad/s, M13 = M3 + M8 by the default machine
file's table, and an M97 routine run twice equals the same lines written out twice.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck import GCodeError, InterpreterSettings, interpret
from fmus_src.nck.blocks import Arc, Coolant, Linear, ProgramEnd, Rapid, SpindleSpeed
from fmus_src.nck.component import NCKernel
from fmus_src.nck.errors import NCParameterError
from fmus_src.nck.m_aliases import DEFAULT_M_CODES, format_m_codes, parse_m_codes
from fmus_src.nck.subprograms import MAX_NESTING
from fmus_src.nck.writer import rewrite_program
from orchestrator import simulate
from orchestrator.machine import MACHINES_DIR, MachineFileError, load_machine, machine_to_toml
from orchestrator.twin import nck_parameters

PAPER_CASE = Path(__file__).resolve().parent.parent / "models" / "examples" / "paper_part"
RAD_PER_S_3000_RPM = 3000.0 * 2.0 * math.pi / 60.0


@pytest.fixture(scope="module")
def settings() -> InterpreterSettings:
    """The default machine file's aliases, as the twin reads them."""
    return InterpreterSettings(m_codes=load_machine("default").m_codes())


def _aux(text: str, settings: InterpreterSettings) -> list[object]:
    return [b for b in interpret(text, "m.nc", settings).blocks if not isinstance(b, ProgramEnd)]


# ------------------------------------------------------------------------------------------ the machine file
def test_default_machine_file_holds_the_documented_aliases() -> None:
    m = load_machine("default")
    assert m.m_codes() == {13: (3, 8), 14: (4, 8), 48: (), 49: (), 88: (8,), 89: (9,)}
    assert m.m_codes() == DEFAULT_M_CODES  # the NC kernel's parameter default is the default machine's table
    assert all(m.provenance[f"nck.m_codes.{c}"].startswith("assumption:") for c in DEFAULT_M_CODES)
    assert nck_parameters(m)["m_codes"] == "13=3,8;14=4,8;48=;49=;88=8;89=9"


def _machine_with(tmp_path: Path, entry: str) -> tuple[Path, int]:
    """default.toml with ``entry`` added to [nck.m_codes]; returns the file and the entry's 1-based line."""
    text = (MACHINES_DIR / "default.toml").read_text(encoding="utf-8")
    lines = text.splitlines()
    at = lines.index("[nck.m_codes]") + 1
    lines.insert(at, entry)
    path = tmp_path / "builder.toml"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path, at + 1


@pytest.mark.parametrize("entry, key, problem", [
    ('130 = { means = [6], source = "x" }', "130", "M6, which an alias cannot stand for"),
    ('131 = { means = [30], source = "x" }', "131", "M30, which an alias cannot stand for"),
    ('3 = { means = [4], source = "x" }', "3", "M3 is a standard M code of the NC kernel and cannot be redefined"),
    ('97 = { means = [], source = "x" }', "97", "M97 is a standard M code"),
    ('132 = { means = [3, 4], source = "x" }', "132", "two spindle codes"),
    ('133 = { means = [7, 8], source = "x" }', "133", "two coolant codes"),
    ('134 = { means = [29, 3], source = "x" }', "134", "M29 stands alone"),
    ('135 = { means = [3.0], source = "x" }', "135", "is not an M code number"),
    ('136 = { source = "x" }', "136", "expected <M code> = { means = ["),
    ('137 = [3]', "137", "expected <M code> = { means = ["),
    ('"M13" = { means = [3], source = "x" }', "M13", "not an M code number"),
])
def test_bad_alias_is_refused_with_file_line_and_key(tmp_path: Path, entry: str, key: str, problem: str) -> None:
    path, line = _machine_with(tmp_path, entry)
    with pytest.raises(MachineFileError) as info:
        load_machine(str(path))
    text = str(info.value)
    assert f"[nck.m_codes] {key}" in text and problem in text
    if not key.startswith("M"):  # a quoted key is not found by the line search: the section's line is named
        assert text.startswith(f"{path}:{line}:")


def test_machine_file_round_trip_keeps_aliases_and_sources(tmp_path: Path) -> None:
    path, _ = _machine_with(tmp_path, '150 = { means = [19], source = "builder manual p. 12" }')
    m = load_machine(str(path))
    again = tmp_path / "again.toml"
    again.write_text(machine_to_toml(m), encoding="utf-8")
    m2 = load_machine(str(again))
    assert m2.m_codes() == {**DEFAULT_M_CODES, 150: (19,)}
    assert m2.provenance["nck.m_codes.150"] == "builder manual p. 12"


def test_machine_file_without_the_section_has_no_aliases(tmp_path: Path) -> None:
    text = (MACHINES_DIR / "default.toml").read_text(encoding="utf-8")
    kept = [ln for ln in text.splitlines() if not ln.startswith(("[nck.m_codes]", "13 =", "14 =", "48 =", "49 =",
                                                                    "88 =", "89 ="))]
    path = tmp_path / "plain.toml"
    path.write_text("\n".join(kept) + "\n", encoding="utf-8")
    m = load_machine(str(path))
    assert m.m_codes() == {} and nck_parameters(m)["m_codes"] == ""


# ------------------------------------------------------------------------------------------ the String parameter
def test_string_parameter_form() -> None:
    assert parse_m_codes(format_m_codes(DEFAULT_M_CODES), "p") == DEFAULT_M_CODES
    assert parse_m_codes("", "p") == {} and parse_m_codes(" 13 = 3 , 8 ; ", "p") == {13: (3, 8)}
    for bad, msg in [("13=3;13=4", "given twice"), ("13:3", "is not <M code>="), ("13=6", "cannot stand for"),
                     ("x=3", "is not <M code>=")]:
        with pytest.raises(NCParameterError, match=msg):
            parse_m_codes(bad, "nck.m_codes")
    with pytest.raises(NCParameterError, match="nck.m_codes: M5 is a standard M code"):
        NCKernel("nck", program_text="M30\n", m_codes="5=3").setup(0.0)


# ------------------------------------------------------------------------------------------ the interpreter
def test_m13_starts_the_spindle_cw_and_the_coolant(settings: InterpreterSettings) -> None:
    assert _aux("S3000 M13\nM30\n", settings) == [SpindleSpeed(1, RAD_PER_S_3000_RPM, 1, 1), Coolant(1, True)]
    # the same blocks as the standard codes written out
    assert _aux("S3000 M13\nM30\n", settings) == _aux("S3000 M3 M8\nM30\n", InterpreterSettings())


def test_m14_ccw_m88_m89_coolant(settings: InterpreterSettings) -> None:
    assert _aux("S3000 M14\nM89\nM88\nM30\n", settings) == [
        SpindleSpeed(1, RAD_PER_S_3000_RPM, -1, 1), Coolant(1, True), Coolant(2, False), Coolant(3, True)]


def test_m48_m49_add_no_blocks(settings: InterpreterSettings) -> None:
    program = interpret("M48\nG1 X1 F100\nM49\nM30\n", "m.nc", settings)
    assert [type(b) for b in program.blocks] == [Linear, ProgramEnd]


def test_conflicts_through_an_alias_are_errors(settings: InterpreterSettings) -> None:
    with pytest.raises(GCodeError, match=r"M13 \(= M3\) and M5 conflict in one block"):
        interpret("S3000 M13 M5\n", "m.nc", settings)
    with pytest.raises(GCodeError, match=r"M13 \(= M3\) and M14 \(= M4\) conflict"):
        interpret("M13 M14\n", "m.nc", settings)
    with pytest.raises(GCodeError, match=r"M88 \(= M8\) and M9 conflict.*\(coolant\)"):
        interpret("M88 M9\n", "m.nc", settings)
    # the same standard code twice is no conflict (as M3 M3): spindle CW, coolant on once each
    assert _aux("S3000 M13 M3 M8\nM30\n", settings) == _aux("S3000 M13\nM30\n", settings)


def test_unknown_m_code_names_the_machine_file_section(settings: InterpreterSettings) -> None:
    with pytest.raises(GCodeError) as info:
        interpret("G0 X1\nM130\nM30\n", "m.nc", settings)
    text = str(info.value)
    assert text.startswith("m.nc:2: 'M130': M code M130 is not supported")
    assert "M29 M30 M97 M98 M99" in text and "M13 (M3 M8)" in text and "M48 (no effect)" in text
    assert "add it under [nck.m_codes] of the machine file" in text
    with pytest.raises(GCodeError, match=r"aliases: none \(a machine builder's M code"):
        interpret("M13\n")  # no machine file: the FANUC codes only


def test_writer_keeps_alias_m_codes_as_written(settings: InterpreterSettings) -> None:
    text = "S3000 M13\nG1 X10 F100 M88\nM48\nM5 M9\nM30\n"
    out = rewrite_program(text, {2: 250.0}, {1: 2000.0})
    assert out.splitlines() == ["S2000 M13", "G1 X10 F250 M88", "M48", "M5 M9", "M30"]
    assert [type(b) for b in interpret(out, "m.nc", settings).blocks][:2] == [SpindleSpeed, Coolant]


def test_simulated_spindle_trace_with_m13_equals_m3_m8(tmp_path: Path) -> None:
    body = "G21 G90 G17 G40 G49 G94\nG54\nS3000 {on}\nG0 X10 Y7 Z5\nG1 X14 F1200\nG0 Z10\n{off}\nM30\n"
    results = {}
    for name, on, off in (("alias", "M13", "M5 M89"), ("standard", "M3 M8", "M5 M9")):
        path = tmp_path / f"{name}.nc"
        path.write_text(body.format(on=on, off=off), encoding="utf-8")
        result = simulate(path, case=PAPER_CASE, plot=False)
        assert result.success, result.message
        results[name] = result.recording
    a, b = results["alias"], results["standard"]
    assert len(a) == len(b)
    np.testing.assert_array_equal(a["spindle_rpm"], b["spindle_rpm"])
    np.testing.assert_array_equal(a["spindle_ref_rpm"], b["spindle_ref_rpm"])
    # the command is S3000 clockwise (positive) until M5
    assert np.max(a["spindle_ref_rpm"]) == pytest.approx(3000.0, rel=1e-12)
    assert np.max(a["spindle_rpm"]) == pytest.approx(3000.0, rel=1e-6)


# ------------------------------------------------------------------------------------------ Haas M97
def _path(program_blocks: tuple) -> list[tuple]:
    """The moves of a program without their source lines: (kind, start, end, feed)."""
    return [(type(b).__name__, b.start, b.end, getattr(b, "feed", None)) for b in program_blocks
            if isinstance(b, (Rapid, Linear, Arc))]


def test_m97_local_subprogram_called_twice_equals_the_program_written_out() -> None:
    called = ("G21 G90 G0 X0 Y0 Z5\nM97 P100 L2\nG0 X50\nM97 P200\nM30\n"
              "N100 G91 G1 X10 F600\nG2 X10 Y0 R5\nG90\nM99\n"
              "N200 G1 Y5 F300\nM99\n")
    written = ("G21 G90 G0 X0 Y0 Z5\n"
               "G91 G1 X10 F600\nG2 X10 Y0 R5\nG90\n"
               "G91 G1 X10 F600\nG2 X10 Y0 R5\nG90\n"
               "G0 X50\nG1 Y5 F300\nM30\n")
    a, b = interpret(called), interpret(written)
    assert _path(a.blocks) == _path(b.blocks)
    assert [bl.end[0] for bl in a.blocks if isinstance(bl, (Linear, Arc))] == pytest.approx(
        [0.010, 0.020, 0.030, 0.040, 0.050])  # X10 and X20 twice, then Y5 at X50 (m)
    assert a.segments == ((1, 2), (6, 9), (6, 9), (3, 4), (10, 11), (5, 5))


def test_m97_inside_a_subprogram_searches_that_subprogram() -> None:
    text = "M98 P1001\nM30\nO1001\nM97 P10\nM99\nN10 G1 X3 F100\nM99\nO1002\nN10 G1 X9 F100\nM99\n"
    moves = [b for b in interpret(text).blocks if isinstance(b, Linear)]
    assert [m.line for m in moves] == [6] and moves[0].end[0] == pytest.approx(0.003)


@pytest.mark.parametrize("text, line, words", [
    ("M97 P5\nM30\nN6 M99\n", 1, "the main program has no block N5 to call"),
    ("M97 P5\nM30\nN5 G1 X1 F100\nM30\n", 1, "reaches 'M30' (line 4) before an M99"),
    ("M97\nM30\n", 1, "M97 without a P word"),
    ("M97 P1.5\nM30\n", 1, "P is not a sequence number"),
    ("M97 P5 L0\nM30\nN5 M99\n", 1, "repeat count L0"),
    ("G4 P1 M97\nM30\n", 1, "G4 and M97 in one block"),
    ("M97 P1\nM30\nN1 M97 P1\nM99\n", 3, f"would nest {MAX_NESTING + 1} levels"),
])
def test_m97_errors(text: str, line: int, words: str) -> None:
    with pytest.raises(GCodeError) as info:
        interpret(text, "h.nc")
    assert info.value.line == line and words in str(info.value)
