"""Content-keyed memo (orchestrator.memo): same content -> one build; other content, or a failed build -> a new one."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator import memo


def test_digest_is_the_content_not_the_object():
    a = {"b": [1.0, 2.0], "a": np.arange(4.0)}
    assert memo.digest(a) == memo.digest({"a": np.arange(4.0), "b": (1.0, 2.0)})   # key order, list/tuple alike
    assert memo.digest(a) != memo.digest({"a": np.arange(4.0) + 1e-12, "b": [1.0, 2.0]})
    assert memo.digest(np.zeros(3)) != memo.digest(np.zeros(3, dtype=np.float32))
    assert memo.digest(np.zeros((2, 3))) != memo.digest(np.zeros((3, 2)))


def test_remember_builds_once_per_key_keeps_a_few_and_never_a_failure():
    memo.forget("test")
    calls = []

    def build(x):
        calls.append(x)
        return [x]

    first = memo.remember("test", "k1", lambda: build(1))
    assert memo.remember("test", "k1", lambda: build(2)) is first and calls == [1]
    with pytest.raises(ValueError):
        memo.remember("test", "bad", lambda: (_ for _ in ()).throw(ValueError("no")))
    assert memo.remember("test", "bad", lambda: build(3)) == [3]
    for i in range(memo.KEEP):   # k1 is the least recently used: dropped
        memo.remember("test", f"n{i}", lambda i=i: build(10 + i))
    assert memo.remember("test", "k1", lambda: build(4)) == [4] and calls[-1] == 4
    memo.forget("test")


def test_clear_drops_every_kind_and_the_next_call_builds_again():
    calls = []
    for kind in ("test_a", "test_b"):
        memo.remember(kind, "k", lambda kind=kind: calls.append(kind) or kind)
    memo.clear()
    assert memo._store == {}
    assert memo.remember("test_a", "k", lambda: calls.append("again") or "new") == "new"
    assert calls == ["test_a", "test_b", "again"]
    memo.clear()
