"""Scorecard of the cutting diagnosis on recordings with concealed cutting effects (seeded, reproducible).

``python -m orchestrator.diagnose.scorecard OUT_DIR --cutting [--seeds N] [--clean-seeds M] [--flutes F]
[--force-period-ms P]`` writes a case per scenario and seed with :func:`.cutting_case.write_cutting_case`
(the short program: two slots at 1 and 2 mm and a 1 mm side pass 3 mm deep, 6 mm end mill with 3 flutes
or ``F``, dynamometer at 5 kHz or every ``P`` ms, about 2.4 s of cutting), diagnoses its
cutting process (``drives=False``; with ``--drives`` the feed drives too, as ``diagnose`` does by
default, and any drive effect found counts as false: the recordings hide none) and tabulates per
scenario: detection rate (every hidden effect found), false effects per run, median relative parameter
error, and the share of the residual power above the noise floor that the diagnosed model removes on
``fx_N``, ``fy_N`` (and ``spindle_rpm``), into ``OUT_DIR/scorecard_cutting.json`` and ``.md``.

Parameter errors: runout by its eccentricity and by the direction of the eccentricity in the spindle
frame (``spindle_angle_deg + phase_deg`` against the truth's, which does not depend on which tooth is
called tooth 0), chatter by the frequency against the tool mode's natural frequency. A 2-flute tool's
forces see only the runout's projection on the line of its teeth (:func:`observable_runout`): it is
scored against that.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ..atomic import atomic_write_json, atomic_write_text
from .core import diagnose
from .cutting_case import CASE_TOML, SHORT_PROGRAM, write_cutting_case
from .errors import DiagnosisError
from .scorecard import rms_gap_closed
from .truth_cutting import Dynamometer

#: Cutting scenarios near the detection limit of a 2.4 s recording with 1 N dynamometer noise.
CUTTING_SCENARIOS: dict[str, dict[str, dict[str, float]]] = {
    "runout": {"runout": {"eccentricity_um": 3.0, "phase_deg": 40.0}},
    "helix_angle": {"helix_angle": {"helix_deg": 30.0}},
    "edge_force": {"edge_force": {"kte_N_per_mm": 8.0, "kre_N_per_mm": 5.0}},
    "tool_deflection": {"tool_deflection": {"stiffness_N_per_um": 10.0}},
    "tool_wear": {"tool_wear": {"rate_percent_per_min": 200.0}},
    "spindle_droop": {"spindle_droop": {"rpm_per_Nm": 30.0}},
    "chatter": {"chatter": {"frequency_Hz": 1150.0, "damping_ratio": 0.03, "stiffness_N_per_um": 30.0}},
    "edge_force + tool_wear": {"edge_force": {"kte_N_per_mm": 8.0, "kre_N_per_mm": 5.0},
                               "tool_wear": {"rate_percent_per_min": 200.0}},
    "runout + tool_deflection": {"runout": {"eccentricity_um": 3.0, "phase_deg": 40.0},
                                 "tool_deflection": {"stiffness_N_per_um": 10.0}},
}

#: Reported parameters compared with the truth (spec names).
COMPARED = {"runout": ("eccentricity_um",), "helix_angle": ("helix_deg",),
            "edge_force": ("kte_N_per_mm", "kre_N_per_mm"), "tool_deflection": ("stiffness_N_per_um",),
            "tool_wear": ("rate_percent_per_min",), "spindle_droop": ("rpm_per_Nm",), "chatter": ("frequency_Hz",)}


def observable_runout(runout: dict[str, float], flutes: int) -> dict[str, float]:
    """The part of a runout (spec units) that a ``flutes``-tooth tool's forces can show.

    Two teeth half a turn apart stand out by ``+-rho cos(lambda)``: only the eccentricity's projection on
    the line of the teeth changes the chips, so a 2-flute tool shows ``rho |cos(lambda)|`` at phase 0
    (180 deg when ``cos(lambda) < 0``). Three or more teeth show all of it.
    """
    if flutes != 2:
        return dict(runout)
    c = math.cos(math.radians(runout["phase_deg"]))
    return {"eccentricity_um": runout["eccentricity_um"] * abs(c), "phase_deg": 0.0 if c >= 0.0 else 180.0}


def parameter_errors(found: dict, truth_effects: dict, spindle_deg: float, truth_angle_deg: float,
                     flutes: int = 3) -> list[float]:
    """Relative parameter errors of the found effects against the hidden ones (runout phase as an angle / 360)."""
    errors = []
    if "runout" in truth_effects:
        truth_effects = {**truth_effects, "runout": observable_runout(truth_effects["runout"], flutes)}
    for e in found:
        name = e["effect"]
        if name not in truth_effects:
            continue
        for k in COMPARED[name]:
            v = truth_effects[name][k]
            errors.append(abs(e["parameters"][k] - v) / abs(v))
        if name == "runout":
            diff = (spindle_deg + e["parameters"]["phase_deg"]) - (truth_angle_deg + truth_effects[name]["phase_deg"])
            errors.append(abs((diff + 180.0) % 360.0 - 180.0) / 360.0)
    return errors


def score_cutting(out: Path, seeds: int = 3, clean_seeds: int = 10, drives: bool = False,
                  only: Sequence[str] | None = None, flutes: int = 3, force_period_s: float = 0.2e-3) -> dict:
    """Run the cutting scorecard; returns the table as a dict (also written to ``out``).

    Parameters
    ----------
    out : Path
        Folder of the cases and the tables.
    seeds, clean_seeds : int
        Runs per effect scenario and of the clean scenario.
    drives : bool
        Diagnose the feed drives as well (the recordings hide no drive effect: any found is false).
    only : sequence of str, optional
        Run only these scenarios (names or their folder slugs, e.g. ``("chatter", "clean")``).
    flutes : int
        Teeth of the 6 mm end mill (the paper's is a 2-flute).
    force_period_s : float
        Dynamometer sample period, s (instantaneous samples).

    Raises
    ------
    DiagnosisError
        An ``only`` entry that names no scenario, or fewer than 2 flutes.
    """
    if int(flutes) != flutes or flutes < 2:
        raise DiagnosisError(f"scorecard flutes: {flutes!r}; expected a whole number of teeth >= 2")
    if not force_period_s > 0.0:
        raise DiagnosisError(f"scorecard force_period_s: {force_period_s!r}; expected a positive period in s")
    case_toml = CASE_TOML.replace("flutes = 3", f"flutes = {int(flutes)}")
    rows = {}
    scenarios = {"clean": {}, **CUTTING_SCENARIOS, "50 Hz hum (outside the table)": {}}
    if only:
        wanted = set(only)
        unknown = wanted - set(scenarios) - {_slug(n) for n in scenarios}
        if unknown:
            raise DiagnosisError(f"scorecard --only: unknown scenario(s) {sorted(unknown)}; expected names or slugs "
                                 f"of {sorted(_slug(n) for n in scenarios)}")
        scenarios = {n: e for n, e in scenarios.items() if n in wanted or _slug(n) in wanted}
    for name, effects in scenarios.items():
        n = clean_seeds if name == "clean" else seeds
        found_all, false_pos, errors, closed, unexplained, modes = 0, 0, [], [], 0, []
        for seed in range(n):
            hum = 5.0 if "hum" in name else 0.0
            folder = write_cutting_case(out / f"{_slug(name)}_{seed}", effects, seed + 100, program=SHORT_PROGRAM,
                                        dynamometer=Dynamometer(period_s=force_period_s, hum_N=hum),
                                        case_toml=case_toml)
            d = diagnose(folder, drives=drives)
            truth = json.loads((folder / "truth.json").read_text())
            names = {e["effect"] for e in d.effects}
            if set(effects) <= names and (effects or not names):
                found_all += 1
            false_pos += len(names - set(effects))
            unexplained += bool(d.unexplained)
            errors += parameter_errors(d.effects, effects, d.alignment.get("spindle_angle_deg", 0.0),
                                       math.degrees(truth["spindle_angle_at_first_force_sample_rad"]), int(flutes))
            fit = d.cutting.chatter_fit if d.cutting is not None else None
            if fit is not None:
                modes.append({"damping_ratio": fit.damping_ratio, "stiffness_N_per_um": fit.stiffness_N_per_um,
                              "natural_frequency_Hz": fit.natural_frequency_Hz, "growth_per_s": fit.growth_per_s,
                              "growth_twin_per_s": fit.growth_twin_per_s, "amplitude_N": fit.amplitude_N,
                              "amplitude_twin_N": fit.amplitude_twin_N, "band_power_ratio": fit.band_power_ratio})
            gap = rms_gap_closed(d, ("fx_N", "fy_N", "spindle_rpm"))
            if gap is not None:
                closed.append(gap)
        rows[name] = {"runs": n, "detected": found_all / n if effects else None,
                      "false_effects_per_run": false_pos / n, "runs_with_unexplained": unexplained / n,
                      "median_relative_parameter_error": float(np.median(errors)) if errors else None,
                      "mean_rms_gap_closed": float(np.mean(closed)) if closed else None}
        if modes:
            rows[name]["chatter_modes"] = modes
    atomic_write_json(out / "scorecard_cutting.json", rows)
    lines = ["| scenario | runs | detection | false effects/run | median param. error | RMS gap closed "
             "| runs with unexplained |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for name, r in rows.items():
        det = "–" if r["detected"] is None else f"{r['detected']:.0%}"
        err = "–" if r["median_relative_parameter_error"] is None else f"{r['median_relative_parameter_error']:.1%}"
        gap = "–" if r["mean_rms_gap_closed"] is None else f"{r['mean_rms_gap_closed']:.0%}"
        lines.append(f"| {name} | {r['runs']} | {det} | {r['false_effects_per_run']:.2f} | {err} | {gap} | "
                     f"{r['runs_with_unexplained']:.0%} |")
    atomic_write_text(out / "scorecard_cutting.md", "\n".join(lines) + "\n")
    return rows


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name).strip("_")
