"""Root of the project's exception hierarchy (dependency-free, shipped inside FMUs)."""
from __future__ import annotations


class CncTwinError(Exception):
    """Base class of all errors the project reports to users.

    The message names the file, the line and what was expected; the CLI
    prints it and exits non-zero without a traceback.
    """
