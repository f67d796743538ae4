"""Loading and checking the recordings an identification needs.

Every fit reads its cases through :func:`load_inputs`, which checks each
recording against its program (:func:`orchestrator.validation.validate_recording`:
plausible values, ``line`` numbers that are blocks of the program, a duration
that fits it), checks the columns it needs, refuses NaN inside them and gives
one :class:`~orchestrator.identify.errors.IdentificationError` naming the file.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..case import Case, load_case, missing_file
from ..recording import Recording, RecordingError
from ..twin import nck_parameters
from ..validation import validate_recording
from .errors import IdentificationError


@dataclass
class CaseData:
    """A case with its recording, ready for identification.

    Attributes
    ----------
    case : Case
        The loaded case (machine, tool, stock, program).
    recording : Recording
        Its recording (single member).
    name : str
        Short label (folder name) for reports and provenance.
    """

    case: Case
    recording: Recording
    name: str

    @property
    def source(self) -> str:
        """The recording file, for error messages."""
        return str(self.recording.source)


def as_case(item: str | Path | Case) -> Case:
    """A :class:`Case` from a case folder, a ``case.toml`` path or a Case."""
    return item if isinstance(item, Case) else load_case(item)


def load_recording(case: Case) -> Recording:
    """Read the case's recording (``recording`` field of ``case.toml``) and check it against the program.

    Raises
    ------
    IdentificationError
        The case names no recording, the file does not exist or is malformed, or
        it does not belong to the case's program (:func:`~orchestrator.validation.validate_recording`:
        the message names the file, the column and the row).
    """
    if case.recording is None:
        raise IdentificationError(
            f"{case.source or case.folder}: the case names no recording; add recording = \"recording.csv\" "
            "to case.toml and put the measured file next to it"
        )
    if not Path(case.recording).is_file():
        raise IdentificationError(
            f"{case.recording}: recording file not found (run the experiment program on the machine and "
            "save the log there, columns per shared/spec/recording.md)"
        )
    problem = missing_file(case, "program")
    if problem is not None:
        raise IdentificationError(f"{problem}; the recording is checked against the program that made it")
    try:
        recording = Recording.read_csv(case.recording)
        validate_recording(recording, case.program, nc_parameters=nck_parameters(case.machine))
    except RecordingError as exc:
        raise IdentificationError(str(exc)) from None
    return recording


def check_columns(recording: Recording, columns: Sequence[str], purpose: str) -> None:
    """Check that ``columns`` exist and hold no NaN (empty cell) and that time increases.

    Parameters
    ----------
    recording : Recording
        Single-member recording.
    columns : sequence of str
        Columns the fit needs.
    purpose : str
        What for (``"friction identification of axis x"``), for the message.

    Raises
    ------
    IdentificationError
        Missing column, empty/NaN cell in a needed column, fewer than 3
        samples, or time not strictly increasing.
    """
    src = recording.source
    missing = [c for c in columns if c not in recording]
    if missing:
        raise IdentificationError(
            f"{src}: {purpose} needs column(s) {missing}; the recording has {recording.channels}"
        )
    if len(recording) < 3:
        raise IdentificationError(f"{src}: {purpose} needs at least 3 samples, the recording has {len(recording)}")
    t = recording.t
    if not np.all(np.isfinite(t)):
        bad = ~np.isfinite(t)
        raise IdentificationError(f"{first_row_place(recording, bad)}: t_s has NaN or infinite values "
                                  f"({row_places(recording, bad)})")
    if np.any(np.diff(t) <= 0.0):
        k = int(np.flatnonzero(np.diff(t) <= 0.0)[0]) + 1
        raise IdentificationError(
            f"{recording.where(k)}: t_s is not strictly increasing ({t[k - 1]!r} then {t[k]!r})"
        )
    for c in columns:
        bad = ~np.isfinite(np.asarray(recording[c], dtype=float))
        if bad.any():
            raise IdentificationError(
                f"{first_row_place(recording, bad)}: column {c!r} has {int(bad.sum())} empty or NaN cell(s) "
                f"({row_places(recording, bad)}); {purpose} needs it at every sample"
            )


def measured_rows(recording: Recording, columns: Sequence[str], purpose: str) -> tuple[Recording, str | None]:
    """The rows in which every one of ``columns`` was measured (recording.md: an empty cell is "not measured").

    A logger whose channels start or stop a sample apart, or that drops a sample now and then, leaves empty
    cells; the fits that need these columns together at every sample (friction, servo) use the other rows,
    sampled unevenly, instead of refusing the whole log. What is left out is said, never silent.

    Parameters
    ----------
    recording : Recording
        Single-member recording.
    columns : sequence of str
        Columns needed together (they must exist; see :func:`check_columns`).
    purpose : str
        What for, for the note.

    Returns
    -------
    recording : Recording
        ``recording`` itself when every row has every column, else its measured rows (file lines kept).
    note : str or None
        ``"file:line: N row(s) ... left out ..."`` naming the columns and the first lines, or None.

    Raises
    ------
    IdentificationError
        Fewer than 3 rows have every column, or a column is missing.
    """
    missing = [c for c in columns if c not in recording]
    if missing:
        raise IdentificationError(
            f"{recording.source}: {purpose} needs column(s) {missing}; the recording has {recording.channels}")
    have = np.ones(len(recording), dtype=bool)
    for c in columns:
        have &= np.isfinite(np.asarray(recording[c], dtype=float))
    if have.all():
        return recording, None
    if have.sum() < 3:
        raise IdentificationError(
            f"{recording.source}: {purpose} needs {list(columns)} measured together in at least 3 rows; "
            f"{int(have.sum())} of the {len(recording)} rows have them all (an empty cell is 'not measured')")
    empty = [c for c in columns if not np.isfinite(np.asarray(recording[c], dtype=float)).all()]
    note = (f"{first_row_place(recording, ~have)}: {int((~have).sum())} of {len(recording)} row(s) without "
            f"{' / '.join(empty)} (empty: not measured) left out of {purpose} ({row_places(recording, ~have)})")
    return recording.take(have), note


def first_row_place(recording: Recording, mask: np.ndarray) -> str:
    """``"file:line"`` (or ``"source, row k"``) of the first True entry of ``mask``."""
    return recording.where(int(np.flatnonzero(mask)[0]))


def row_places(recording: Recording, mask: np.ndarray) -> str:
    """The first few True entries of ``mask`` as file lines (1-based, blank lines counted) or, in memory, rows."""
    rows = np.flatnonzero(mask)[:5]
    if recording.file_lines is not None:
        return f"first at line(s) {recording.file_lines.of(rows).tolist()}"
    return f"first at row(s) {[int(i) + 1 for i in rows]}"


def load_inputs(cases: Iterable[str | Path | Case]) -> list[CaseData]:
    """Load cases and their recordings.

    Parameters
    ----------
    cases : iterable of str, Path or Case
        Case folders (or ``case.toml`` paths, or loaded cases).

    Returns
    -------
    list of CaseData
    """
    out = []
    for item in cases:
        case = as_case(item)
        rec = load_recording(case)
        out.append(CaseData(case, rec, Path(case.folder).name or str(case.folder)))
    if not out:
        raise IdentificationError("no case given; pass at least one case folder with a recording")
    return out


def axes_in(recording: Recording, suffixes: Sequence[str]) -> list[str]:
    """Axes (of ``x, y, z``) for which every ``{axis}{suffix}`` column exists."""
    return [a for a in "xyz" if all(f"{a}{s}" in recording for s in suffixes)]


def force_per_amp(case: Case, axis: str) -> float:
    """Driving force per ampere of current command, ``kt 2 pi / Lb`` [N/A] (Eq. 2)."""
    sec = case.machine.si(f"axis.{axis}")
    return float(sec["torque_constant"]) * 2.0 * np.pi / float(sec["screw_lead"])
