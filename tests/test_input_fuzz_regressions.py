"""Regressions found by fuzzing the files users bring (case.toml, recording.csv, machine files, FMUs).

Each test is one input that used to crash (a Python traceback), hang or give a silently wrong result, and
now either works or fails with the project's own error naming the file, the line or field, and what was
expected. Line numbers are counted in the text each test writes.
"""
from __future__ import annotations

import _ctypes
import re
import sys
import zipfile
from pathlib import Path

import pytest

from orchestrator.case import CaseError, load_case
from orchestrator.cli import main
from orchestrator.fmu.binary_check import shared_library_problem
from orchestrator.fmu.check import check_fmu
from orchestrator.fmu.component import FMUComponent, load_fmu
from orchestrator.fmu.errors import FMUError
from orchestrator.machine import MACHINES_DIR, MachineFileError, load_machine
from orchestrator.recording import Recording, RecordingError

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "models" / "examples" / "paper_part"
DEFAULT_TOML = (MACHINES_DIR / "default.toml").read_text(encoding="utf-8")
CASE_TOML = (PAPER / "case.toml").read_text(encoding="utf-8")


def line_of(text: str, pattern: str, after: str | None = None) -> int:
    """1-based number of the first line matching ``pattern`` (after the line ``after``, a section header)."""
    lines = text.splitlines()
    start = lines.index(after) + 1 if after is not None else 0
    return next(i for i in range(start, len(lines)) if re.match(pattern, lines[i])) + 1


def write_case(folder: Path, toml: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "case.toml").write_text(toml, encoding="utf-8")
    (folder / "program.nc").write_text((PAPER / "program.nc").read_text(encoding="utf-8"), encoding="utf-8")
    return folder


def set_machine_value(section: str, key: str, value: str) -> tuple[str, int]:
    """default.toml with ``[section] key = value`` (the inline table replaced); the text and that line."""
    n = line_of(DEFAULT_TOML, rf"{re.escape(key)}\s*=", after=f"[{section}]")
    lines = DEFAULT_TOML.splitlines()
    lines[n - 1] = f'{key} = {{ value = {value}, source = "test" }}'
    return "\n".join(lines) + "\n", n


def load_text(tmp_path: Path, text: str) -> None:
    path = tmp_path / "mach.toml"
    path.write_text(text, encoding="utf-8")
    load_machine(path)


# ----------------------------------------------------------------------------- recordings
RECORDING = "t_s,line,x_mm,x_tcmd_A\n0.000,1,0.0,0.1\n0.001,1,0.0,0.2\n0.002,1,0.001,0.3\n"


def test_a_cell_longer_than_the_csv_field_limit_is_a_recording_error(tmp_path):
    """A 1 MB cell used to end in _csv.Error ('field larger than field limit') from the row-by-row reader."""
    lines = RECORDING.splitlines()
    lines[2] = lines[2] + "," + "1" * 1_000_000  # file line 3
    path = tmp_path / "long.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=r"long\.csv:3: field larger than field limit") as info:
        Recording.read_csv(path)
    assert "expected comma-separated cells of numbers" in str(info.value)


def test_a_header_longer_than_the_csv_field_limit_is_a_recording_error(tmp_path):
    path = tmp_path / "wide.csv"
    path.write_text("t_s,x_" + "m" * 200_000 + '"' + "\n0,1\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=r"wide\.csv:1: .*expected a header row"):
        Recording.read_csv(path)


@pytest.mark.parametrize("data, line, byte, offset", [
    # a Latin-1 'e acute' (0xe9) in the 2nd data row, file line 3: '0.001,caf' is 9 bytes before it on the line
    (b"t_s,note\n0,ok\n0.001,caf\xe9\n", 3, 10, len(b"t_s,note\n0,ok\n0.001,caf")),
    # the same with CR LF line ends, and a Latin-1 degree sign (0xb0) in the header, line 1 byte 9
    (b"t_s,temp_\xb0C\r\n0,20\r\n", 1, 10, 9),
    # CR-only line ends (old Mac): the reader counts CR as a line end, so the bad byte is on line 3
    (b"t_s,note\r0,ok\r0.001,\xff\r", 3, 7, len(b"t_s,note\r0,ok\r0.001,")),
])
def test_undecodable_bytes_name_their_line_and_byte(tmp_path, data, line, byte, offset):
    """The message used to say 'after line 0' whatever line held the byte (the decoder reads ahead)."""
    path = tmp_path / "latin1.csv"
    path.write_bytes(data)
    with pytest.raises(RecordingError, match=r"latin1\.csv: not a UTF-8 text file") as info:
        Recording.read_csv(path)
    assert f"line {line}, byte {byte} (byte offset {offset})" in str(info.value)


def test_non_ascii_digits_are_not_plain_decimal_numbers(tmp_path):
    """'١٢٣' (Arabic-Indic 123) used to be read as 123 by the row-by-row reader, though numpy's fast path refuses it."""
    path = tmp_path / "digits.csv"
    path.write_text("t_s,x_mm\n0,1\n0.001,\u0661\u0662\u0663\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=r"digits\.csv:3: column 'x_mm': .* is not a plain decimal number"):
        Recording.read_csv(path)


# ----------------------------------------------------------------------------- case.toml
def test_a_tool_diameter_below_the_smallest_end_mill_is_a_case_error(tmp_path):
    """diameter_mm = 1e-300 used to pass the (0, 1000) check and crash numpy (a 1e300-point swept path)."""
    toml = CASE_TOML.replace("diameter_mm = 6.0", "diameter_mm = 1e-300")
    folder = write_case(tmp_path / "c", toml)
    with pytest.raises(CaseError, match=r"\[tool\] diameter_mm must be a number in mm from 0.01 .* got 1e-300") as info:
        load_case(folder)
    assert str(folder / "case.toml") + f":{line_of(toml, 'diameter_mm')}:" in str(info.value)
    write_case(tmp_path / "d", CASE_TOML.replace("diameter_mm = 6.0", "diameter_mm = 0.01"))
    assert load_case(tmp_path / "d").tool.diameter_mm == 0.01  # a 10 um micro end mill is fine


def test_a_stock_beyond_any_machine_is_refused_when_the_case_is_loaded(tmp_path):
    """min = [-1e300, ...] used to overflow the Z-map cell count and simulate with no stock (0 N everywhere)."""
    toml = CASE_TOML.replace("min = [0.0, 0.0, -10.0]", "min = [-1e300, 0.0, -10.0]")
    folder = write_case(tmp_path / "c", toml)
    with pytest.raises(CaseError, match=r"\[stock\] min = \[-1e\+300, 0.0, -10.0\] mm lies beyond \+-10000 mm") as info:
        load_case(folder)
    assert f"case.toml:{line_of(toml, 'min =')}:" in str(info.value)


@pytest.mark.parametrize("which", ["case", "machine"])
def test_deeply_nested_toml_is_a_file_error(tmp_path, which):
    """5000 nested arrays used to raise RecursionError out of tomllib."""
    deep = "a = " + "[" * 5000 + "]" * 5000 + "\n"
    if which == "case":
        folder = write_case(tmp_path / "c", deep + CASE_TOML)
        with pytest.raises(CaseError, match=r"case\.toml: arrays or tables nested too deeply to read"):
            load_case(folder)
    else:
        with pytest.raises(MachineFileError, match=r"mach\.toml: arrays or tables nested too deeply to read"):
            load_text(tmp_path, deep + DEFAULT_TOML)


# ----------------------------------------------------------------------------- machine files
@pytest.mark.parametrize("section, key, value", [
    ("axis.x", "mass_kg", '"heavy"'),                     # used to be ValueError: could not convert string to float
    ("nck", "lookahead_blocks", '"fast"'),
    ("servo", "position_loop_period_ms", '""'),
    ("cost", "taylor_C", '"abc"'),
    ("cutting.effects", "helix_deg", '"30"'),             # used to reach the cutting load as 30 rad, not 30 deg
])
def test_a_string_where_a_number_belongs_names_file_line_and_key(tmp_path, section, key, value):
    if section == "cutting.effects":
        text = DEFAULT_TOML + f"\n[cutting.effects]\n{key} = {value}\n"
        n = len(text.splitlines())
    else:
        text, n = set_machine_value(section, key, value)
    with pytest.raises(MachineFileError, match=rf"mach\.toml:{n}: \[{re.escape(section)}\] {key} must be a number"):
        load_text(tmp_path, text)


@pytest.mark.parametrize("section, key, value, expected", [
    # used to be refused by the component with a multi-line numpy repr and no file or line
    ("axis.x", "mass_kg", "-600.0", "a number > 0"),
    ("axis.y", "torque_constant_Nm_per_A", "0.0", "a number > 0"),
    ("axis.z", "screw_lead_mm", "-1.0", "a number > 0"),
    ("axis.z", "peak_current_A", "0.0", "a number > 0"),
    ("axis.x", "rapid_feed_mm_per_min", "0.0", "a number > 0"),
    ("axis.x.friction.positive", "coulomb_N", "-1.0", "a magnitude >= 0"),
    ("axis.z.friction.negative", "stribeck_velocity_m_per_s", "0.0", "a number > 0"),
    ("nck", "interpolation_period_ms", "0.0", "a number > 0"),
    ("nck", "in_position_width_mm", "0.0", "a number > 0"),
    ("nck", "rapid_time_constant_ms", "-1.0", "a number >= 0"),
    ("nck", "lookahead_blocks", "0", "a whole number >= 1"),
    ("nck", "lookahead_blocks", "2.5", "a whole number >= 1"),
    ("spindle", "max_speed_rpm", "-1.0", "a number > 0"),
    ("material.A6061", "kt_N_per_m2", "-1.0", "a number >= 0"),
    ("nck", "cutting_filter", "5", "text in quotes among ['linear', 'bell']"),
    ("nck", "boring_shift", '"Q"', "one of ['+X', '+Y', '-X', '-Y']"),
    ("nck", "rigid_tapping_mode", '"x"', "one of ['M29', 'always']"),
    # used to end in ZeroDivisionError (velocity loop 0, Taylor n 0) or NaN/inf in summary.json (ValueError)
    ("servo", "velocity_loop_period_ms", "0", "a number > 0"),
    ("cost", "taylor_n", "0", "a number > 0"),
    ("cost", "taylor_n", "-1.0", "a number > 0"),
    ("cost", "taylor_C", "0", "a number > 0"),
    # position gain 0: the axis never moves (the run used to go on to the time limit)
    ("axis.x", "position_gain_per_s", "0.0", "a number > 0"),
])
def test_a_value_outside_what_the_twin_accepts_names_file_line_and_range(tmp_path, section, key, value, expected):
    text, n = set_machine_value(section, key, value)
    with pytest.raises(MachineFileError) as info:
        load_text(tmp_path, text)
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'mach.toml'}:{n}: [{section}] {key} must be {expected}, got ")
    assert "\n" not in message


def test_a_moving_mass_too_small_for_the_drive_integrator_is_refused_instead_of_hanging(tmp_path):
    """mass_kg = 1e-12 used to run for hours: the Stribeck step cap 0.25 M / ((Fs - Fc)/vs - mu_v) is 3.3e-18 s.

    X positive (default.toml): (775.2 - 641.6) / 0.0016 - 7702 = 75 798 N s/m, the larger branch; the
    step is at least 1e-8 s for M >= 1e-8 x 75 798 / 0.25 = 3.03e-3 kg.
    """
    text, n = set_machine_value("axis.x", "mass_kg", "1e-12")
    with pytest.raises(MachineFileError, match=rf"mach\.toml:{n}: \[axis\.x\] mass_kg = 1e-12 .* substeps of "
                                               r"3\.3e-18 s; expected .* at least 1e-08 s"):
        load_text(tmp_path, text)
    with pytest.raises(MachineFileError, match=r"substeps of 2\.31e-09 s"):  # 0.25 x 7e-4 / 75 798
        load_text(tmp_path, set_machine_value("axis.x", "mass_kg", "7e-4")[0])
    load_text(tmp_path, set_machine_value("axis.x", "mass_kg", "4e-3")[0])  # step 1.32e-8 s: loads


def test_a_position_loop_period_that_is_not_a_multiple_of_the_velocity_loop_is_refused(tmp_path):
    text, n = set_machine_value("servo", "position_loop_period_ms", "0.3")  # velocity loop 0.25 ms
    with pytest.raises(MachineFileError, match=rf"mach\.toml:{n}: \[servo\] position_loop_period_ms = 0.3 must be a "
                                               r"whole multiple .* of velocity_loop_period_ms = 0.25"):
        load_text(tmp_path, text)


def test_the_cli_prints_one_line_naming_the_machine_file_and_exits_2(tmp_path, capsys):
    text, n = set_machine_value("axis.y", "mass_kg", '"heavy"')
    (tmp_path / "mach.toml").write_text(text, encoding="utf-8")
    folder = write_case(tmp_path, CASE_TOML.replace('parameters = "default"', 'parameters = "mach.toml"'))
    assert main(["simulate", "--case", str(folder), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"cnctwin: error: {tmp_path / 'mach.toml'}:{n}: [axis.y] mass_kg")
    assert not (tmp_path / "out").exists()  # nothing written


# ----------------------------------------------------------------------------- FMUs
LAG_DESCRIPTION = (ROOT / "orchestrator" / "bench" / "lag_fmu" / "modelDescription.xml").read_text(encoding="utf-8")
#: A real shared library of this platform (the interpreter's own ctypes extension), to stand in for an FMU binary.
HOST_LIBRARY = Path(getattr(_ctypes, "__file__", "") or "nowhere")
needs_host_library = pytest.mark.skipif(not (sys.platform.startswith("linux") and HOST_LIBRARY.suffix == ".so"),
                                        reason="needs a Linux shared library of this interpreter")


def pack_fmu(path: Path, binary: bytes, description: str = LAG_DESCRIPTION) -> Path:
    """A Lag FMU archive with the given binary as binaries/linux64/Lag.so."""
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", description)
        zf.writestr("binaries/linux64/Lag.so", binary)
    return path


@pytest.mark.parametrize("binary, problem", [
    (b"#!/bin/sh\necho not elf\n", r"is not an ELF shared library \(it starts with b'#!/bin/sh"),
    (b"", r"is an empty file"),
])
def test_a_binary_that_is_not_a_shared_library_is_an_fmu_error(tmp_path, binary, problem):
    """dlopen used to fail inside fmpy with a plain Exception ('file too short'): a traceback."""
    fmu = pack_fmu(tmp_path / "broken.fmu", binary)
    with pytest.raises(FMUError, match=rf"broken\.fmu: binaries/linux64/Lag\.so {problem}.*expected a shared library"):
        FMUComponent(fmu)


@needs_host_library
def test_a_truncated_shared_library_is_refused_before_it_is_loaded(tmp_path):
    """dlopen of a library cut at 4096 bytes used to kill the process with SIGBUS (exit status -7)."""
    data = HOST_LIBRARY.read_bytes()
    assert shared_library_problem(data, "linux64") is None  # the whole library is loadable
    fmu = pack_fmu(tmp_path / "cut.fmu", data[:4096])
    with pytest.raises(FMUError, match=r"cut\.fmu: binaries/linux64/Lag\.so is truncated: 4096 bytes, .* ends at byte"):
        FMUComponent(fmu)  # the variables bind, then the binary is checked before dlopen


@needs_host_library
def test_an_illegal_model_description_is_an_fmu_error(tmp_path):
    """fmpy's plain Exception for causality="banana" used to escape as a traceback."""
    text = LAG_DESCRIPTION.replace('causality="output"', 'causality="banana"', 1)
    fmu = pack_fmu(tmp_path / "bad.fmu", HOST_LIBRARY.read_bytes(), text)
    with pytest.raises(FMUError, match=r'bad\.fmu: cannot read modelDescription\.xml \(.*causality="banana"'):
        load_fmu(fmu)


@needs_host_library
def test_a_start_value_that_is_not_a_number_is_an_fmu_error(tmp_path):
    """<Real start="abc"/> used to raise ValueError from float() while the variables were bound."""
    text = LAG_DESCRIPTION.replace('<Real start="0.01"', '<Real start="abc"', 1)
    assert text != LAG_DESCRIPTION
    fmu = pack_fmu(tmp_path / "start.fmu", HOST_LIBRARY.read_bytes(), text)
    with pytest.raises(FMUError, match=r"start\.fmu: modelDescription\.xml: variable 'tau': start='abc' is not a Real"):
        FMUComponent(fmu)


@needs_host_library
def test_check_fmu_reports_a_step_size_that_is_not_a_number(tmp_path):
    """<DefaultExperiment stepSize="abc"/> used to raise ValueError out of check_fmu's smoke run."""
    text = re.sub(r'stepSize="[^"]*"', 'stepSize="abc"', LAG_DESCRIPTION, count=1)
    assert text != LAG_DESCRIPTION
    report = check_fmu(pack_fmu(tmp_path / "step.fmu", HOST_LIBRARY.read_bytes(), text))
    assert not report.ok and not report.smoke_ok
    assert "stepSize='abc'> is not a number; expected times in s" in report.smoke_message


# ----------------------------------------------------------------------------- diagnosis inputs
SHORT_PROGRAM = "G21 G90 G17\nS3000 M3\nG0 X0 Y0 Z5.\nG1 X20. F600\nM5\nM30\n"


def diagnosis_case(folder: Path, recording: str | None) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "short.nc").write_text(SHORT_PROGRAM, encoding="utf-8")
    (folder / "case.toml").write_text('program = "short.nc"\nrecording = "recording.csv"\n', encoding="utf-8")
    if recording is not None:
        (folder / "recording.csv").write_text(recording, encoding="utf-8")
    return folder


@pytest.mark.parametrize("rows", [0, 1, 2])
def test_a_recording_with_fewer_than_3_samples_is_a_diagnosis_error(tmp_path, rows):
    """One or two rows used to end in numpy's ValueError (a gradient of fewer than 2 points); a header
    alone printed numpy RuntimeWarnings before the error."""
    from orchestrator.diagnose import DiagnosisError, diagnose

    body = "".join(f"{0.001 * k},{0.01 * k},{0.01 * k},0.5\n" for k in range(rows))
    folder = diagnosis_case(tmp_path / "c", "t_s,x_ref_mm,x_mm,x_tcmd_A\n" + body)
    with pytest.raises(DiagnosisError, match=rf"^{re.escape(str(folder / 'recording.csv'))}: the recording has "
                                             rf"{rows} sample\(s\); a diagnosis needs at least 3"):
        diagnose(folder)


def test_3_samples_within_2_ms_cannot_be_aligned_and_say_so(tmp_path):
    """Three samples 0.1 ms apart (a 10 kHz logger) left one point on the 1 ms correlation grid: ValueError."""
    from orchestrator.diagnose import DiagnosisError, diagnose

    body = "".join(f"{1.0 + 1e-4 * k},{0.01 * k},{0.01 * k},0.5\n" for k in range(3))
    folder = diagnosis_case(tmp_path / "c", "t_s,x_ref_mm,x_mm,x_tcmd_A\n" + body)
    with pytest.raises(DiagnosisError, match=r"recording\.csv: column 'x_ref_mm' is measured at 3 sample\(s\) over "
                                             r"0\.0002 s; .* needs at least 3 samples over more than 2 ms"):
        diagnose(folder)


def test_a_missing_recording_file_is_named_as_missing(tmp_path):
    """The message used to say 'the case needs a recording (recording = ... in case.toml)' though it names one."""
    from orchestrator.diagnose import DiagnosisError, diagnose

    folder = diagnosis_case(tmp_path / "c", None)
    with pytest.raises(DiagnosisError, match=rf"^{re.escape(str(folder / 'recording.csv'))}: recording file not "
                                             r"found; .*\(named by recording = .* in .*case\.toml\)"):
        diagnose(folder)
