"""``import orchestrator`` is light: the twin, numba and matplotlib load on first use of a capability."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

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
