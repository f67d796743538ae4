"""Where imported FMUs are unpacked, and how those folders are removed again.

Every process unpacks an FMU once into a folder of the system's temporary
directory named ``cnctwin_p<pid>_<modelIdentifier>_<random>``, and removes its
folders when it exits (``atexit``, and ``multiprocessing``'s finalizers, which
also run in pool workers that leave through ``os._exit``).

A process that is killed (``SIGKILL``, a pool terminated, a Dask worker
restarted, a test run interrupted) runs neither, so its folders stay behind.
The first extraction of every later process therefore removes the folders
whose process is gone: those of this user whose ``<pid>`` is not a running
process (on POSIX systems). A folder of a live process is never touched; a pid reused by another
running process only keeps a stale folder a little longer.
"""
from __future__ import annotations

import atexit
import errno
import logging
import multiprocessing.util
import os
import re
import shutil
import tempfile
import zipfile
from pathlib import Path

__all__ = ["extract_fmu", "remove_extracted", "sweep_stale_extractions"]

_LOG = logging.getLogger(__name__)
_PREFIX = "cnctwin_p"
_OWNED = re.compile(r"^cnctwin_p(?P<pid>\d+)_")

_extracted: dict[tuple[str, int, int], Path] = {}
_swept = False
_finalizer_pid: int | None = None


def extract_fmu(path: Path, identifier: str) -> Path:
    """The folder holding the unpacked ``path`` (unpacked once per process and file version).

    Parameters
    ----------
    path : Path
        The ``.fmu`` archive (already checked to be a zip file).
    identifier : str
        Its ``modelIdentifier``, part of the folder's name.

    Returns
    -------
    Path
        The folder; the same one for every later call with an unchanged file.
    """
    global _swept, _finalizer_pid
    stat = path.stat()
    key = (str(path), stat.st_mtime_ns, stat.st_size)
    folder = _extracted.get(key)
    if folder is not None and folder.is_dir():
        return folder
    if not _swept:
        _swept = True
        sweep_stale_extractions()
    if _finalizer_pid != os.getpid():  # a forked child starts with multiprocessing's finalizers cleared
        _finalizer_pid = os.getpid()
        multiprocessing.util.Finalize(None, remove_extracted, exitpriority=10)
    folder = Path(tempfile.mkdtemp(prefix=f"{_PREFIX}{os.getpid()}_{_safe(identifier)}_"))
    with zipfile.ZipFile(path) as zf:
        zf.extractall(folder)
    _extracted[key] = folder
    return folder


def remove_extracted() -> None:
    """Remove every folder this process unpacked (runs at exit; callable any time no instance is alive).

    A forked child inherits its parent's table; it removes only the folders it
    unpacked itself, never those of the parent it still shares them with.
    """
    own = f"{_PREFIX}{os.getpid()}_"
    for folder in _extracted.values():
        if folder.name.startswith(own):
            shutil.rmtree(folder, ignore_errors=True)
    _extracted.clear()


def sweep_stale_extractions(directory: str | os.PathLike[str] | None = None) -> list[Path]:
    """Remove the unpacked-FMU folders left by processes that no longer run.

    Parameters
    ----------
    directory : path-like, optional
        Where to look; the system's temporary directory by default.

    Returns
    -------
    list of Path
        The folders removed.
    """
    root = Path(directory) if directory is not None else Path(tempfile.gettempdir())
    removed: list[Path] = []
    if os.name != "posix":  # kill(pid, 0) is a probe on POSIX only (on Windows it would end the process)
        return removed
    try:
        entries = list(os.scandir(root))
    except OSError as exc:
        _LOG.debug("not sweeping %s: %s", root, exc)
        return removed
    uid = os.getuid()
    for entry in entries:
        match = _OWNED.match(entry.name)
        if match is None:
            continue
        try:
            if not entry.is_dir(follow_symlinks=False):
                continue
            if entry.stat(follow_symlinks=False).st_uid != uid:
                continue
        except OSError:
            continue
        pid = int(match["pid"])
        if pid == os.getpid() or _running(pid):
            continue
        shutil.rmtree(entry.path, ignore_errors=True)
        removed.append(Path(entry.path))
    if removed:
        _LOG.debug("removed %d unpacked-FMU folder(s) of ended processes in %s", len(removed), root)
    return removed


def _running(pid: int) -> bool:
    """Whether a process with this id exists (``kill(pid, 0)``: no signal is sent)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError as exc:  # EPERM: it exists and belongs to someone else
        return exc.errno == errno.EPERM
    return True


def _safe(identifier: str) -> str:
    """The identifier with anything but letters, digits, ``-`` and ``_`` replaced, at most 40 characters."""
    return re.sub(r"[^A-Za-z0-9_-]", "_", identifier)[:40] or "fmu"


atexit.register(remove_extracted)
