"""Diagnosis of the cutting process: force and spindle-speed residuals, named, refitted.

Pipeline (called by :func:`.core.diagnose` when the recording has forces and
the case a stock):

1. :func:`prepare_cutting` — the force rows, the recorded motion and
   spindle speed as the replay's inputs (:mod:`.cutting_replay`), the cuts
   and the spindle phase of each cut (:mod:`.cutting_align`), noise floors;
2. :func:`cutting_columns` — one batched replay: the baseline (the machine
   file's ``Kt``, ``Ke``), the derivatives that are always fitted (``Kt``,
   ``Ke``: identified coefficients, not effects; spindle phase and drift
   per cut, dynamometer offsets: alignment) and one member per candidate
   column (:mod:`.cutting_library`); the droop column ``-T`` on the
   ``spindle_rpm`` rows;
3. selection with BIC and minimum gains (:func:`.select.select`, the same
   rules as the feed drives), after cuts with chatter are set aside
   (:mod:`.cutting_locate`: a vibration off the spindle harmonics is not
   replayable sample by sample);
4. :func:`refit_cutting` — Levenberg-Marquardt on batched replays of
   ``Kt``, ``Ke`` and the chosen effects' parameters, artefacts projected
   out at every evaluation; 90 % intervals from the Gauss-Newton covariance
   inflated for residual autocorrelation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..case import Case
from ..recording import Recording
from .align import noise_floor
from .cutting_align import (FINE_OFFSETS, PHASE_STEPS, Cuts, best_phase, cut_segments, fine_phase, initial_angle,
                            phase_speed, spindle_samples)
from .cutting_library import component_values, cutting_variants
from .cutting_replay import ForceInputs, ForceReplay, force_inputs, run_force_replay, step_speeds
from .cutting_table import one_cutter_table
from .errors import DiagnosisError
from .library import Column, Variant
from .select import Selection, select

#: Finite-difference step of the spindle phase, rad; samples whose engaged teeth change within it are
#: tooth entries and exits (a force jump: a fraction of a degree of phase swaps full force and zero)
#: and are not compared.
PHASE_EPS = math.radians(2.0)
#: Relative Kt step and absolute Ke step of the always-fitted coefficient columns.
KT_STEP = 0.05
KE_STEP = 0.05
#: Lag of the torque the spindle-speed loop reacts to (droop column), s.
DROOP_LAG_S = 1e-3
#: Edge-force coefficient of the phase scan's edge basis, N/m.
EDGE_UNIT = 1e4
#: Force channels compared.
FORCE_CHANNELS = ("fx_N", "fy_N")
#: Lowest force noise floor, N (see :func:`prepare_cutting`).
FORCE_FLOOR_N = 0.5

CuttingModel = dict[str, dict[str, float]]


@dataclass
class CuttingData:
    """A force recording aligned with the twin's cutting model.

    Attributes
    ----------
    case : Case
    table : EngagementTable
    inputs : ForceInputs
    rows : ndarray of int
        Recording rows of the force samples.
    measured : ndarray, shape (n, 2)
        Measured fx, fy [N].
    kt, ke : float
        The machine file's cutting coefficients (N/m2, 1).
    flutes : int
    cuts : Cuts
        Cut segments and their spindle phases.
    theta0 : float
        Spindle angle of tooth 0 at the first force sample (first cut's phase included), rad.
    depth : float
        Force-weighted mean axial depth of the cuts, m.
    step_omega : ndarray
        Spindle speed input of each replay step (phases of later cuts included), rad/s.
    sigma : float
        Force noise floor, N.
    spindle_rows : ndarray of int
        Recording rows of ``spindle_rpm`` usable for droop.
    spindle_residual : ndarray
        ``spindle_rpm - spindle_ref_rpm`` at those rows, rpm.
    sigma_rpm : float
    """

    case: Case
    table: Any
    inputs: ForceInputs
    rows: np.ndarray
    measured: np.ndarray
    kt: float
    ke: float
    flutes: int
    cuts: Cuts
    theta0: float
    step_omega: np.ndarray
    sigma: float
    spindle_rows: np.ndarray
    spindle_residual: np.ndarray
    sigma_rpm: float
    recording: Recording
    chatter_cuts: list[int] = field(default_factory=list)
    boundary: np.ndarray | None = None
    depth: float = 0.0

    @property
    def t(self) -> np.ndarray:
        """Force sample times (logger clock), s."""
        return self.inputs.t

    def run(self, members: list[CuttingModel], theta_shift: np.ndarray | None = None) -> ForceReplay:
        """Replay ``members`` (spec-unit models incl. ``coefficients``) at the aligned spindle phases."""
        params = []
        shift = np.zeros(len(members)) if theta_shift is None else np.asarray(theta_shift, dtype=float).copy()
        for i, m in enumerate(members):
            p = {"kt": self.kt, "ke": self.ke}
            p.update(component_values({e: v for e, v in m.items() if e != "alignment"}))
            params.append(p)
            shift[i] += math.radians(m.get("alignment", {}).get("spindle_phase_deg", 0.0))
        theta = self.theta0 + shift
        return run_force_replay(self.case, self.table, self.inputs, params, theta, self.step_omega)

    def force_rows(self) -> np.ndarray:
        """Force samples compared: all but tooth entries/exits and the cuts set aside for chatter."""
        keep = np.ones(self.t.size, bool) if self.boundary is None else ~self.boundary
        for s in self.chatter_cuts:
            i0, i1 = self.cuts.bounds[s]
            keep[i0:i1] = False
        return np.flatnonzero(keep & np.isfinite(self.measured).all(axis=1))


def _ref_rpm(recording: Recording) -> np.ndarray | None:
    return np.asarray(recording["spindle_ref_rpm"], float) if "spindle_ref_rpm" in recording else None


def has_forces(recording: Recording, case: Case) -> bool:
    """Whether a cutting diagnosis applies: fx_N and fy_N recorded and a stock in the case."""
    return (case.stock is not None and all(c in recording and np.isfinite(recording[c]).sum() > 100
                                           for c in FORCE_CHANNELS))


def prepare_cutting(case: Case, recording: Recording, spindle_command=None, say=lambda m: None) -> CuttingData:
    """Inputs, cuts, spindle phase per cut and noise floors of a force recording (step 1).

    Parameters
    ----------
    case : Case
    recording : Recording
    spindle_command : callable, optional
        ``f(t_logger)`` -> the controller's (ramped) spindle speed command [rpm], e.g. the twin's NC run
        through the logger offset; the droop rows are those where it is constant. Without it the
        recorded ``spindle_ref_rpm`` is used.

    Raises
    ------
    DiagnosisError
        No force samples, no cut of the stock, missing positions or spindle speed.
    """
    f = np.column_stack([np.asarray(recording[c], float) for c in FORCE_CHANNELS])
    rows = np.flatnonzero(np.isfinite(f).all(axis=1))
    if rows.size < 100:
        raise DiagnosisError(f"{recording.source}: fewer than 100 rows with both fx_N and fy_N; the cutting "
                             "diagnosis needs the dynamometer forces")
    inputs = force_inputs(recording, rows)
    say("building the engagement table of the program")
    table = one_cutter_table(case)
    mat = case.machine.si(f"material.{case.material}")
    kt, ke = float(mat["kt"]), float(mat["ke"])
    flutes = int(case.tool.flutes)
    pitch = 2.0 * math.pi / flutes
    trial = np.arange(PHASE_STEPS) * pitch / PHASE_STEPS
    measured = f[rows]
    say(f"spindle phase scan ({PHASE_STEPS} phases per tooth pitch)")
    unit_members = [{"kt": kt, "ke": 0.0}, {"kt": kt, "ke": 1.0},
                    {"kt": 0.0, "ke": 0.0, "edge_force_tangential": EDGE_UNIT},
                    {"kt": 0.0, "ke": 0.0, "edge_force_radial": EDGE_UNIT}]

    def basis(runs: ForceReplay, k: int, parts: int = 4) -> list[np.ndarray]:
        f = [np.stack([runs.fx[:, i * k:(i + 1) * k], runs.fy[:, i * k:(i + 1) * k]], axis=-1) for i in range(parts)]
        return [f[0], f[1] - f[0], *f[2:]]

    # coarse: the Kt and Ke parts only (edge forces pull it by a few degrees: the fine scan has them)
    runs = run_force_replay(case, table, inputs, [m for m in unit_members[:2] for _ in range(PHASE_STEPS)],
                            np.tile(trial, 2))
    a = basis(runs, PHASE_STEPS, 2)[0]
    engaged = np.any(np.abs(a).sum(axis=2) > 0.0, axis=1)
    cuts = cut_segments(inputs.t, engaged)
    if not cuts.bounds:
        raise DiagnosisError(f"{recording.source}: the recorded tool path does not cut the stock of "
                             f"{case.source or case.folder} (check work coordinates and [stock])")
    cuts.phase = np.full(len(cuts.bounds), best_phase(measured, basis(runs, PHASE_STEPS, 2), cuts, trial))
    # fine scan around it
    k = FINE_OFFSETS.size
    runs = run_force_replay(case, table, inputs, [m for m in unit_members for _ in range(k)],
                            initial_angle(0.0, cuts) + np.tile(FINE_OFFSETS, 4),
                            phase_speed(step_speeds(inputs), inputs.t, cuts))
    cuts.phase = cuts.phase + fine_phase(measured, basis(runs, k), runs.engaged[:, :k], cuts, FINE_OFFSETS)
    f0 = np.hypot(runs.fx[:, 0], runs.fy[:, 0])
    depth = float(np.sum(runs.depth[:, 0] * f0) / max(float(np.sum(f0)), 1e-12))
    theta0 = initial_angle(0.0, cuts)
    step_omega = phase_speed(step_speeds(inputs), inputs.t, cuts)
    # noise floor from the samples in air (the dynamometer's own noise)
    air = ~cuts.mask(inputs.t.size)
    sigma = noise_floor(np.concatenate([measured[air, 0], measured[air, 1]])) if air.sum() > 50 else \
        noise_floor(measured[:, 0])
    sigma = max(sigma, FORCE_FLOOR_N)
    # spindle speed rows for droop: the commanded speed constant, the actual one near it
    t_all = np.asarray(recording.t, float)
    sp_rows = np.zeros(0, int)
    sp_res = np.zeros(0)
    sig_rpm = float("nan")
    if "spindle_rpm" in recording and (spindle_command is not None or _ref_rpm(recording) is not None):
        rpm = np.asarray(recording["spindle_rpm"], float)
        if spindle_command is not None:
            cmd = np.asarray(spindle_command(t_all), float)
            steady = np.asarray(spindle_command(t_all - 0.2), float)
            sp_rows = np.flatnonzero(np.isfinite(rpm) & (cmd > 0) & (np.abs(cmd - steady) < 1e-6 * cmd + 1e-9)
                                     & (np.abs(rpm - cmd) < 0.05 * cmd))
        else:
            from .align import fill_gaps

            cmd = fill_gaps(t_all, _ref_rpm(recording))
            sp_rows = spindle_samples(t_all, rpm, cmd)
        sp_res = rpm[sp_rows] - cmd[sp_rows]
        sig_rpm = noise_floor(sp_res, quantum=_quantum(rpm)) if sp_rows.size > 20 else float("nan")
    return CuttingData(case, table, inputs, rows, measured, kt, ke, flutes, cuts, theta0, step_omega,
                       float(sigma), sp_rows, sp_res, float(sig_rpm), recording, depth=depth)


def _quantum(x: np.ndarray) -> float:
    """Resolution of a logged channel (smallest non-zero step, when the values sit on a grid), else 0."""
    v = x[np.isfinite(x)]
    d = np.abs(np.diff(v))
    d = d[d > 1e-9]
    if d.size < 10:
        return 0.0
    q = float(np.min(d))
    return q if np.allclose(np.round(v / q) * q, v, atol=1e-6 * q) else 0.0


@dataclass
class CuttingColumns:
    """Regression design of the cutting diagnosis.

    Attributes
    ----------
    rows : ndarray of int
        Force samples compared.
    y : ndarray
        Weighted residual: fx rows, fy rows (over the force noise floor), spindle rows (over its floor).
    columns : dict
        Column key -> weighted column.
    artefacts : dict
        Always-fitted columns (coefficients, phases, offsets).
    variants : list of Variant
    base : ForceReplay
        The baseline replay (machine file's coefficients).
    torque : ndarray
        Baseline cutting torque at the spindle rows, N.m.
    """

    rows: np.ndarray
    y: np.ndarray
    columns: dict[str, np.ndarray]
    artefacts: dict[str, np.ndarray]
    variants: list[Variant]
    base: ForceReplay
    torque: np.ndarray


def _member(col: Column) -> CuttingModel:
    """Model of a column's replay member (its parameter at ``unit``)."""
    u = col.unit
    if col.effect == "runout":
        return {"runout": {"eccentricity_um": u, "phase_deg": 0.0 if col.parameter == "a_um" else 90.0}}
    if col.effect == "helix_angle":
        return {"helix_angle": {"helix_deg": dict(col.fixed)["helix_deg"]}}
    if col.effect == "edge_force":
        return {"edge_force": {col.parameter: u}}
    if col.effect == "tool_deflection":
        return {"tool_deflection": {"stiffness_N_per_um": 1.0 / u}}
    if col.effect == "tool_wear":
        return {"tool_wear": {"rate_percent_per_min": u}}
    raise KeyError(col.key)


def helix_lead(data: CuttingData, helix_deg: float) -> float:
    """Phase [rad] by which a helix of ``helix_deg`` moves the force pulse on average (the scan's phase absorbed it).

    A slice at height ``z`` lags by ``z tan(beta) / R``: over the engaged depth ``d`` the pulse is late by
    about ``d tan(beta) / (2 R)``; ``d`` is the force-weighted mean depth of the cuts (:attr:`CuttingData.depth`).
    """
    if helix_deg == 0.0 or data.depth <= 0.0:
        return 0.0
    radius = 0.5 * data.case.tool.diameter_mm * 1e-3
    return data.depth * math.tan(math.radians(helix_deg)) / (2.0 * radius)


def lagged_torque(t: np.ndarray, torque: np.ndarray, lag: float = DROOP_LAG_S) -> np.ndarray:
    """First-order lag of the cutting torque (what a spindle speed loop sees), N.m."""
    out = np.empty_like(torque)
    y = 0.0
    prev = t[0]
    for k in range(t.size):
        dt = t[k] - prev
        y += (torque[k] - y) * (1.0 - math.exp(-dt / lag)) if dt > 0 else 0.0
        out[k] = y
        prev = t[k]
    return out


def phase_columns(data: CuttingData, plus: ForceReplay, minus: ForceReplay, rows: np.ndarray) -> dict[str, np.ndarray]:
    """Spindle-phase error and phase drift over the recording (weighted, fx then fy rows), per rad."""
    dfx = (plus.fx[:, 0] - minus.fx[:, 0]) / (2 * PHASE_EPS)
    dfy = (plus.fy[:, 0] - minus.fy[:, 0]) / (2 * PHASE_EPS)
    inside = data.cuts.mask(data.t.size)
    t_in = data.t[inside]
    mid = 0.5 * (t_in[0] + t_in[-1])
    span = max(t_in[-1] - t_in[0], 1e-3)
    out = {}
    for name, w in (("spindle phase", np.ones_like(data.t)), ("spindle phase drift", (data.t - mid) / span)):
        out[name] = np.concatenate([(dfx * w)[rows], (dfy * w)[rows]]) / data.sigma
    return out


def cutting_columns(data: CuttingData, base_model: CuttingModel | None = None,
                    say=lambda m: None) -> CuttingColumns:
    """Baseline, always-fitted columns and candidate columns from one batched replay (step 2)."""
    base_model = base_model or {}
    variants = cutting_variants(data.flutes, droop=data.spindle_rows.size > 20)
    dyn: dict[str, Column] = {}
    for v in variants:
        for c in v.columns:
            if c.kind == "dynamic":
                dyn.setdefault(c.key, c)
    coef = dict(base_model.get("coefficients", {}))
    kt0 = coef.get("kt_N_per_m2", data.kt)
    ke0 = coef.get("ke", data.ke)
    members: list[CuttingModel] = [base_model]
    shifts = [0.0]

    def add(model: CuttingModel, shift: float = 0.0) -> int:
        merged = {e: dict(p) for e, p in base_model.items()}
        for e, p in model.items():
            merged.setdefault(e, {}).update(p)
        members.append(merged)
        shifts.append(shift)
        return len(members) - 1

    j_plus = add({}, PHASE_EPS)
    j_minus = add({}, -PHASE_EPS)
    j_kt = add({"coefficients": {"kt_N_per_m2": kt0 * (1 + KT_STEP), "ke": ke0}})
    j_ke = add({"coefficients": {"kt_N_per_m2": kt0, "ke": ke0 + KE_STEP}})
    j_col = {key: add(_member(c), helix_lead(data, dict(c.fixed).get("helix_deg", 0.0)))
             for key, c in dyn.items()}
    say(f"cutting effect library ({len(members)} replay members)")
    sim = data.run(members, np.array(shifts))
    data.boundary = (sim.engaged[:, j_plus] != sim.engaged[:, 0]) | (sim.engaged[:, j_minus] != sim.engaged[:, 0])
    rows = data.force_rows()
    sig = data.sigma

    def stacked(k: int) -> np.ndarray:
        return np.concatenate([sim.fx[rows, k] - sim.fx[rows, 0], sim.fy[rows, k] - sim.fy[rows, 0]]) / sig

    n_sp = data.spindle_rows.size
    pad = np.zeros(n_sp)
    columns = {key: np.concatenate([stacked(j) / dyn[key].unit, pad]) for key, j in j_col.items()}
    # droop: spindle_rpm drop -T(lagged) per rpm/N.m, on the spindle rows only
    t_all = np.asarray(data.recording.t, float)
    torque_lag = lagged_torque(data.t, sim.torque[:, 0])
    torque_sp = np.interp(t_all[data.spindle_rows], data.t, torque_lag) if n_sp else np.zeros(0)
    if n_sp:
        columns["spindle_droop.rpm_per_Nm"] = np.concatenate([np.zeros(2 * rows.size), -torque_sp / data.sigma_rpm])
    artefacts: dict[str, np.ndarray] = {
        "kt (relative)": np.concatenate([stacked(j_kt) / KT_STEP, pad]),
        "ke": np.concatenate([stacked(j_ke) / KE_STEP, pad]),
        "fx_N offset": np.concatenate([np.ones(rows.size), np.zeros(rows.size), pad]) / sig,
        "fy_N offset": np.concatenate([np.zeros(rows.size), np.ones(rows.size), pad]) / sig,
    }
    plus, minus = sim.member(j_plus), sim.member(j_minus)
    for name, col in phase_columns(data, plus, minus, rows).items():
        artefacts[name] = np.concatenate([col, pad])
    if n_sp:
        artefacts["spindle_rpm offset"] = np.concatenate([np.zeros(2 * rows.size), np.ones(n_sp) / data.sigma_rpm])
    y = np.concatenate([(data.measured[rows, 0] - sim.fx[rows, 0]) / sig,
                        (data.measured[rows, 1] - sim.fy[rows, 0]) / sig,
                        data.spindle_residual / data.sigma_rpm if n_sp else np.zeros(0)])
    base = sim.member(0)
    return CuttingColumns(rows, y, columns, artefacts, variants, base, torque_sp)


def select_cutting(cols: CuttingColumns) -> Selection:
    """Forward-backward selection of the cutting effects (BIC and minimum gains, :mod:`.select`)."""
    return select(cols.y, cols.artefacts, cols.variants, cols.columns)


def start_model(selection: Selection, data: CuttingData, cols: CuttingColumns) -> CuttingModel:
    """Spec-unit start values of the refit from the selection's linear coefficients."""
    art = selection.artefacts
    model: CuttingModel = {"coefficients": {"kt_N_per_m2": data.kt * (1.0 + art.get("kt (relative)", 0.0)),
                                            "ke": data.ke + art.get("ke", 0.0)}}
    for ch in selection.choices:
        e, c, fixed = ch.variant.effect, ch.coefficients, dict(ch.variant.fixed)
        if e == "runout":
            a, b = c.get("a_um", 0.0), c.get("b_um", 0.0)
            model[e] = {"eccentricity_um": math.hypot(a, b), "phase_deg": math.degrees(math.atan2(b, a))}
        elif e == "helix_angle":
            scale = max(c.get("scale", 1.0), 0.05)
            deg = float(np.clip(fixed["helix_deg"] * math.sqrt(scale), 1.0, 70.0))
            model[e] = {"helix_deg": deg}
            model["alignment"] = {"spindle_phase_deg": math.degrees(helix_lead(data, deg))}
        elif e == "edge_force":
            model[e] = {"kte_N_per_mm": c.get("kte_N_per_mm", 0.0), "kre_N_per_mm": c.get("kre_N_per_mm", 0.0)}
        elif e == "tool_deflection":
            model[e] = {"stiffness_N_per_um": 1.0 / max(c["compliance_um_per_N"], 1e-6)}
        elif e == "tool_wear":
            model[e] = {"rate_percent_per_min": c["rate_percent_per_min"]}
        elif e == "spindle_droop":
            model[e] = {"rpm_per_Nm": c["rpm_per_Nm"]}
    return model
