"""Cutting test cases: a short program in a small block and a truth recording with hidden effects.

:func:`write_cutting_case` writes ``program.nc``, ``case.toml``,
``recording.csv`` and ``truth.json``. The recording comes from the
independent truth simulations (:mod:`.truth` for the feed drives,
:mod:`.truth_cutting` for the forces) and realistic loggers.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Mapping

import numpy as np

from fmus_src.cutting.axial import AXIAL_RATIO_DEFAULT

from ..atomic import atomic_write_json, atomic_write_text
from ..case import Case, load_case
from ..machine import Machine
from ..recording import Recording
from .cutting_table import one_cutter_table
from .prepare import twin_commands
from .truth import Recorder, record, simulate_truth
from .truth_cutting import (CuttingRun, Dynamometer, cutting_parameters_packed, fine_grid, merge_recordings,
                            sample_forces, simulate_cutting, spindle_channel, tick_mean)
from .truth_thrust import truth_thrust

#: Two full slots at 1 and 2 mm depth and a 1 mm side pass 3 mm deep (A6061, 6 mm 3-flute end mill).
PROGRAM = """%
O0009 (DIAGNOSIS: CUTTING - TWO SLOTS AT TWO DEPTHS AND A SIDE PASS)
N10 G21 G17 G90 G94
N20 S6000 M3
N30 G0 X-4. Y5. Z1.
N40 G1 Z-1. F1000
N50 X10. F600 (FULL SLOT 1 MM DEEP)
N60 G0 Z1.
N70 X-4. Y14.
N80 G1 Z-2. F1000
N90 X10. F450 (FULL SLOT 2 MM DEEP)
N100 G0 Z1.
N110 X18. Y-4.
N120 G1 Z-3. F1000
N130 Y16. F900 (SIDE PASS 1 MM RADIAL 3 MM DEEP)
N140 G0 Z5.
N150 M30
%
"""

#: The same cuts, shorter (about 2.4 s of cutting instead of 4.7 s): for the tests.
SHORT_PROGRAM = PROGRAM.replace("N50 X10. F600", "N50 X4. F600").replace("N90 X10. F450", "N90 X4. F450") \
    .replace("N130 Y16. F900", "N130 Y8. F900")

CASE_TOML = """program = "program.nc"
recording = "recording.csv"

[stock]
min = [0.0, 0.0, -6.0]
max = [16.0, 20.0, 0.0]

[tool]
diameter_mm = 6.0
flutes = 3

[machine]
parameters = "default"
"""

#: The dynamometer starts when the spindle is nearly up to speed (program clock), s; the CNC logger runs
#: from the program start (the drives' integrators hold a friction-dependent current at rest, which a
#: replay can only know from the start).
LOGGER_START_S = 1.3


def write_cutting_case(folder: Path, effects: Mapping[str, Mapping[str, float]] | None, seed: int,
                       drive_effects: Mapping[str, Mapping[str, Mapping[str, float]]] | None = None,
                       dynamometer: Dynamometer | None = None, recorder: Recorder | None = None,
                       offset_range_s: tuple[float, float] = (0.1, 2.0), program: str = PROGRAM,
                       case_toml: str = CASE_TOML, forces_on_cnc_rows: bool = False) -> Path:
    """A cutting case folder whose recording hides ``effects`` (spec vocabulary, no axis).

    Parameters
    ----------
    folder : Path
    effects : mapping effect -> {parameter: value}, optional
        Hidden cutting effects (``truth_cutting.CUTTING_PARAMETERS``).
    seed : int
        Noise, jitter, logger offset and initial spindle angle.
    drive_effects : mapping axis -> effects, optional
        Hidden feed-drive effects (as :func:`.scorecard.write_case`).
    dynamometer, recorder : optional
        Force logger and CNC logger (the CNC logger's offset and start are set here).
    offset_range_s : (float, float)
        Range of the seeded logger clock offset, s.
    program, case_toml : str
        The G-code and the case manifest.
    forces_on_cnc_rows : bool
        One logger for everything (a controller logging the dynamometer with its servo data): the forces
        are sampled at the CNC logger's rows (with the dynamometer's noise and hum; empty cells before the
        dynamometer's start, :data:`LOGGER_START_S`) instead of on the dynamometer's own rows.

    Returns
    -------
    Path
        ``folder``; ``truth.json`` holds the hidden truth, the offset and the spindle angle of tooth 0
        at the first force sample.
    """
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_text(folder / "program.nc", program)
    atomic_write_text(folder / "case.toml", case_toml)
    case = load_case(folder)
    machine = case.machine
    rng = np.random.default_rng(seed)
    offset = float(rng.uniform(*offset_range_s))
    theta0 = float(rng.uniform(0.0, 2.0 * math.pi))
    dyn = dynamometer or Dynamometer()
    rec = replace(recorder or Recorder(), time_offset_s=offset)
    nc = twin_commands(case, machine)
    table = one_cutter_table(case)
    drives = {a: dict(v) for a, v in (drive_effects or {}).items()}
    first = simulate_truth(machine, nc, drives, axes=("x", "y", "z"))
    t_f = fine_grid(LOGGER_START_S, float(first.t[-1]))
    pos = np.column_stack([np.interp(t_f, first.t, first.table[a]) for a in "xyz"])
    omega_cmd = np.interp(t_f, np.asarray(nc.t, float), np.asarray(nc["spindle_rpm"], float)) * 2.0 * math.pi / 60.0
    packed = cutting_parameters_packed(machine, case.material, case.tool.diameter_mm * 1e-3, case.tool.flutes,
                                       effects, theta0)
    run = simulate_cutting(table, t_f, pos, omega_cmd, packed)
    tv = float(machine.si("servo")["velocity_loop_period"])
    thrust = _thrust(case, machine, packed, t_f, pos, run)
    # the cutting force loads the feed drives (one fixed-point pass: drives, then forces again); the Z slide
    # carries the tool: the end edges' thrust pushes it up, a load -thrust = fz resisting positive motion
    dist = {"x": lambda tk: tick_mean(t_f, run.fx, tk, tv), "y": lambda tk: tick_mean(t_f, run.fy, tk, tv),
            "z": lambda tk: tick_mean(t_f, -thrust, tk, tv)}
    truth = simulate_truth(machine, nc, drives, axes=("x", "y", "z"), disturbance=dist)
    # the forces of the loaded motion (the positions move by well under a micrometre more in a third pass)
    pos = np.column_stack([np.interp(t_f, truth.t, truth.table[a]) for a in "xyz"])
    run = simulate_cutting(table, t_f, pos, omega_cmd, packed)
    cnc = record(truth, rec, seed=seed)
    t_cnc_prog = np.asarray(cnc.t, float) - offset
    channels = {name: np.asarray(cnc[name], float) for name in cnc.channels}
    channels["spindle_ref_rpm"] = np.interp(t_cnc_prog, np.asarray(nc.t, float),
                                            np.asarray(nc["spindle_ref_rpm"], float))
    channels["spindle_rpm"] = spindle_channel(run, t_cnc_prog, dyn, rng)
    if forces_on_cnc_rows:
        inside = (t_cnc_prog >= t_f[0]) & (t_cnc_prog <= t_f[-1])
        channels.update({k: np.where(inside, v, np.nan) for k, v in sample_forces(run, t_cnc_prog, dyn, rng).items()})
        Recording.from_channels(channels, source="<truth CNC logger>").write_csv(folder / "recording.csv")
        t_first = float(t_cnc_prog[inside][0])
    else:
        cnc = Recording.from_channels(channels, source="<truth CNC logger>")
        t_dyn = np.arange(t_f[0] + 0.5 * dyn.period_s, t_f[-1], dyn.period_s)
        forces = {"t_s": t_dyn + offset, **sample_forces(run, t_dyn, dyn, rng)}
        merge_recordings(cnc, forces).write_csv(folder / "recording.csv")
        t_first = float(t_dyn[0])
    theta_first = float(np.interp(t_first, t_f, run.theta))
    atomic_write_json(folder / "truth.json", {
        "cutting_effects": {k: dict(v) for k, v in (effects or {}).items()},
        "drive_effects": drives, "time_offset_s": offset, "seed": seed,
        "spindle_angle_at_first_force_sample_rad": theta_first % (2.0 * math.pi),
        "dynamometer": {"period_s": dyn.period_s, "force_noise_N": dyn.force_noise_N, "hum_N": dyn.hum_N,
                        "hum_Hz": dyn.hum_Hz, "on_cnc_rows": bool(forces_on_cnc_rows)},
    })
    return folder


def _thrust(case: Case, machine: Machine, packed: np.ndarray, t_f: np.ndarray, pos: np.ndarray,
            run: CuttingRun) -> np.ndarray:
    """The truth's end-edge thrust on the tool [N, upward] on the fine grid (:mod:`.truth_thrust`; 0 without a
    stock). ``packed[2]`` is the truth's Kt (a hidden ``kt_mismatch`` included), N/m2."""
    if case.stock is None:
        return np.zeros(t_f.size)
    mat = machine.si(f"material.{case.material}")
    ka = float(mat["ka"]) if "ka" in mat else AXIAL_RATIO_DEFAULT
    return truth_thrust(t_f, pos, run.omega, run.theta, 0.5 * case.tool.diameter_mm * 1e-3, case.tool.flutes,
                        float(packed[2]), ka, np.asarray(case.stock.min_mm, float) * 1e-3,
                        np.asarray(case.stock.max_mm, float) * 1e-3)
