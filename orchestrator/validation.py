"""Plausibility checks of recordings and cases beyond what the readers check.

:meth:`Recording.read_csv` and :func:`load_case` check the *format* (columns,
numbers, time order, TOML fields). The checks here catch files that are well
formed but cannot be what they claim to be:

* a value outside any physically plausible range for its unit (a position of
  1e9 mm, a spindle at -5e6 rpm, a current of 1e5 A, a negative cutting load);
* a ``line`` that is not a whole number, not a line of the program, or a line
  that holds no block (a comment, a blank line);
* ``line`` going back in time where the program does not: a program without subprograms (M98/M99) or
  macro loops (GOTO, WHILE) executes its lines in increasing order; the lines of one with them must follow
  the order the interpreter executes its blocks in;
* a recording much longer than the program runs (the wrong recording for
  this program);
* a case whose program or recording file is missing or whose stock lies
  beyond any machine's reach.

Every problem raises the reader's own error type (:class:`RecordingError`,
:class:`CaseError`) naming the file, the line (for a recording read from a file: its 1-based line in the
file, blank lines counted; in memory: the row) with its time, and the field.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from fmus_src.nck import GCodeError, NCKernel
from fmus_src.nck.lexer import LexError, lex_line, split_lines

from .case import MAX_STOCK_COORDINATE_MM, Case, CaseError, missing_file
from .recording import Recording, RecordingError


@dataclass(frozen=True)
class Range:
    """Closed plausible interval ``[low, high]`` of a channel, in the channel's unit, and why."""

    low: float
    high: float
    reason: str


#: Plausible range by channel unit (any machining center, with a wide margin).
PLAUSIBLE_BY_UNIT: dict[str, Range] = {
    "mm": Range(-10_000.0, 10_000.0, "no machining-center axis travels 10 m"),
    "rpm": Range(-100_000.0, 100_000.0, "no machining-center spindle turns 100,000 rpm"),
    "A": Range(-2_000.0, 2_000.0, "no feed-axis servo amplifier delivers 2 kA"),
    "N": Range(-1e6, 1e6, "1 MN is far beyond any milling force"),
}
#: Channel-specific ranges (they win over the unit's).
PLAUSIBLE_BY_CHANNEL: dict[str, Range] = {
    "fc_N": Range(0.0, 1e6, "the cutting load sqrt(fx^2 + fy^2) is not negative"),
}
#: A recording may last at most this factor times the planned program time (plus :data:`DURATION_SLACK_S`).
MAX_DURATION_RATIO = 2.0
#: Seconds a logger may run before and after the program in addition to the ratio.
DURATION_SLACK_S = 60.0


def plausible_range(channel: str, unit: str) -> Range | None:
    """The plausible range of a channel, or None when nothing is known about it."""
    return PLAUSIBLE_BY_CHANNEL.get(channel) or PLAUSIBLE_BY_UNIT.get(unit)


def block_lines(text: str) -> set[int]:
    """1-based numbers of the lines of a program that hold a block (at least one word).

    Lines that do not lex (they would fail in the interpreter) count as blocks:
    this function only tells lines that *can* execute from comments and blanks.
    """
    out: set[int] = set()
    for number, raw in enumerate(split_lines(text), start=1):
        try:
            if lex_line(raw).words:
                out.add(number)
        except LexError:
            out.add(number)
    return out


def _at(recording: Recording, k: int, column: str, time: bool = True) -> str:
    """Where the cell of ``column`` in the 0-based row ``k`` is, to start a message.

    ``"file.csv:412: column 'x_mm' (t_s = 5.03)"`` for a recording read from a file (its 1-based line, blank
    lines counted), ``"<memory>: column 'x_mm', row 4 (t_s = 5.03)"`` for one built in memory.
    """
    # to 1 µs, whatever the clock: 6 significant digits named a Unix-time logger's every row "1.7643e+09"
    when = f" (t_s = {round(float(recording.t[k]), 6):.16g})" if time else ""
    if recording.file_lines is not None:
        return f"{recording.where(k)}: column {column!r}{when}"
    return f"{recording.source}: column {column!r}, row {k + 1}{when}"


def _check_ranges(recording: Recording, ranges: Mapping[str, Range] | None) -> None:
    for name in recording.channels:
        if name in ("t_s", "line"):
            continue
        rng = (ranges or {}).get(name) or plausible_range(name, recording.units.get(name, "1"))
        if rng is None:
            continue
        col = np.asarray(recording[name], dtype=float)
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero(np.isinf(col) | (col < rng.low) | (col > rng.high))
        if bad.size:
            k = int(bad[0]) if col.ndim == 1 else int(bad[0] // col.shape[1])
            value = col.reshape(len(recording), -1)[k]
            shown = float(value[0]) if value.size == 1 else value.tolist()
            raise RecordingError(
                f"{_at(recording, k, name)}: {shown!r} is outside the plausible range "
                f"[{rng.low:g}, {rng.high:g}] {recording.units.get(name, '')} ({rng.reason}); "
                f"{bad.size} value(s) out of range: wrong unit or wrong column?"
            )


def _program_text(program: str | Path) -> tuple[str, str]:
    from fmus_src.nck import read_program

    path = Path(program)
    try:
        return read_program(path), str(path)
    except GCodeError as exc:
        raise RecordingError(f"cannot check the recording against the program: {exc}") from None


def _check_lines(recording: Recording, text: str, program_name: str,
                 nc_parameters: Mapping[str, object]) -> None:
    line = np.asarray(recording["line"], dtype=float)
    known = ~np.isnan(line)
    whole = known & (np.floor(line) == line) & (line >= 1)
    if (known & ~whole).any():
        k = int(np.flatnonzero(known & ~whole)[0])
        raise RecordingError(f"{_at(recording, k, 'line')}: {float(line[k])!r} is not a line number; "
                             f"expected whole numbers >= 1 (1-based lines of {program_name})")
    n_lines = len(split_lines(text))
    blocks = block_lines(text)
    for k in np.flatnonzero(known):
        value = int(line[k])
        if value > n_lines:
            raise RecordingError(
                f"{_at(recording, int(k), 'line')}: line {value} does not exist, {program_name} has "
                f"{n_lines} lines: is this the recording of another program?")
        if value not in blocks:
            raise RecordingError(
                f"{_at(recording, int(k), 'line')}: line {value} of {program_name} holds no block "
                f"(a comment or blank line cannot execute): is this the recording of another program?")
    seq = line[known]
    back = np.flatnonzero(np.diff(seq) < 0)
    if not back.size:
        return
    executed = _executed_lines(text, program_name, nc_parameters)
    if not (np.diff(executed) < 0).any():
        k = int(np.flatnonzero(known)[back[0] + 1])
        raise RecordingError(
            f"{_at(recording, k, 'line')}: the line goes back from {int(seq[back[0]])} to "
            f"{int(seq[back[0] + 1])}; {program_name} has no loops or subprograms, so a run executes its lines in "
            "increasing order")
    _check_execution_order(recording, np.flatnonzero(known), seq, executed, program_name)


def _executed_lines(text: str, program_name: str, nc_parameters: Mapping[str, object]) -> np.ndarray:
    """The program lines of the interpreted blocks in execution order (subprogram calls and loops unrolled)."""
    kernel = _planned_kernel(text, program_name, nc_parameters)
    return np.array([int(block.line) for block in kernel.program_.blocks], dtype=np.int64)


def _check_execution_order(recording: Recording, rows: np.ndarray, seq: np.ndarray, executed: np.ndarray,
                           program_name: str) -> None:
    """Raise RecordingError when the recorded lines do not occur in the program's execution order.

    A logger samples the block being executed, so the recorded lines that are lines of interpreted blocks must
    be a subsequence of ``executed`` (consecutive repeats merged). Lines of statements that make no block
    (``M98``, ``WHILE``, ``GOTO``), which a controller may report, are not placed in that order.

    Parameters
    ----------
    recording : Recording
        The recording, for the message.
    rows : ndarray of int
        0-based rows of the recorded lines ``seq``.
    seq : ndarray of float
        Recorded lines (whole numbers).
    executed : ndarray of int
        Lines of the interpreted blocks in execution order.
    program_name : str
        The program, for the message.
    """
    order = executed[np.concatenate([[True], np.diff(executed) != 0])]
    where = {int(v): np.flatnonzero(order == v) for v in np.unique(order)}  # line -> its places in the order
    values = seq.astype(np.int64)
    inside = np.isin(values, order)
    rows, values = rows[inside], values[inside]
    change = np.concatenate([[True], np.diff(values) != 0]) if values.size else np.zeros(0, bool)
    at = 0  # place in ``order`` of the line the recording is at
    previous = None
    for k, value in zip(rows[change].tolist(), values[change].tolist()):
        places = where[value]
        i = int(np.searchsorted(places, at))
        if i == places.size:
            raise RecordingError(
                f"{_at(recording, k, 'line')}: line {value} after line {previous} is not in the order "
                f"{program_name} executes its blocks in (subprogram calls and loops unrolled): is this the "
                "recording of another program?")
        at = int(places[i])
        previous = value


def _planned_kernel(text: str, program_name: str, nc_parameters: Mapping[str, object]) -> NCKernel:
    """An NC kernel with the program interpreted and planned (``nc_parameters``: SI, as for the twin)."""
    kernel = NCKernel("nck", program_text=text, **nc_parameters)
    kernel.set_program_text(text, program_name)
    try:
        kernel.setup(0.0)
    except GCodeError as exc:
        raise RecordingError(f"cannot check the recording against the program: {exc}") from None
    return kernel


def _check_duration(recording: Recording, text: str, program_name: str, nc_parameters: Mapping[str, object]) -> None:
    if len(recording) < 2:
        return
    planned = float(_planned_kernel(text, program_name, nc_parameters).duration_[0])
    span = float(recording.t[-1] - recording.t[0])
    allowed = MAX_DURATION_RATIO * planned + DURATION_SLACK_S
    if span > allowed:
        unit = " Or is t_s written in ms? recording.md asks for seconds." if span * 1e-3 <= allowed else ""
        raise RecordingError(
            f"{recording.source}: column 't_s': the recording lasts {span:.6g} s but {program_name} runs "
            f"{planned:.6g} s (planned with the given NC parameters); expected at most {allowed:.6g} s "
            f"({MAX_DURATION_RATIO:g} x the program + {DURATION_SLACK_S:g} s): is this the recording of another "
            f"program?{unit}")


def validate_recording(
    recording: Recording,
    program: str | Path | None = None,
    *,
    program_text: str | None = None,
    nc_parameters: Mapping[str, object] | None = None,
    ranges: Mapping[str, Range] | None = None,
) -> None:
    """Check that a (well-formed) recording is plausible, and that it belongs to ``program``.

    Parameters
    ----------
    recording : Recording
        A single-member recording, e.g. from :meth:`Recording.read_csv`.
    program : str or Path, optional
        The program file that was run; enables the ``line`` and duration checks.
    program_text : str, optional
        The program as text instead of a file (``program`` then only names it).
    nc_parameters : mapping, optional
        NC kernel parameters (SI, e.g. :func:`orchestrator.twin.nck_parameters`) used to plan the
        program for the duration check; default: the NC kernel's defaults (the default machine's values, but
        without its stroke check and with machine zero at the axis origin, so G53 positions differ from it).
    ranges : mapping channel -> Range, optional
        Plausible ranges that replace the built-in ones for some channels.

    Raises
    ------
    RecordingError
        The first problem found, naming the recording file and its line (``file.csv:412``; for a recording
        built in memory its source and row), the column and the row's time.
    """
    if any(recording.data.dtype[n].shape for n in recording.channels):
        raise RecordingError(f"{recording.source}: validate one member at a time (use recording.member(b))")
    t = recording.t
    if len(t) and not np.isfinite(t).all():
        k = int(np.flatnonzero(~np.isfinite(t))[0])
        raise RecordingError(f"{_at(recording, k, 't_s', time=False)}: {float(t[k])!r}; every row needs a finite time")
    if len(t) > 1 and (np.diff(t) <= 0).any():
        k = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
        raise RecordingError(f"{_at(recording, k, 't_s')}: time does not increase "
                             f"({float(t[k - 1])!r} then {float(t[k])!r})")
    _check_ranges(recording, ranges)
    if program is None and program_text is None:
        return
    if program_text is not None:
        text, name = program_text, str(program) if program is not None else "<text>"
    else:
        text, name = _program_text(program)  # type: ignore[arg-type]
    if "line" in recording:
        _check_lines(recording, text, name, dict(nc_parameters or {}))
    _check_duration(recording, text, name, dict(nc_parameters or {}))




def validate_case(case: Case) -> None:
    """Check that a loaded case is complete and plausible (files exist, stock within reach).

    Raises
    ------
    CaseError
        Naming ``case.toml`` (or the folder) and the field.
    """
    where = str(case.source or case.folder)
    for key in ("program", "recording"):
        problem = missing_file(case, key)
        if problem is not None:
            raise CaseError(problem)
    if case.stock is not None:
        for key, vec in (("min", case.stock.min_mm), ("max", case.stock.max_mm)):
            if not all(math.isfinite(v) and abs(v) <= MAX_STOCK_COORDINATE_MM for v in vec):
                raise CaseError(f"{where}: [stock] {key} = {list(vec)} mm lies beyond "
                                f"+-{MAX_STOCK_COORDINATE_MM:g} mm; expected work coordinates in mm")
