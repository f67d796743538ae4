"""Checkpoint files of long jobs (optimisation, identification): atomic pickles in ``DIR/checkpoints/``.

Each checkpoint is one pickle written atomically (:func:`orchestrator.atomic.atomic_write_bytes`),
so a job killed at any moment leaves either the previous set of checkpoints
or the previous set plus one complete new file, never a half-written one. A
checkpoint carries a ``format`` number; a file that does not unpickle (from an
older version of the code, or damaged on disk) is skipped, a file of another
format is refused with the job's own error type.

Used by :mod:`orchestrator.optimize.checkpoint` (one state per generation)
and :mod:`orchestrator.identify.journal` (the evaluations of an
identification, one file per batch).
"""
from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

from .atomic import atomic_write_bytes
from .errors import CncTwinError

#: Errors that mean "this file is not a usable checkpoint" (skipped, the previous one is used).
UNREADABLE = (OSError, EOFError, pickle.UnpicklingError, AttributeError, ValueError, ImportError, IndexError)


def checkpoint_dir(out: str | Path) -> Path:
    """Folder of the checkpoints inside the output folder ``out``."""
    return Path(out) / "checkpoints"


def write_pickle(path: str | Path, obj: Any) -> Path:
    """Pickle ``obj`` to ``path`` atomically; returns the path."""
    return atomic_write_bytes(Path(path), pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL))


def read_pickle(path: str | Path) -> Any:
    """Read a pickle written by :func:`write_pickle`."""
    with Path(path).open("rb") as handle:
        return pickle.load(handle)


def write_checkpoint(out: str | Path, name: str, state: dict[str, Any], fmt: int) -> Path:
    """Write ``DIR/checkpoints/<name>.pkl`` atomically with ``{"format": fmt, **state}``; returns the file."""
    return write_pickle(checkpoint_dir(out) / f"{name}.pkl", {"format": fmt, **state})


def read_checkpoints(out: str | Path, pattern: str, fmt: int, error: type[CncTwinError] = CncTwinError,
                     newest_only: bool = False) -> list[dict[str, Any]]:
    """The readable checkpoints ``DIR/checkpoints/<pattern>`` in name order (oldest first).

    Parameters
    ----------
    out : str or Path
        Output folder of the job.
    pattern : str
        Glob of the checkpoint files, e.g. ``"gen_*.pkl"`` (names sort in write order).
    fmt : int
        Expected ``format``.
    error : type of CncTwinError
        Raised for a checkpoint of another format.
    newest_only : bool
        Return at most the newest readable checkpoint.

    Returns
    -------
    list of dict
        Each state with ``"path"`` added.
    """
    files = sorted(checkpoint_dir(out).glob(pattern), reverse=newest_only)
    states = []
    for path in files:
        try:
            state = read_pickle(path)
        except UNREADABLE:
            continue  # a checkpoint from an older version or damaged: skip it
        if not isinstance(state, dict) or state.get("format") != fmt:
            found = state.get("format") if isinstance(state, dict) else type(state).__name__
            raise error(f"{path}: checkpoint format {found!r}, expected {fmt}")
        state["path"] = path
        states.append(state)
        if newest_only:
            break
    return states
