"""Numba cache locator for ``fmus_src`` running from an unpacked FMU: keyed by content, not by path.

A master (fmpy, another vendor's tool) unpacks an FMU into a new temporary
folder at every instantiation. numba's own locators key the on-disk cache on
the source file's *path* (``__pycache__`` next to it, or a hash of its folder
under ``NUMBA_CACHE_DIR``), so every instantiation of one of our FMUs would
recompile all its kernels (seconds each). :class:`FmuContentCacheLocator`
serves the functions of an ``fmus_src`` package that sits in an FMU's
``resources/`` folder (``<unpacked>/resources/fmus_src`` next to
pythonfmu's ``resources/slavemodule.txt``) from a stable folder keyed by the SHA-256
of the whole shipped package::

    <root>/fmus_src-<first 20 hex digits of the package digest>/<subpackage>/

where ``<root>`` is ``$CNCTWIN_FMU_CACHE_DIR`` when set (for FMU kernels only:
a test suite or CI job keeps them out of the user's cache), else
``$NUMBA_CACHE_DIR`` when set, else the per-user cache folder
``~/.cache/cnctwin/numba`` (platform equivalent via numba's ``appdirs``). Any
change to any file of the package gives another folder, so a kernel is never
loaded against changed callees (the guarantee that :mod:`fmus_src.jit_cache`
gives inside the source tree). The unpacked FMU itself is never written to.

Housekeeping: a process's first use of a folder refreshes its modification
time (the folder's "last used"); when a process creates a new folder, the
other ``fmus_src-*`` folders beyond the newest :data:`KEEP_NEWEST` that were
not used for :data:`MAX_UNUSED_S` (30 days) are deleted
(:func:`prune_cache_folders`), so package versions that are gone do not pile up.

Anything else (the source tree, other packages) keeps numba's default
locators, and so does everything when this locator fails for any reason
(unwritable cache folder, unexpected numba internals).
"""
from __future__ import annotations

import functools
import hashlib
import logging
import os
import shutil
import stat
import time
from pathlib import Path
from types import FunctionType

log = logging.getLogger(__name__)

#: Name of the package this locator serves.
PACKAGE = "fmus_src"

#: File pythonfmu writes into every FMU's ``resources/`` (names the slave's script).
PYTHONFMU_MARKER = "slavemodule.txt"

#: Hex digits of the package digest kept in the cache folder name.
DIGEST_DIGITS = 20

#: Environment variable naming the cache root of FMU-served kernels (read before ``NUMBA_CACHE_DIR``, and unlike
#: it without moving the caches of numba's own locators).
CACHE_DIR_ENV = "CNCTWIN_FMU_CACHE_DIR"

#: Cache folders always kept, newest first by modification time (the folder in use among them).
KEEP_NEWEST = 3

#: Folders beyond the newest :data:`KEEP_NEWEST` unused (modification time) for longer are deleted, s (30 days).
MAX_UNUSED_S = 30 * 86400.0

try:  # numba internals (numba >= 0.50): keep the import optional, never fatal in a user's master
    from numba.core import caching as _caching
    from numba.core import config as _config
    from numba.misc.appdirs import AppDirs as _AppDirs

    _Base: type = _caching._CacheLocator
except (ImportError, AttributeError):  # pragma: no cover - numba missing or reorganised
    _caching = None
    _Base = object


def unpacked_fmu_package(py_file: str | os.PathLike) -> Path | None:
    """The ``fmus_src`` folder containing ``py_file`` when it sits in an unpacked FMU's ``resources/``.

    Parameters
    ----------
    py_file : str or path-like
        Source file of a compiled function.

    Returns
    -------
    Path or None
        ``<unpacked>/resources/fmus_src`` when ``resources/slavemodule.txt``
        (written by pythonfmu) or ``<unpacked>/modelDescription.xml`` exists,
        else None. (fmpy's ``simulate_fmu`` unpacks only ``resources/`` and
        ``binaries/``.)
    """
    path = Path(py_file).resolve()
    for parent in path.parents:
        if parent.name == PACKAGE:
            resources = parent.parent
            if resources.name == "resources" and any(f.is_file() for f in (resources / PYTHONFMU_MARKER,
                                                                           resources.parent / "modelDescription.xml")):
                return parent
            return None
    return None


@functools.lru_cache(maxsize=None)
def package_digest(package: Path) -> str:
    """SHA-256 (hex) of every ``*.py`` file under ``package``: relative paths and bytes, in sorted order.

    Memoized per folder: an unpacked FMU does not change while it runs.
    """
    h = hashlib.sha256()
    for file in sorted(p for p in package.rglob("*.py") if "__pycache__" not in p.parts):
        h.update(file.relative_to(package).as_posix().encode())
        h.update(b"\0")
        h.update(file.read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def cache_root() -> Path:
    """``$CNCTWIN_FMU_CACHE_DIR`` when set, else ``$NUMBA_CACHE_DIR`` when set, else the per-user
    ``cnctwin/numba`` cache folder."""
    own = os.environ.get(CACHE_DIR_ENV)
    if own:
        return Path(own)
    if _config.CACHE_DIR:
        return Path(_config.CACHE_DIR)
    return Path(_AppDirs(appname="cnctwin", appauthor=False).user_cache_dir) / "numba"


def _ignore_vanished(function: object, path: str, exc_info: tuple) -> None:
    """``shutil.rmtree`` error handler: a file or folder removed meanwhile is fine; anything else is logged."""
    if not isinstance(exc_info[1], FileNotFoundError):
        log.debug("cache cleanup left %s: %s", path, exc_info[1])


def prune_cache_folders(root: Path, in_use: str, *, keep: int = KEEP_NEWEST, max_unused_s: float = MAX_UNUSED_S,
                        now: float | None = None) -> list[Path]:
    """Delete the ``fmus_src-*`` folders of ``root`` beyond the newest ``keep`` that are unused for ``max_unused_s``.

    "Used" is a folder's modification time, which :func:`open_cache_folder` refreshes at every process's first
    use. The folder ``in_use`` is never deleted. Safe against concurrent processes: a folder is first renamed to
    a hidden name (atomic; one that vanished or was taken by another process meanwhile is skipped), then removed
    (as is any such hidden folder a pruner left when it died); errors leave files behind and are logged at debug
    level, never raised.

    Parameters
    ----------
    root : Path
        The cache root (:func:`cache_root`).
    in_use : str
        Folder name of the running package (``fmus_src-<digest>``).
    keep : int
        Folders always kept, newest first by modification time.
    max_unused_s : float
        Age of a folder's modification time beyond which it is deleted when not among the newest ``keep``, s.
    now : float, optional
        Current time (``time.time()`` when None), s since the epoch.

    Returns
    -------
    list of Path
        The folders deleted (by their original names).
    """
    now = time.time() if now is None else now
    folders = []
    for folder in root.glob(f"{PACKAGE}-*"):
        try:
            info = folder.stat()
        except OSError:  # vanished: pruned by another process
            continue
        if stat.S_ISDIR(info.st_mode):
            folders.append((info.st_mtime, folder))
    folders.sort(key=lambda item: item[0], reverse=True)
    deleted = []
    for mtime, folder in folders[keep:]:
        if folder.name == in_use or now - mtime <= max_unused_s:
            continue
        trash = root / f".{folder.name}.deleting-{os.getpid()}"
        try:
            folder.rename(trash)
        except OSError as exc:  # vanished, or renamed by a concurrent pruner
            log.debug("cache folder %s not pruned: %s", folder, exc)
            continue
        shutil.rmtree(trash, onerror=_ignore_vanished)
        deleted.append(folder)
    for trash in root.glob(f".{PACKAGE}-*.deleting-*"):  # left by a pruner that died while removing
        shutil.rmtree(trash, onerror=_ignore_vanished)
    return deleted


@functools.lru_cache(maxsize=None)
def open_cache_folder(root: Path, name: str) -> Path:
    """``root / name``, created if missing, once per process and folder.

    An existing folder gets its modification time refreshed (it is in use); a new one triggers
    :func:`prune_cache_folders` of its siblings. Cleanup failures never propagate.

    Parameters
    ----------
    root : Path
        The cache root (:func:`cache_root`).
    name : str
        ``fmus_src-<digest>``.

    Returns
    -------
    Path
        The folder.
    """
    folder = root / name
    try:
        folder.mkdir(parents=True)
    except FileExistsError:
        try:
            os.utime(folder)
        except OSError as exc:  # read-only cache or vanished: numba's own checks decide
            log.debug("cache folder %s not touched: %s", folder, exc)
        return folder
    try:
        prune_cache_folders(root, name)
    except OSError as exc:  # an unreadable root must not fail a master
        log.debug("cache folders of %s not pruned: %s", root, exc)
    return folder


class FmuContentCacheLocator(_Base):  # type: ignore[misc,valid-type]
    """numba ``_CacheLocator`` for ``fmus_src`` functions running from an unpacked FMU (see module doc)."""

    def __init__(self, py_func: FunctionType, py_file: str, package: Path) -> None:
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        digest = package_digest(package)
        sub = Path(py_file).resolve().parent.relative_to(package)
        self._cache_path = str(open_cache_folder(cache_root(), f"{PACKAGE}-{digest[:DIGEST_DIGITS]}") / sub)
        self._stamp = digest

    def get_cache_path(self) -> str:
        """Folder of the index and data files (outside the unpacked FMU)."""
        return self._cache_path

    def get_source_stamp(self) -> str:
        """The package digest (the folder already depends on it; kept as numba's freshness check)."""
        return self._stamp

    def get_disambiguator(self) -> str:
        """First line number of the function, as numba's own locators."""
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func: FunctionType, py_file: str) -> "FmuContentCacheLocator | None":
        """The locator for ``py_func`` when it belongs to an unpacked FMU's ``fmus_src``, else None.

        None also when anything fails (numba then tries its default locators).
        """
        module = getattr(py_func, "__module__", None) or ""
        if module != PACKAGE and not module.startswith(PACKAGE + "."):
            return None
        try:
            package = unpacked_fmu_package(py_file)
            if package is None:
                return None
            self = cls(py_func, py_file, package)
            self.ensure_cache_path()
        except Exception as exc:  # noqa: BLE001 - any failure falls back to numba's locators, never crashes a master
            log.debug("content cache locator not used for %s (%s): %s", py_file, type(exc).__name__, exc)
            return None
        return self


def install() -> bool:
    """Put :class:`FmuContentCacheLocator` first in numba's locator list (idempotent).

    Returns
    -------
    bool
        True when the locator is registered (False without numba or with
        unexpected numba internals; numba's defaults then apply).
    """
    if _caching is None:  # pragma: no cover
        return False
    impl = getattr(_caching, "CacheImpl", None) or getattr(_caching, "_CacheImpl", None)  # older numba: _CacheImpl
    classes = getattr(impl, "_locator_classes", None)
    if not isinstance(classes, list):  # pragma: no cover - numba reorganised
        return False
    if not any(getattr(c, "__name__", "") == FmuContentCacheLocator.__name__
               and getattr(c, "__module__", "") == FmuContentCacheLocator.__module__ for c in classes):
        classes.insert(0, FmuContentCacheLocator)
    return True
