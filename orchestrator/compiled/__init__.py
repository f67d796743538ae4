"""Compiled master loop for all-native twins (issue 9): the whole communication-step loop in one numba call.

:func:`run_compiled` runs a :class:`~orchestrator.master.Master` with the
step loop of :func:`.loop.run_chunk` when every component has a kernel the
loop knows (see :mod:`.layout` for what is covered) and returns None
otherwise. :meth:`Master.run` calls it first unless
``MasterSettings(compiled=False)``; recordings are bit-identical to the
Python loop's (tested).
"""
from __future__ import annotations

from .layout import Layout, Unsupported
from .runner import compiled_support, run_compiled

__all__ = ["Layout", "Unsupported", "compiled_support", "run_compiled"]
