"""Optional numba compilation of the cutting hot paths.

Same policy as :mod:`fmus_src.servo._jit` (kept separate so that the cutting
package does not depend on the servo package): ``numba.njit(cache=True)``
without fastmath; without a usable cache directory the function is compiled
uncached; without numba the plain Python function is returned (correct, slow).
"""
from __future__ import annotations

from typing import Callable, TypeVar

try:
    import numba
except ImportError:  # pragma: no cover - numba is a declared dependency
    numba = None

F = TypeVar("F", bound=Callable)

#: True when the compiled kernels are available (``import numba`` works).
NUMBA_AVAILABLE: bool = numba is not None


def njit(fn: F) -> F:
    """``numba.njit(cache=True)``; uncached when no cache location is writable; identity without numba."""
    if numba is None:  # pragma: no cover
        return fn
    try:
        return numba.njit(cache=True)(fn)
    except RuntimeError:  # pragma: no cover - "no locator available" (read-only install)
        return numba.njit(fn)
