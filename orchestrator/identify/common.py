"""Shared helpers of the identifiers: provenance text, fitted machine files, reports."""
from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import Any, Mapping

from ..atomic import atomic_write_json, atomic_write_text
from ..machine import Machine, machine_to_toml


def provenance(method: str, cases: list[str]) -> str:
    """``"identified: <method>, <date>, from <case>[, <case>...]"``."""
    return f"identified: {method}, {_dt.date.today().isoformat()}, from {', '.join(cases)}"


def fitted_machine(base: Machine, updates: Mapping[str, Mapping[str, float]], source: str,
                   name_suffix: str) -> tuple[Machine, dict[str, str]]:
    """A copy of ``base`` with ``updates`` (section -> {key with unit suffix: value}) and their provenance.

    Returns
    -------
    machine : Machine
    extra_provenance : dict
        Dotted key -> ``source`` for every updated key (pass to ``machine_to_toml``).
    """
    machine = base
    extra: dict[str, str] = {}
    for section, values in updates.items():
        machine = machine.with_values(section, **{k: float(v) for k, v in values.items()})
        for key in values:
            extra[f"{section}.{key}"] = source
    machine = machine.with_values("machine", name=f"{base.name}-{name_suffix}")
    return machine, extra


def write_outputs(out: str | Path, machine: Machine, extra_provenance: dict[str, str],
                  report: dict[str, Any]) -> dict[str, Path]:
    """Write ``machine.toml`` and ``report.json`` into ``out`` (atomically)."""
    out = Path(out)
    files = {
        "machine": atomic_write_text(out / "machine.toml", machine_to_toml(machine, extra_provenance)),
        "report": atomic_write_json(out / "report.json", report),
    }
    return files
