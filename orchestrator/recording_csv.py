"""Recording CSV files, read and written in chunks: memory bounded by the table, not by its text.

A 1 kHz machine log of a 30 min program has 1.8 million rows. Reading it as one list of Python strings took
about 13 bytes of memory per byte of file (a 114 MB recording: 1.4 GB and 17 s); this module reads and writes
``CHUNK_BYTES`` of text at a time, so memory is the float table (8 bytes per cell) plus one chunk.

Reading
-------
Every chunk of lines is first tried on the *fast path*: one regular expression per line checks that the line
has exactly the header's cells (then, optionally, empty cells after the last column: a trailing comma), each a
plain decimal number or empty, with ``t_s`` not empty, blanks and tabs allowed around a number. A chunk whose
lines all match is converted by numpy in one call (empty cell -> NaN). Any other chunk (a quoted cell, a word in
an extra column, a bad number, a blank line, a row with another number of cells) goes to the *strict path*:
:mod:`csv` row by row, with the checks and messages of :meth:`Recording.read_csv`. Both paths accept and reject
the same files and give the same numbers (``float`` of the cell: correctly rounded).

Writing
-------
Rows are formatted with ``%.12g`` per cell (``t_s`` to 1 µs also beyond 1e6 s; ``line`` truncated to an integer) in
chunks and streamed into the temporary file of :func:`orchestrator.atomic.atomic_writer`, so nothing half-written
ever has the target's name.
"""
from __future__ import annotations

import csv
import logging
import math
import re
from dataclasses import dataclass
from operator import itemgetter
from pathlib import Path
from typing import IO, Iterable, Iterator, Sequence

import numpy as np

from .atomic import atomic_writer
from .errors import CncTwinError

_log = logging.getLogger(__name__)

#: Text read or written per chunk, characters.
CHUNK_BYTES = 4 << 20
#: A plain decimal number: sign, digits with ``.`` as the decimal point, optional exponent (as written by
#: loggers and by :func:`write_table`); no thousands separators, underscores, hex, NaN or infinity.
DECIMAL = r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"
_DECIMAL_RE = re.compile(DECIMAL)
_BLANKS = str.maketrans("", "", " \t")
#: The characters of lines of plain numbers.
_NUMBER_CHARACTERS = b"0123456789eE+-., \t\r\n"
#: Blanks between two characters of numbers: one cell written as two numbers ('1 2').
_BLANK_INSIDE = re.compile(r"[0-9.eE+\-][ \t]+[0-9.eE+\-]")


def _fill_empty(text: str) -> str:
    """Comma-separated cells without blanks, with 'nan' in every empty cell."""
    text = text.replace(",,", ",nan,").replace(",,", ",nan,")
    if text.startswith(","):
        text = "nan" + text
    if text.endswith(","):
        text += "nan"
    return text or "nan"


class RecordingError(CncTwinError):
    """A recording file or object does not follow the recording contract."""


def cell_problem(cell: str) -> str | None:
    """Why a stripped, non-empty CSV cell is not a plain finite decimal number (None when it is one)."""
    if _DECIMAL_RE.fullmatch(cell) is None:
        if cell.lower().lstrip("+-") in ("nan", "inf", "infinity"):
            return "; write an empty cell for 'not measured'"
        return " is not a plain decimal number"
    if not math.isfinite(float(cell)):
        return " is beyond the floating-point range; write an empty cell for 'not measured'"
    return None


@dataclass
class Table:
    """The body of a recording CSV.

    Attributes
    ----------
    header : list of str
        Column names, stripped, in file order.
    values : ndarray (n, len(header))
        Cell values; NaN for an empty cell and in ignored columns.
    ignored : set of int
        Columns that are not read (no name, an unknown name twice, or an extra column with a non-number).
    lines : ndarray of int (n,)
        File line number (1-based) of every row.
    """

    header: list[str]
    values: np.ndarray
    ignored: set[int]
    lines: np.ndarray


@dataclass(frozen=True)
class FileLines:
    """Where the rows of a recording stand in its CSV file: 1-based line numbers, kept as runs.

    A file's rows are consecutive lines except where blank lines (or a cell spanning lines) come between, so
    the line of every row is stored as runs of consecutive lines: memory grows with the number of such breaks,
    not with the number of rows (a 10-minute log of 600 000 rows without a blank line is one run).

    Attributes
    ----------
    path : str
        The file.
    starts : ndarray of int64
        First row (0-based) of each run, increasing; ``starts[0] == 0`` when there are rows.
    first : ndarray of int64
        File line (1-based) of that row.
    rows : int
        Number of rows.
    """

    path: str
    starts: np.ndarray
    first: np.ndarray
    rows: int

    @classmethod
    def from_numbers(cls, path: str | Path, numbers: np.ndarray) -> "FileLines":
        """Runs of the file line numbers ``numbers`` (one per row, increasing)."""
        numbers = np.asarray(numbers, dtype=np.int64)
        if numbers.size == 0:
            return cls(str(path), np.zeros(0, np.int64), np.zeros(0, np.int64), 0)
        starts = np.concatenate([[0], np.flatnonzero(np.diff(numbers) != 1) + 1]).astype(np.int64)
        return cls(str(path), starts, numbers[starts].copy(), int(numbers.size))

    def of(self, rows: np.ndarray | int) -> np.ndarray:
        """File lines (1-based) of 0-based ``rows``.

        Raises
        ------
        IndexError
            A row outside ``0 .. rows - 1``.
        """
        k = np.asarray(rows, dtype=np.int64)
        if k.size and (k.min() < 0 or k.max() >= self.rows):
            raise IndexError(f"{self.path}: row {int(k.max() if k.max() >= self.rows else k.min())} is not one of "
                             f"its {self.rows} rows")
        run = np.searchsorted(self.starts, k, side="right") - 1
        return self.first[run] + (k - self.starts[run])

    def line(self, row: int) -> int:
        """File line (1-based) of the 0-based ``row``."""
        return int(self.of(np.int64(row)))

    def take(self, index: np.ndarray) -> "FileLines":
        """The lines of the rows ``index`` (integer indices, or a boolean mask over all rows)."""
        index = np.asarray(index)
        rows = np.flatnonzero(index) if index.dtype == bool else index.astype(np.int64)
        return FileLines.from_numbers(self.path, self.of(rows))


def read_table(path: Path, contract: Iterable[str], required: Iterable[str] = ()) -> Table:
    """Read a recording CSV into a float table, checking the header and every cell.

    Parameters
    ----------
    path : Path
        The CSV file.
    contract : iterable of str
        Column names the recording contract defines (a bad cell there is an error; in another column it makes
        the column ignored).
    required : iterable of str
        Columns the caller needs besides ``t_s``.

    Raises
    ------
    RecordingError
        As listed in :meth:`orchestrator.recording.Recording.read_csv`, naming the file, line and column.
    """
    contract = set(contract)
    if not path.is_file():
        raise RecordingError(f"{path}: recording file not found")
    with open(path, encoding="utf-8-sig", newline="") as handle:
        reader = _LineReader(path, handle)
        first = reader.header_line()
        try:
            header = [cell.strip() for cell in next(csv.reader([first]), [])]
        except csv.Error as exc:
            raise RecordingError(f"{path}:1: {exc}; expected a header row of column names, 't_s' first") from None
        _check_header(path, header, contract, required)
        counts = {name: header.count(name) for name in header}
        ignored = {j for j, name in enumerate(header) if not name or counts[name] > 1}
        parser = _ChunkParser(path, header, contract, ignored)
        chunks: list[np.ndarray] = []
        line_numbers: list[np.ndarray] = []
        for first_line, lines in reader.chunks():
            values, numbers = parser.parse(first_line, lines)
            chunks.append(values)
            line_numbers.append(numbers)
    values = np.concatenate(chunks) if chunks else np.empty((0, len(header)))
    numbers = np.concatenate(line_numbers) if line_numbers else np.empty(0, dtype=np.int64)
    return Table(header, values, parser.ignored, numbers)


def _check_header(path: Path, header: list[str], contract: set[str], required: Iterable[str]) -> None:
    """Raise RecordingError for an empty header, no ``t_s``, a contract column twice or a required one missing."""
    if not any(header):
        raise RecordingError(f"{path}:1: empty file; expected a header row with column names, 't_s' first")
    if "t_s" not in header:
        separator = next((name for sep, name in (("\t", "tabs"), (";", "';'"), ("|", "'|'"))
                          if len(header) == 1 and sep in header[0]), None)
        hint = (f": its columns are separated by {separator}; recording.md asks for ',' (and '.' as the "
                "decimal point)") if separator else ""
        other_time = [name for name in header if re.fullmatch(r"(?i)t(ime)?(_?\(?(s|ms|us|min)\)?)?", name)]
        if not hint and other_time:
            hint = f"; expected the time in seconds as 't_s' (case-sensitive), not {other_time[0]!r}"
        raise RecordingError(f"{path}:1: no 't_s' column; header is {header}{hint}")
    for name in header:
        if name in contract and header.count(name) > 1:
            raise RecordingError(f"{path}:1: column {name!r} appears twice")
    missing = [c for c in required if c not in header]
    if missing:
        raise RecordingError(f"{path}:1: missing column(s) {missing} needed here; header is {header}"
                             f"{near_miss_hint(header, contract)}")
    misses = near_misses(header, contract)
    if misses:
        _log.warning("%s:1: column(s) %s are not recording.md names and are read as extra columns%s", path,
                     sorted(misses), near_miss_hint(header, contract))


def near_misses(names: Iterable[str], contract: Iterable[str]) -> dict[str, str]:
    """Names that are a contract column but for upper/lower case or blanks (``'X_MM'`` -> ``'x_mm'``)."""
    known = {re.sub(r"\s+", "", c).lower(): c for c in contract}
    names = list(names)
    return {n: known[re.sub(r"\s+", "", n).lower()] for n in names
            if n not in known.values() and re.sub(r"\s+", "", n).lower() in known
            and known[re.sub(r"\s+", "", n).lower()] not in names}


def near_miss_hint(names: Iterable[str], contract: Iterable[str]) -> str:
    """``"; 'X_MM' is not 'x_mm' ..."`` for the names of :func:`near_misses` (empty when there are none)."""
    misses = near_misses(names, contract)
    if not misses:
        return ""
    pairs = ", ".join(f"{n!r} is not {c!r}" for n, c in list(misses.items())[:4])
    return f"; {pairs}{' ...' if len(misses) > 4 else ''}: column names are case-sensitive (recording.md)"


_LINE_BREAK = re.compile(rb"\r\n|\r|\n")


def _not_utf8(path: Path, exc: UnicodeDecodeError) -> RecordingError:
    """The error for a file that is not UTF-8, naming the line and byte of the first undecodable byte.

    The text reader decodes ahead of the lines it hands out, so the position is found again in the bytes
    (lines end at CR LF, CR or LF, as the reader counts them).
    """
    line, consumed = 1, 0
    with open(path, "rb") as handle:
        for raw in handle:  # split at LF only: a CR-only file is one piece, counted below
            try:
                raw.decode("utf-8")
            except UnicodeDecodeError as bad:
                before = raw[:bad.start]
                breaks = list(_LINE_BREAK.finditer(before))
                start = breaks[-1].end() if breaks else 0
                return RecordingError(
                    f"{path}: not a UTF-8 text file: line {line + len(breaks)}, byte {bad.start - start + 1} "
                    f"(byte offset {consumed + bad.start}) is 0x{raw[bad.start]:02x}, not UTF-8 text; expected a "
                    "CSV recording in UTF-8 (save it as UTF-8, not Latin-1 or UTF-16)")
            line += len(_LINE_BREAK.findall(raw))
            consumed += len(raw)
    return RecordingError(f"{path}: not a UTF-8 text file ({exc.reason}); expected a CSV recording in UTF-8")


class _LineReader:
    """The lines of an open CSV file: the header line, then chunks of about CHUNK_BYTES characters."""

    def __init__(self, path: Path, handle: IO[str]) -> None:
        self.path = path
        self.handle = handle
        self.count = 0  # lines read so far

    def _read(self, hint: int) -> list[str]:
        try:
            lines = self.handle.readlines(hint) if hint else [self.handle.readline()]
        except UnicodeDecodeError as exc:
            raise _not_utf8(self.path, exc) from None
        return [line for line in lines if line]

    def header_line(self) -> str:
        lines = self._read(0)
        if not lines:
            raise RecordingError(f"{self.path}:1: empty file; expected a header row with column names, 't_s' first")
        self.count = 1
        return lines[0]

    def chunks(self) -> Iterable[tuple[int, list[str]]]:
        """``(line number of the first line, lines)`` until the end of the file."""
        while True:
            lines = self._read(CHUNK_BYTES)
            if not lines:
                return
            yield self.count + 1, lines
            self.count += len(lines)


class _ChunkParser:
    """Turns chunks of lines into rows of floats (fast path, else the strict row-by-row path)."""

    def __init__(self, path: Path, header: list[str], contract: set[str], ignored: set[int]) -> None:
        self.path = path
        self.header = header
        self.contract = contract
        self.ignored = ignored
        self._compile()

    def _compile(self) -> None:
        blank = r"[ \t]*"
        number = f"({DECIMAL})"
        cells = []
        for j, name in enumerate(self.header):
            if j in self.ignored:
                cells.append(r"([^,\"\r\n]*)")
            elif name == "t_s":
                cells.append(blank + number + blank)
            else:
                cells.append(blank + f"((?:{DECIMAL})?)" + blank)
        self._line = re.compile("(" + ",".join(cells) + r")(?:,[ \t]*)*(?:\r\n|\r|\n)?")
        kept = [j for j in range(len(self.header)) if j not in self.ignored]
        self._kept = kept
        self._time = kept.index(self.header.index("t_s"))
        # groups: 1 = the header's cells; 2.. = one per cell
        self._pick = itemgetter(*[j + 1 for j in kept]) if len(kept) > 1 else None

    def parse(self, first_line: int, lines: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """Rows of one chunk and their file line numbers."""
        fast = self._fast(lines)
        if fast is not None:
            return fast, np.arange(first_line, first_line + len(lines), dtype=np.int64)
        return self._strict(first_line, lines)

    def _fast(self, lines: list[str]) -> np.ndarray | None:
        """The chunk's rows when every line is plain numbers in the header's cells; None otherwise."""
        if self.ignored:
            return self._fast_with_ignored(lines)
        raw = "".join(lines)
        try:
            data = raw.encode("ascii")
        except UnicodeEncodeError:
            return None
        if data.translate(None, _NUMBER_CHARACTERS):  # something else than numbers, commas, blanks, line ends
            return None
        if (b" " in data or b"\t" in data) and _BLANK_INSIDE.search(raw):
            return None
        commas = len(self.header) - 1
        if any(line.count(",") != commas for line in lines):
            return None
        text = ",".join([line.rstrip("\r\n") for line in lines]).translate(_BLANKS)
        return self._numbers(_fill_empty(text), len(lines))

    def _fast_with_ignored(self, lines: list[str]) -> np.ndarray | None:
        """The fast path for a file with ignored columns: a regular expression per line picks the kept cells."""
        match = self._line.fullmatch
        found = [match(line) for line in lines]
        if not all(found):
            return None
        if len(self._kept) == 1:
            text = ",".join(m.group(self._kept[0] + 2) for m in found)  # type: ignore[union-attr]
        else:
            pick = self._pick
            text = ",".join(",".join(pick(m.groups())) for m in found)  # type: ignore[union-attr, misc]
        values = self._numbers(_fill_empty(text.translate(_BLANKS)), len(lines))
        if values is None:
            return None
        table = np.full((len(lines), len(self.header)), np.nan)
        table[:, self._kept] = values
        return table

    def _numbers(self, text: str, n: int) -> np.ndarray | None:
        """``n`` rows of the kept columns from comma-separated plain numbers ('nan' for empty cells)."""
        try:
            flat = np.fromstring(text, sep=",")  # C parser, correctly rounded as float()
        except ValueError:  # e.g. '1-2', '1e': the strict path names the cell
            return None
        kept = len(self._kept)
        if flat.size != n * kept or np.isinf(flat).any():
            return None  # e.g. a number beyond the floating-point range: the strict path names it
        values = flat.reshape(n, kept)
        if np.isnan(values[:, self._time]).any():
            return None  # a row without a time, or a blank row: the strict path skips or names it
        return values

    def _strict(self, first_line: int, lines: list[str]) -> tuple[np.ndarray, np.ndarray]:
        header, width = self.header, len(self.header)
        rows: list[tuple[int, list[str]]] = []
        reader = csv.reader(lines)
        while True:
            lineno = first_line + reader.line_num  # a quoted cell may span lines: the row starts after the last
            try:
                row = next(reader, None)
            except csv.Error as exc:  # e.g. a cell longer than csv.field_size_limit()
                raise RecordingError(f"{self.path}:{lineno}: {exc}; expected comma-separated cells of numbers") from None
            if row is None:
                break
            rows.append((lineno, row))
        body = [(lineno, row) for lineno, row in rows if any(cell.strip() for cell in row)]
        values = np.full((len(body), width), np.nan)
        before = set(self.ignored)
        for k, (lineno, row) in enumerate(body):
            if len(row) > width and not any(cell.strip() for cell in row[width:]):
                row = row[:width]  # empty cells after the last column (a trailing comma)
            if len(row) != width:
                hint = ""
                if len(row) > width and any(c.strip().isdigit() for c in row):
                    hint = ("; is ',' the decimal point here (e.g. '0,5')? recording.md asks for '.' as the decimal "
                            "point and ',' between cells")
                raise RecordingError(f"{self.path}:{lineno}: {len(row)} cells, header has {width} columns{hint}")
            for j, cell in enumerate(row):
                cell = cell.strip()
                if not cell or j in self.ignored:
                    continue
                problem = cell_problem(cell)
                if problem is None:
                    values[k, j] = float(cell)
                elif header[j] in self.contract:
                    raise RecordingError(f"{self.path}:{lineno}: column {header[j]!r}: {cell!r}{problem}")
                else:
                    self.ignored.add(j)
                    _log.info("%s:%d: extra column %r ignored: %r%s", self.path, lineno, header[j], cell, problem)
        if self.ignored != before:
            self._compile()
        return values, np.array([lineno for lineno, _ in body], dtype=np.int64)


#: Significant digits of a written cell.
DIGITS = 12
#: Finest time step ``t_s`` keeps when written, s: a logger clock of 1.7e9 s (Unix time) needs 16 digits.
TIME_RESOLUTION_S = 1e-6


def time_digits(t: np.ndarray) -> int:
    """Significant digits that write every time of ``t`` [s] to :data:`TIME_RESOLUTION_S` or finer (12 to 17).

    ``%.12g`` keeps 1 µs up to 1e6 s; a logger clock beyond that (Unix time, 1.7e9 s) would come back in steps
    of 10 ms, and 1 ms samples would repeat.
    """
    finite = np.abs(np.asarray(t, dtype=float))
    finite = finite[np.isfinite(finite)]
    top = float(finite.max()) if finite.size else 0.0
    if top < 1.0:
        return DIGITS
    return int(min(17, max(DIGITS, math.floor(math.log10(top)) + 1 - round(math.log10(TIME_RESOLUTION_S)))))


def _text_chunks(names: Sequence[str], columns: Sequence[np.ndarray], integer: Iterable[str]) -> Iterator[str]:
    """The CSV text of the columns in chunks of about CHUNK_BYTES characters, the header first."""
    integer = set(integer)
    fmt = ",".join(f"%.{time_digits(c) if name == 't_s' else DIGITS}g" for name, c in zip(names, columns))
    yield ",".join(names) + "\n"
    n = len(columns[0]) if len(columns) else 0
    rows_per_chunk = max(1, CHUNK_BYTES // (14 * max(1, len(names))))
    for start in range(0, n, rows_per_chunk):
        stop = min(n, start + rows_per_chunk)
        block = np.column_stack([np.trunc(c[start:stop]) if name in integer else np.asarray(c[start:stop], float)
                                 for name, c in zip(names, columns)])
        text = "\n".join([fmt % tuple(row) for row in block.tolist()]) + "\n"
        yield text.replace("nan", "")


def write_table(path: Path, names: Sequence[str], columns: Sequence[np.ndarray], integer: Iterable[str] = ()
                ) -> Path:
    """Write columns as a recording CSV atomically, in chunks.

    Parameters
    ----------
    path : Path
        Target file (replaced only when the whole file is written).
    names : sequence of str
        Column names, ``t_s`` first.
    columns : sequence of ndarray (n,)
        Values, ``%.12g`` (``t_s``: more digits beyond 1e6 s, see :func:`time_digits`); NaN is written as an
        empty cell.
    integer : iterable of str
        Columns written as integers (truncated, as ``int()`` does).
    """
    with atomic_writer(path) as handle:
        for text in _text_chunks(names, columns, integer):
            handle.write(text.encode("utf-8"))
    return path


def table_text(names: Sequence[str], columns: Sequence[np.ndarray], integer: Iterable[str] = ()) -> str:
    """The text :func:`write_table` writes, as one string."""
    return "".join(_text_chunks(names, columns, integer))
