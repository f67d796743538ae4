"""Optional numba compilation of the hot paths of the components (servo, drives, cutting).

``numba`` is a dependency of cnctwin, but ``fmus_src`` is also shipped inside
FMUs, whose host interpreter might lack it. Without numba, :func:`njit`
returns the plain Python function (importable, correct, slow) and
:data:`NUMBA_AVAILABLE` is False, so the components fall back to the numpy
reference implementation.

Compiled code is cached next to the source (``__pycache__``); when no cache
location is writable numba refuses ``cache=True`` at decoration time, and the
function is then compiled without a cache (once per process). Inside an
unpacked FMU the cache lives outside the FMU, keyed by the content of the
shipped package (:mod:`fmus_src.jit_locator`), so that a master unpacking the
FMU into a new folder at every instantiation does not recompile.
"""
from __future__ import annotations

from typing import Callable, TypeVar

try:
    import numba
except ImportError:  # pragma: no cover - numba is a declared dependency
    numba = None
else:
    from .jit_locator import install as _install_locator

    _install_locator()

F = TypeVar("F", bound=Callable)

#: True when the compiled kernels are available (``import numba`` works).
NUMBA_AVAILABLE: bool = numba is not None


def _compile(fn: F, **options: object) -> F:
    """``numba.njit(cache=True, **options)(fn)``; uncached when no cache directory is usable; ``fn`` without numba."""
    if numba is None:  # pragma: no cover
        return fn
    try:
        return numba.njit(cache=True, **options)(fn)
    except RuntimeError:  # "cannot cache function ...: no locator available" (read-only install)
        return numba.njit(**options)(fn)


def njit(fn: F) -> F:
    """``numba.njit(cache=True)`` without fastmath (IEEE results equal to numpy's, operation by operation).

    Falls back to an uncached compilation when no cache directory is usable,
    and to the Python function itself when numba is missing. Reference
    counting is on explicitly, so a function called from an :func:`njit_borrowed`
    one still allocates (numba would otherwise inherit the caller's setting).
    """
    return _compile(fn, _nrt=True)


def njit_inline(fn: F) -> F:
    """:func:`njit` with ``inline="always"``: the function is inlined into its compiled callers (numba IR level).

    For small helpers shared by several hot loops, where a call across compiled
    functions would cost more than the work (the floating-point operations are unchanged).
    """
    return _compile(fn, inline="always", _nrt=True)


def njit_borrowed(fn: F) -> F:
    """:func:`njit` without numba's reference counting (``_nrt=False``): for kernels that only *borrow* arrays.

    Numba counts references to every array a compiled function receives or
    views (``NRT_incref`` / ``NRT_decref``: a call and an atomic operation each,
    on entry and exit of every call and around every view). In a small kernel
    called many times per step that costs as much as its arithmetic. A
    function declared with this decorator takes arrays, reads and writes them,
    makes views of them and calls other compiled functions, but must not
    allocate an array or return one (numba refuses to compile that without
    reference counting). Its callers keep the arrays alive. The floating-point
    operations are unchanged.
    """
    return _compile(fn, _nrt=False)


def njit_nogil(fn: F) -> F:
    """:func:`njit` with ``nogil=True``: the compiled function releases the GIL while it runs.

    For loops that Python threads run side by side on separate data (the
    compiled master loop over blocks of batch members); the compiled
    functions it calls run without the GIL too.
    """
    return _compile(fn, nogil=True, _nrt=True)


def njit_rows(fn: F) -> F:
    """:func:`njit_borrowed` with ``error_model="numpy"``: for loops over batch members that LLVM should vectorise.

    Under numba's default ``error_model="python"`` every float division checks its divisor and
    raises ``ZeroDivisionError``; that branch keeps a member loop scalar. With the numpy error model a
    division by zero gives ``inf`` or ``NaN`` instead. Use it only where no divisor can be zero (the
    floating-point operations are otherwise unchanged: same IEEE results, member by member).
    """
    return _compile(fn, _nrt=False, error_model="numpy")
