"""Real FMUs: export every component with pythonfmu, import any FMI 2.0 or 3.0 CS FMU through fmpy.

* :func:`build_fmus` / :func:`build_fmu` — one co-simulation FMU per component.
* :class:`FMUComponent` — an FMU behind the component protocol (batch 1),
  optionally standing in for a role of the twin through a name mapping.
* :func:`check_fmu` — variables, validation, smoke run and role fit.
* :class:`FMUError` — the one exception type of all of it.
"""
from .build import COMPONENTS, DEFAULT_OUT_DIR, available_components, build_fmu, build_fmus, machine_parameters
from .check import FMUCheckReport, check_fmu
from .component import FMUComponent, load_fmu
from .errors import FMUError
from .roles import ROLES, Role, get_role

__all__ = [
    "COMPONENTS", "DEFAULT_OUT_DIR", "available_components", "build_fmu", "build_fmus", "machine_parameters",
    "FMUCheckReport", "check_fmu", "FMUComponent", "load_fmu", "FMUError", "ROLES", "Role", "get_role",
]
