"""Recordings and case folders as users bring them: logger artefacts, exports and hand-written case files.

Each test starts from what a user would plausibly hand over (the twin's own ``recording.csv`` transformed like a
real logger or spreadsheet does, a ``case.toml`` written by hand) and asserts either the right numbers or an error
naming the file, the line and the field (``shared/spec/recording.md``).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from orchestrator.case import CaseError, load_case
from orchestrator.recording import Recording, RecordingError
from orchestrator.validation import validate_case
from tests.test_diagnose_logger import _x_friction_plus_100_N

CASE = """program = "program.nc"
recording = "recording.csv"

[stock]
min = [0.0, 0.0, -10.0]
max = [30.0, 20.0, 0.0]

[tool]
diameter_mm = 6.0
flutes = 2

[machine]
parameters = "default"
"""
PROGRAM = "G21 G90 G17\nS3000 M3\nG0 X0 Y0 Z5.\nG1 X20. F600\nM5\nM30\n"


def write_case(folder: Path, toml: str, recording: str | None = "t_s,x_mm\n0,0\n0.001,0\n") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "program.nc").write_text(PROGRAM, encoding="utf-8")
    (folder / "case.toml").write_text(toml, encoding="utf-8")
    if recording is not None:
        (folder / "recording.csv").write_text(recording, encoding="utf-8")
    return folder


# ----------------------------------------------------------------------------- case.toml as users write it
def test_a_case_file_saved_with_a_byte_order_mark_loads(tmp_path):
    """Windows editors save UTF-8 with a BOM; tomllib read it as 'Invalid statement (at line 1, column 1)'."""
    folder = write_case(tmp_path / "c", CASE)
    (folder / "case.toml").write_bytes(b"\xef\xbb\xbf" + CASE.replace("\n", "\r\n").encode())
    case = load_case(folder)
    assert case.tool.diameter_mm == 6.0 and case.stock is not None and case.stock.max_mm == (30.0, 20.0, 0.0)


def test_a_machine_file_saved_with_a_byte_order_mark_loads(tmp_path):
    from orchestrator.machine import MACHINES_DIR

    folder = write_case(tmp_path / "c", CASE.replace('"default"', '"machines/mine.toml"'))
    (folder / "machines").mkdir()
    (folder / "machines" / "mine.toml").write_bytes(b"\xef\xbb\xbf" + (MACHINES_DIR / "default.toml").read_bytes())
    case = load_case(folder)
    assert case.machine.path == folder / "machines" / "mine.toml"


@pytest.mark.parametrize("value, inner", [
    ('"nosuch"', r"no machine parameter set named 'nosuch'; shipped sets: \[.*'default'.*\]"),
    ('"nosuch.toml"', r".*nosuch\.toml: machine parameter file not found"),
    ('"../elsewhere/m.toml"', r".*elsewhere/m\.toml: machine parameter file not found"),
])
def test_a_machine_that_is_not_there_names_case_file_line_and_field(tmp_path, value, inner):
    """The message named neither case.toml nor [machine] parameters, only the set or file that was not found."""
    folder = write_case(tmp_path / "c", CASE.replace('"default"', value))
    with pytest.raises(CaseError, match=rf"^{re.escape(str(folder / 'case.toml'))}:13: \[machine\] parameters = "
                                        rf"'{re.escape(value[1:-1])}': {inner}; expected a shipped set name or a "
                                        r"\.toml path \(relative to the case folder\)$"):
        load_case(folder)


def test_an_empty_recording_name_is_a_case_error_not_the_folder(tmp_path):
    """recording = "" made the case folder itself the recording ('file <folder> not found')."""
    folder = write_case(tmp_path / "c", CASE.replace('"recording.csv"', '""'))
    with pytest.raises(CaseError, match=r"case\.toml:2: 'recording' must name the recording file .*got ''"):
        load_case(folder)


@pytest.mark.parametrize("key, line", [("program", 1), ("recording", 2)])
def test_a_field_naming_a_folder_is_a_case_error(tmp_path, key, line):
    folder = write_case(tmp_path / "c", CASE.replace('"program.nc"' if key == "program" else '"recording.csv"',
                                                     '"data"'))
    (folder / "data").mkdir()
    with pytest.raises(CaseError, match=rf"case\.toml:{line}: '{key}' names the folder .*data; expected a file"):
        load_case(folder)


def test_a_dotted_key_is_named_by_its_line(tmp_path):
    """tool.diameter_mm = 0 (a dotted key instead of a [tool] table) was reported at line 0."""
    text = CASE.replace("[tool]\ndiameter_mm = 6.0\nflutes = 2\n", "").replace(
        'recording = "recording.csv"\n', 'recording = "recording.csv"\ntool.diameter_mm = 0\n')
    folder = write_case(tmp_path / "c", text)
    with pytest.raises(CaseError, match=r"case\.toml:3: \[tool\] diameter_mm must be a number in mm"):
        load_case(folder)


def test_program_in_a_subfolder_and_absolute_paths_load(tmp_path):
    folder = write_case(tmp_path / "c", CASE.replace('"program.nc"', '"nc/part.nc"'))
    (folder / "nc").mkdir()
    (folder / "nc" / "part.nc").write_text(PROGRAM)
    case = load_case(folder)
    validate_case(case)
    assert case.program == folder / "nc" / "part.nc"
    other = write_case(tmp_path / "d", CASE.replace('"program.nc"', f'"{folder / "nc" / "part.nc"}"'))
    assert load_case(other).program == folder / "nc" / "part.nc"


def test_a_missing_program_is_named_by_case_file_and_line_in_every_command(tmp_path):
    """diagnose and identify said 'cannot check the recording against the program: …nope.nc: program file not
    found' and simulate '…nope.nc: program file not found', none naming case.toml or its field."""
    from orchestrator.diagnose import DiagnosisError, diagnose
    from orchestrator.identify import IdentificationError
    from orchestrator.identify.data import load_recording
    from orchestrator.simulate import simulate

    folder = write_case(tmp_path / "c", CASE.replace('"program.nc"', '"nope.nc"'))
    expected = (rf"^{re.escape(str(folder / 'case.toml'))}:1: program = 'nope\.nc': file "
                rf"{re.escape(str(folder / 'nope.nc'))} not found")
    with pytest.raises(CaseError, match=expected + "$"):
        validate_case(load_case(folder))
    with pytest.raises(CaseError, match=expected + "$"):
        simulate(case=folder, plot=False)
    with pytest.raises(DiagnosisError, match=expected + "; the diagnosis runs the program"):
        diagnose(folder)
    with pytest.raises(IdentificationError, match=expected + "; the recording is checked against the program"):
        load_recording(load_case(folder))


# ----------------------------------------------------------------------------- recordings as exported
def test_a_comma_decimal_export_names_file_line_and_the_decimal_point(tmp_path):
    """A European spreadsheet export with ',' as the decimal point: '3 cells, header has 2 columns' only."""
    path = tmp_path / "recording.csv"
    path.write_text("t_s,fc_N\n0,12\n0,001,12,5\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=rf"^{re.escape(str(path))}:3: 4 cells, header has 2 columns; is ',' "
                                             r"the decimal point here \(e\.g\. '0,5'\)\? recording\.md asks for '\.'"):
        Recording.read_csv(path)


def test_logger_artefacts_of_the_file_itself_read_to_the_same_numbers(tmp_path):
    """CRLF, a BOM, columns in another order, 'line' written as 12.0, blank lines at the end, an unknown text
    column and a logger clock that starts late (negative, here) all read to the same table."""
    t = np.round(np.arange(6) * 0.004 - 3.2, 6)
    x = np.array([0.0, 0.5, 1.25, 2.0, 2.5, 2.75])
    plain = Recording.from_channels({"t_s": t, "line": np.array([3, 3, 4, 4, 4, 5.0]), "x_mm": x})
    rows = [f"{float(x[k])!r},text {k},{[3, 3, 4, 4, 4, 5][k]}.0,{float(t[k])!r}" for k in range(6)]
    path = tmp_path / "recording.csv"
    path.write_bytes(("\ufeffx_mm,comment,line,t_s\r\n" + "\r\n".join(rows) + "\r\n\r\n\r\n").encode("utf-8"))
    rec = Recording.read_csv(path)
    assert rec.channels == ["t_s", "x_mm", "line"]
    for name in ("t_s", "x_mm", "line"):
        np.testing.assert_array_equal(rec[name], plain[name])


# ----------------------------------------------------------------------------- coarse loggers with commands
AIR_PROGRAM = "G21 G90 G17\nG0 X0 Y0 Z5.\nG1 X20. Y10. F1500\nX5. Y15. Z0\nG0 X0 Y0 Z5.\nM30\n"
SERVO_CHANNELS = ("line", "x_ref_mm", "y_ref_mm", "z_ref_mm", "x_mm", "y_mm", "z_mm", "x_tcmd_A", "y_tcmd_A",
                  "z_tcmd_A")


@pytest.fixture(scope="module")
def air_runs(tmp_path_factory):
    """The twin's own 1 ms run of an air-cut program, and the run of a machine with 100 N more X friction."""
    from orchestrator.machine import MACHINES_DIR
    from orchestrator.simulate import simulate

    folder = tmp_path_factory.mktemp("air")
    (folder / "program.nc").write_text(AIR_PROGRAM)
    (folder / "case.toml").write_text('program = "program.nc"\nrecording = "recording.csv"\n')
    (folder / "truth.toml").write_text(_x_friction_plus_100_N((MACHINES_DIR / "default.toml").read_text()))
    own = simulate(case=folder, plot=False).recording
    truth = simulate(case=folder, machine=folder / "truth.toml", plot=False).recording
    return folder, own, truth


def _logged(folder: Path, run: Recording, idx: np.ndarray, shift_s: float, rng=None) -> Path:
    """``run`` logged at the samples ``idx`` on a clock ``shift_s`` late (1 µm encoder and 10 mA noise with rng)."""
    channels = {"t_s": run.t[idx] + shift_s}
    for name in SERVO_CHANNELS:
        channels[name] = np.asarray(run[name], float)[idx]
        if rng is not None and name[1:] == "_mm":
            channels[name] = np.round(channels[name] * 1e3) / 1e3
        elif rng is not None and name.endswith("_tcmd_A"):
            channels[name] = channels[name] + rng.normal(0.0, 0.01, idx.size)
    Recording.from_channels(channels).write_csv(folder / "recording.csv")
    return folder


@pytest.mark.parametrize("keep", ["every 4 ms", "every 10 ms", "a random third"])
def test_the_twins_own_run_logged_coarsely_with_commands_names_no_effect(air_runs, keep):
    """Recorded commands at 4 ms, 10 ms or uneven were interpolated (PCHIP) between samples for the replay, which
    reshaped every acceleration: 7, 9 and 7 false effects (friction, gravity, inertia, pitch, reversal friction,
    feed-forward) on this noise-free run. The twin's command now carries the recorded one between samples."""
    from orchestrator.diagnose import diagnose

    folder, own, _ = air_runs
    n = len(own)
    idx = {"every 4 ms": np.arange(0, n, 4), "every 10 ms": np.arange(0, n, 10),
           "a random third": np.sort(np.random.default_rng(3).choice(n, n // 3, replace=False))}[keep]
    result = diagnose(_logged(folder, own, idx, 0.7))
    assert result.effects == []
    assert result.alignment["time_offset_s"] == pytest.approx(0.7, abs=1e-6)
    for a in "xyz":  # the replay reproduces the run: no residual before any effect (was 0.3-1.0 µm at 10 ms)
        assert result.rms_before[f"{a}_fe_um"] < 0.01


def test_a_coarse_log_with_commands_still_names_a_real_difference(air_runs):
    """With the commands PCHIP-interpolated, a 4 ms log of a machine with 100 N more X friction also named
    viscous friction changes of -87, -102 and -22 Ns/m on x, y and z."""
    from orchestrator.diagnose import diagnose

    folder, _, truth = air_runs
    result = diagnose(_logged(folder, truth, np.arange(0, len(truth), 4), 1.3, np.random.default_rng(5)))
    assert [(e["effect"], e["axis"]) for e in result.effects] == [("friction_mismatch", "x")]
    assert result.effects[0]["parameters"]["coulomb_N"] == pytest.approx(100.0, rel=0.02)


@pytest.mark.parametrize("step, was", [(4, "Svi 0.907 on z"), (10, "Svp 0.48 on x")])
def test_servo_identification_on_a_coarse_log_with_commands_is_exact(air_runs, step, was):
    """identify_servo replayed the recorded commands interpolated between the logger's samples: the twin's own
    run logged every 4 ms gave z Svi 0.907, every 10 ms x Svp 0.48 (the truth: 1 on every factor)."""
    from orchestrator.identify import identify_servo

    folder, own, _ = air_runs
    fit = identify_servo([_logged(folder, own, np.arange(0, len(own), step), 0.0)])
    for a in "xyz":
        for symbol in ("Spp", "Svp", "Svi"):
            assert fit.scales_[a][symbol] == pytest.approx(1.0, abs=2e-3), (a, symbol, was)


# ----------------------------------------------------------------------------- names and units off the contract
def test_upper_case_column_names_are_named_as_near_misses(tmp_path, caplog):
    """'X_MM' is an extra column to the contract, so a log exported in upper case lost every channel and the
    diagnosis said only that there was no moving position."""
    from orchestrator.diagnose import DiagnosisError, diagnose

    rows = "".join(f"{0.001 * k},{3 + k // 50},{0.01 * k},{0.01 * k}\n" for k in range(200))
    folder = write_case(tmp_path / "c", CASE.replace("[stock]", "[stock_]").split("[stock_]")[0],
                        "t_s,LINE,X_REF_MM,X_MM\n" + rows)
    with caplog.at_level("WARNING", logger="orchestrator.recording_csv"):
        with pytest.raises(DiagnosisError, match=r"'LINE' is not 'line', 'X_REF_MM' is not 'x_ref_mm', 'X_MM' is not "
                                                 r"'x_mm': column names are case-sensitive \(recording\.md\)$"):
            diagnose(folder)
    assert "recording.csv:1: column(s) ['LINE', 'X_MM', 'X_REF_MM'] are not recording.md names" in caplog.text
    with pytest.raises(RecordingError, match=r"missing column\(s\) \['x_mm'\] needed here; .*'X_MM' is not 'x_mm'"):
        Recording.read_csv(folder / "recording.csv", required=["x_mm"])


def test_time_in_milliseconds_is_named(tmp_path):
    from orchestrator.validation import validate_recording

    path = tmp_path / "recording.csv"
    path.write_text("t_ms,x_mm\n0,0\n1,0\n", encoding="utf-8")
    with pytest.raises(RecordingError, match=r":1: no 't_s' column; header is \['t_ms', 'x_mm'\]; expected the time "
                                             r"in seconds as 't_s' \(case-sensitive\), not 't_ms'$"):
        Recording.read_csv(path)
    program = tmp_path / "program.nc"
    program.write_text(PROGRAM)
    ms = Recording.from_channels({"t_s": np.arange(0.0, 9000.0, 10.0), "x_mm": np.zeros(900)})
    with pytest.raises(RecordingError, match=r"the recording lasts 8990 s .* Or is t_s written in ms\? recording\.md "
                                             r"asks for seconds\.$"):
        validate_recording(ms, program)


def test_a_cutting_load_alone_says_which_columns_a_diagnosis_needs(tmp_path):
    """Only t_s and fc_N, in a case with a [stock]: the message told the user to add a [stock] and cutting=True,
    which the case already had."""
    from orchestrator.diagnose import DiagnosisError, diagnose

    rows = "".join(f"{0.001 * k},{40.0 + (k % 5)}\n" for k in range(300))
    folder = write_case(tmp_path / "c", CASE, "t_s,fc_N\n" + rows)
    with pytest.raises(DiagnosisError, match=r"so the feed drives cannot be diagnosed \(its columns are \['t_s', "
                                             r"'fc_N'\]\); a cutting diagnosis needs \['fx_N', 'fy_N'\] too \(at least "
                                             r"100 samples each\) \('fc_N' is not enough: the cutting diagnosis "
                                             r"compares the force components\)$"):
        diagnose(folder)


def test_positions_logged_on_a_third_of_the_rows_are_diagnosed_on_those_rows(air_runs, tmp_path):
    """recording.md: an empty cell means 'not measured at this sample'. Positions on every third row, commands
    and currents on every row, is a legal log; the drive diagnosis took only axes whose position fills more than
    half the rows and refused it ('no axis moves'). It is diagnosed on the rows with a position: the twin's own
    run, so nothing is named and the replay reproduces it."""
    from orchestrator.diagnose import diagnose

    folder, own, _ = air_runs
    case = tmp_path / "thirds"
    case.mkdir()
    for name in ("program.nc", "case.toml"):
        (case / name).write_text((folder / name).read_text())
    _logged(case, own, np.arange(len(own)), 0.7)
    rec = Recording.read_csv(case / "recording.csv")
    channels = {c: np.asarray(rec[c], float).copy() for c in rec.channels}
    for a in "xyz":
        channels[f"{a}_mm"][np.arange(len(rec)) % 3 != 0] = np.nan
    Recording.from_channels(channels).write_csv(case / "recording.csv")
    result = diagnose(case)
    assert result.effects == [], result.log
    assert result.alignment["time_offset_s"] == pytest.approx(0.7, abs=1e-6)
    for a in "xyz":
        assert result.rms_before[f"{a}_fe_um"] < 0.01


def test_commands_logged_on_a_third_of_the_rows_are_not_dropped_silently(air_runs, tmp_path):
    """recording.md: readers never silently drop columns they know. Commands on every third row fill too little
    of the log to drive the replay (half the rows or fewer): the twin's commands do, and the log says so."""
    from orchestrator.diagnose import diagnose

    folder, own, _ = air_runs
    case = tmp_path / "thirds"
    case.mkdir()
    for name in ("program.nc", "case.toml"):
        (case / name).write_text((folder / name).read_text())
    _logged(case, own, np.arange(len(own)), 0.0)
    rec = Recording.read_csv(case / "recording.csv")
    channels = {c: np.asarray(rec[c], float).copy() for c in rec.channels}
    for a in "xyz":
        channels[f"{a}_ref_mm"][np.arange(len(rec)) % 3 != 0] = np.nan
    Recording.from_channels(channels).write_csv(case / "recording.csv")
    result = diagnose(case)
    assert result.effects == [], result.log
    share = f"{np.mean(np.arange(len(rec)) % 3 == 0):.0%}"   # 33 % (34 % when the row count is 1 mod 3)
    for a in "xyz":
        assert f"{a}_ref_mm is measured on {share} of the rows, half or fewer: the twin's own commands drive the " \
               f"{a} servo" in "\n".join(result.log)
