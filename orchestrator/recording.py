"""Recordings: named, unit-carrying time series, read and written per ``shared/spec/recording.md``.

A :class:`Recording` wraps a numpy structured array (one field per channel,
first field ``t_s``), the unit of every channel, and the run's ``success`` and
``message``. Channel names carry their unit (``x_ref_mm``); "not measured at
this sample" is NaN in memory and an empty cell in CSV.

A batched run (``B`` members) gives a recording whose channels have shape
``(n, B)``; :meth:`Recording.member` picks one member as an ordinary
recording.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from fmus_src.units import split_unit_suffix

from .errors import CncTwinError
from .recording_csv import FileLines, RecordingError, read_table, table_text, write_table

#: Columns defined by the recording contract, with their units.
SPEC_COLUMNS: dict[str, str] = {
    "t_s": "s",
    "line": "1",
    **{f"{a}_ref_mm": "mm" for a in "xyz"},
    **{f"{a}_mm": "mm" for a in "xyz"},
    **{f"{a}_tcmd_A": "A" for a in "xyz"},
    "spindle_ref_rpm": "rpm",
    "spindle_rpm": "rpm",
    **{f"f{a}_N": "N" for a in "xyz"},
    "fc_N": "N",
}


def unit_of_column(name: str) -> str:
    """Unit of a column from its name (``"x_ref_mm"`` → ``"mm"``; ``"line"`` → ``"1"``)."""
    if name in SPEC_COLUMNS:
        return SPEC_COLUMNS[name]
    return split_unit_suffix(name)[1]


def _unit_map(names: Iterable[str], units: Mapping[str, str | None] | None) -> dict[str, str | None]:
    """Every channel's unit: from ``units``, else from the channel name.

    An explicit None in ``units`` stays None: the channel records a variable
    that declares no unit (a foreign FMU's), which is not dimensionless.
    """
    given = units or {}
    return {name: None if name in given and given[name] is None else (given.get(name) or unit_of_column(name))
            for name in names}


def _rounded_time_hint(t: np.ndarray) -> str:
    """Why ``t`` [s] repeats when its times are written on a decimal grid coarser than the sampling.

    A logger sampling every 0.5 ms that writes ``t_s`` with 3 decimals repeats every other time; the hint
    names the grid (the smallest step between different times, when it is a power of ten) and asks for more
    decimals. Empty when the times are not on such a grid.
    """
    steps = np.diff(t)
    positive = steps[steps > 0]
    if not positive.size:
        return ""
    grid = float(positive.min())
    exponent = round(math.log10(grid))
    if abs(grid / 10.0 ** exponent - 1.0) > 1e-3:  # 1e-3: Unix-time clocks carry steps to 2.4e-7 s
        return ""
    return (f"; t_s is written to {10.0 ** exponent:g} s: does the logger sample faster than that? write t_s "
            "with more decimals")


@dataclass
class Recording:
    """Time series of named channels with units.

    Parameters
    ----------
    data : numpy structured array, shape (n,)
        One field per channel; the first is ``t_s``. Fields have shape
        ``()`` for a single run or ``(B,)`` for a batched run (``t_s`` is
        always scalar per sample).
    units : dict[str, str or None]
        Unit symbol of every field; None for a channel of a variable that
        declares no unit (a foreign FMU's).
    success : bool
        Whether the run reached its end condition.
    message : str
        Why it stopped (or what went wrong).
    source : str
        Where it came from (file path or description), for error messages.
    meta : dict
        Free-form annotations.
    file_lines : FileLines, optional
        The file line (1-based) of every row, for a recording read from a CSV file (errors name
        ``file:line``); None for a recording built in memory.
    """

    data: np.ndarray
    units: dict[str, str | None]
    success: bool = True
    message: str = ""
    source: str = "<memory>"
    meta: dict = field(default_factory=dict)
    file_lines: FileLines | None = field(default=None, repr=False)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_channels(
        cls,
        channels: Mapping[str, np.ndarray],
        units: Mapping[str, str] | None = None,
        success: bool = True,
        message: str = "",
        source: str = "<memory>",
        file_lines: FileLines | None = None,
    ) -> "Recording":
        """Build from a mapping name → array (``t_s`` required, shape (n,) or (n, B)).

        Integer channels (``line``) are stored as float so that "not
        measured" (NaN) is representable. ``file_lines`` gives the file line
        of every row (see :class:`FileLines`).
        """
        if "t_s" not in channels:
            raise RecordingError(f"{source}: a recording needs a 't_s' channel")
        t = np.asarray(channels["t_s"], dtype=float)
        if t.ndim != 1:
            raise RecordingError(f"{source}: t_s must be one-dimensional, got shape {t.shape}")
        n = t.shape[0]
        fields = []
        arrays = {}
        for name, values in channels.items():
            arr = np.asarray(values, dtype=float)
            if arr.shape[:1] != (n,):
                raise RecordingError(f"{source}: channel {name!r} has {arr.shape[0]} samples, t_s has {n}")
            arrays[name] = arr
            fields.append((name, np.float64, arr.shape[1:]))
        data = np.empty(n, dtype=fields)
        for name, arr in arrays.items():
            data[name] = arr
        if file_lines is not None and file_lines.rows != n:
            raise RecordingError(f"{source}: {file_lines.rows} file lines given for {n} rows")
        return cls(data, _unit_map(channels, units), success, message, source, file_lines=file_lines)

    @classmethod
    def from_rows(
        cls,
        rows: np.ndarray,
        names: Iterable[str],
        batch: int,
        units: Mapping[str, str] | None = None,
        success: bool = True,
        message: str = "",
        source: str = "<memory>",
    ) -> "Recording":
        """A recording that *is* ``rows`` (no copy): one sample per row, ``t_s`` first.

        Parameters
        ----------
        rows : ndarray of float64, shape (n, 1 + n_channels * batch), C-contiguous
            Row ``i``: ``t_s``, then every channel's ``batch`` member values in ``names`` order.
        names : iterable of str
            Channel names after ``t_s``.
        batch : int
            Members B (fields of shape (B,); scalar fields when B is 1).
        """
        names = ["t_s", *names]
        rows = np.asarray(rows)
        if rows.dtype != np.float64 or rows.ndim != 2 or not rows.flags.c_contiguous \
                or rows.shape[1] != 1 + (len(names) - 1) * batch:
            raise RecordingError(f"{source}: rows of {rows.dtype} {rows.shape} are not 1 + "
                                 f"{len(names) - 1} x {batch} contiguous float64 columns")
        member = () if batch == 1 else (batch,)
        dtype = np.dtype([("t_s", np.float64)] + [(name, np.float64, member) for name in names[1:]])
        data = rows.view(dtype)[:, 0]
        return cls(data, _unit_map(names, units), success, message, source)

    # ------------------------------------------------------------------ access
    @property
    def channels(self) -> list[str]:
        """Channel names in column order (``t_s`` first)."""
        return list(self.data.dtype.names or ())

    @property
    def t(self) -> np.ndarray:
        """Sample times, s, shape (n,)."""
        return self.data["t_s"]

    @property
    def batch(self) -> int:
        """Number of batch members (1 for an ordinary recording)."""
        shapes = [self.data.dtype[n].shape for n in self.channels if n != "t_s"]
        return shapes[0][0] if shapes and shapes[0] else 1

    def __len__(self) -> int:
        return int(self.data.shape[0])

    def __contains__(self, name: object) -> bool:
        return name in self.channels

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.channels:
            raise RecordingError(f"{self.source}: no channel {name!r}; channels are {self.channels}")
        return self.data[name]

    def where(self, row: int) -> str:
        """Where a 0-based row is, for messages: ``"file:line"`` when read from a file, else ``"source, row k"``."""
        if self.file_lines is not None:
            return f"{self.file_lines.path}:{self.file_lines.line(row)}"
        return f"{self.source}, row {int(row) + 1}"

    def take(self, index: np.ndarray) -> "Recording":
        """The rows ``index`` (integer indices or a boolean mask) as a new recording, with their file lines.

        Parameters
        ----------
        index : ndarray of int or bool
            Rows to keep, in increasing order (time must still increase).
        """
        index = np.asarray(index)
        rows = np.flatnonzero(index) if index.dtype == bool else index.astype(np.int64)
        lines = self.file_lines.take(rows) if self.file_lines is not None else None
        return Recording(self.data[rows], dict(self.units), self.success, self.message, self.source,
                         dict(self.meta), lines)

    def member(self, b: int) -> "Recording":
        """Batch member ``b`` as an ordinary recording."""
        if self.batch == 1 and not any(self.data.dtype[n].shape for n in self.channels):
            if b != 0:
                raise RecordingError(f"{self.source}: not a batched recording; member {b} does not exist")
            return self
        channels = {"t_s": self.t}
        for name in self.channels[1:]:
            col = self.data[name]
            channels[name] = col[:, b] if col.ndim == 2 else col
        return Recording.from_channels(channels, self.units, self.success, self.message, f"{self.source}[{b}]",
                                       file_lines=self.file_lines)

    def following_error_um(self, axis: str) -> np.ndarray:
        """Following error ``ref - actual`` of one axis in µm (derived, never stored)."""
        return (self[f"{axis}_ref_mm"] - self[f"{axis}_mm"]) * 1000.0

    def to_pandas(self):  # -> pandas.DataFrame
        """A pandas DataFrame indexed by ``t_s`` (needs pandas; single-member recordings only)."""
        try:
            import pandas as pd
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise CncTwinError("to_pandas() needs pandas: pip install 'cnctwin[pandas]'") from exc
        single = self.member(0) if self.batch == 1 else None
        if single is None:
            raise RecordingError("to_pandas() needs a single-member recording; use member(b) first")
        frame = pd.DataFrame({n: single.data[n] for n in single.channels[1:]}, index=single.t)
        frame.index.name = "t_s"
        frame.attrs["units"] = dict(self.units)
        return frame

    # ------------------------------------------------------------------ CSV
    def to_csv_text(self) -> str:
        """CSV text per the recording contract (empty cell for NaN, ``%.12g``, ``line`` as an integer)."""
        self._check_single()
        return table_text(self.channels, [self.data[n] for n in self.channels], integer=("line",))

    def write_csv(self, path: str | Path) -> Path:
        """Write the recording as CSV atomically (temp file + rename), in chunks of text."""
        self._check_single()
        return write_table(Path(path), self.channels, [self.data[n] for n in self.channels], integer=("line",))

    def _check_single(self) -> None:
        if self.batch != 1 or any(self.data.dtype[n].shape for n in self.channels):
            raise RecordingError("only a single-member recording can be written as CSV; use member(b)")

    @classmethod
    def read_csv(cls, path: str | Path, required: Iterable[str] = ()) -> "Recording":
        """Read a recording CSV and check it against the contract.

        Parameters
        ----------
        path : str or Path
            CSV file.
        required : iterable of str
            Columns the caller needs besides ``t_s``.

        Raises
        ------
        RecordingError
            Missing file, no header, no ``t_s``, a contract column (``x_mm``,
            ``fc_N``, ...) twice, a cell of a contract column that is not a
            plain finite decimal number, an empty ``t_s``, time not strictly
            increasing, a row with a different number of cells, or a required
            column missing. The message names the file, the line and the column.

        Notes
        -----
        Columns the contract does not define are extra columns: they are kept
        when every cell is a number (or empty) and ignored otherwise, as are
        columns without a name and unknown names that appear twice
        (recording.md: "Extra columns are allowed and must be ignored by
        readers that do not know them"). Empty cells after the last column
        (a trailing comma) are not cells.
        """
        path = Path(path)
        table = read_table(path, SPEC_COLUMNS, required)
        header, values, ignored = table.header, table.values, table.ignored
        it = header.index("t_s")
        t = values[:, it]
        if np.isnan(t).any():
            bad = int(table.lines[int(np.flatnonzero(np.isnan(t))[0])])
            raise RecordingError(f"{path}:{bad}: empty t_s; every row needs a time")
        if len(t) > 1:
            steps = np.diff(t)
            if (steps <= 0).any():
                k = int(np.flatnonzero(steps <= 0)[0]) + 1
                what = "repeats" if steps[k - 1] == 0 else "goes back"
                raise RecordingError(
                    f"{path}:{int(table.lines[k])}: t_s {what} ({float(t[k - 1])!r} then {float(t[k])!r}); rows "
                    f"must be in strictly increasing time{_rounded_time_hint(t) if what == 'repeats' else ''}"
                )
        order = [it] + [j for j in range(len(header)) if j != it and j not in ignored]
        channels = {header[j]: values[:, j] for j in order}
        return cls.from_channels(channels, source=str(path), file_lines=FileLines.from_numbers(path, table.lines))
