"""Reliability on bad case and recording files: each problem is one clear error naming the file and the field.

Format problems are caught by the readers (:meth:`Recording.read_csv`,
:func:`load_case`); plausibility and program/recording mismatches by
:mod:`orchestrator.validation`. The good recording used here is built from
the NC kernel's own plan of the paper part (time, line, reference), so it is
consistent with the program by construction; each test breaks one thing.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck import NCKernel
from orchestrator.case import CaseError, load_case
from orchestrator.errors import CncTwinError
from orchestrator.recording import Recording, RecordingError
from orchestrator.validation import (
    DURATION_SLACK_S, MAX_DURATION_RATIO, Range, block_lines, validate_case, validate_recording,
)

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "models" / "examples" / "paper_part"
PROGRAM_TEXT = (PAPER / "program.nc").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def plan():
    kernel = NCKernel("nck", program_text=PROGRAM_TEXT)
    kernel.setup(0.0)
    return kernel


@pytest.fixture()
def good(plan, tmp_path):
    """A recording CSV consistent with the paper program (every 10th interpolation period)."""
    p = plan.plan_
    idx = np.arange(0, p.feed.shape[1], 10)
    rec = Recording.from_channels({
        "t_s": 5.0 + idx * p.period,  # a logger started 5 s into its own clock
        "line": p.line[0, idx].astype(float),
        "x_ref_mm": p.position[0, idx, 0] * 1e3,
        "x_mm": p.position[0, idx, 0] * 1e3 - 0.01,
        "spindle_rpm": p.spindle_speed[0, idx] * 60 / (2 * math.pi),
        "x_tcmd_A": np.sin(idx * 1e-3),
        "fc_N": np.full(idx.size, 40.0),
    })
    path = rec.write_csv(tmp_path / "recording.csv")
    return path


def rewrite(path: Path, column: str, row: int, value: str) -> Path:
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    cells = lines[row + 1].split(",")
    cells[header.index(column)] = value
    lines[row + 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    return path


def test_the_good_recording_passes(good, plan):
    rec = Recording.read_csv(good)
    validate_recording(rec, PAPER / "program.nc")
    assert set(np.unique(rec["line"]).astype(int)) <= block_lines(PROGRAM_TEXT)


# ----------------------------------------------------------------------------- reader (format) errors
@pytest.mark.parametrize("column, value, match", [
    ("x_mm", "nan", r"column 'x_mm': 'nan'; write an empty cell"),
    ("x_mm", "inf", r"column 'x_mm': 'inf'"),
    ("x_mm", "1,5", r"cells, header has"),
    ("spindle_rpm", "5000 rpm", r"column 'spindle_rpm': '5000 rpm' is not a plain decimal number"),
    ("t_s", "", r"empty t_s"),
    ("t_s", "5.0", r"t_s repeats \(.*5.0.* then .*5.0.*\)"),  # row 1 gets the time of row 0: duplicated timestamp
    ("t_s", "4.0", r"t_s goes back \(.*5.0.* then .*4.0.*\)"),  # unsorted time
])
def test_malformed_cells_name_file_line_and_column(good, column, value, match):
    rewrite(good, column, 1, value)
    with pytest.raises(RecordingError, match=match) as info:
        Recording.read_csv(good)
    assert str(good) in str(info.value) and ":3:" in str(info.value)  # CSV line 3 = data row 1


def test_missing_file_wrong_columns_and_binary(good, tmp_path):
    with pytest.raises(RecordingError, match="recording file not found") as info:
        Recording.read_csv(tmp_path / "nope.csv")
    assert "nope.csv" in str(info.value)
    with pytest.raises(RecordingError, match=r"missing column\(s\) \['fx_N'\]"):
        Recording.read_csv(good, required=["x_mm", "fx_N"])
    wrong = tmp_path / "wrong.csv"
    wrong.write_text("time,x\n0,1\n")
    with pytest.raises(RecordingError, match=r"wrong.csv:1: no 't_s' column"):
        Recording.read_csv(wrong)
    binary = tmp_path / "bin.csv"
    binary.write_bytes(b"t_s,x_mm\n0,1\n\xff\xfe\x00\x01")
    with pytest.raises(RecordingError, match=r"bin.csv: not a UTF-8 text file"):
        Recording.read_csv(binary)


# ----------------------------------------------------------------------------- plausibility
@pytest.mark.parametrize("column, value, match", [
    ("x_mm", "1000000000", r"recording.csv:5: column 'x_mm' \(t_s = 5.03\): 1000000000.0 is outside the plausible range "
                           r"\[-10000, 10000\] mm"),
    ("x_ref_mm", "-20000", r"recording.csv:5: column 'x_ref_mm'"),
    ("spindle_rpm", "-5000000", r"recording.csv:5: column 'spindle_rpm' .*\[-100000, 100000\] rpm"),
    ("x_tcmd_A", "1e5", r"recording.csv:5: column 'x_tcmd_A' .* A"),
    ("fc_N", "-3", r"recording.csv:5: column 'fc_N' .*is not negative"),
])
def test_values_outside_plausible_ranges_name_file_line_and_column(good, column, value, match):
    rewrite(good, column, 3, value)
    rec = Recording.read_csv(good)  # well formed: the reader accepts it
    with pytest.raises(RecordingError, match=match) as info:
        validate_recording(rec)
    assert str(good) in str(info.value)


def test_ranges_can_be_overridden_and_unknown_columns_are_not_judged(good):
    rewrite(good, "x_mm", 3, "12000")
    rec = Recording.read_csv(good)
    validate_recording(rec, ranges={"x_mm": Range(-20_000, 20_000, "a gantry mill")})
    extra = Recording.from_channels({"t_s": [0.0, 1.0], "logger_temp_C": [1e9, -1e9]})
    validate_recording(extra)


def test_recordings_built_in_memory_with_bad_time_are_caught():
    rec = Recording.from_channels({"t_s": [0.0, 2.0, 1.0], "x_mm": [0.0, 0.0, 0.0]})
    with pytest.raises(RecordingError, match=r"column 't_s', row 3 \(t_s = 1\): time does not increase"):
        validate_recording(rec)
    rec = Recording.from_channels({"t_s": [0.0, math.nan], "x_mm": [0.0, 0.0]})
    with pytest.raises(RecordingError, match=r"column 't_s', row 2: nan"):
        validate_recording(rec)


# ----------------------------------------------------------------------------- recording vs program
def test_line_numbers_that_do_not_exist_in_the_program(good):
    n = len(PROGRAM_TEXT.splitlines())
    rewrite(good, "line", 3, str(n + 1))
    with pytest.raises(RecordingError, match=rf"line {n + 1} does not exist, .*program.nc has {n} lines"):
        validate_recording(Recording.read_csv(good), PAPER / "program.nc")


def test_line_numbers_of_comments_and_fractions(good, tmp_path):
    # line 3 of the paper program is a comment: nothing there can execute
    assert 3 not in block_lines(PROGRAM_TEXT) and 6 in block_lines(PROGRAM_TEXT)
    rewrite(good, "line", 0, "3")
    with pytest.raises(RecordingError, match=r"recording.csv:2: column 'line' .*: line 3 of .*holds no block"):
        validate_recording(Recording.read_csv(good), PAPER / "program.nc")
    rewrite(good, "line", 0, "6.5")
    with pytest.raises(RecordingError, match=r"6.5 is not a line number"):
        validate_recording(Recording.read_csv(good), PAPER / "program.nc")


def test_line_going_back_means_another_program(good):
    rec = Recording.read_csv(good)
    k = int(np.flatnonzero(rec["line"] == 23)[0])  # first sample of the last contour block
    rewrite(good, "line", k, "7")
    with pytest.raises(RecordingError, match=r"the line goes back from 22 to 7"):
        validate_recording(Recording.read_csv(good), PAPER / "program.nc")


def test_recording_much_longer_than_the_program(good, plan):
    rec = Recording.read_csv(good)
    planned = float(plan.duration_[0])
    allowed = MAX_DURATION_RATIO * planned + DURATION_SLACK_S
    t = rec.t.copy()
    stretch = (allowed + 1.0) / (t[-1] - t[0])  # just beyond the limit
    long = Recording.from_channels({**{n: rec[n] for n in rec.channels}, "t_s": t[0] + (t - t[0]) * stretch},
                                   source=str(good))
    with pytest.raises(RecordingError, match=r"column 't_s': the recording lasts .* is this the recording of another"):
        validate_recording(long, PAPER / "program.nc")
    ok = Recording.from_channels({**{n: rec[n] for n in rec.channels},
                                  "t_s": t[0] + (t - t[0]) * (allowed - 1.0) / (t[-1] - t[0])})
    validate_recording(ok, PAPER / "program.nc")


def test_program_problems_while_validating_are_recording_errors(good, tmp_path):
    missing = tmp_path / "missing.nc"
    with pytest.raises(RecordingError, match="missing.nc.*program file not found"):
        validate_recording(Recording.read_csv(good), missing)
    with pytest.raises(RecordingError, match="other.nc:1"):
        validate_recording(Recording.read_csv(good), "other.nc", program_text="G1 X1\n" + "G0 X0\n" * 40)


# ----------------------------------------------------------------------------- case files
def write_case(folder: Path, toml: str, program: bool = True, recording: str | None = None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "case.toml").write_text(toml)
    if program:
        (folder / "program.nc").write_text(PROGRAM_TEXT)
    if recording is not None:
        (folder / "recording.csv").write_text(recording)
    return folder


CASE = """program = "program.nc"
recording = "recording.csv"

[stock]
min = [0.0, 0.0, -10.0]
max = [30.0, 20.0, 0.0]

[tool]
diameter_mm = 6.0
flutes = 2
"""


@pytest.mark.parametrize("change, match", [
    (("diameter_mm = 6.0", "diameter_mm = 0"), r"case.toml:9: \[tool\] diameter_mm must be a number in mm"),
    (("diameter_mm = 6.0", "diameter_mm = 1e6"), r"case.toml:9: \[tool\] diameter_mm .* got 1000000.0"),
    (("diameter_mm = 6.0", "diameter_mm = nan"), r"case.toml:9: \[tool\] diameter_mm"),
    (("min = [0.0, 0.0, -10.0]", "min = [40.0, 0.0, -10.0]"), r"case.toml:6: \[stock\] max .* must exceed min"),
    (("min = [0.0, 0.0, -10.0]", "min = [nan, 0.0, -10.0]"), r"case.toml:5: \[stock\] min must be finite"),
    (("min = [0.0, 0.0, -10.0]", 'min = ["0", 0.0, -10.0]'), r"case.toml:5: \[stock\] min must be a list of 3 numbers"),
    (('program = "program.nc"', "program = 3"), r"case.toml:1: 'program' must name the G-code file"),
    (("flutes = 2", "flutes = 2\nspeed = 3"), r"case.toml:11: unknown field 'speed' in \[tool\]"),
    (("[tool]", "[tool\n"), r"not valid TOML"),
])
def test_bad_case_fields_name_file_line_and_field(tmp_path, change, match):
    folder = write_case(tmp_path / "c", CASE.replace(*change))
    with pytest.raises(CaseError, match=match) as info:
        load_case(folder)
    assert str(folder / "case.toml") in str(info.value)


def test_missing_case_program_and_recording_files(tmp_path, good):
    with pytest.raises(CaseError, match=r"nowhere: case file not found"):
        load_case(tmp_path / "nowhere")
    folder = write_case(tmp_path / "c", CASE, program=False)
    case = load_case(folder)  # the loader reads the manifest only ...
    with pytest.raises(CaseError, match=r"case.toml:1: program = .program.nc.: file .*program.nc not found"):
        validate_case(case)  # ... validation checks the files it names
    folder = write_case(tmp_path / "d", CASE)
    with pytest.raises(CaseError, match=r"case.toml:2: recording = .recording.csv.: file .*recording.csv not found"):
        validate_case(load_case(folder))
    folder = write_case(tmp_path / "e", CASE, recording=good.read_text())
    case = load_case(folder)
    validate_case(case)
    validate_recording(Recording.read_csv(case.recording), case.program)


def test_stock_beyond_any_machine(tmp_path):
    folder = write_case(tmp_path / "c", CASE.replace("max = [30.0, 20.0, 0.0]", "max = [1e9, 20.0, 0.0]"),
                        recording="t_s\n0\n")
    with pytest.raises(CaseError, match=r"\[stock\] max = \[1000000000.0, 20.0, 0.0\] mm lies beyond"):
        validate_case(load_case(folder))


def test_every_error_here_is_a_project_error():
    assert issubclass(RecordingError, CncTwinError) and issubclass(CaseError, CncTwinError)


@pytest.mark.parametrize("which", ["case", "machine"])
def test_binary_case_and_machine_files_are_project_errors(tmp_path, which):
    from orchestrator.machine import load_machine

    if which == "case":
        folder = write_case(tmp_path / "c", CASE)
        (folder / "case.toml").write_bytes(b'program = "program.nc"\n\xff\xfe\x00')
        with pytest.raises(CncTwinError, match="case.toml"):
            load_case(folder)
    else:
        bad = tmp_path / "machine.toml"
        bad.write_bytes(b"[nck]\n\xff\xfe")
        with pytest.raises(CncTwinError, match="machine.toml"):
            load_machine(bad)


# ------------------------------------------------------------------------------------------ users of validation
def mismatched_case(good: Path) -> tuple[Path, int]:
    """A case folder (paper program) whose recording names a line the program does not have."""
    folder = good.parent
    (folder / "program.nc").write_text(PROGRAM_TEXT, encoding="utf-8")
    (folder / "case.toml").write_text('program = "program.nc"\nrecording = "recording.csv"\n\n'
                                      '[tool]\ndiameter_mm = 6.0\nflutes = 2\n\n[machine]\nparameters = "default"\n')
    n = len(PROGRAM_TEXT.splitlines())
    rewrite(good, "line", 3, str(n + 1))
    return folder, n


@pytest.mark.parametrize("kind", ["friction", "servo", "cutting"])
def test_identification_rejects_the_recording_of_another_program(good, kind):
    from orchestrator.identify import IdentificationError, identify

    folder, n = mismatched_case(good)
    with pytest.raises(IdentificationError, match=rf"^{good}:5: column 'line' .*line {n + 1} does not exist"):
        identify(kind, [folder])


def test_diagnosis_rejects_the_recording_of_another_program(good):
    from orchestrator.diagnose import DiagnosisError, diagnose

    folder, n = mismatched_case(good)
    with pytest.raises(DiagnosisError, match=rf"^{good}:5: column 'line' .*line {n + 1} does not exist"):
        diagnose(folder)
