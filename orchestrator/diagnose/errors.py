"""Errors of the diagnosis."""
from __future__ import annotations

from ..errors import CncTwinError


class DiagnosisError(CncTwinError):
    """A case cannot be diagnosed (missing channels, no moving axis, malformed input)."""
