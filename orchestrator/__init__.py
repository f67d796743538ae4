"""cnctwin orchestrator: co-simulation master, system description, recordings, CLI.

Every capability is a Python call first and a ``cnctwin`` command second::

    from orchestrator import simulate
    result = simulate(case="models/examples/paper_part", out="out/paper_part")
"""
from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

from .errors import CncTwinError, SimulationError, SystemDescriptionError

#: Public name -> module that defines it; imported on first use (``import orchestrator`` stays fast:
#: the twin, numba and the plotting stack load only when a capability is used).
_LAZY = {
    "Component": "fmus_src.component", "ComponentError": "fmus_src.component", "Variable": "fmus_src.component",
    "Machine": ".machine", "MachineFileError": ".machine", "load_machine": ".machine",
    "Master": ".master", "MasterSettings": ".master", "Probe": ".master", "RunResult": ".master",
    "simulate_system": ".master",
    "Recording": ".recording", "RecordingError": ".recording",
    "SimulationResult": ".simulate", "simulate": ".simulate",
    "Connection": ".system", "System": ".system",
}

__all__ = [
    "CncTwinError", "Component", "ComponentError", "Connection", "Machine", "MachineFileError", "Master",
    "MasterSettings", "Probe", "Recording", "RecordingError", "RunResult", "SimulationError", "System",
    "SimulationResult", "SystemDescriptionError", "Variable", "load_machine", "simulate", "simulate_system",
]


def __getattr__(name: str) -> Any:
    """Import a public name on first access (PEP 562)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'orchestrator' has no attribute {name!r}")
    value = getattr(importlib.import_module(module, __name__), name)
    if name != "simulate":
        globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """This package's module type: ``orchestrator.simulate`` is always the function.

    The function shares its name with the submodule :mod:`orchestrator.simulate`,
    which the import system binds as a package attribute whenever the submodule
    is imported (by any code, at any time); the eager ``from .simulate import
    simulate`` used to rebind it once. A data descriptor keeps the function.
    """

    @property
    def simulate(self) -> Any:
        return importlib.import_module(".simulate", __name__).simulate

    @simulate.setter
    def simulate(self, value: Any) -> None:
        """Ignore the import system's binding of the submodule (``sys.modules`` keeps it)."""


sys.modules[__name__].__class__ = _Package


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs
    from fmus_src.component import Component, ComponentError, Variable

    from .machine import Machine, MachineFileError, load_machine
    from .master import Master, MasterSettings, Probe, RunResult, simulate_system
    from .recording import Recording, RecordingError
    from .simulate import SimulationResult, simulate
    from .system import Connection, System
