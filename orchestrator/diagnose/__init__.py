"""Diagnosis: where a recording disagrees with the twin, which missing physics explains it, refitted.

``diagnose(case, holdout=None)`` returns a :class:`Diagnosis` whose
``to_json()`` is ``diagnosis.json`` of ``shared/spec/diagnosis.md`` and whose
``write(out)`` also writes ``machine.toml`` (the parameter set extended with
the effects), ``report.md`` and the residual-map plots. Feed drives and
controller per axis (:mod:`.core`), the cutting process from the forces and the
spindle speed (:mod:`.cutting_core`).
"""
from __future__ import annotations

from .core import Diagnosis, diagnose
from .errors import DiagnosisError
from .library import EFFECT_PARAMETERS

__all__ = ["Diagnosis", "DiagnosisError", "EFFECT_PARAMETERS", "diagnose"]
