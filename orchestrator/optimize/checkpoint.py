"""Checkpoints: one pickle per generation, written atomically.

``DIR/checkpoints/gen_0003.pkl`` holds the pymoo algorithm (population,
archive and its random generator), the evaluation cache, the history and the
settings that must match on resume. Resuming loads the newest checkpoint that
unpickles and continues with the same random stream, so ``--resume`` gives
the same result as an uninterrupted run with the same seed.
"""
from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

from ..atomic import atomic_write_bytes
from .errors import OptimizeError

FORMAT = 1


def checkpoint_dir(out: Path) -> Path:
    """Folder of the checkpoints inside the output folder."""
    return Path(out) / "checkpoints"


def write_checkpoint(out: Path, generation: int, state: dict[str, Any]) -> Path:
    """Write generation ``generation`` atomically; returns the file."""
    data = pickle.dumps({"format": FORMAT, "generation": generation, **state}, protocol=pickle.HIGHEST_PROTOCOL)
    return atomic_write_bytes(checkpoint_dir(out) / f"gen_{generation:04d}.pkl", data)


def latest_checkpoint(out: Path) -> dict[str, Any] | None:
    """The newest readable checkpoint in ``out``, or None when there is none."""
    files = sorted(checkpoint_dir(out).glob("gen_*.pkl"), reverse=True)
    for path in files:
        try:
            with path.open("rb") as handle:
                state = pickle.load(handle)
        except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ValueError):
            continue  # a checkpoint from an older version or damaged: try the previous one
        if state.get("format") != FORMAT:
            raise OptimizeError(f"{path}: checkpoint format {state.get('format')!r}, expected {FORMAT}")
        state["path"] = path
        return state
    return None


def write_pickle(path: Path, obj: Any) -> Path:
    """Pickle ``obj`` to ``path`` atomically."""
    return atomic_write_bytes(Path(path), pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL))


def read_pickle(path: Path) -> Any:
    """Read a pickle written by :func:`write_pickle`."""
    with Path(path).open("rb") as handle:
        return pickle.load(handle)
