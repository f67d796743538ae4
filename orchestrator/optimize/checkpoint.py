"""Checkpoints: one pickle per generation, written atomically.

``DIR/checkpoints/gen_0003.pkl`` holds the pymoo algorithm (population,
archive and its random generator), the evaluation cache, the history and the
settings that must match on resume. Resuming loads the newest checkpoint that
unpickles and continues with the same random stream, so ``--resume`` gives
the same result as an uninterrupted run with the same seed.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from ..checkpoint import checkpoint_dir, read_checkpoints, read_pickle, write_pickle
from ..checkpoint import write_checkpoint as _write_checkpoint
from .errors import OptimizeError

__all__ = ["FORMAT", "checkpoint_dir", "latest_checkpoint", "read_pickle", "write_checkpoint", "write_pickle"]

FORMAT = 1


def write_checkpoint(out: Path, generation: int, state: dict[str, Any]) -> Path:
    """Write generation ``generation`` atomically; returns the file."""
    return _write_checkpoint(out, f"gen_{generation:04d}", {"generation": generation, **state}, FORMAT)


def latest_checkpoint(out: Path) -> dict[str, Any] | None:
    """The newest readable checkpoint in ``out``, or None when there is none."""
    states = read_checkpoints(out, "gen_*.pkl", FORMAT, OptimizeError, newest_only=True)
    return states[0] if states else None
