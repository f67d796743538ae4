"""shared/spec/recording.md clause by clause, on files a *foreign* logger or spreadsheet writes.

Each test names the clause it checks. A file obeying a clause must read to the numbers written in it (``float``
of the cell), through the recording reader and through the readers of the commands that consume it
(identification, diagnosis); a file violating one must give an error naming the file, the line and the field.
Clauses already covered elsewhere are listed at the end of this module's docstring, not repeated.

Covered elsewhere: columns in another order, CRLF, a BOM, ``line`` written as ``12.0``, trailing blank lines and
a negative logger clock (test_unseen_recordings); rows going back or repeating, NaN, infinity, ``1_000``, hex,
tabs and ';' as separators, a contract column twice (test_recording); text in an extra column, a column without
a name (test_recording); ``fc_N`` without ``fx_N``/``fy_N`` (test_identify_cutting); ``[machine] parameters`` as
a path, a machine that is not there (test_unseen_recordings); stock and tool values out of range
(test_reliability_files, test_machine_case).
"""
from __future__ import annotations

import re

import numpy as np
import pytest

from orchestrator.case import CaseError, load_case
from orchestrator.diagnose.core import _read as diagnosis_reads
from orchestrator.identify import IdentificationError
from orchestrator.identify.data import load_recording
from orchestrator.recording import SPEC_COLUMNS, Recording, RecordingError
from tests.test_unseen_recordings import CASE, write_case


def _read(tmp_path, text: str, name: str = "recording.csv") -> Recording:
    path = tmp_path / name
    path.write_bytes(text.encode("utf-8"))
    return Recording.read_csv(path)


# ----------------------------------------------------------------------------- "First row: column names.
#                                                             Every column is optional except t_s"
def test_t_s_alone_is_a_recording(tmp_path):
    rec = _read(tmp_path, "t_s\n0.5\n0.75\n")
    assert rec.channels == ["t_s"]
    np.testing.assert_array_equal(rec.t, [0.5, 0.75])


def test_an_excel_export_with_quoted_names_and_cells_and_blanks_around_them_reads_the_same(tmp_path):
    """Excel quotes every cell it saves as CSV ("t_s","x_mm"); hand-edited files put blanks around names and
    numbers. Names are stripped, quotes removed, blanks around a number ignored, 1e-3 is a plain decimal."""
    plain = _read(tmp_path, "t_s,x_mm,fc_N\n0.001,1.5,20\n0.002,-2.5e-1,\n", "plain.csv")
    for text in ('"t_s","x_mm","fc_N"\r\n"1e-3","1.5","20"\r\n"2E-3","-0.25",""\r\n',
                 ' t_s , x_mm ,\tfc_N\n 0.001 ,1.5 , 2e1\n0.002\t, -.25 ,   \n'):
        rec = _read(tmp_path, text)
        assert rec.channels == ["t_s", "x_mm", "fc_N"]
        for name in rec.channels:
            np.testing.assert_array_equal(rec[name], plain[name])


# ----------------------------------------------------------------------------- "an empty cell means not measured"
def test_empty_cells_in_every_contract_column_whole_empty_columns_and_first_and_last_rows(tmp_path):
    """Every contract column, each empty somewhere; the first and last rows hold only t_s; fz_N is never
    measured. Empty cells are NaN, every other cell its number, no row or known column dropped."""
    names = list(SPEC_COLUMNS)
    n = 6
    values = {name: np.arange(n) + 10.0 * j for j, name in enumerate(names)}
    values["t_s"] = 100.0 + 0.004 * np.arange(n)
    values["line"] = np.array([1, 2, 2, 3, 3, 4], dtype=float)
    empty = {name: np.zeros(n, dtype=bool) for name in names}
    for j, name in enumerate(names[1:]):
        empty[name][[0, n - 1, 1 + j % (n - 2)]] = True   # first and last row, and one row inside
    empty["fz_N"][:] = True
    rows = [",".join("" if empty[name][k] else repr(float(values[name][k])) for name in names) for k in range(n)]
    rec = _read(tmp_path, ",".join(names) + "\n" + "\n".join(rows) + "\n")
    assert rec.channels == names
    for name in names:
        expected = np.where(empty[name], np.nan, values[name])
        np.testing.assert_array_equal(rec[name], expected, err_msg=name)
    assert rec.file_lines.of(np.arange(n)).tolist() == [2, 3, 4, 5, 6, 7]


# ----------------------------------------------------------------------------- "Extra columns are allowed and
#                                                             must be ignored by readers that do not know them"
def test_extra_number_columns_are_kept_through_a_rewrite_and_text_ones_are_not(tmp_path):
    rec = _read(tmp_path, "t_s,spindle_load_pct,x_mm,operator\n0,12.5,1,ann\n0.001,13,2,bob\n")
    assert rec.channels == ["t_s", "spindle_load_pct", "x_mm"]
    back = Recording.read_csv(rec.write_csv(tmp_path / "again.csv"))
    assert back.channels == rec.channels
    np.testing.assert_array_equal(back["spindle_load_pct"], [12.5, 13.0])
    np.testing.assert_array_equal(back["x_mm"], [1.0, 2.0])


# ----------------------------------------------------------------------------- "Sampling may be uneven, start at
#                                                             any time, and be shifted against the program start"
@pytest.mark.parametrize("start", [-3.25, 1e5, 1.7643e9])
def test_a_logger_clock_anywhere_reads_exactly_and_survives_a_rewrite(tmp_path, start):
    """A logger clock of 1e5 s, or Unix time (1.7643e9 s), at 1 ms and then 0.5 ms steps. Written back with
    %.12g, Unix time came back in 10 ms steps (so rows repeated); t_s is now written to 1 µs or finer."""
    steps = np.concatenate([np.full(5, 1e-3), np.full(5, 0.5e-3)])
    t = start + np.concatenate([[0.0], np.cumsum(steps)])
    cells = [f"{v:.6f}" for v in t]
    rec = _read(tmp_path, "t_s,x_mm\n" + "".join(f"{c},{k}\n" for k, c in enumerate(cells)))
    np.testing.assert_array_equal(rec.t, [float(c) for c in cells])
    back = Recording.read_csv(rec.write_csv(tmp_path / "again.csv"))
    np.testing.assert_allclose(np.diff(back.t), steps, rtol=0, atol=1e-6)
    assert np.abs(back.t - rec.t).max() <= 0.5e-6


# ----------------------------------------------------------------------------- "Rows are in increasing t_s"
@pytest.mark.parametrize("clock", ["", "1764300000"])
def test_times_rounded_coarser_than_the_sampling_are_named_with_the_cause(tmp_path, clock):
    """A 0.5 ms logger writing t_s with 3 decimals repeats every other time: the error names the line and the
    grid the times are written on (also on a Unix-time clock, whose steps carry 2.4e-7 s of rounding)."""
    t = [f"{clock or 0}.00{k}" for k in (0, 1, 1, 2)]
    with pytest.raises(RecordingError, match=rf"recording\.csv:4: t_s repeats \({float(t[1])!r} then "
                                             rf"{float(t[2])!r}\); rows must be in strictly increasing time; t_s is "
                                             r"written to 0\.001 s: does the logger sample faster than that\? write "
                                             r"t_s with more decimals$"):
        _read(tmp_path, "t_s,x_mm\n" + "".join(f"{v},0\n" for v in t))
    with pytest.raises(RecordingError, match=r"recording\.csv:3: t_s repeats \(0\.0 then 0\.0\); rows must be in "
                                             r"strictly increasing time$"):   # no grid to name: no hint
        _read(tmp_path, "t_s,x_mm\n0,0\n0,0\n")


# ----------------------------------------------------------------------------- every command reads the same file
def test_identification_and_diagnosis_read_a_foreign_export_as_the_reader_does(tmp_path):
    """The identification's and the diagnosis's readers (which also check the file against the program) give
    the reader's numbers for a quoted, CRLF, blank-padded export with a Unix-time clock and an extra column."""
    body = "".join(f'"{1.7643e9 + 0.002 * k:.3f}", {k // 3 + 3} ,"{0.25 * k}","{k % 3}",""\r\n' for k in range(8))
    folder = write_case(tmp_path / "c", CASE, recording='"t_s","line","x_mm","temp_C","fc_N"\r\n' + body)
    expected = Recording.read_csv(folder / "recording.csv")
    np.testing.assert_array_equal(expected.t, [float(f"{1.7643e9 + 0.002 * k:.3f}") for k in range(8)])
    case = load_case(folder)
    for rec in (load_recording(case), diagnosis_reads(case)):
        assert rec.channels == ["t_s", "line", "x_mm", "temp_C", "fc_N"]
        for name in rec.channels:
            np.testing.assert_array_equal(rec[name], expected[name])
    # a value the checks refuse is named with its time to the microsecond (it was "t_s = 1.7643e+09" on every row)
    (folder / "recording.csv").write_text('"t_s","line","x_mm","temp_C","fc_N"\r\n' + body.replace('"0.75"', '"1e9"'))
    with pytest.raises(IdentificationError, match=r"recording\.csv:5: column 'x_mm' \(t_s = 1764300000\.006\): "
                                                  r"1000000000\.0 is outside the plausible range"):
        load_recording(case)


# ----------------------------------------------------------------------------- case.toml: "a clear error naming
#                                                             the file, the line and the field"
@pytest.mark.parametrize("change, line, message", [
    (("flutes = 2\n", ""), 8, r"\[tool\] needs 'flutes' \(the number of teeth\); without a \[tool\] table the case "
                              r"uses 6 mm, 2 flutes"),
    (("diameter_mm = 6.0\n", ""), 8, r"\[tool\] needs 'diameter_mm' \(the cutter diameter in mm\)"),
    (('parameters = "default"\n', ""), 12, r"\[machine\] needs 'parameters' \(a set shipped in models/machines"),
    (("diameter_mm = 6.0", 'diameter_mm = "6.0"'), 9, r"\[tool\] diameter_mm must be a number in mm .* got '6\.0'"),
    (("flutes = 2", 'flutes = "2"'), 10, r"\[tool\] flutes must be a whole number 1\.\.24, got '2'"),
    (("max = [30.0, 20.0, 0.0]\n", ""), 4, r"\[stock\] needs 'max' = \[x, y, z\] in mm"),
    (('parameters = "default"', "parameters = 3"), 13, r"\[machine\] parameters must be a string"),
])
def test_a_case_field_missing_or_of_the_wrong_type_names_file_line_and_field(tmp_path, change, line, message):
    """A [tool] table without its diameter silently became the 6 mm paper tool (and without flutes, 2 flutes):
    the cutting load and every cutting coefficient fitted with it were off without a word."""
    folder = write_case(tmp_path / "c", CASE.replace(*change))
    with pytest.raises(CaseError, match=rf"^{re.escape(str(folder / 'case.toml'))}:{line}: {message}"):
        load_case(folder)


def test_a_case_without_tool_and_machine_tables_takes_the_documented_defaults(tmp_path):
    folder = write_case(tmp_path / "c", 'program = "program.nc"\nrecording = "recording.csv"\n')
    case = load_case(folder)
    assert (case.tool.diameter_mm, case.tool.flutes, case.machine.name, case.stock) == (6.0, 2, "default", None)
