"""Scorecard of a cutting part whose drives feel the cutting force, with drive and cutting effects at once.

``python -m orchestrator.diagnose.scorecard_part OUT_DIR [--seeds N] [--only ...] [--loggers ...]`` writes a
case per scenario, logger and seed with :func:`.cutting_case.write_cutting_case` (the independent truth servo
of :mod:`.truth` loaded by the independent truth forces of :mod:`.truth_cutting`) on :data:`PART_PROGRAM`: two
slots in x at 1 and 2 mm depth and a contour with an arc around a corner of the stock (1 mm radial, 2 mm
deep), 6 mm 2-flute end mill at 6000 rpm in A6061, plunges and rapids on z. Hidden: drive effects on one or
two axes, cutting effects, or both (:data:`SCENARIOS`). Loggers (:data:`LOGGERS`): one 1 ms logger with
everything (positions, currents, commands, ``line``, forces and spindle speed on the same rows), a 2 ms one
with forces but without commands, the forces alone (a dynamometer file, 1 ms) and the servo channels alone
(1 ms, no forces). It diagnoses each (drives and cutting) and tabulates detection, false effects and
parameter errors as the other scorecards do, into ``OUT_DIR/scorecard_part.json`` and ``.md``.

Counting: a run detects when every hidden effect that its logger can show is named (drive effects on
their axis; cutting effects need forces, drive effects need positions and currents); any other (effect,
axis) named is false. Parameter errors as :func:`.scorecard_contour.judge` (drives) and
:func:`.scorecard_cutting.parameter_errors` (cutting; a 2-flute runout against what it shows).
"""
from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..atomic import atomic_write_json, atomic_write_text
from ..recording import Recording
from .core import diagnose
from .cutting_case import write_cutting_case
from .errors import DiagnosisError
from .scorecard_contour import score_row
from .scorecard_cutting import parameter_errors
from .truth import Recorder
from .truth_cutting import Dynamometer

#: Two slots in x (1 and 2 mm deep) and a contour around the stock's front-left corner (1 mm radial, 2 mm
#: deep, climb milling: up the left side, an arc, along the back), as the paper part in small (about 3 s of
#: cutting, 7 s in all).
PART_PROGRAM = """%
O0010 (DIAGNOSIS: CUTTING PART - TWO SLOTS AND A CONTOUR)
N10 G21 G17 G90 G94
N20 S6000 M3
N30 G0 X-4. Y3.5 Z1.
N40 G1 Z-1. F1000
N50 X4. F600 (FULL SLOT 1 MM DEEP)
N60 G0 Z1.
N70 X-4. Y10.
N80 G1 Z-2. F1000
N90 X4. F450 (FULL SLOT 2 MM DEEP)
N100 G0 Z1.
N110 X-2. Y-4.
N120 G1 Z-2. F1000
N130 Y12. F900 (CONTOUR 1 MM RADIAL 2 MM DEEP)
N140 G2 X2. Y16. R4.
N150 G1 X8.
N160 G0 Z5.
N170 M30
%
"""

#: The case manifest: a 16 x 14 x 6 mm block, the paper's 6 mm 2-flute end mill.
PART_CASE_TOML = """program = "program.nc"
recording = "recording.csv"

[stock]
min = [0.0, 0.0, -6.0]
max = [16.0, 14.0, 0.0]

[tool]
diameter_mm = 6.0
flutes = 2

[machine]
parameters = "default"
"""

#: The same kinds of cut, shorter (for the tests): one slot 2 mm deep and the contour around the corner of
#: a 10 x 8 mm block (about 1.7 s of cutting, 5 s in all).
SHORT_PART_PROGRAM = """%
O0011 (DIAGNOSIS: SHORT CUTTING PART - A SLOT AND A CONTOUR)
N10 G21 G17 G90 G94
N20 S6000 M3
N30 G0 X-4. Y4. Z1.
N40 G1 Z-2. F1000
N50 X3. F450 (FULL SLOT 2 MM DEEP)
N60 G0 Z1.
N70 X-2. Y-4.
N80 G1 Z-2. F1000
N90 Y6. F900 (CONTOUR 1 MM RADIAL 2 MM DEEP)
N100 G2 X2. Y10. R4.
N110 G1 X6.
N120 G0 Z5.
N130 M30
%
"""

#: The short part's manifest: a 10 x 8 x 6 mm block.
SHORT_PART_CASE_TOML = PART_CASE_TOML.replace("max = [16.0, 14.0, 0.0]", "max = [10.0, 8.0, 0.0]")

FLUTES = 2


@dataclass(frozen=True)
class Logger:
    """One way of logging the part.

    Attributes
    ----------
    period_s : float
        Sample period of the CNC logger (and of the forces when they share its rows), s.
    keep : tuple of str or None
        Channels written (besides ``t_s``); None: every channel of the truth loggers.
    drop : tuple of str
        Channels the CNC logger does not record.
    shared_rows : bool
        Forces on the CNC logger's rows (one logger) instead of the dynamometer's own.
    drives, cutting : bool
        Whether drive effects (positions and currents) and cutting effects (forces) can show.
    """

    period_s: float
    keep: tuple[str, ...] | None = None
    drop: tuple[str, ...] = ()
    shared_rows: bool = True
    drives: bool = True
    cutting: bool = True


_COMMANDS = ("x_ref_mm", "y_ref_mm", "z_ref_mm")
_SERVO = ("line", *_COMMANDS, "x_mm", "y_mm", "z_mm", "x_tcmd_A", "y_tcmd_A", "z_tcmd_A")

#: The loggers of the study.
LOGGERS: dict[str, Logger] = {
    "1 ms, everything": Logger(1e-3),
    "2 ms, forces, no commands": Logger(2e-3, drop=_COMMANDS),
    "forces only": Logger(1e-3, keep=("fx_N", "fy_N", "fc_N"), shared_rows=False, drives=False),
    "currents only": Logger(1e-3, keep=_SERVO, cutting=False),
}

#: Scenario -> (drive effects per axis, cutting effects), each a few noise floors on this part.
SCENARIOS: dict[str, tuple[dict[str, dict[str, dict[str, float]]], dict[str, dict[str, float]]]] = {
    "clean": ({}, {}),
    "gravity z": ({"z": {"gravity": {"force_N": 40.0}}}, {}),
    "friction_mismatch x": ({"x": {"friction_mismatch": {"coulomb_N": 30.0}}}, {}),
    "backlash y": ({"y": {"backlash": {"width_um": 3.0}}}, {}),
    "inertia_mismatch x": ({"x": {"inertia_mismatch": {"mass_kg": 60.0}}}, {}),
    "servo_delay y": ({"y": {"servo_delay": {"delay_ms": 0.3}}}, {}),
    "velocity_feedforward x": ({"x": {"velocity_feedforward": {"gain": 0.05}}}, {}),
    "runout": ({}, {"runout": {"eccentricity_um": 3.0, "phase_deg": 40.0}}),
    "edge_force": ({}, {"edge_force": {"kte_N_per_mm": 8.0, "kre_N_per_mm": 5.0}}),
    "tool_wear": ({}, {"tool_wear": {"rate_percent_per_min": 200.0}}),
    "gravity z + runout": ({"z": {"gravity": {"force_N": 40.0}}},
                           {"runout": {"eccentricity_um": 3.0, "phase_deg": 40.0}}),
    "friction_mismatch x + edge_force": ({"x": {"friction_mismatch": {"coulomb_N": 30.0}}},
                                         {"edge_force": {"kte_N_per_mm": 8.0, "kre_N_per_mm": 5.0}}),
    "backlash y + tool_wear": ({"y": {"backlash": {"width_um": 3.0}}},
                               {"tool_wear": {"rate_percent_per_min": 200.0}}),
    "friction_mismatch x + servo_delay y": ({"x": {"friction_mismatch": {"coulomb_N": 30.0}},
                                             "y": {"servo_delay": {"delay_ms": 0.3}}}, {}),
}


def write_part_case(folder: Path, drive_effects: Mapping, cutting_effects: Mapping, seed: int,
                    logger: Logger, program: str = PART_PROGRAM, case_toml: str = PART_CASE_TOML) -> Path:
    """A case folder of :data:`PART_PROGRAM` with hidden effects, logged by ``logger``.

    Parameters
    ----------
    folder : Path
    drive_effects : mapping axis -> {effect: {parameter: value}}
        Hidden feed-drive effects (spec vocabulary).
    cutting_effects : mapping effect -> {parameter: value}
        Hidden cutting effects (spec vocabulary).
    seed : int
        Noise, jitter (5 % of the period), clock offset (0.1 to 2 s) and initial spindle angle.
    logger : Logger
    program, case_toml : str
        The part (:data:`PART_PROGRAM`, or :data:`SHORT_PART_PROGRAM` with :data:`SHORT_PART_CASE_TOML`).

    Returns
    -------
    Path
        ``folder``, with ``truth.json`` (see :func:`.cutting_case.write_cutting_case`).
    """
    rec = Recorder(period_s=logger.period_s, jitter_s=0.05 * logger.period_s, drop=tuple(logger.drop))
    write_cutting_case(folder, cutting_effects, seed, drive_effects=drive_effects,
                       dynamometer=Dynamometer(period_s=logger.period_s), recorder=rec, program=program,
                       case_toml=case_toml, forces_on_cnc_rows=logger.shared_rows)
    if logger.keep is not None:
        keep_channels(folder / "recording.csv", logger.keep)
    return folder


def keep_channels(path: Path, keep: Sequence[str]) -> None:
    """Rewrite a recording with only ``t_s`` and the channels ``keep``, dropping rows left empty."""
    rec = Recording.read_csv(path)
    names = [c for c in keep if c in rec.channels]
    values = np.column_stack([np.asarray(rec[c], float) for c in names])
    rows = np.flatnonzero(np.any(np.isfinite(values), axis=1))
    channels = {"t_s": np.asarray(rec.t, float)[rows], **{c: values[rows, i] for i, c in enumerate(names)}}
    Recording.from_channels(channels, source=str(path)).write_csv(path)


def judge_part(d, drive_effects: Mapping, cutting_effects: Mapping, logger: Logger, truth: Mapping) -> dict:
    """Detection, false effects and relative parameter errors of one diagnosis of a part case.

    Parameters
    ----------
    d : Diagnosis
    drive_effects, cutting_effects : mapping
        The hidden truth.
    logger : Logger
        Which hidden effects the recording can show at all.
    truth : mapping
        The case's ``truth.json`` (spindle angle of the first force sample).

    Returns
    -------
    dict
        ``found`` (every effect the logger can show was named), ``false`` (other named (effect, axis)),
        ``errors`` (relative parameter errors; runout's direction as an angle / 360), ``missed``.
    """
    hidden = {(name, axis) for axis, effects in drive_effects.items() for name in effects}
    hidden |= {(name, None) for name in cutting_effects}
    visible = {(n, a) for n, a in hidden if (logger.drives if a is not None else logger.cutting)}
    named = {(e["effect"], e.get("axis")) for e in d.effects}
    errors = []
    for e in d.effects:
        axis = e.get("axis")
        if axis is not None and e["effect"] in drive_effects.get(axis, {}):
            for k, v in drive_effects[axis][e["effect"]].items():
                if v != 0.0 and k in e["parameters"] and not k.startswith("period"):
                    errors.append(abs(e["parameters"][k] - v) / abs(v))
    errors += parameter_errors([e for e in d.effects if e.get("axis") is None], dict(cutting_effects),
                               d.alignment.get("spindle_angle_deg", 0.0),
                               math.degrees(truth["spindle_angle_at_first_force_sample_rad"]), FLUTES)
    return {"found": visible <= named, "missed": sorted(_label(k) for k in visible - named),
            "false": sorted(_label(k) for k in named - hidden), "errors": errors}


def _label(key: tuple[str, str | None]) -> str:
    return key[0] if key[1] is None else f"{key[0]} {key[1]}"


def score_part(out: Path, seeds: int = 1, only: Sequence[str] | None = None,
               loggers: Sequence[str] | None = None) -> dict:
    """Run the study; returns ``{"runs": [...], "by_scenario": {...}, "by_logger": {...}}`` (also written).

    Raises
    ------
    DiagnosisError
        An ``only`` or ``loggers`` entry that names nothing of the study.
    """
    names = _pick(only, SCENARIOS, "--only")
    logger_names = _pick(loggers, LOGGERS, "--loggers")
    runs = []
    for name in names:
        drive_effects, cutting_effects = SCENARIOS[name]
        for j, lname in enumerate(logger_names):
            logger = LOGGERS[lname]
            for k in range(seeds):
                seed = 100 * k + 10 * list(LOGGERS).index(lname) + 1
                folder = out / f"{_slug(name)}__{_slug(lname)}__{seed}"
                write_part_case(folder, drive_effects, cutting_effects, seed, logger)
                truth = json.loads((folder / "truth.json").read_text())
                entry = {"scenario": name, "logger": lname, "seed": seed}
                try:
                    d = diagnose(folder)
                except Exception as exc:  # a study: a failure is a finding, tabulated with its message
                    runs.append({**entry, "error": f"{type(exc).__name__}: {exc}"})
                    continue
                j_ = judge_part(d, drive_effects, cutting_effects, logger, truth)
                runs.append({**entry, **j_, "effects": [[e["effect"], e.get("axis"), e["parameters"]]
                                                         for e in d.effects],
                             "unexplained": [u["channels"] for u in d.unexplained],
                             "offset_error_ms": 1e3 * (d.alignment["time_offset_s"] - truth["time_offset_s"])})
                atomic_write_json(out / "scorecard_part_runs.json", runs)
    table = {"runs": runs, "by_scenario": _summary(runs, "scenario"), "by_logger": _summary(runs, "logger")}
    atomic_write_json(out / "scorecard_part.json", table)
    atomic_write_text(out / "scorecard_part.md", _markdown(table))
    return table


def _pick(wanted: Sequence[str] | None, known: Mapping, option: str) -> list[str]:
    if not wanted:
        return list(known)
    by_slug = {_slug(n): n for n in known}
    unknown = [w for w in wanted if w not in known and _slug(w) not in by_slug]
    if unknown:
        raise DiagnosisError(f"scorecard_part {option}: unknown {unknown}; expected one of {sorted(known)}")
    return [w if w in known else by_slug[_slug(w)] for w in wanted]


def _summary(runs: list[dict], key: str) -> dict:
    groups: dict[str, list[dict]] = {}
    for r in runs:
        groups.setdefault(r[key], []).append(r)
    rows = {}
    for name, rs in groups.items():
        ok = [r for r in rs if "error" not in r]
        scored = [r for r in ok if SCENARIOS[r["scenario"]] != ({}, {})
                  and (LOGGERS[r["logger"]].drives or SCENARIOS[r["scenario"]][1])
                  and (LOGGERS[r["logger"]].cutting or SCENARIOS[r["scenario"]][0])]
        rows[name] = {**score_row(rs, ok, scored),
                      "runs_with_unexplained": (sum(bool(r["unexplained"]) for r in ok) / len(ok)) if ok else None}
    return rows


def _markdown(table: dict) -> str:
    lines = []
    for title, rows in (("scenario", table["by_scenario"]), ("logger", table["by_logger"])):
        lines += [f"| {title} | runs | detection | false effects/run | median param. error | runs with unexplained |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for name, r in rows.items():
            det = "–" if r["detected"] is None else f"{r['detected']:.0%}"
            fp = "–" if r["false_effects_per_run"] is None else f"{r['false_effects_per_run']:.2f}"
            err = ("–" if r["median_relative_parameter_error"] is None
                   else f"{r['median_relative_parameter_error']:.1%}")
            un = "–" if r["runs_with_unexplained"] is None else f"{r['runs_with_unexplained']:.0%}"
            failed = f" ({r['failed']} failed)" if r["failed"] else ""
            lines.append(f"| {name} | {r['runs']}{failed} | {det} | {fp} | {err} | {un} |")
        lines.append("")
    lines += ["| run | found | missed | false effects | offset error |", "| --- | --- | --- | --- | --- |"]
    for r in table["runs"]:
        label = f"{r['scenario']}, {r['logger']}, seed {r['seed']}"
        if "error" in r:
            lines.append(f"| {label} | error | {r['error'][:120]} | – | – |")
        else:
            lines.append(f"| {label} | {r['found']} | {', '.join(r['missed']) or '–'} | "
                         f"{', '.join(r['false']) or '–'} | {r['offset_error_ms']:.3f} ms |")
    return "\n".join(lines) + "\n"


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() else "_" for c in name).strip("_")


def main() -> None:  # pragma: no cover - a study, run by hand
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("out")
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--only", default=None, help="comma-separated scenarios (names or slugs)")
    parser.add_argument("--loggers", default=None, help="comma-separated loggers (names or slugs)")
    args = parser.parse_args()
    from ..cli import emit

    only = [s.strip() for s in args.only.split(",") if s.strip()] if args.only else None
    loggers = [s.strip() for s in args.loggers.split(",") if s.strip()] if args.loggers else None
    table = score_part(Path(args.out), args.seeds, only, loggers)
    emit(json.dumps({"by_scenario": table["by_scenario"], "by_logger": table["by_logger"]}, indent=2))


if __name__ == "__main__":  # pragma: no cover
    main()
