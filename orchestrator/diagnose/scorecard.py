"""Scorecard of the diagnosis on recordings with concealed effects (seeded, reproducible).

``python -m orchestrator.diagnose.scorecard OUT_DIR [--seeds N]`` writes a
case per scenario and seed, generates its recording with the independent
truth simulation (:mod:`.truth`) and a realistic logger, diagnoses it and
tabulates per effect: detection rate, false positives (effects other than the
hidden one), median relative parameter error and the share of the residual
power above the noise floor that the diagnosed model removes
(``(rms_before^2 - rms_after^2) / (rms_before^2 - noise^2)``, channels with
``rms_before > 1.2 noise``), into ``OUT_DIR/scorecard.json`` and
``OUT_DIR/scorecard.md``. With ``--cutting``: the cutting-process scorecard
(:mod:`.scorecard_cutting`), with ``--cutting --drives`` diagnosing the feed drives too.
"""
from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from ..atomic import atomic_write_json, atomic_write_text
from ..case import load_case
from .core import diagnose
from .prepare import twin_commands
from .truth import Recorder, record, simulate_truth

#: Z-axis strokes at three feeds with a dwell (about 3 s).
PROGRAM = """%
O0008 (diagnosis scorecard: z strokes)
N10 G90 G21 G17
N20 G01 Z35. F2500
N30 Z55. F1500
N40 G04 P100
N50 Z38. F3000
N60 Z52. F900
N70 M30
%
"""

CASE_TOML = """program = "program.nc"
recording = "recording.csv"

[machine]
parameters = "default"
"""

#: Effect scenarios (axis z) near the noise floor of the default logger (0.42 µm, 0.02 A).
SCENARIOS: dict[str, dict[str, dict[str, float]]] = {
    "gravity": {"gravity": {"force_N": 40.0}},                                  # 0.076 A, ~4 noise floors
    "backlash": {"backlash": {"width_um": 1.5}},                                # +-0.75 µm, < 2 noise floors
    "reversal_friction": {"reversal_friction": {"peak_N": 60.0, "decay_mm": 0.1}},
    "friction_mismatch": {"friction_mismatch": {"coulomb_N": 15.0}},            # 0.029 A
    "inertia_mismatch": {"inertia_mismatch": {"mass_kg": 30.0}},
    "screw_compliance": {"screw_compliance": {"stiffness_N_per_um": 600.0}},
    "pitch_error": {"pitch_error": {"amplitude_um": 0.8, "period_mm": 12.0}},
    "thermal_drift": {"thermal_drift": {"rate_um_per_min": 20.0}},
    "torque_ripple": {"torque_ripple": {"amplitude_N": 12.0, "period_mm": 6.0}},  # 0.023 A, ~1 noise floor
    "velocity_feedforward": {"velocity_feedforward": {"gain": 0.05}},
    "servo_delay": {"servo_delay": {"delay_ms": 0.3}},
}


#: Several effects at once and effects concealed under others: name -> (effects, recorder options).
COMBINATIONS: dict[str, tuple[dict[str, dict[str, float]], dict]] = {
    "gravity+friction_mismatch": ({"gravity": {"force_N": 60.0}, "friction_mismatch": {"coulomb_N": 50.0}}, {}),
    "gravity+backlash+torque_ripple": ({"gravity": {"force_N": 120.0}, "backlash": {"width_um": 3.0},
                                        "torque_ripple": {"amplitude_N": 25.0, "period_mm": 12.0}}, {}),
    "velocity_feedforward, no recorded command": ({"velocity_feedforward": {"gain": 0.2}}, {"drop": ("z_ref_mm",)}),
}


def write_case(folder: Path, effects: dict, seed: int, recorder: Recorder | None = None,
               disturbance_um: Callable[[np.ndarray], np.ndarray] | None = None,
               offset_range_s: tuple[float, float] = (0.1, 2.0), ref_filter_s: float = 0.0) -> Path:
    """A case folder with the scorecard program and a truth recording (axis z) with hidden ``effects``.

    Parameters
    ----------
    folder : Path
    effects : dict
        Hidden effects of axis z (spec vocabulary).
    seed : int
        Noise, jitter and logger-offset seed.
    recorder : Recorder, optional
        Logger settings (its ``time_offset_s`` is replaced by a seeded draw from ``offset_range_s``).
    disturbance_um : callable, optional
        ``f(t_program)`` -> extra actual z position [µm]: a phenomenon outside the effect table.
    offset_range_s : (float, float)
        Range of the seeded logger clock offset, s.
    ref_filter_s : float
        The machine's controller smooths the commands with an extra moving average of this length
        (an interpolation that differs from the twin's NC kernel), s.
    """
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(folder / "program.nc", PROGRAM)
    atomic_write_text(folder / "case.toml", CASE_TOML)
    case = load_case(folder)
    nc = twin_commands(case, case.machine)
    truth = simulate_truth(case.machine, nc, {"z": effects} if effects else {}, axes=("z",),
                           ref_filter_s=ref_filter_s)
    rec = recorder or Recorder()
    rng = np.random.default_rng(seed)
    rec = replace(rec, time_offset_s=float(rng.uniform(*offset_range_s)))
    extra = {"z": disturbance_um(truth.t)} if disturbance_um is not None else None
    record(truth, rec, seed=seed, extra_position_um=extra).write_csv(folder / "recording.csv")
    atomic_write_json(folder / "truth.json", {"axis": "z", "effects": effects, "time_offset_s": rec.time_offset_s,
                                              "seed": seed, "ref_filter_s": ref_filter_s})
    return folder


def score(out: Path, seeds: int = 3, clean_seeds: int = 10) -> dict:
    """Run the scorecard; returns the table as a dict (also written to ``out``)."""
    rows = {}
    scenarios = {"clean": ({}, {}), **{k: (v, {}) for k, v in SCENARIOS.items()}, **COMBINATIONS}
    for name, (effects, options) in scenarios.items():
        n = clean_seeds if name == "clean" else seeds
        found, false_pos, errors, closed, offsets = 0, 0, [], [], []
        for seed in range(n):
            folder = write_case(out / f"{name.replace(' ', '_').replace(',', '')}_{seed}", effects, seed,
                                Recorder(**options))
            d = diagnose(folder)
            truth = json.loads((folder / "truth.json").read_text())
            offsets.append(abs(d.alignment["time_offset_s"] - truth["time_offset_s"]))
            names = {e["effect"] for e in d.effects}
            if set(effects) <= names and (effects or not names):
                found += 1
            for e in d.effects:
                if e["effect"] in effects:
                    for k, v in effects[e["effect"]].items():
                        if v != 0.0 and k in e["parameters"] and not k.startswith("period"):
                            errors.append(abs(e["parameters"][k] - v) / abs(v))
            false_pos += len(names - set(effects))
            gap = rms_gap_closed(d, ("z_fe_um", "z_tcmd_A"))
            if gap is not None:
                closed.append(gap)
        rows[name] = {"runs": n, "detected": found / n if effects else None,
                      "false_effects_per_run": false_pos / n,
                      "median_relative_parameter_error": float(np.median(errors)) if errors else None,
                      "mean_rms_gap_closed": float(np.mean(closed)) if closed else None,
                      "max_time_offset_error_ms": float(np.max(offsets)) * 1e3}
    atomic_write_json(out / "scorecard.json", rows)
    lines = ["| scenario | runs | detection rate | false effects / run | median parameter error | RMS gap closed "
             "| max time-offset error |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for name, r in rows.items():
        det = "-" if r["detected"] is None else f"{r['detected']:.0%}"
        err = "-" if r["median_relative_parameter_error"] is None else f"{r['median_relative_parameter_error']:.1%}"
        gap = "-" if r["mean_rms_gap_closed"] is None else f"{r['mean_rms_gap_closed']:.0%}"
        lines.append(f"| {name} | {r['runs']} | {det} | {r['false_effects_per_run']:.2f} | {err} | {gap} | "
                     f"{r['max_time_offset_error_ms']:.3f} ms |")
    atomic_write_text(out / "scorecard.md", "\n".join(lines) + "\n")
    return rows


def rms_gap_closed(d, channels: tuple[str, ...]) -> float | None:
    """Mean share of the residual power above the noise floor that the diagnosis removed.

    Parameters
    ----------
    d : Diagnosis
        Its ``rms_before``, ``rms_after`` and ``noise`` per channel.
    channels : tuple of str
        Channels to score; those missing or with a residual within 1.2 x the noise floor are left out.

    Returns
    -------
    float or None
        ``mean((before**2 - after**2) / (before**2 - noise**2))``, or None when no channel had a residual.
    """
    shares = []
    for c in channels:
        if c not in d.rms_before:
            continue
        before, after, noise = d.rms_before[c], d.rms_after[c], d.noise[c]
        if before > 1.2 * noise:
            shares.append((before ** 2 - after ** 2) / (before ** 2 - noise ** 2))
    return float(np.mean(shares)) if shares else None


def main() -> None:  # pragma: no cover - a study, run by hand
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("out")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--clean-seeds", type=int, default=10)
    parser.add_argument("--cutting", action="store_true",
                        help="the cutting-process scorecard (scorecard_cutting.json/.md) instead of the drives'")
    parser.add_argument("--drives", action="store_true",
                        help="with --cutting: diagnose the feed drives too (drive effects found count as false)")
    parser.add_argument("--only", default=None,
                        help="with --cutting: comma-separated scenarios to run (e.g. chatter,clean)")
    parser.add_argument("--flutes", type=int, default=3, help="with --cutting: teeth of the 6 mm end mill")
    parser.add_argument("--force-period-ms", type=float, default=0.2,
                        help="with --cutting: dynamometer sample period, ms")
    args = parser.parse_args()
    from ..cli import emit  # the command line's one output point

    if args.cutting:
        from .scorecard_cutting import score_cutting

        only = [s.strip() for s in args.only.split(",") if s.strip()] if args.only else None
        rows = score_cutting(Path(args.out), args.seeds, args.clean_seeds, drives=args.drives, only=only,
                             flutes=args.flutes, force_period_s=args.force_period_ms * 1e-3)
    else:
        rows = score(Path(args.out), args.seeds, args.clean_seeds)
    emit(json.dumps(rows, indent=2))


if __name__ == "__main__":  # pragma: no cover
    main()
