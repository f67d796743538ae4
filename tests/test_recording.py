"""Recording CSV contract (shared/spec/recording.md): round trip and clear errors."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator import Recording, RecordingError


def sample_recording(n=500, seed=1):
    rng = np.random.default_rng(seed)
    t = 0.0125 + np.arange(n) * 1e-3
    x = np.cumsum(rng.normal(0, 1e-3, n))
    channels = {
        "t_s": t,
        "line": np.repeat(np.arange(1, 6), n // 5).astype(float),
        "x_ref_mm": x,
        "x_mm": x - 0.05,
        "x_tcmd_A": rng.normal(0, 2, n),
        "spindle_rpm": np.full(n, 5000.0),
        "fc_N": rng.uniform(0, 60, n),
    }
    channels["fc_N"][10:20] = np.nan  # not measured
    return Recording.from_channels(channels)


def test_csv_round_trip_preserves_values_units_and_gaps(tmp_path):
    rec = sample_recording()
    path = rec.write_csv(tmp_path / "recording.csv")
    back = Recording.read_csv(path)
    assert back.channels == rec.channels
    for name in rec.channels:
        np.testing.assert_allclose(back[name], rec[name], rtol=1e-11, atol=0, equal_nan=True)
    assert np.isnan(back["fc_N"][10:20]).all()
    assert back.units["x_ref_mm"] == "mm" and back.units["x_tcmd_A"] == "A" and back.units["spindle_rpm"] == "rpm"
    header = path.read_text().splitlines()[0]
    assert header == "t_s,line,x_ref_mm,x_mm,x_tcmd_A,spindle_rpm,fc_N"
    # empty cell, not "nan", for not measured
    assert ",," in path.read_text().splitlines()[12] or path.read_text().splitlines()[12].endswith(",")


def test_following_error_is_derived(tmp_path):
    rec = sample_recording()
    np.testing.assert_allclose(rec.following_error_um("x"), 50.0, rtol=1e-9)


def test_extra_columns_are_kept_and_uneven_sampling_allowed(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("t_s,x_mm,logger_temp_C\n10.0,1.5,21\n10.003,1.6,\n10.0041,1.7,22\n")
    rec = Recording.read_csv(path)
    assert rec.channels == ["t_s", "x_mm", "logger_temp_C"]
    np.testing.assert_allclose(rec.t, [10.0, 10.003, 10.0041])


def test_extra_columns_that_are_not_numbers_are_ignored_not_fatal(tmp_path):
    # recording.md: "Extra columns are allowed and must be ignored by readers that do not know them."
    path = tmp_path / "log.csv"
    path.write_text("stamp,t_s,x_mm,alarm,note,note,,fc_N,\n"
                    "10:00:00.000,0.0,1.5,,a,b,,2.0,\n"
                    "10:00:00.001,0.001,1.6,SV0410,c,d,,2.5,\n")
    rec = Recording.read_csv(path)
    assert rec.channels == ["t_s", "x_mm", "fc_N"]
    np.testing.assert_array_equal(rec["x_mm"], [1.5, 1.6])
    np.testing.assert_array_equal(rec["fc_N"], [2.0, 2.5])


def test_numbers_are_plain_decimals_with_optional_exponent(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("t_s,x_mm,y_mm\n0,-.5,+2.\n1E-3,2.5e+1,3\n")
    rec = Recording.read_csv(path)
    np.testing.assert_array_equal(rec.t, [0.0, 0.001])
    np.testing.assert_array_equal(rec["x_mm"], [-0.5, 25.0])
    np.testing.assert_array_equal(rec["y_mm"], [2.0, 3.0])


@pytest.mark.parametrize(
    "body, match",
    [
        ("", "empty file"),
        ("t_s,x_mm\n0,1_000\n", r":2: column 'x_mm': '1_000' is not a plain decimal"),
        ("t_s,x_mm\n0,1\n0.001,0x10\n", r":3: column 'x_mm': '0x10'"),
        ("t_s,x_mm\n0,-inf\n", "empty cell"),
        ("t_s,x_mm,fc_N,fc_N\n0,1,2,3\n", "'fc_N' appears twice"),
        ("x_mm\n1\n", "no 't_s' column"),
        ("t_s\tx_mm\n0.0\t1.0\n", "separated by tabs; recording.md asks for ','"),        # a spreadsheet's TSV
        ("t_s;x_mm\n0,0;1,0\n", "separated by ';'; recording.md asks for ','"),           # a German locale
        ("t_s,x_mm,x_mm\n0,1,2\n", "appears twice"),
        ("t_s,x_mm\n0,1\n0.001,abc\n", r":3: column 'x_mm': 'abc'"),
        ("t_s,x_mm\n0,1\n0.002,1\n0.001,1\n", r":4: t_s goes back"),
        ("t_s,x_mm\n0,1\n0,1\n", r":3: t_s repeats"),
        ("t_s,x_mm\n0,1\n,1\n", r":3: empty t_s"),
        ("t_s,x_mm\n0,nan\n", "empty cell"),
        ("t_s,x_mm\n0,1,3\n", r":2: 3 cells"),
    ],
)
def test_bad_files_name_file_line_and_column(tmp_path, body, match):
    path = tmp_path / "bad.csv"
    path.write_text(body)
    with pytest.raises(RecordingError, match=match) as info:
        Recording.read_csv(path)
    assert "bad.csv" in str(info.value)


def test_missing_required_column_is_named(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("t_s,x_mm\n0,1\n")
    with pytest.raises(RecordingError, match=r"x_tcmd_A"):
        Recording.read_csv(path, required=["x_tcmd_A"])


def test_missing_and_binary_files(tmp_path):
    with pytest.raises(RecordingError, match="not found"):
        Recording.read_csv(tmp_path / "none.csv")
    path = tmp_path / "bin.csv"
    path.write_bytes(b"\xff\xfe\x00\x01garbage")
    with pytest.raises(RecordingError, match="not a UTF-8"):
        Recording.read_csv(path)


def test_to_pandas_has_time_index():
    pd = pytest.importorskip("pandas")
    frame = sample_recording().to_pandas()
    assert isinstance(frame, pd.DataFrame)
    assert frame.index.name == "t_s"
    assert frame.attrs["units"]["x_mm"] == "mm"


@pytest.mark.parametrize("batch", [1, 3])
def test_recording_from_rows_is_a_view_of_the_rows(batch):
    """Row i = (t, every channel's members): the fields are those columns, and no data is copied."""
    n, names = 5, ["x_mm", "fc_N"]
    rows = np.arange(n * (1 + 2 * batch), dtype=float).reshape(n, 1 + 2 * batch)
    rec = Recording.from_rows(rows, names, batch, {"x_mm": "mm"})
    assert rec.channels == ["t_s", *names] and len(rec) == n and rec.batch == batch
    np.testing.assert_array_equal(rec.t, rows[:, 0])
    for i, name in enumerate(names):
        expected = rows[:, 1 + i * batch:1 + (i + 1) * batch]
        np.testing.assert_array_equal(rec[name], expected[:, 0] if batch == 1 else expected)
    assert rec.units == {"t_s": "s", "x_mm": "mm", "fc_N": "N"}
    rows[2, 0] = -1.0
    assert rec.t[2] == -1.0  # the same memory
    with pytest.raises(RecordingError, match="contiguous float64"):
        Recording.from_rows(rows[:, :-1], names, batch)
