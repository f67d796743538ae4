"""Content-keyed memo of costly, deterministic results (engagement tables, the twin's runs of a program).

A diagnosis builds the same engagement table and runs the twin on the same program and machine several
times (the clock of a dynamometer, the drives' loads, the cutting replay, a held-out case of the same
program); the truth generators of the tests do so too. :func:`remember` keeps the last few results per kind,
keyed by a digest of everything the result depends on (:func:`digest`), never by a file path, so a result
is reused only for the same content.

Results are shared, not copied: callers must not modify them (:class:`fmus_src.cutting.table.EngagementTable`
is frozen; recordings are copied by the callers that hand them on).
"""
from __future__ import annotations

import hashlib
import json
from collections import OrderedDict
from typing import Any, Callable, TypeVar

import numpy as np

T = TypeVar("T")

#: Results kept per kind (least recently used dropped first). Few: a long program's table or run is large
#: (a 595 s log's twin run at 1 ms has about 0.6 M rows), and a diagnosis reuses the last one.
KEEP = 2

_store: dict[str, OrderedDict[str, Any]] = {}


def _plain(x: Any) -> Any:
    """A JSON-able, order-stable form of ``x`` (arrays by their bytes' digest, dtype and shape)."""
    if isinstance(x, np.ndarray):
        a = np.ascontiguousarray(x)
        return ["ndarray", str(a.dtype), list(a.shape), hashlib.sha256(a.tobytes()).hexdigest()]
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, dict):
        return {str(k): _plain(v) for k, v in sorted(x.items(), key=lambda kv: str(kv[0]))}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, (str, int, float, bool)) or x is None:
        return x
    return repr(x)


def digest(*parts: Any) -> str:
    """SHA-256 of ``parts`` (nested dicts, sequences, numbers, strings, arrays), hex."""
    text = json.dumps(_plain(list(parts)), sort_keys=True, allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()


def remember(kind: str, key: str, build: Callable[[], T]) -> T:
    """``build()``, or its earlier result for the same ``kind`` and ``key`` (see module docstring).

    An exception of ``build`` propagates and nothing is kept.
    """
    kept = _store.setdefault(kind, OrderedDict())
    if key in kept:
        kept.move_to_end(key)
        return kept[key]
    value = build()
    kept[key] = value
    while len(kept) > KEEP:
        kept.popitem(last=False)
    return value


def forget(kind: str | None = None) -> None:
    """Drop the kept results of ``kind`` (all kinds when None)."""
    if kind is None:
        _store.clear()
    else:
        _store.pop(kind, None)


def clear() -> None:
    """Drop every kept result, of every kind (their memory is freed once no caller holds them).

    For a long-lived process (a notebook, a service) that is done with a diagnosis or an optimisation and
    wants the memory of their largest intermediate results back (a twin run of a long log, an engagement
    table). Always safe: results are keyed by content, so a later call only builds again what it needs.
    :func:`orchestrator.diagnose.diagnose` and :func:`orchestrator.optimize.optimize` do not call it
    themselves: successive jobs on one program reuse the kept twin runs and tables (a scorecard's seeds, the
    tests' scenarios).
    """
    _store.clear()
