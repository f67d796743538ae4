"""Recording CSV in chunks: the fast path reads exactly what the strict row-by-row path reads.

The strict path (``csv`` row by row, every cell checked) is the reference: files mixing valid rows with every
kind of trouble a logger writes are read with the chunked fast path and with the strict path alone, and must
give the same table, the same ignored columns, or the same error message.
"""
from __future__ import annotations

import random
from pathlib import Path

import numpy as np
import pytest

from orchestrator import recording_csv
from orchestrator.recording import Recording, RecordingError, SPEC_COLUMNS
from orchestrator.recording_csv import read_table, table_text, write_table

HEADER = ["t_s", "line", "x_mm", "fx_N", "probe_V"]

# cells a logger may write, with what the contract says of them
GOOD = ["1", "-2.5", "+.5", "3.", "1e-3", "2E+4", " 7 ", "\t-0", "", "  ", "0.000000000000000000001"]
BAD = ["1-2", "1e", ".", "nan", "inf", "1 2", "0x10", "1,5", "abc", '"3.5"', "1e999", "- 1", "١"]


def _row(rng: random.Random, t: float, bad_share: float) -> list[str]:
    cells = [repr(round(t, 6))]
    for _ in HEADER[1:]:
        pool = BAD if rng.random() < bad_share else GOOD
        cells.append(rng.choice(pool))
    return cells


def _file_text(rng: random.Random, rows: int, bad_share: float) -> str:
    ending = rng.choice(["\n", "\r\n", "\r"])
    lines = [",".join(HEADER)]
    odd_share = rng.choice([0.0, 0.005, 0.02])  # blank lines, trailing commas, no time, a cell missing
    for i in range(rows):
        cells = _row(rng, 0.001 * (i + 1), bad_share)
        kind = rng.random() / max(odd_share, 1e-9)
        if kind < 0.4:
            lines.append("")
        elif kind < 0.8:
            cells.append("")
        elif kind < 0.9:
            cells[0] = ""
        elif kind < 1.0:
            cells = cells[:-1]
        lines.append(",".join(cells))
    return ending.join(lines) + rng.choice(["", ending])


def _read(path: Path, strict_only: bool, monkeypatch: pytest.MonkeyPatch):
    with monkeypatch.context() as m:
        m.setattr(recording_csv, "CHUNK_BYTES", 256)  # many chunks of a few lines each
        if strict_only:
            m.setattr(recording_csv._ChunkParser, "_fast", lambda self, lines: None)
        try:
            table = read_table(path, SPEC_COLUMNS)
        except RecordingError as exc:
            return str(exc)
        return table


@pytest.mark.parametrize("seed", range(40))
def test_fast_path_reads_what_the_strict_path_reads(tmp_path, monkeypatch, seed):
    rng = random.Random(seed)
    path = tmp_path / "rec.csv"
    bad_share = rng.choice([0.0, 0.0, 0.001, 0.01])
    path.write_bytes(_file_text(rng, rng.randint(1, 120), bad_share).encode("utf-8"))
    fast = _read(path, False, monkeypatch)
    strict = _read(path, True, monkeypatch)
    if isinstance(strict, str):
        assert fast == strict
        return
    assert not isinstance(fast, str), fast
    assert fast.header == strict.header and fast.ignored == strict.ignored
    assert np.array_equal(fast.lines, strict.lines)
    assert fast.values.shape == strict.values.shape
    assert np.array_equal(fast.values.view(np.uint64), strict.values.view(np.uint64))  # bit for bit, NaN too


def test_plain_numbers_take_the_fast_path_with_float_rounding(tmp_path, monkeypatch):
    rng = np.random.default_rng(5)
    values = rng.normal(scale=10.0 ** rng.integers(-8, 8, size=(300, 4)), size=(300, 4))
    values[:, 0] = np.arange(300) * 0.001
    cells = [[repr(float(v)) for v in row] for row in values]
    cells[7][2] = ""  # not measured
    path = tmp_path / "rec.csv"
    path.write_text("t_s,x_mm,fx_N,other_V\n" + "\n".join(",".join(r) for r in cells) + "\n")
    calls = []
    strict = recording_csv._ChunkParser._strict
    monkeypatch.setattr(recording_csv._ChunkParser, "_strict", lambda self, *a: calls.append(1) or strict(self, *a))
    monkeypatch.setattr(recording_csv, "CHUNK_BYTES", 1000)
    table = read_table(path, SPEC_COLUMNS)
    assert not calls  # every chunk went the fast way
    expected = np.array([[float(c) if c else np.nan for c in r] for r in cells])
    assert np.array_equal(table.values.view(np.uint64), expected.view(np.uint64))
    assert table.lines.tolist() == list(range(2, 302))


def test_error_in_a_later_chunk_names_its_line(tmp_path, monkeypatch):
    monkeypatch.setattr(recording_csv, "CHUNK_BYTES", 200)
    rows = [f"{0.001 * i:.3f},{i}" for i in range(1, 500)]
    rows[399] = "0.400,1O"  # line 401: letter O for zero
    path = tmp_path / "rec.csv"
    path.write_text("t_s,x_mm\n" + "\n".join(rows) + "\n")
    with pytest.raises(RecordingError, match=r"rec.csv:401: column 'x_mm': '1O' is not a plain decimal"):
        Recording.read_csv(path)
    rows[399] = "0.400,1"
    rows[300] = "0.100,1"  # line 302: time goes back across chunks
    path.write_text("t_s,x_mm\n" + "\n".join(rows) + "\n")
    with pytest.raises(RecordingError, match=r"rec.csv:302: t_s goes back \(0.3 then 0.1\)"):
        Recording.read_csv(path)


def test_text_column_is_ignored_in_every_chunk(tmp_path, monkeypatch):
    monkeypatch.setattr(recording_csv, "CHUNK_BYTES", 100)
    rows = [f"{0.001 * i:.3f},{i}.5,{'ok' if i % 7 else 'WARN'},{-i}" for i in range(1, 200)]
    path = tmp_path / "rec.csv"
    path.write_text("t_s,x_mm,status,y_mm\n" + "\n".join(rows) + "\n")
    rec = Recording.read_csv(path)
    assert rec.channels == ["t_s", "x_mm", "y_mm"]
    assert np.array_equal(rec["x_mm"], np.arange(1, 200) + 0.5)
    assert np.array_equal(rec["y_mm"], -np.arange(1.0, 200.0))


def test_written_file_reads_back_to_twelve_significant_digits(tmp_path, monkeypatch):
    monkeypatch.setattr(recording_csv, "CHUNK_BYTES", 300)  # several chunks of rows
    rng = np.random.default_rng(2)
    t = np.arange(250) * 1e-3
    x = rng.normal(size=250) * 1e3
    x[[3, 100]] = np.nan
    line = np.floor(rng.uniform(1, 50, size=250))
    path = write_table(tmp_path / "out.csv", ["t_s", "line", "x_mm"], [t, line, x], integer=["line"])
    text = path.read_text()
    assert text == table_text(["t_s", "line", "x_mm"], [t, line, x], integer=["line"])
    rec = Recording.read_csv(path)
    assert np.array_equal(rec["line"], line)
    expected = np.array([float(f"{v:.12g}") for v in x])
    assert np.array_equal(rec["x_mm"], expected, equal_nan=True)
    assert text.splitlines()[4] == f"{t[3]:.12g},{int(line[3])},"  # NaN: an empty cell


def test_failed_write_leaves_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "out.csv"
    path.write_text("old\n")

    def broken(names, columns, integer):
        yield "t_s\n"
        raise RuntimeError("disk gone")

    monkeypatch.setattr(recording_csv, "_text_chunks", broken)
    with pytest.raises(RuntimeError, match="disk gone"):
        write_table(path, ["t_s"], [np.zeros(3)])
    assert path.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]  # no temporary file left
