"""Identification experiments: G-code programs and case folders to run on the machine.

``write_experiment(kind, out)`` writes a case folder (``case.toml``,
``program.nc``) for one of

``"friction"``
    Reciprocating runs of each axis at log-spaced speeds spanning the
    Stribeck region (default 16 speeds, 10 ... 10000 mm/min), each with a
    constant-velocity window of ``plateau_s`` (shortened, never below
    ``min_plateau_s``, where the stroke would exceed the axis limit) and a
    dwell between runs. Incremental (G91) moves: start with the axes near
    the middle of their travel.
``"servo"``
    Reciprocating runs at 100 ... 500 mm/min (Sim & Lee 2023, Fig. 5) of
    ``run_s`` each, for following error and current-command identification.
``"cutting"``
    A full-immersion slot and two partial-immersion (half, quarter) side
    cuts in a block, along X and along Y, at two feeds (6 mm 2-flute end
    mill, A6061 conditions of the paper).

The user runs ``program.nc``, logs the columns of ``shared/spec/recording.md``
(FANUC Servo Guide: position command, actual position, TCMD; dynamometer:
fx, fy) into ``recording.csv`` next to ``case.toml`` and runs
``cnctwin identify <kind> <folder> --out <dir>``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from .atomic import atomic_write_text
from .errors import CncTwinError
from .machine import AXES, Machine, load_machine


class ExperimentError(CncTwinError):
    """An experiment cannot be generated with the given settings."""


#: Default friction speeds: 16 log-spaced values from 10 to 10000 mm/min (3 significant digits).
FRICTION_SPEEDS_MM_MIN: tuple[float, ...] = tuple(float(f"{v:.3g}") for v in np.logspace(1, 4, 16))
#: Default servo speeds (paper Fig. 5), mm/min.
SERVO_SPEEDS_MM_MIN: tuple[float, ...] = (100.0, 200.0, 300.0, 400.0, 500.0)
#: Default largest stroke per axis, mm (well inside DNM 4500 travels 800 / 450 / 510 mm).
STROKE_LIMIT_MM = {"x": 200.0, "y": 150.0, "z": 100.0}


@dataclass(frozen=True)
class Run:
    """One reciprocating run: out and back at one speed."""

    axis: str
    speed_mm_min: float
    stroke_mm: float
    plateau_s: float


def _fmt(value: float) -> str:
    """A G-code number with a decimal point (FANUC reads '10' as 10 µm in some modes)."""
    return f"{value:.4f}".rstrip("0")


def _ramp_distance(speed_mm_s: float, machine: Machine) -> float:
    """Travel used by one acceleration plus one deceleration at the NC kernel limits, mm."""
    nck = machine.si("nck")
    accel = float(nck["accel_before_interp"]) * 1e3  # mm/s2
    lag = float(nck["accel_change_time_before_interp"]) + float(nck["cutting_time_constant"])
    return speed_mm_s * speed_mm_s / accel + 2.0 * speed_mm_s * lag


def plan_runs(
    axis: str,
    speeds_mm_min: Sequence[float],
    plateau_s: float,
    machine: Machine,
    stroke_limit_mm: float,
    min_plateau_s: float,
) -> list[Run]:
    """Runs of one axis: stroke = speed x plateau + ramps, shortened to the stroke limit.

    Raises
    ------
    ExperimentError
        A speed above the machine's maximum cutting feed, or a plateau that
        cannot reach ``min_plateau_s`` within ``stroke_limit_mm``.
    """
    fmax = float(machine.table("nck")["max_cutting_feed_mm_per_min"])
    runs = []
    for f in speeds_mm_min:
        if not 0.0 < f <= fmax:
            raise ExperimentError(
                f"speed {f} mm/min is outside (0, {fmax}] mm/min (max cutting feed of {machine.path})"
            )
        v = f / 60.0
        ramp = _ramp_distance(v, machine)
        plateau = plateau_s
        if v * plateau + ramp > stroke_limit_mm:
            plateau = (stroke_limit_mm - ramp) / v
        if plateau < min_plateau_s:
            raise ExperimentError(
                f"axis {axis} at {f} mm/min: a {min_plateau_s} s constant-velocity window needs "
                f"{v * min_plateau_s + ramp:.1f} mm of travel; the stroke limit is {stroke_limit_mm} mm"
            )
        runs.append(Run(axis, float(f), round(v * plateau + ramp, 3), plateau))
    return runs


def reciprocating_program(title: str, runs: Sequence[Run], dwell_s: float) -> str:
    """G-code (G91 incremental) of reciprocating runs: out, dwell, back, dwell."""
    lines = ["%", "O9001", f"({title})",
             "(INCREMENTAL MOVES: START WITH THE AXES NEAR THE MIDDLE OF THEIR TRAVEL)",
             "(LOG: POSITION COMMAND, ACTUAL POSITION AND TCMD OF EVERY AXIS, 1 KHZ)",
             "G21 G91 G94 G17"]
    dwell = f"G4 P{int(round(dwell_s * 1000))}"
    n = 10
    for r in runs:
        a = r.axis.upper()
        lines.append(f"({a} AT {r.speed_mm_min:g} MM/MIN, STROKE {r.stroke_mm:g} MM, PLATEAU {r.plateau_s:.2f} S)")
        lines.append(f"N{n} G1 {a}{_fmt(r.stroke_mm)} F{r.speed_mm_min:g}")
        lines.append(dwell)
        lines.append(f"G1 {a}{_fmt(-r.stroke_mm)}")
        lines.append(dwell)
        n += 10
    lines += ["G90", "M30", "%", ""]
    return "\n".join(lines)


def cutting_program(
    feeds_mm_min: Sequence[float] = (300.0, 450.0),
    spindle_rpm: float = 6000.0,
    depth_mm: float = 1.0,
    tool_diameter_mm: float = 6.0,
    length_mm: float = 60.0,
    width_mm: float = 40.0,
) -> tuple[str, tuple[list[float], list[float]]]:
    """Slot and partial-immersion cuts in a block; returns the program and the stock (min, max) in mm.

    Layout (work zero at the top front-left corner of the block): per feed,
    a full slot along X, a half-immersion and a quarter-immersion side cut
    along the back face (+Y), and a full slot along Y; each pass on a fresh
    lane.
    """
    r = 0.5 * tool_diameter_mm
    lanes = len(feeds_mm_min)
    if width_mm < lanes * 3.0 * tool_diameter_mm:
        raise ExperimentError(f"block width {width_mm} mm is too narrow for {lanes} slot lanes")
    stock = ([0.0, 0.0, -10.0], [float(length_mm), float(width_mm), 0.0])
    z = -abs(depth_mm)
    lines = ["%", "O9003", "(CUTTING COEFFICIENT IDENTIFICATION: SLOTS AND PARTIAL IMMERSION)",
             f"(STOCK {length_mm:g} X {width_mm:g} X 10 MM, WORK ZERO AT THE TOP FRONT-LEFT CORNER)",
             f"(TOOL T1: {tool_diameter_mm:g} MM 2-FLUTE FLAT END MILL; LOG FX, FY OF THE DYNAMOMETER AND POSITIONS)",
             "G21 G17 G40 G49 G90 G94", "G54", "T1 M6", f"S{spindle_rpm:g} M3"]
    back = width_mm
    for i, f in enumerate(feeds_mm_min):
        y_slot = 1.5 * tool_diameter_mm + i * 2.0 * tool_diameter_mm
        x_slot = length_mm - 1.5 * tool_diameter_mm - i * 2.0 * tool_diameter_mm
        lines.append(f"(FEED {f:g} MM/MIN: FULL SLOT ALONG X)")
        lines += [f"G0 X{_fmt(-r - 2.0)} Y{_fmt(y_slot)} Z2.", f"G1 Z{_fmt(z)} F200",
                  f"X{_fmt(length_mm * 0.5)} F{f:g}", "G0 Z2."]
        for frac, label in ((0.5, "HALF"), (0.25, "QUARTER")):
            yc = back - (frac * tool_diameter_mm - r)
            back -= frac * tool_diameter_mm
            lines.append(f"({label} IMMERSION SIDE CUT ALONG THE BACK FACE)")
            lines += [f"G0 X{_fmt(-r - 2.0)} Y{_fmt(yc)}", f"G1 Z{_fmt(z)} F200",
                      f"X{_fmt(length_mm * 0.5)} F{f:g}", "G0 Z2."]
        lines.append("(FULL SLOT ALONG Y)")
        lines += [f"G0 X{_fmt(x_slot)} Y{_fmt(-r - 2.0)}", f"G1 Z{_fmt(z)} F200", f"Y{_fmt(width_mm * 0.4)} F{f:g}",
                  "G0 Z2."]
    lines += ["G0 Z50.", "M5", "M30", "%", ""]
    return "\n".join(lines), stock


def _case_toml(kind: str, machine_ref: str, stock: tuple[list[float], list[float]] | None,
               tool: tuple[float, int]) -> str:
    text = [f"# cnctwin identification experiment: {kind}",
            "# Run program.nc on the machine, log the columns of shared/spec/recording.md into recording.csv",
            f"# next to this file, then: cnctwin identify {kind} <this folder> --out <result folder>",
            'program = "program.nc"', 'recording = "recording.csv"', ""]
    if stock is not None:
        text += ["[stock]", f"min = {stock[0]}", f"max = {stock[1]}", ""]
    text += ["[tool]", f"diameter_mm = {tool[0]:g}", f"flutes = {tool[1]}", "",
             "[machine]", f'parameters = "{machine_ref}"', ""]
    return "\n".join(text)


def write_experiment(
    kind: str,
    out: str | Path,
    machine: str | Path = "default",
    axes: Sequence[str] = AXES,
    speeds_mm_min: Sequence[float] | None = None,
    plateau_s: float | None = None,
    dwell_s: float = 0.3,
    min_plateau_s: float = 0.3,
    stroke_limit_mm: dict[str, float] | None = None,
    feeds_mm_min: Sequence[float] = (300.0, 450.0),
    spindle_rpm: float = 6000.0,
    block_mm: tuple[float, float] = (60.0, 40.0),
) -> dict[str, Path]:
    """Write an identification experiment as a case folder.

    Parameters
    ----------
    kind : {"friction", "servo", "cutting"}
    out : str or Path
        Case folder to create.
    machine : str or Path
        Machine set name or file (limits, accelerations; copied into case.toml).
    axes : sequence of str
        Axes to run (friction, servo).
    speeds_mm_min : sequence of float, optional
        Speeds (default :data:`FRICTION_SPEEDS_MM_MIN` / :data:`SERVO_SPEEDS_MM_MIN`).
    plateau_s : float, optional
        Constant-velocity time per run (default 1.0 s friction, 0.6 s servo).
    dwell_s : float
        Dwell between runs, s.
    min_plateau_s : float
        Shortest acceptable constant-velocity window, s.
    stroke_limit_mm : dict, optional
        Largest stroke per axis (default :data:`STROKE_LIMIT_MM`).
    feeds_mm_min, spindle_rpm
        Cutting conditions.
    block_mm : (float, float)
        Length (X) and width (Y) of the block, mm.

    Returns
    -------
    dict
        ``{"case": case.toml, "program": program.nc}``.

    Examples
    --------
    >>> write_experiment("friction", "runs/friction", axes=("x",))   # doctest: +SKIP
    """
    out = Path(out)
    m = load_machine(machine)
    machine_ref = str(machine) if not isinstance(machine, Path) else str(machine.resolve())
    if ("/" in machine_ref or machine_ref.endswith(".toml")) and not Path(machine_ref).is_absolute():
        machine_ref = str(Path(machine_ref).resolve())
    bad = [a for a in axes if a not in AXES]
    if bad:
        raise ExperimentError(f"unknown axis {bad[0]!r}; expected some of {list(AXES)}")
    limits = {**STROKE_LIMIT_MM, **(stroke_limit_mm or {})}
    stock = None
    if kind == "friction":
        speeds = speeds_mm_min or FRICTION_SPEEDS_MM_MIN
        plateau = 1.0 if plateau_s is None else plateau_s
        runs = [r for a in axes for r in plan_runs(a, speeds, plateau, m, limits[a], min_plateau_s)]
        program = reciprocating_program("FRICTION IDENTIFICATION: RECIPROCATING RUNS, STRIBECK SPEEDS", runs, dwell_s)
    elif kind == "servo":
        speeds = speeds_mm_min or SERVO_SPEEDS_MM_MIN
        plateau = 0.6 if plateau_s is None else plateau_s
        runs = [r for a in axes for r in plan_runs(a, speeds, plateau, m, limits[a], min(min_plateau_s, plateau))]
        program = reciprocating_program("SERVO SCALE-FACTOR IDENTIFICATION: RECIPROCATING RUNS", runs, dwell_s)
    elif kind == "cutting":
        program, stock = cutting_program(feeds_mm_min, spindle_rpm, length_mm=block_mm[0], width_mm=block_mm[1])
    else:
        raise ExperimentError(f"unknown experiment {kind!r}; expected 'friction', 'servo' or 'cutting'")
    return {
        "program": atomic_write_text(out / "program.nc", program),
        "case": atomic_write_text(out / "case.toml", _case_toml(kind, machine_ref, stock, (6.0, 2))),
    }
