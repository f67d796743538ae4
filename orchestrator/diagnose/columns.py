"""Regression columns of the candidate effects, from one batched replay plus kinematics."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .align import noise_floor, recorded_quantum
from .library import Column, Variant, candidate_variants, channel_scale_variant, dynamic_columns
from .model import Model, Simulated, simulate
from .prepare import Prepared

#: Backlash width of the kinematic column (the column is per µm), m.
BACKLASH_PROBE_M = 10e-6
#: Encoder and current resolutions assumed for the noise-floor floor (µm, A); 0 = not assumed.
POSITION_QUANTUM_UM = 0.1
CURRENT_QUANTUM_A = 0.01


def column_model(col: Column) -> dict[str, dict[str, float]]:
    """Axis model of a dynamic column's replay member (its parameter at ``unit``, fixed ones set)."""
    params = {col.parameter: col.unit, **dict(col.fixed)}
    return {col.effect: params}


def play(x: np.ndarray, width: float) -> np.ndarray:
    """Backlash play operator over a sampled signal (output starts at the input)."""
    out = np.empty_like(x)
    y = x[0]
    half = 0.5 * width
    for i, v in enumerate(x):
        if y < v - half:
            y = v - half
        elif y > v + half:
            y = v + half
        out[i] = y
    return out


def kinematic_fe(col: Column, t: np.ndarray, motor: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Following-error column [µm per spec unit] of a motor-to-table effect (no replay needed).

    ``fe = cmd - table`` and ``table = motor + lead error - force / k`` (play, drift), so a
    table shift ``d`` gives ``-d`` in the following error.
    """
    fixed = dict(col.fixed)
    if col.effect == "backlash":
        return -(play(motor, BACKLASH_PROBE_M) - motor) * 1e6 / (BACKLASH_PROBE_M * 1e6)
    if col.effect == "screw_compliance":
        return force.copy()  # µm per (µm/N)
    if col.effect == "pitch_error" and col.parameter == "slope_um_per_m":
        return -motor.copy()  # m x µm/m = µm
    if col.effect == "pitch_error" and col.parameter == "amplitude_um":
        return -np.sin(2.0 * np.pi * motor / (fixed["period_mm"] * 1e-3))
    if col.effect == "thermal_drift":
        return -(t - t[0]) / 60.0
    raise KeyError(f"no kinematic column for {col.key}")


@dataclass
class AxisColumns:
    """Everything the selection of one axis needs.

    Attributes
    ----------
    rows_fe, rows_tc : ndarray of int
        Sample indices of the following-error and current rows.
    sigma_fe, sigma_tc : float
        Noise floors [µm], [A] (NaN when the channel is missing).
    y : ndarray
        Weighted residual, FE rows then current rows.
    columns : dict
        Column key -> weighted column.
    artefacts : dict
        Artefact name -> weighted column.
    variants : list of Variant
    """

    rows_fe: np.ndarray
    rows_tc: np.ndarray
    sigma_fe: float
    sigma_tc: float
    y: np.ndarray
    columns: dict[str, np.ndarray]
    artefacts: dict[str, np.ndarray]
    variants: list[Variant]
    rows_left_out: int = 0


def plateau_limit(measured: np.ndarray, simulated: np.ndarray, sigma: float) -> float | None:
    """A current limit below the model's: the measured command flat-tops where the simulation goes beyond.

    Returns the plateau level [A] when at least 10 samples sit within 3 noise floors of the measured
    maximum magnitude and the simulation exceeds that level by more than 10 noise floors; else None.
    """
    m = np.abs(measured[np.isfinite(measured)])
    if m.size == 0:
        return None
    top = float(np.max(m))
    flat = int(np.sum(m >= top - 3 * sigma))
    if flat >= 10 and float(np.max(np.abs(simulated))) > top + 10 * sigma:
        return top
    return None


def _members(axes: list[str], base: Model, dyn: dict[str, list[Column]]) -> list[Model]:
    """Replay members: the baseline, then member ``j`` carrying dynamic column ``j - 1`` of every axis."""
    width = 1 + max(len(c) for c in dyn.values())
    members: list[Model] = []
    for j in range(width):
        m: Model = {a: {e: dict(p) for e, p in base.get(a, {}).items()} for a in axes}
        if j > 0:
            for a in axes:
                if j - 1 < len(dyn[a]):
                    col = dyn[a][j - 1]
                    extra = column_model(col)
                    for e, p in extra.items():
                        merged = dict(m[a].get(e, {}))
                        for k, v in p.items():
                            merged[k] = merged.get(k, 0.0) + v if k == col.parameter else v
                        m[a][e] = merged
        members.append(m)
    return members


def _with_member(sim: Simulated, extra: Simulated, column: dict[str, int]) -> Simulated:
    """``sim`` with member 0 of ``extra`` as column ``column[a]`` of the axes in ``column`` (the others kept)."""
    out = Simulated({}, {}, {}, {})
    for a in sim.fe:
        for name in ("fe", "current", "motor", "force"):
            arr = getattr(sim, name)[a]
            if a in column:
                arr = np.column_stack([arr[:, :column[a]], getattr(extra, name)[a][:, :1]])
            getattr(out, name)[a] = arr
    return out


def build(prep: Prepared, base: Model, lead_mm: dict[str, float], vertical: tuple[str, ...] = ("z",),
          channel_scales: bool = False) -> tuple[dict[str, AxisColumns], Simulated]:
    """Baseline replay, dynamic columns (one batched replay) and kinematic columns of every axis.

    ``channel_scales``: offer the scale error of each current channel (:func:`.library.channel_scale_variant`,
    the baseline's current as its column) to the selection, except where the current flat-tops below the
    model's limit (a saturation candidate).
    """
    variants = {a: candidate_variants(a, lead_mm[a], a in vertical) for a in prep.axes}
    dyn = {a: dynamic_columns(variants[a]) for a in prep.axes}
    members = _members(prep.axes, base, dyn)
    sim = simulate(prep.machine, prep.t, prep.commands, members, prep.t_start, twin=prep.twin_commands(),
                   disturbance=prep.disturbance, start=prep.start)
    # a current plateau below the model's limit: saturation candidate (member 0 is the baseline). Its member
    # is replayed on its own: every member of a batched replay is its solo run bit for bit, whatever the rest
    saturation: Model = {}
    for a in prep.axes:
        cur = prep.current[a]
        if cur is None:
            continue
        sig = noise_floor((cur - sim.current[a][:, 0])[prep.valid])
        limit = plateau_limit(cur[prep.valid], sim.current[a][prep.valid, 0], sig)
        if limit is not None:
            col = Column(f"current_saturation.switch@limit_A={limit:.4g}", "current_saturation", "switch",
                         (("limit_A", limit),), "dynamic", 1.0)
            variants[a].append(Variant("current_saturation", (col,), {"limit_A": limit}))
            dyn[a].append(col)
            saturation[a] = {**{e: dict(p) for e, p in base.get(a, {}).items()},
                             "current_saturation": {"limit_A": limit}}
    if saturation:
        extra = simulate(prep.machine, prep.t, prep.commands,
                         [{a: saturation.get(a, {e: dict(p) for e, p in base.get(a, {}).items()}) for a in prep.axes}],
                         prep.t_start, twin=prep.twin_commands(), disturbance=prep.disturbance, start=prep.start)
        sim = _with_member(sim, extra, {a: len(dyn[a]) for a in saturation})
    out: dict[str, AxisColumns] = {}
    v = prep.valid
    for a in prep.axes:
        fe_meas = prep.fe[a]
        rows_fe = np.flatnonzero(v & np.isfinite(fe_meas))
        r_fe = fe_meas[rows_fe] - sim.fe[a][rows_fe, 0]
        # a standing axis read through a quantised encoder gives a residual that is mostly exactly 0: its
        # noise is then the quantisation's, q / sqrt(12), not the (vanishing) spread of its differences
        q_fe = max(POSITION_QUANTUM_UM, 1e3 * recorded_quantum(prep.recording[f"{a}_mm"]))
        s_fe = noise_floor(r_fe, q_fe)
        cur = prep.current[a]
        if cur is not None:
            rows_tc = np.flatnonzero(v & np.isfinite(cur))
            r_tc = cur[rows_tc] - sim.current[a][rows_tc, 0]
            s_tc = noise_floor(r_tc, max(CURRENT_QUANTUM_A, recorded_quantum(cur)))
        else:
            rows_tc, r_tc, s_tc = np.zeros(0, int), np.zeros(0), float("nan")
        nf, nt = rows_fe.size, rows_tc.size

        def stacked(fe_col: np.ndarray | None, tc_col: np.ndarray | None) -> np.ndarray:
            top = np.zeros(nf) if fe_col is None else fe_col[rows_fe] / s_fe
            bottom = np.zeros(nt) if (tc_col is None or nt == 0) else tc_col[rows_tc] / s_tc
            return np.concatenate([top, bottom])

        cols: dict[str, np.ndarray] = {}
        for j, col in enumerate(dyn[a]):
            fe_c = (sim.fe[a][:, j + 1] - sim.fe[a][:, 0]) / col.unit
            tc_c = (sim.current[a][:, j + 1] - sim.current[a][:, 0]) / col.unit
            cols[col.key] = stacked(fe_c, tc_c)
        motor, force = sim.motor[a][:, 0], sim.force[a][:, 0]
        for var in variants[a]:
            for col in var.columns:
                if col.kind == "kinematic" and col.key not in cols:
                    cols[col.key] = stacked(kinematic_fe(col, prep.t, motor, force), None)
        if channel_scales and cur is not None and a not in saturation:
            # (not next to a saturation candidate: the linearised clip leaves residuals a scale mops up, and
            # the refit that drops such leftovers does not see the channel's scale)
            scale = channel_scale_variant(a)
            cols[scale.columns[0].key] = stacked(None, sim.current[a][:, 0])   # recorded = (1 + c) x replayed
            variants[a].append(scale)
        artefacts = {f"{a}_mm offset": stacked(-np.ones_like(prep.t), None)}  # x_mm = true + o -> fe - o
        if cur is not None and a in ("x", "y"):
            artefacts[f"{a}_tcmd_A offset"] = stacked(None, np.ones_like(prep.t))
        if True:
            # servo-clock phase / residual logger offset: the response shifted by s [ms] (first order)
            table_rate = np.gradient(prep.commands[a] - sim.fe[a][:, 0] * 1e-6, prep.t) * 1e6 * 1e-3
            cur_rate = -np.gradient(sim.current[a][:, 0], prep.t) * 1e-3
            artefacts["time shift ms"] = stacked(table_rate, cur_rate if cur is not None else None)
        y = np.concatenate([r_fe / s_fe, r_tc / s_tc if nt else np.zeros(0)])
        out[a] = AxisColumns(rows_fe, rows_tc, s_fe, s_tc, y, cols, artefacts, variants[a])
    return out, sim
