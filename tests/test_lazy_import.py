"""``import orchestrator`` is light: the twin, numba and matplotlib load on first use of a capability."""
from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_import_orchestrator_loads_no_heavy_module_and_every_public_name_resolves():
    code = (
        "import sys, orchestrator\n"
        "heavy = [m for m in ('numba', 'matplotlib', 'scipy', 'pymoo', 'orchestrator.twin', 'orchestrator.simulate')"
        " if m in sys.modules]\n"
        "assert not heavy, heavy\n"
        "values = [getattr(orchestrator, n) for n in orchestrator.__all__]\n"
        "from orchestrator import simulate, Master, CncTwinError\n"
        "assert orchestrator.simulate is simulate and callable(simulate)\n"
        "try:\n    orchestrator.no_such_name\nexcept AttributeError as e:\n    assert 'no_such_name' in str(e)\n"
        "else:\n    raise SystemExit('no AttributeError')\n"
        "print(len(values))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    import orchestrator

    assert int(out.stdout) == len(orchestrator.__all__)


def test_simulate_is_the_function_even_after_its_submodule_was_imported():
    code = ("import types\nfrom orchestrator.simulate import resolve_case\nfrom orchestrator import simulate\n"
            "import orchestrator\nassert not isinstance(simulate, types.ModuleType) and simulate.__name__ == 'simulate'\n"
            "assert orchestrator.simulate is simulate\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


def test_cli_help_version_argument_errors_and_reading_a_machine_file_load_no_heavy_module():
    """``cnctwin --help`` used to import numba and scipy.signal through ``orchestrator.fmu`` → machine →
    ``fmus_src.nck`` (about 2 s of CPU before the first line of help), and reading a machine file imported numba
    through ``fmus_src.servo``: the parser and the machine file need neither, nor fmpy, pythonfmu, pymoo or
    matplotlib."""
    code = (
        "import contextlib, io, sys\n"
        "from orchestrator.cli import main\n"
        "codes = []\n"
        "for argv in (['--help'], ['--version'], ['simulate', '--out', 'x'], ['check-fmu'], ['optimize', '--help']):\n"
        "    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):\n"
        "        try:\n            main(argv)\n        except SystemExit as e:\n            codes.append(e.code)\n"
        "from orchestrator.machine import load_machine\n"
        "load_machine('default')\n"
        "heavy = [m for m in ('numba', 'scipy', 'fmpy', 'pythonfmu', 'pymoo', 'matplotlib', 'fmus_src.nck.planner')"
        " if m in sys.modules]\n"
        "assert not heavy, heavy\n"
        "print(codes)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[0, 0, 2, 2, 0]"  # help and version exit 0, argparse errors exit 2


def test_lazy_packages_resolve_every_public_name():
    import fmus_src.nck
    import fmus_src.servo
    import orchestrator.fmu

    for package in (fmus_src.nck, fmus_src.servo, orchestrator.fmu):
        assert set(package.__all__) == set(package._LAZY)
        for name in package.__all__:
            assert getattr(package, name) is getattr(importlib.import_module(package._LAZY[name], package.__name__), name)
        with pytest.raises(AttributeError, match="no_such_name"):
            package.no_such_name
