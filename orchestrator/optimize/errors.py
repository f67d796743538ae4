"""Errors of the optimiser (all :class:`~orchestrator.errors.CncTwinError`)."""
from __future__ import annotations

from ..errors import CncTwinError


class OptimizeError(CncTwinError):
    """An optimisation cannot run or resume (bad settings, no cutting lines, checkpoint mismatch)."""
