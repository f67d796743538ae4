"""numba cache of ``fmus_src`` inside an unpacked FMU: keyed by the package content, not the unpack folder.

A master unpacks an FMU into a new folder at every instantiation. The tests
lay out ``<unpacked>/resources/fmus_src`` (+ pythonfmu's ``slavemodule.txt``)
as fmpy does, with two probe kernels added to the package (``f(x) = g(x) + 1``
with ``g(x) = 2 x`` in another module), and run each instantiation in a new
process with a temporary ``NUMBA_CACHE_DIR``; numba's dispatcher statistics
tell whether ``f`` was compiled or loaded from the cache.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

import fmus_src
from fmus_src import jit_locator
from fmus_src.jit_locator import FmuContentCacheLocator, unpacked_fmu_package

PACKAGE = Path(fmus_src.__file__).resolve().parent

CALLER = "from .jit import njit\nfrom ._probe_callee import g\n\n\n@njit\ndef f(x):\n    return g(x) + {add}\n"
CALLEE = "from .jit import njit\n\n\n@njit\ndef g(x):\n    return {gain} * x\n"

_RUN = r"""
import json, os, sys
# hide the project's editable install: fmus_src must come from the unpacked folder
sys.meta_path[:] = [f for f in sys.meta_path if "editable" not in type(f).__module__
                    and "editable" not in getattr(f, "__module__", "")]
sys.path[:] = [sys.argv[1]] + [p for p in sys.path if p not in ("", ".")]
from fmus_src import _probe
value = _probe.f(1.0)
stats = _probe.f.stats
print(json.dumps({"value": value, "hits": sum(stats.cache_hits.values()), "misses": sum(stats.cache_misses.values()),
                  "origin": _probe.__file__, "cache": _probe.f._cache.cache_path}))
"""


def _unpack(folder: Path, add: float = 1.0, gain: float = 2.0) -> Path:
    """Lay out ``folder/resources/fmus_src`` as an unpacked pythonfmu FMU, with the probe kernels."""
    resources = folder / "resources"
    package = resources / "fmus_src"
    shutil.copytree(PACKAGE, package, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    (package / "_probe.py").write_text(CALLER.format(add=add))
    (package / "_probe_callee.py").write_text(CALLEE.format(gain=gain))
    (resources / "slavemodule.txt").write_text("cnctwin_probe")
    return resources


def _instantiate(resources: Path, cache_dir: Path) -> dict:
    """Import the probe from ``resources`` and call ``f(1.0)`` in a new process."""
    env = {k: v for k, v in os.environ.items() if k != jit_locator.CACHE_DIR_ENV}  # NUMBA_CACHE_DIR decides here
    env.update({"PYTHONPATH": "", "NUMBA_CACHE_DIR": str(cache_dir)})
    out = subprocess.run([sys.executable, "-c", _RUN, str(resources)], cwd=resources, capture_output=True,
                         text=True, timeout=300, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert result["origin"] == str(resources / "fmus_src" / "_probe.py")
    return result


@pytest.fixture(scope="module")
def primed(tmp_path_factory):
    """A cache directory filled by a first instantiation (from an unpack folder deleted afterwards)."""
    cache = tmp_path_factory.mktemp("numba_cache")
    first = tmp_path_factory.mktemp("unpack1")
    result = _instantiate(_unpack(first), cache)
    shutil.rmtree(first)
    return cache, result


def test_first_instantiation_compiles_into_the_cache_outside_the_fmu(primed):
    cache, result = primed
    assert result["value"] == 3.0  # 2 * 1 + 1
    assert (result["hits"], result["misses"]) == (0, 1)
    assert Path(result["cache"]).parent == cache  # <NUMBA_CACHE_DIR>/fmus_src-<digest> (probe at package top)
    assert Path(result["cache"]).name.startswith("fmus_src-")


def test_second_unpack_folder_in_a_new_process_loads_the_kernel_from_cache(primed, tmp_path):
    cache, first = primed
    resources = _unpack(tmp_path / "unpack2")
    result = _instantiate(resources, cache)
    assert result["value"] == 3.0
    assert (result["hits"], result["misses"]) == (1, 0)
    assert result["cache"] == first["cache"]
    assert not list(resources.rglob("*.nbi"))  # nothing written into the unpacked FMU


@pytest.mark.parametrize(("add", "gain", "expected"), [(10.0, 2.0, 12.0), (1.0, 5.0, 6.0)],
                         ids=["own-source-changed", "callee-module-changed"])
def test_changed_package_content_is_not_served_from_cache(primed, tmp_path, add, gain, expected):
    cache, first = primed
    result = _instantiate(_unpack(tmp_path / "changed", add=add, gain=gain), cache)
    assert result["value"] == expected  # g(1) + add with the changed sources
    assert (result["hits"], result["misses"]) == (0, 1)
    assert result["cache"] != first["cache"]


def test_source_tree_keeps_numbas_own_locators():
    assert unpacked_fmu_package(PACKAGE / "jit.py") is None
    from fmus_src.cutting import kernel

    dispatcher = next(v for v in vars(kernel).values() if hasattr(v, "_cache"))
    assert not isinstance(dispatcher._cache._impl.locator, FmuContentCacheLocator)


def _func_in(module: str):
    def probe(x):
        return x

    probe.__module__ = module
    return probe


def test_locator_only_serves_fmus_src_and_falls_back_when_the_cache_is_unusable(tmp_path, monkeypatch):
    resources = tmp_path / "unpacked" / "resources"
    package = resources / "fmus_src"
    package.mkdir(parents=True)
    (resources / "slavemodule.txt").write_text("x")
    source = package / "mod.py"
    source.write_text("def probe(x):\n    return x\n")
    monkeypatch.delenv(jit_locator.CACHE_DIR_ENV, raising=False)
    monkeypatch.setattr(jit_locator._config, "CACHE_DIR", str(tmp_path / "cache"))
    locator = FmuContentCacheLocator.from_function(_func_in("fmus_src.mod"), str(source))
    digest = jit_locator.package_digest(package)
    assert Path(locator.get_cache_path()) == tmp_path / "cache" / f"fmus_src-{digest[:jit_locator.DIGEST_DIGITS]}"
    assert FmuContentCacheLocator.from_function(_func_in("other.mod"), str(source)) is None
    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    monkeypatch.setattr(jit_locator._config, "CACHE_DIR", str(blocker))
    assert FmuContentCacheLocator.from_function(_func_in("fmus_src.mod"), str(source)) is None  # numba's defaults


def test_locator_is_registered_first_once():
    from numba.core import caching

    assert jit_locator.install() and jit_locator.install()
    classes = caching.CacheImpl._locator_classes
    assert classes[0] is FmuContentCacheLocator
    assert sum(c is FmuContentCacheLocator for c in classes) == 1


# ----------------------------------------------------------------------------- housekeeping of the cache root
DAY = 86400.0
NOW = time.time()  # the fake mtimes are ages before the start of the tests (the thresholds are days)


def _folders(root: Path, ages_days: dict[str, float]) -> None:
    """``root/<name>`` for each name, with a file inside and the folder's mtime ``age`` days before NOW."""
    for name, age in ages_days.items():
        (root / name).mkdir(parents=True)
        (root / name / "f.nbi").write_bytes(b"x")
        os.utime(root / name, (NOW - age * DAY, NOW - age * DAY))


def _left(root: Path) -> set[str]:
    return {p.name for p in root.iterdir()}


def test_prune_deletes_folders_unused_for_30_days_beyond_the_newest_three(tmp_path):
    ages = {"fmus_src-new": 0.0, "fmus_src-a": 10.0, "fmus_src-b": 40.0, "fmus_src-c": 50.0, "fmus_src-d": 29.0,
            "fmus_src-e": 31.0, "other-x": 400.0}
    _folders(tmp_path, ages)
    (tmp_path / ".fmus_src-f.deleting-123").mkdir()  # a pruner that died while removing f
    (tmp_path / ".fmus_src-f.deleting-123" / "f.nbi").write_bytes(b"x")
    (tmp_path / "fmus_src-file").write_text("not a cache folder of ours, older than all")
    os.utime(tmp_path / "fmus_src-file", (NOW - 500 * DAY,) * 2)
    deleted = jit_locator.prune_cache_folders(tmp_path, "fmus_src-new", now=NOW)
    # newest three by mtime: new (0), a (10), d (29) kept; beyond them e (31), b (40), c (50) are > 30 days old
    # (a file and other names are left alone)
    assert {p.name for p in deleted} == {"fmus_src-e", "fmus_src-b", "fmus_src-c"}
    assert _left(tmp_path) == {"fmus_src-new", "fmus_src-a", "fmus_src-d", "other-x", "fmus_src-file"}
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no leftover of the rename-then-delete


def test_prune_keeps_young_folders_and_the_folder_in_use_whatever_their_number_or_age(tmp_path):
    _folders(tmp_path, {"fmus_src-a": 1.0, "fmus_src-b": 2.0, "fmus_src-c": 3.0, "fmus_src-d": 29.9,
                        "fmus_src-used": 90.0})
    # d is beyond the newest three but used 29.9 days ago; "used" is the oldest, but it is the one in use
    assert jit_locator.prune_cache_folders(tmp_path, "fmus_src-used", now=NOW) == []
    assert len(_left(tmp_path)) == 5


def test_prune_skips_a_folder_another_process_removed_meanwhile(tmp_path, monkeypatch):
    _folders(tmp_path, {"fmus_src-new": 0.0, "fmus_src-a": 1.0, "fmus_src-b": 2.0, "fmus_src-gone": 60.0,
                        "fmus_src-old": 70.0})
    rename = Path.rename

    def concurrent_prune_first(self, target):
        if self.name == "fmus_src-gone":  # another process pruned it between the listing and the rename
            shutil.rmtree(self)
        return rename(self, target)

    monkeypatch.setattr(Path, "rename", concurrent_prune_first)
    deleted = jit_locator.prune_cache_folders(tmp_path, "fmus_src-new", now=NOW)
    assert [p.name for p in deleted] == ["fmus_src-old"]
    assert _left(tmp_path) == {"fmus_src-new", "fmus_src-a", "fmus_src-b"}


def test_opening_a_new_folder_prunes_its_siblings_and_reopening_marks_it_used(tmp_path):
    _folders(tmp_path, {"fmus_src-a": 1.0, "fmus_src-b": 2.0, "fmus_src-old": 31.0, "fmus_src-older": 45.0})
    jit_locator.open_cache_folder.cache_clear()
    folder = jit_locator.open_cache_folder(tmp_path, "fmus_src-new")
    assert folder == tmp_path / "fmus_src-new" and folder.is_dir()
    assert _left(tmp_path) == {"fmus_src-new", "fmus_src-a", "fmus_src-b"}  # the newest three, and no other
    # an existing folder: its mtime is refreshed (its last use), nothing is pruned
    _folders(tmp_path, {"fmus_src-again": 45.0, "fmus_src-z": 60.0})
    jit_locator.open_cache_folder(tmp_path, "fmus_src-again")
    assert (tmp_path / "fmus_src-again").stat().st_mtime > NOW - DAY
    assert "fmus_src-z" in _left(tmp_path)
    jit_locator.open_cache_folder.cache_clear()


def test_the_fmu_cache_root_variable_comes_before_numbas(tmp_path, monkeypatch):
    monkeypatch.setattr(jit_locator._config, "CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setenv(jit_locator.CACHE_DIR_ENV, str(tmp_path / "fmus"))
    assert jit_locator.cache_root() == tmp_path / "fmus"
    monkeypatch.delenv(jit_locator.CACHE_DIR_ENV)
    assert jit_locator.cache_root() == tmp_path / "numba"


def test_the_suite_keeps_fmu_kernels_out_of_the_users_cache():
    root = Path(os.environ[jit_locator.CACHE_DIR_ENV])  # set by conftest.py for this process and its children
    assert jit_locator.cache_root() == root
    user_cache = Path(jit_locator._AppDirs(appname="cnctwin", appauthor=False).user_cache_dir)
    assert root != user_cache and user_cache not in root.parents
