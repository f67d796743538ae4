"""Scorecard on cases unlike the Z strokes: X and Y effects on an XY contour, loggers of 1 to 8 ms (seeded).

``python -m orchestrator.diagnose.scorecard_contour OUT_DIR [--seeds N] [--periods 1,2,4,8]`` writes a case per
hidden effect, logger and seed: an air-cut XY contour with arcs, reversals on X and Y and a Z move (about
5 s after the rapid from the reference position; no stock, so no forces and no spindle channel), recorded by
the independent truth simulation (:mod:`.truth`) with the hidden effect on X or Y, and logged at each sample
period with the channels a user may have: commands and ``line``, ``line`` only, commands only, or neither (a
Servo Guide log). Every logger of a scenario has its own seed: noise, jitter (5 % of the period) and clock
offset (0.1 to 2 s); a 1 µm encoder, 0.3 µm / 0.02 A noise, 0.01 A current resolution. It diagnoses each and
tabulates detection, false effects and the parameter error per effect and per logger, into
``OUT_DIR/scorecard_contour.json`` and ``.md``.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from ..atomic import atomic_write_json, atomic_write_text
from ..case import load_case
from ..recording import Recording
from .core import diagnose
from .prepare import twin_commands
from .truth import Recorder, record, simulate_truth

#: An XY contour in the air: arcs both ways, reversals on X and Y at several feeds, a rapid and a Z move.
PROGRAM = """%
O0009 (diagnosis scorecard: xy contour with arcs and reversals, in the air)
N10 G90 G21 G17 G94
N20 G0 X0 Y0 Z5.
N30 G1 X30. F2000
N40 G3 X40. Y10. R10.
N50 G1 Y25. F1500
N60 G3 X30. Y35. R10.
N70 G1 X5. F2500
N80 G3 X-5. Y25. R10.
N90 G1 Y10. F1200
N100 Y22. F3000
N110 X15. F900
N120 X2. F1800
N130 G2 X12. Y12. R10. F1500
N140 G1 X20. Y5. Z2. F1000
N150 G0 X0 Y0 Z5.
N160 M30
%
"""

CASE_TOML = """program = "program.nc"
recording = "recording.csv"

[machine]
parameters = "default"
"""

#: Hidden effect -> (axis, parameters): a few noise floors each on the default machine and logger.
SCENARIOS: dict[str, tuple[str, dict[str, dict[str, float]]]] = {
    "clean": ("x", {}),
    "backlash x": ("x", {"backlash": {"width_um": 3.0}}),
    "reversal_friction y": ("y", {"reversal_friction": {"peak_N": 80.0, "decay_mm": 0.1}}),
    "friction_mismatch x": ("x", {"friction_mismatch": {"coulomb_N": 30.0}}),
    "inertia_mismatch y": ("y", {"inertia_mismatch": {"mass_kg": 60.0}}),
    "screw_compliance x": ("x", {"screw_compliance": {"stiffness_N_per_um": 300.0}}),
    "pitch_error y": ("y", {"pitch_error": {"amplitude_um": 1.5, "period_mm": 12.0}}),
    "thermal_drift x": ("x", {"thermal_drift": {"rate_um_per_min": 60.0}}),
    "torque_ripple y": ("y", {"torque_ripple": {"amplitude_N": 25.0, "period_mm": 6.0}}),
    "velocity_feedforward x": ("x", {"velocity_feedforward": {"gain": 0.05}}),
    "servo_delay y": ("y", {"servo_delay": {"delay_ms": 0.3}}),
}

#: Logger channel sets: name -> channels dropped from the truth recording.
CHANNELS: dict[str, tuple[str, ...]] = {
    "commands + line": (),
    "line only": ("x_ref_mm", "y_ref_mm", "z_ref_mm"),
    "commands only": ("line",),
    "servo guide": ("line", "x_ref_mm", "y_ref_mm", "z_ref_mm"),
}


def write_contour_case(folder: Path, axis: str, effects: dict, seed: int, period_s: float,
                       drop: tuple[str, ...] = (), offset_range_s: tuple[float, float] = (0.1, 2.0),
                       nc: Recording | None = None) -> Path:
    """A case folder with the contour program and a truth recording with ``effects`` hidden on ``axis``.

    Parameters
    ----------
    folder : Path
    axis : str
        ``"x"``, ``"y"`` or ``"z"``: the axis that carries the hidden effects.
    effects : dict
        Hidden effects (spec vocabulary), e.g. ``{"backlash": {"width_um": 3.0}}``.
    seed : int
        Noise, jitter and logger-offset seed.
    period_s : float
        Logger sample period, s (jitter 5 % of it).
    drop : tuple of str
        Channels the logger does not record.
    offset_range_s : (float, float)
        Range of the seeded logger clock offset, s.
    nc : Recording, optional
        The twin's run of :data:`PROGRAM` on the default machine (:func:`.prepare.twin_commands`), when
        already at hand: the controller's commands of the truth.
    """
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(folder / "program.nc", PROGRAM)
    atomic_write_text(folder / "case.toml", CASE_TOML)
    case = load_case(folder)
    nc = nc if nc is not None else twin_commands(case, case.machine)
    truth = simulate_truth(case.machine, nc, {axis: effects} if effects else {})
    rng = np.random.default_rng(seed)
    rec = Recorder(period_s=period_s, jitter_s=0.05 * period_s, time_offset_s=float(rng.uniform(*offset_range_s)),
                   drop=tuple(drop))
    record(truth, rec, seed=seed).write_csv(folder / "recording.csv")
    atomic_write_json(folder / "truth.json", {"axis": axis, "effects": effects, "time_offset_s": rec.time_offset_s,
                                              "seed": seed, "period_s": period_s, "drop": list(drop)})
    return folder


def judge(d, axis: str, effects: dict) -> dict:
    """Detection, false effects and relative parameter errors of one diagnosis against its hidden truth.

    An effect counts as found when its name and axis match; any other (effect, axis) is false. Parameters
    that are zero in the truth and periods (searched at lead / n only) are not scored.
    """
    named = {(e["effect"], e.get("axis")) for e in d.effects}
    hidden = {(name, axis) for name in effects}
    errors = []
    for e in d.effects:
        if (e["effect"], e.get("axis")) in hidden:
            for k, v in effects[e["effect"]].items():
                if v != 0.0 and k in e["parameters"] and not k.startswith("period"):
                    errors.append(abs(e["parameters"][k] - v) / abs(v))
    return {"found": hidden <= named, "false": sorted(f"{n} {a}" for n, a in named - hidden), "errors": errors}


def score_contour(out: Path, seeds: int = 1, periods_ms: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0),
                  scenarios: list[str] | None = None, channels: list[str] | None = None) -> dict:
    """Run the study; returns ``{"runs": [...], "by_effect": {...}, "by_logger": {...}}`` (also written)."""
    runs = []
    program = out / "program"
    program.mkdir(parents=True, exist_ok=True)
    atomic_write_text(program / "program.nc", PROGRAM)
    atomic_write_text(program / "case.toml", CASE_TOML)
    case = load_case(program)
    nc = twin_commands(case, case.machine)
    for name in scenarios or list(SCENARIOS):
        axis, effects = SCENARIOS[name]
        for c, chan in enumerate(channels or list(CHANNELS)):
            for p, period in enumerate(periods_ms):
                for k in range(seeds):
                    # every logger of a scenario its own noise, jitter and clock offset
                    seed = 100 * k + 10 * c + p
                    tag = f"{name}_{chan}_{period:g}ms_{seed}".replace(" ", "_").replace("+", "and")
                    folder = write_contour_case(out / tag, axis, effects, seed, period * 1e-3, CHANNELS[chan],
                                                nc=nc)
                    truth = json.loads((folder / "truth.json").read_text())
                    try:
                        d = diagnose(folder)
                    except Exception as exc:  # a study: a failure is a finding, tabulated with its message
                        runs.append({"scenario": name, "channels": chan, "period_ms": period, "seed": seed,
                                     "error": f"{type(exc).__name__}: {exc}"})
                        continue
                    j = judge(d, axis, effects)
                    runs.append({"scenario": name, "channels": chan, "period_ms": period, "seed": seed,
                                 "found": j["found"], "false": j["false"], "errors": j["errors"],
                                 "effects": [[e["effect"], e.get("axis"), e["parameters"]] for e in d.effects],
                                 "offset_error_ms": 1e3 * (d.alignment["time_offset_s"] - truth["time_offset_s"])})
    table = {"runs": runs, "by_effect": _summary(runs, "scenario"),
             "by_logger": _summary(runs, lambda r: f"{r['channels']}, {r['period_ms']:g} ms")}
    atomic_write_json(out / "scorecard_contour.json", table)
    atomic_write_text(out / "scorecard_contour.md", _markdown(table))
    return table


def _summary(runs: list[dict], key) -> dict:
    groups: dict[str, list[dict]] = {}
    for r in runs:
        groups.setdefault(key(r) if callable(key) else r[key], []).append(r)
    rows = {}
    for name, rs in groups.items():
        ok = [r for r in rs if "error" not in r]
        scored = [r for r in ok if r["scenario"] != "clean"]
        rows[name] = {**score_row(rs, ok, scored),
                      "max_offset_error_ms": max((abs(r["offset_error_ms"]) for r in ok), default=None)}
    return rows


def score_row(runs: list[dict], ok: list[dict], scored: list[dict]) -> dict:
    """The columns every diagnosis study tabulates for one group of runs.

    ``runs`` all runs of the group, ``ok`` those that did not fail, ``scored`` those with an effect their logger
    can show. Returns ``runs``, ``failed``, ``detected`` (share of ``scored`` that found every hidden effect),
    ``false_effects_per_run`` and ``median_relative_parameter_error`` (None where there is nothing to count).
    """
    errors = [e for r in ok for e in r["errors"]]
    return {"runs": len(runs), "failed": len(runs) - len(ok),
            "detected": (sum(r["found"] for r in scored) / len(scored)) if scored else None,
            "false_effects_per_run": (sum(len(r["false"]) for r in ok) / len(ok)) if ok else None,
            "median_relative_parameter_error": float(np.median(errors)) if errors else None}


def _markdown(table: dict) -> str:
    lines = []
    for title, rows in (("effect", table["by_effect"]), ("logger", table["by_logger"])):
        lines += [f"| {title} | runs | detection | false effects/run | median param. error | max offset error |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for name, r in rows.items():
            det = "–" if r["detected"] is None else f"{r['detected']:.0%}"
            fp = "–" if r["false_effects_per_run"] is None else f"{r['false_effects_per_run']:.2f}"
            err = ("–" if r["median_relative_parameter_error"] is None
                   else f"{r['median_relative_parameter_error']:.1%}")
            off = "–" if r["max_offset_error_ms"] is None else f"{r['max_offset_error_ms']:.3f} ms"
            failed = f" ({r['failed']} failed)" if r["failed"] else ""
            lines.append(f"| {name} | {r['runs']}{failed} | {det} | {fp} | {err} | {off} |")
        lines.append("")
    lines.append("| run | found | false effects | offset error |")
    lines.append("| --- | --- | --- | --- |")
    for r in table["runs"]:
        label = f"{r['scenario']}, {r['channels']}, {r['period_ms']:g} ms, seed {r['seed']}"
        if "error" in r:
            lines.append(f"| {label} | error | {r['error'][:120]} | – |")
        else:
            lines.append(f"| {label} | {r['found']} | {', '.join(r['false']) or '–'} | "
                         f"{r['offset_error_ms']:.3f} ms |")
    return "\n".join(lines) + "\n"


def main() -> None:  # pragma: no cover - a study, run by hand
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("out")
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--periods", default="1,2,4,8", help="logger periods, ms, comma-separated")
    parser.add_argument("--only", default=None, help="comma-separated scenarios (e.g. 'clean,backlash x')")
    parser.add_argument("--channels", default=None, help="comma-separated channel sets (e.g. 'servo guide')")
    args = parser.parse_args()
    from ..cli import emit

    only = [s.strip() for s in args.only.split(",")] if args.only else None
    chans = [s.strip() for s in args.channels.split(",")] if args.channels else None
    table = score_contour(Path(args.out), args.seeds, tuple(float(p) for p in args.periods.split(",")), only, chans)
    emit(json.dumps({"by_effect": table["by_effect"], "by_logger": table["by_logger"]}, indent=2))


if __name__ == "__main__":  # pragma: no cover
    main()
