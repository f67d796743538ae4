"""Atomic writes keep the permissions a plain write would give (not the temporary file's private 0o600)."""
from __future__ import annotations

import os
import stat

import pytest

from orchestrator.atomic import atomic_write_text, atomic_writer


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
def test_new_file_gets_0o666_less_the_umask(tmp_path):
    old = os.umask(0o027)
    try:
        path = atomic_write_text(tmp_path / "optimized.nc", "G0 X0\n")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~0o027 == 0o640


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
def test_replaced_file_keeps_its_permissions(tmp_path):
    path = tmp_path / "report.json"
    path.write_text("{}\n")
    path.chmod(0o604)
    atomic_write_text(path, "{\"a\": 1}\n")
    assert stat.S_IMODE(path.stat().st_mode) == 0o604
    assert path.read_text() == "{\"a\": 1}\n"


def test_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "recording.csv"
    path.write_text("t_s\n0\n")
    with pytest.raises(RuntimeError):
        with atomic_writer(path) as handle:
            handle.write(b"t_s\n1\n")
            raise RuntimeError("killed half-way")
    assert path.read_text() == "t_s\n0\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recording.csv"]
