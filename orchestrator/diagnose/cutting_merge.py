"""Putting the cutting half into a :class:`.core.Diagnosis`, and re-simulating a held-out cutting case."""
from __future__ import annotations

import datetime as _dt
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..case import Case
from ..recording import Recording
from .cutting import cutting_columns, prepare_cutting
from .cutting_core import CuttingResult, _fitted, _rms
from .cutting_refit import projector

if TYPE_CHECKING:
    from .core import Diagnosis


def merge_cutting(d: "Diagnosis", cres: CuttingResult, case: Case) -> None:
    """Add the cutting effects, residuals, RMS, alignment and model to ``d`` (in place)."""
    d.cutting = cres
    # diagnosis.md: "Effects are listed most certain first" across both halves (each half is ordered on its own:
    # the drives by BIC, the cutting process with chatter first); stable, so equal confidences keep that order
    d.effects = sorted(d.effects + cres.effects, key=lambda e: -float(e["confidence"]))
    d.unexplained = d.unexplained + cres.unexplained
    d.rms_before.update(cres.rms_before)
    d.rms_after.update(cres.rms_after)
    d.noise.update(cres.noise)
    d.alignment.setdefault("channels", {}).update(cres.alignment["channels"])
    d.alignment["spindle_angle_deg"] = cres.alignment["spindle_angle_deg"]
    d.log += cres.log
    d.notes += cres.notes
    source = f"diagnosed: cnctwin diagnose, {_dt.date.today().isoformat()}, from {Path(case.folder).name}"
    m = d.machine
    for section, values in cres.machine_values.items():
        m = m.with_values(section, **values)
        for key in values:
            d.provenance[f"{section}.{key}"] = source
    d.machine = m


def holdout_cutting(case: Case, recording: Recording, model: dict) -> tuple[dict[str, float], dict[str, float]]:
    """RMS of fx_N, fy_N before (machine file) and after (diagnosed model) on a held-out cutting case.

    The held-out recording is aligned on its own (spindle phase scan, dynamometer offsets), then the
    baseline and the diagnosed model are replayed; nothing is refitted.
    """
    data = prepare_cutting(case, recording)
    cols = cutting_columns(data)
    proj = projector(cols)
    final = {e: dict(p) for e, p in model.items() if e not in ("spindle_droop", "chatter", "alignment")}
    sim = data.run([{}, final])
    before = _fitted(data, cols, sim, 0, proj)
    after = _fitted(data, cols, sim, 1, proj)
    return ({"fx_N": _rms(before.rx), "fy_N": _rms(before.ry)},
            {"fx_N": _rms(after.rx), "fy_N": _rms(after.ry)})


def spindle_angle_of(cres: CuttingResult) -> np.ndarray:
    """Spindle angle of tooth 0 at each force sample (final alignment), rad."""
    from .cutting_locate import angle_of

    phase = np.radians(cres.model.get("alignment", {}).get("spindle_phase_deg", 0.0))
    return angle_of(cres.data, float(phase))
