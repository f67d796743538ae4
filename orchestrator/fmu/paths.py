"""Where :func:`orchestrator.fmu.build_fmus` writes by default (a module of its own: the CLI parser reads it
without importing pythonfmu and the components)."""
from __future__ import annotations

from pathlib import Path

#: Default output folder of :func:`orchestrator.fmu.build_fmus`: ``models/fmus`` of the repository.
DEFAULT_OUT_DIR = Path(__file__).resolve().parents[2] / "models" / "fmus"
