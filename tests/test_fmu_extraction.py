"""Unpacked-FMU folders: removed at exit, swept when their process was killed, never taken from a live process."""
from __future__ import annotations

import multiprocessing
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from orchestrator.fmu import extraction

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture()
def archive(tmp_path: Path) -> Path:
    """A stand-in .fmu: a zip with a model description."""
    path = tmp_path / "Stand_in.fmu"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("modelDescription.xml", "<fmiModelDescription/>")
    return path


def _child(code: str, tmp: Path) -> subprocess.CompletedProcess:
    env = dict(os.environ, TMPDIR=str(tmp), PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120,
                          check=True)


@pytest.mark.skipif(os.name != "posix", reason="the sweep probes pids with kill(pid, 0), POSIX only")
def test_folder_of_a_killed_process_is_swept_and_a_normal_exit_cleans_up(archive: Path, tmp_path: Path) -> None:
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    extract = ("from pathlib import Path; from orchestrator.fmu.extraction import extract_fmu; "
               f"f = extract_fmu(Path({str(archive)!r}), 'Stand_in'); "
               "assert (f / 'modelDescription.xml').is_file(); ")
    _child(extract, tmp)                                            # a normal exit removes its folder
    assert list(tmp.iterdir()) == []
    _child(extract + "import os; os._exit(0)", tmp)                 # like a killed worker: no exit handlers
    left = list(tmp.iterdir())
    assert len(left) == 1 and left[0].name.startswith("cnctwin_p") and "_Stand_in_" in left[0].name
    mine = tmp / f"cnctwin_p{os.getpid()}_Live_x"                   # a live process's folder (this one)
    mine.mkdir()
    other = tmp / "cnctwin_Scale_abc"                               # not of this naming: left alone
    other.mkdir()
    assert extraction.sweep_stale_extractions(tmp) == left
    assert sorted(p.name for p in tmp.iterdir()) == sorted([mine.name, other.name])


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork only")
def test_forked_child_does_not_remove_the_parents_folder(archive: Path, tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(extraction, "_extracted", {})
    monkeypatch.setattr(extraction.tempfile, "tempdir", str(tmp_path))
    folder = extraction.extract_fmu(archive, "Stand_in")
    assert extraction.extract_fmu(archive, "Stand_in") == folder    # once per process and file version
    pid = os.fork()
    if pid == 0:                                                    # the child: what its exit handlers run
        extraction.remove_extracted()
        os._exit(0)
    os.waitpid(pid, 0)
    assert (folder / "modelDescription.xml").is_file()
    extraction.remove_extracted()
    assert not folder.exists()


def _extract_in_worker(archive: str) -> str:
    return str(extraction.extract_fmu(Path(archive), "Stand_in"))


#: The pool start methods of this platform: spawn everywhere, fork (the optimiser's workers on Linux) on POSIX.
START_METHODS = [m for m in ("fork", "spawn") if m in multiprocessing.get_all_start_methods()]


@pytest.mark.parametrize("method", START_METHODS)
def test_pool_worker_removes_its_folder_when_the_pool_closes(archive: Path, tmp_path: Path, method: str,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(ROOT))
    monkeypatch.setattr(extraction.tempfile, "tempdir", str(tmp_path))
    with multiprocessing.get_context(method).Pool(1) as pool:
        folder = Path(pool.apply(_extract_in_worker, (str(archive),)))
        assert (folder / "modelDescription.xml").is_file()
        pool.close()
        pool.join()
    assert not folder.exists()
