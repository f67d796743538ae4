"""Invalidate a numba on-disk cache when a *called* module's source changes.

numba's ``cache=True`` keys a cached function on its own source file only: a
compiled function that calls jitted functions of other modules keeps running
the old callee code after those modules change (numba issue #6845). Call
:func:`guard_cache` right after defining such a function; it stores a digest
of the callee modules' sources next to the cache and flushes the function's
cache index when the digest differs, so the next call recompiles.
"""
from __future__ import annotations

import hashlib
import inspect
import logging
from pathlib import Path
from types import ModuleType

log = logging.getLogger(__name__)


def source_digest(modules: tuple[ModuleType, ...]) -> str:
    """SHA-256 of the source files of ``modules`` (in the given order), hex."""
    h = hashlib.sha256()
    for module in modules:
        path = inspect.getsourcefile(module)
        h.update(module.__name__.encode())
        h.update(Path(path).read_bytes() if path else b"")
    return h.hexdigest()


def guard_cache(dispatcher: object, *modules: ModuleType) -> bool:
    """Flush ``dispatcher``'s cache index if the sources of ``modules`` changed since it was written.

    Parameters
    ----------
    dispatcher : numba dispatcher
        A function made by :func:`fmus_src.jit.njit` (anything else, or an uncached one, is left alone).
    *modules : module
        The modules whose jitted functions ``dispatcher`` calls.

    Returns
    -------
    bool
        True when the cache was flushed.
    """
    cache = getattr(dispatcher, "_cache", None)
    folder = getattr(cache, "cache_path", None)
    if cache is None or not folder:
        return False
    func = getattr(dispatcher, "py_func", None)
    name = f"{getattr(func, '__module__', '?')}.{getattr(func, '__qualname__', '?')}.deps"
    stamp = Path(folder) / name
    digest = source_digest(modules)
    try:
        if stamp.read_text() == digest:
            return False
    except OSError:
        pass
    cache.flush()
    try:
        stamp.write_text(digest)
    except OSError as exc:  # read-only cache folder: the flush still holds for this process
        log.debug("cannot write %s: %s", stamp, exc)
    return True
