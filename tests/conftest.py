"""Suite-wide pytest hooks.

PythonFMU 0.7 can corrupt the heap while the interpreter shuts down after its
FMUs have been loaded in the process ("corrupted double-linked list", SIGABRT,
exit status 134; NTNU-IHB/PythonFMU#228). It happens after every test has
run and been reported, about one run in four of ``tests/test_fmu_import.py``,
and it would turn a green suite red. ``FMUComponent`` no longer frees PythonFMU
instances (``NO_FREE_TOOLS``), but ``fmpy.simulate_fmu`` and fmpy's validation,
which the FMU tests call, still do. So once pytest is completely done
(results reported, every other plugin unconfigured), the process leaves with
pytest's own exit status without running the interpreter's teardown.

The numba kernels of FMUs run standalone (``fmus_src`` from an unpacked FMU,
:mod:`fmus_src.jit_locator`) are cached under ``$CNCTWIN_FMU_CACHE_DIR``, set
here (unless already set) for the test process and every process it starts to
a per-user folder in the system's temporary directory, not the user's
``~/.cache``; it persists between sessions, so FMU tests load their kernels
instead of recompiling them, and the locator prunes it as any cache root.
"""
from __future__ import annotations

import getpass
import os
import sys
import tempfile
from pathlib import Path

import pytest

os.environ.setdefault("CNCTWIN_FMU_CACHE_DIR",
                      str(Path(tempfile.gettempdir()) / f"cnctwin-tests-fmu-numba-{getpass.getuser()}"))

_EXIT_STATUS: list[int] = []


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    _EXIT_STATUS.append(int(exitstatus))


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config: pytest.Config) -> None:
    if not _EXIT_STATUS or hasattr(config, "workerinput"):  # not a finished main session (or an xdist worker)
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(_EXIT_STATUS[-1])
