"""The project's own exception hierarchy.

Every error a user can cause (bad G-code, bad files, bad FMUs, diverging
simulations) is a :class:`CncTwinError` with a message naming the file, the
line and what was expected. The CLI prints the message and exits non-zero;
it never shows a traceback for these.
"""
from __future__ import annotations

from fmus_src.errors import CncTwinError

__all__ = ["CncTwinError", "SystemDescriptionError", "SimulationError"]


class SystemDescriptionError(CncTwinError):
    """A system (components and connections) is inconsistent: unknown variable, unit mismatch, cycle."""


class SimulationError(CncTwinError):
    """A simulation could not continue (diverged, a component failed)."""
