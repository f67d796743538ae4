"""Atomic file writes: a kill never leaves a half-written file that looks whole.

Content goes to a temporary file in the same folder, is flushed and fsync'ed,
then renamed over the target (``os.replace`` is atomic on POSIX and Windows).
The file gets the permissions a plain ``open(path, "w")`` would give it: those
of the file it replaces, else ``0o666`` less the process umask (a temporary
file alone would be private to its owner, ``0o600``, and a shop's DNC server or
a colleague could not read the optimised program).
"""
from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, BinaryIO, Iterator


def _target_mode(path: Path) -> int:
    """Permission bits for ``path``: those of the existing file, else ``0o666`` less the umask."""
    try:
        return path.stat().st_mode & 0o7777
    except FileNotFoundError:
        mask = os.umask(0)  # the only portable way to read the umask: set it and put it back at once
        os.umask(mask)
        return 0o666 & ~mask


@contextmanager
def atomic_writer(path: Path) -> Iterator[BinaryIO]:
    """A binary handle whose content replaces ``path`` when the ``with`` block ends without an exception.

    The content goes to a temporary file in the same folder (parent folders are created), is flushed and
    fsync'ed, then renamed over ``path``; on any exception (or a kill) the temporary file is removed and
    ``path`` is untouched. For content written in pieces, e.g. a large recording.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            os.chmod(tmp, _target_mode(path))
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; create parent folders. Returns ``path``."""
    path = Path(path)
    with atomic_writer(path) as handle:
        handle.write(data)
    return path


def atomic_write_text(path: Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def atomic_write_json(path: Path, obj: Any) -> Path:
    """Write ``obj`` as indented JSON atomically (NaN is refused: it is not JSON)."""
    return atomic_write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n")
