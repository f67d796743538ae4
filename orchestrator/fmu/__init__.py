"""Real FMUs: export every component with pythonfmu, import any FMI 2.0 or 3.0 CS FMU through fmpy.

* :func:`build_fmus` / :func:`build_fmu` — one co-simulation FMU per component.
* :class:`FMUComponent` — an FMU behind the component protocol (batch 1),
  optionally standing in for a role of the twin through a name mapping.
* :func:`check_fmu` — variables, validation, smoke run and role fit.
* :class:`FMUError` — the one exception type of all of it.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from fmus_src.lazy_exports import lazy_exports

#: Public name -> submodule that defines it, imported on first access (PEP 562): the ``cnctwin`` parser
#: and ``import orchestrator.fmu.roles`` do not load fmpy, pythonfmu or the components.
_LAZY = {
    **dict.fromkeys(("COMPONENTS", "DEFAULT_OUT_DIR", "available_components", "build_fmu", "build_fmus",
                     "machine_parameters"), ".build"),
    "FMUCheckReport": ".check", "check_fmu": ".check",
    "FMUComponent": ".component", "load_fmu": ".component",
    "FMUError": ".errors",
    "ROLES": ".roles", "Role": ".roles", "get_role": ".roles",
}

__all__ = [
    "COMPONENTS", "DEFAULT_OUT_DIR", "available_components", "build_fmu", "build_fmus", "machine_parameters",
    "FMUCheckReport", "check_fmu", "FMUComponent", "load_fmu", "FMUError", "ROLES", "Role", "get_role",
]


#: Imports a public name on first access (PEP 562); submodules import as usual.
__getattr__, __dir__ = lazy_exports(__name__, _LAZY, globals(), __all__)


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs
    from .build import COMPONENTS, DEFAULT_OUT_DIR, available_components, build_fmu, build_fmus, machine_parameters
    from .check import FMUCheckReport, check_fmu
    from .component import FMUComponent, load_fmu
    from .errors import FMUError
    from .roles import ROLES, Role, get_role
