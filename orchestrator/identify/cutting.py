"""Cutting-coefficient identification: Kt and Ke from measured forces (Sim & Lee 2023, Eq. 14-16).

The twin's own :class:`fmus_src.cutting.CuttingLoad` is driven with the
**recorded** actual tool positions (lightly smoothed: encoder quantisation
would otherwise enter the chip thickness through the feed per tooth) and the
recorded spindle speed, on the case's stock and tool, so the engagement is
exactly the one the twin computes for that program.

The force is linear in ``Kt`` and in ``Kt Ke``::

    F(t) = Kt A(t) + Kt Ke B(t),   A = F(Kt=1, Ke=0),  B = F(Kt=1, Ke=1) - A

so one batched run gives ``A`` and ``B`` for every candidate. The spindle
angle at the start of the recording is unknown (no encoder phase is logged):
it is estimated by a coarse scan over one tooth pitch (``phases``
members), a fine scan with a parabolic fit, and (with fx, fy) Gauss-Newton
steps using the force derivative with respect to the phase, then a final run
at that phase. Samples taken within
2 degrees of a tooth entering or leaving the material are not used: the
force jumps there, and a micrometre of position error (encoder quantisation
at a wall) or a small phase error swaps full force for zero.

``"default"``
    With ``fx_N`` and ``fy_N``: linear least squares for ``(Kt, Kt Ke)``
    (exact, no iterations). With only ``fc_N``: nonlinear least squares on
    ``Fc = Kt |A + Ke B|`` (trust region, from a linear initial guess).
``"paper-ga"``
    pymoo GA on ``J = sum e^2 + max |e|`` of the cutting load ``Fc``
    (Eq. 14-16), 500 generations at most, fitness limit 1 N^2, at the
    estimated spindle phase.
"""
from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import savgol_filter

from fmus_src.cutting import CuttingLoad

from ..case import Case
from ..twin import cutting_parameters
from .common import fitted_machine, provenance, write_outputs
from .data import CaseData, check_columns, first_row_place, load_inputs, row_places
from .errors import IdentificationError
from .ga import paper_objective, run_ga
from .journal import Journal

_log = logging.getLogger(__name__)

#: Kt of the unit runs, N/m2 (a realistic magnitude keeps every threshold of the component meaningful).
KT_UNIT = 1.0e9
PAPER_GENERATIONS = 500
PAPER_FITNESS_LIMIT = 1.0
#: Spindle-angle margin around tooth entry/exit within which samples are not used, rad (2 degrees).
BOUNDARY_PHASE = math.radians(2.0)
#: Gauss-Newton refinements of the spindle phase after the scans (fx, fy recordings).
PHASE_REFINEMENTS = 2


@dataclass
class _Prepared:
    """One case: samples, measured forces and the basis forces A, B at the estimated phase."""

    data: CaseData
    t: np.ndarray
    measured: dict[str, np.ndarray]   # "fx", "fy" and/or "fc", N
    a: np.ndarray                     # (n, 2) basis A (fx, fy), N per (N/m2) * KT_UNIT
    b: np.ndarray                     # (n, 2)
    mask: np.ndarray                  # samples used in the fit
    phase: float


@dataclass
class CuttingFit:
    """Result of :func:`identify_cutting` (attributes ending in ``_``).

    Attributes
    ----------
    kt_ : float
        Tangential cutting coefficient, N/m2.
    ke_ : float
        Radial / tangential ratio.
    fitness_ : float
        ``J = sum e^2 + max |e|`` of the cutting load ``Fc`` (Eq. 14), N^2.
    rms_ : dict
        Residual RMS of ``fc`` (and ``fx``, ``fy`` when measured), N.
    spindle_phase_ : list of float
        Estimated initial spindle angle per case, rad.
    iterations_ : int
    machine_ : Machine
    provenance_ : dict
    material : str
    method : str
    wall_time_ : float
    traces_ : list of dict
        Per case: ``t``, measured and simulated ``fc`` (for plots).
    notes_ : list of str
        Warnings (e.g. Kt, Ke not separately identifiable from ``fc`` alone) and rows left out because a
        needed cell was empty (not measured), per stream (``report.json`` -> ``notes``).
    """

    kt_: float
    ke_: float
    fitness_: float
    rms_: dict[str, float]
    spindle_phase_: list[float]
    iterations_: int
    machine_: object
    provenance_: dict[str, str]
    material: str
    method: str
    wall_time_: float
    cases: list[str] = field(default_factory=list)
    traces_: list[dict] = field(default_factory=list, repr=False)
    notes_: list[str] = field(default_factory=list)

    def report(self) -> dict:
        """JSON-ready report."""
        return {"kind": "cutting", "method": self.method, "cases": self.cases, "material": self.material,
                "notes": self.notes_, "kt_N_per_m2": self.kt_, "ke": self.ke_, "fitness_J_N2": self.fitness_,
                "residual_rms_N": self.rms_, "spindle_phase_rad": self.spindle_phase_,
                "iterations": self.iterations_, "wall_time_s": self.wall_time_}

    def write(self, out: str | Path, plots: bool = True) -> dict[str, Path]:
        """Write ``machine.toml``, ``report.json`` and ``cutting_load.png`` (Fig. 6c style)."""
        files = write_outputs(out, self.machine_, self.provenance_, self.report())
        if plots:
            from .plots import cutting_png

            files["cutting_load"] = cutting_png(self, Path(out) / "cutting_load.png")
        return files


def smooth_positions(t: np.ndarray, x: np.ndarray, window_s: float) -> np.ndarray:
    """Savitzky-Golay smoothing (quadratic, ``window_s``) when sampling is uniform within 1 %, else ``x``."""
    dt = np.diff(t)
    if window_s <= 0.0 or dt.size < 5 or np.ptp(dt) > 0.01 * np.median(dt):
        return x
    n = int(round(window_s / float(np.median(dt)))) | 1
    if n < 5 or n > x.size:
        return x
    return savgol_filter(x, n, 2, mode="interp")


def _columns(d: CaseData) -> tuple[str, list[str]]:
    rec = d.recording
    spindle = "spindle_rpm" if "spindle_rpm" in rec else "spindle_ref_rpm"
    forces = ["fx_N", "fy_N"] if ("fx_N" in rec and "fy_N" in rec) else (["fc_N"] if "fc_N" in rec else [])
    if not forces:
        raise IdentificationError(
            f"{d.source}: cutting identification needs measured forces: 'fx_N' and 'fy_N' (dynamometer) or at "
            f"least 'fc_N'; the recording has {rec.channels}"
        )
    if d.case.stock is None:
        raise IdentificationError(f"{d.case.source or d.case.folder}: cutting identification needs the [stock] block "
                                  "of the workpiece in case.toml (min, max in mm)")
    return spindle, forces


def cutting_samples(d: CaseData, notes: list[str] | None = None) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Times [s] and the columns cutting identification uses, on common rows.

    A controller log and a dynamometer log merged into one file (``fx_N``, ``fy_N`` at 10 kHz, positions at
    1 ms, an empty cell where one side has no sample) are two streams: the fit runs on the rows of the
    sparser one, with the denser one linearly interpolated there (rows outside the other stream's time
    span, or in a gap of more than 5 of its median sampling steps, are not used). A recording in which
    every row has every column is used as it is.

    A row with only part of a stream (e.g. ``fx_N`` without ``fy_N``: the logger dropped one cell, an
    empty cell is "not measured") is left out of that stream, as friction and servo identification leave
    out incomplete rows; each such stream adds a line to ``notes`` (and a log warning) when ``notes`` is given.

    Parameters
    ----------
    d : CaseData
        The case and its recording.
    notes : list of str, optional
        Receives ``"file:line: N of M row(s) with only part of ... left out ..."`` per stream concerned.

    Returns
    -------
    t : ndarray, shape (n,)
        Times, s.
    columns : dict
        ``x_mm``, ``y_mm``, ``z_mm``, the spindle speed column and the force columns, each shape (n,).

    Raises
    ------
    IdentificationError
        A missing column, a stream with fewer than 3 complete rows (naming the file and the columns), or
        streams that do not overlap in time.
    """
    rec = d.recording
    spindle, forces = _columns(d)
    kinematic = ["x_mm", "y_mm", "z_mm", spindle]
    check_columns(rec, ["t_s"], "cutting identification")
    missing = [c for c in kinematic if c not in rec]
    if missing:
        raise IdentificationError(f"{d.source}: cutting identification needs column(s) {missing}; the recording has "
                                  f"{rec.channels}")
    t = np.asarray(rec.t, dtype=float)
    cols = {c: np.asarray(rec[c], dtype=float) for c in kinematic + forces}
    streams = {"positions and spindle speed": kinematic, "forces": forces}
    full = {}
    for name, names in streams.items():
        have = np.array([np.isfinite(cols[c]) for c in names])
        partial = have.any(axis=0) & ~have.all(axis=0)
        full[name] = have.all(axis=0)
        if full[name].sum() < 3:
            raise IdentificationError(f"{d.source}: cutting identification needs {name} ({names}) measured together "
                                      f"in at least 3 rows; the recording has them all in {int(full[name].sum())} "
                                      "(an empty cell is 'not measured')")
        if partial.any():
            empty = [c for c, h in zip(names, have) if not h[partial].all()]
            note = (f"{first_row_place(rec, partial)}: {int(partial.sum())} of {len(rec)} row(s) with only "
                    f"part of the {name} ({' / '.join(empty)} empty: not measured) left out of cutting identification "
                    f"({row_places(rec, partial)})")
            if notes is not None:
                _log.warning("%s", note)
                notes.append(note)
    kin, frc = full["positions and spindle speed"], full["forces"]
    if (kin & frc).all():
        return t, cols
    # two streams: the rows of the sparser one, the denser one interpolated there
    (base, mine), (other, _) = sorted([(frc, forces), (kin, kinematic)], key=lambda item: int(item[0].sum()))
    to = t[other]
    tb = t[base]
    gap = 5.0 * float(np.median(np.diff(to)))
    k = np.clip(np.searchsorted(to, tb), 1, to.size - 1)
    usable = (tb >= to[0]) & (tb <= to[-1]) & (to[k] - to[k - 1] <= gap)
    if usable.sum() < 3:
        raise IdentificationError(
            f"{d.source}: the forces ({int(frc.sum())} rows, {t[frc][0]:.6g} to {t[frc][-1]:.6g} s) and the "
            f"positions ({int(kin.sum())} rows, {t[kin][0]:.6g} to {t[kin][-1]:.6g} s) do not overlap in time")
    rows = np.flatnonzero(base)[usable]
    out = {}
    for c, v in cols.items():
        out[c] = v[rows] if c in mine else np.interp(t[rows], to, v[other])
    return t[rows], out


def basis_forces(d: CaseData, phases: np.ndarray, smooth_s: float,
                 position_lag_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Forces of the unit runs at spindle phases ``phases``: ``A``, ``B`` of shape (n, P, 2) [N at Kt = KT_UNIT].

    ``position_lag_s``: the component at sample ``t`` gets the recorded position at ``t - position_lag_s``.
    """
    spindle, _ = _columns(d)
    t, cols = cutting_samples(d)
    pos = np.stack([smooth_positions(t, cols[f"{a}_mm"], smooth_s) * 1e-3 for a in "xyz"], 1)
    if position_lag_s > 0.0:
        pos = np.stack([np.interp(t - position_lag_s, t, pos[:, i]) for i in range(3)], 1)
    omega = np.maximum(cols[spindle], 0.0) * (2.0 * math.pi / 60.0)
    p = phases.size
    params = cutting_parameters(d.case)
    params.update(kt=KT_UNIT, ke=np.tile([0.0, 1.0], p), initial_spindle_angle=np.repeat(phases, 2))
    comp = CuttingLoad("cutting", batch=2 * p, **params)
    for i, a in enumerate("xyz"):
        comp.set(f"{a}_position", pos[0, i])
    comp.setup(float(t[0]))
    n = t.size
    fx = np.zeros((n, 2 * p))
    fy = np.zeros((n, 2 * p))
    v = comp.values
    for k in range(n - 1):
        for i, a in enumerate("xyz"):
            v[f"{a}_position"][...] = pos[k + 1, i]
        v["spindle_speed"][...] = omega[k + 1]
        comp.do_step(float(t[k]), float(t[k + 1] - t[k]))
        fx[k + 1] = v["fx"]
        fy[k + 1] = v["fy"]
    f = np.stack([fx, fy], axis=-1).reshape(n, p, 2, 2)  # (n, phase, ke, xy)
    return f[:, :, 0, :], f[:, :, 1, :] - f[:, :, 0, :]


def _linear_fit(
    meas: dict[str, np.ndarray], a: np.ndarray, b: np.ndarray, mask: np.ndarray
) -> tuple[np.ndarray, float]:
    """(Kt/KT_UNIT, Kt Ke/KT_UNIT) and the SSE: least squares on fx, fy, or on fc with Ke from a 1-D scan."""
    if "fx" in meas:
        y = np.concatenate([meas["fx"][mask], meas["fy"][mask]])
        x = np.column_stack([np.concatenate([a[mask, 0], a[mask, 1]]), np.concatenate([b[mask, 0], b[mask, 1]])])
        c, *_ = np.linalg.lstsq(x, y, rcond=None)
        r = y - x @ c
        return c, float(r @ r)
    fc = meas["fc"][mask]
    best = (np.array([0.0, 0.0]), math.inf)
    for ke in np.linspace(0.0, 2.0, 81):
        g = np.hypot(a[mask, 0] + ke * b[mask, 0], a[mask, 1] + ke * b[mask, 1])
        kt = float(g @ fc / max(g @ g, 1e-300))
        r = fc - kt * g
        sse = float(r @ r)
        if sse < best[1]:
            best = (np.array([kt, kt * ke]), sse)
    return best


def _scan(meas: dict[str, np.ndarray], a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Trimmed SSE (largest 5 % of squared residuals dropped: entry/exit samples) per phase column."""
    out = []
    for j in range(a.shape[1]):
        c, _ = _linear_fit(meas, a[:, j], b[:, j], mask)
        if "fx" in meas:
            r = np.concatenate([meas["fx"][mask] - a[mask, j, 0] * c[0] - b[mask, j, 0] * c[1],
                                meas["fy"][mask] - a[mask, j, 1] * c[0] - b[mask, j, 1] * c[1]])
        else:
            ke = c[1] / c[0] if c[0] else 0.0
            g = np.hypot(a[mask, j, 0] + ke * b[mask, j, 0], a[mask, j, 1] + ke * b[mask, j, 1])
            r = meas["fc"][mask] - c[0] * g
        r2 = np.sort(r * r)
        out.append(float(r2[: max(1, int(0.95 * r2.size))].sum()))
    return np.array(out)


def _parabola_min(x: np.ndarray, y: np.ndarray) -> float:
    """Abscissa of the minimum of the parabola through the lowest sample and its neighbours (x equally spaced)."""
    j = int(np.argmin(y))
    if j == 0 or j == y.size - 1:
        return float(x[j])
    denom = y[j - 1] - 2.0 * y[j] + y[j + 1]
    shift = 0.5 * (y[j - 1] - y[j + 1]) / denom if denom > 0 else 0.0
    return float(x[j] + np.clip(shift, -1.0, 1.0) * (x[1] - x[0]))


def _prepare(d: CaseData, phases: int, smooth_s: float, position_lag_s: float, journal: Journal,
             index: int = 0, notes: list[str] | None = None) -> _Prepared:
    rec = d.recording

    def unit_runs(angles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:func:`basis_forces` of this case, journaled (a resumed job reads them back)."""
        return journal.memo("cutting.basis_forces", (index, angles, smooth_s, position_lag_s),
                            lambda: basis_forces(d, angles, smooth_s, position_lag_s))

    _, forces = _columns(d)
    t, cols = cutting_samples(d, notes)
    meas = {"fx": cols["fx_N"], "fy": cols["fy_N"]} if "fx_N" in forces else {"fc": cols["fc_N"]}
    flutes = int(d.case.tool.flutes)
    pitch = 2.0 * math.pi / flutes
    step = pitch / phases
    grid = np.arange(-1, phases + 1) * step  # coarse scan, wrapped by one step on each side
    a, b = unit_runs(grid[1:-1])
    engaged = np.any(np.abs(a).sum(axis=2) > 0.0, axis=1)
    if int(engaged.sum()) < 10:
        raise IdentificationError(
            f"{d.source}: the recorded tool path cuts the stock of {d.case.source} in {int(engaged.sum())} samples; "
            "expected a cut (check that positions are in work coordinates and [stock] matches the block)"
        )
    sse = _scan(meas, a, b, engaged)
    centre = grid[1 + int(np.argmin(sse))]
    fine = centre + np.linspace(-step, step, 9)  # fine scan around the best coarse phase
    a, b = unit_runs(fine)
    phase = float(np.mod(_parabola_min(fine, _scan(meas, a, b, engaged)), pitch))
    # final run at the phase and at +-BOUNDARY_PHASE: a sample whose engagement changes within that margin
    # sits on a tooth entry/exit (a force jump) and is dropped; a few microns of position error or a
    # slightly wrong phase would otherwise swap full force and zero there
    margins = np.array([0.0, -BOUNDARY_PHASE, BOUNDARY_PHASE])
    for refine in range(PHASE_REFINEMENTS + 1):
        a3, b3 = unit_runs(phase + margins)
        inside = np.abs(a3).sum(axis=2) > 0.0
        robust = inside.all(axis=1)
        if int(robust.sum()) < 10:
            robust = inside[:, 0]
        if refine == PHASE_REFINEMENTS or "fx" not in meas:
            break
        # Gauss-Newton step on the phase: F(phi + d) ~ Kt (A + d A') + Kt Ke (B + d B'), linear in
        # (Kt, Kt Ke, Kt d, Kt Ke d) with A', B' from the +-margin runs (Ke is sensitive to the phase:
        # one degree of error moves it by about 5 %)
        da = (a3[:, 2] - a3[:, 1]) / (2.0 * BOUNDARY_PHASE)
        db = (b3[:, 2] - b3[:, 1]) / (2.0 * BOUNDARY_PHASE)
        m = robust
        y = np.concatenate([meas["fx"][m], meas["fy"][m]])
        x = np.column_stack([np.concatenate([q[m, 0], q[m, 1]]) for q in (a3[:, 0], b3[:, 0], da, db)])
        c, *_ = np.linalg.lstsq(x, y, rcond=None)
        if c[0] == 0.0:
            break
        # the phase and Ke are nearly collinear in a single cut geometry: take the step only when it is
        # statistically significant (|Kt d| > 3 standard errors), else noise would move Ke through it
        r = y - x @ c
        dof = max(y.size - 4, 1)
        cov = np.linalg.pinv(x.T @ x) * float(r @ r) / dof
        if abs(c[2]) <= 3.0 * math.sqrt(max(cov[2, 2], 0.0)):
            break
        delta = float(np.clip(c[2] / c[0], -0.5 * step, 0.5 * step))
        phase = float(np.mod(phase + delta, pitch))
        if abs(delta) < 1e-5:
            break
    return _Prepared(d, t, meas, a3[:, 0], b3[:, 0], robust, phase)


def identify_cutting(
    cases: Iterable[str | Path | Case],
    method: str = "default",
    seed: int = 0,
    phases: int = 12,
    smooth_s: float = 0.021,
    position_lag_s: float = 0.0,
    journal: Journal | None = None,
) -> CuttingFit:
    """Identify the cutting coefficients Kt, Ke of the case's material.

    Parameters
    ----------
    cases : iterable of case folders / ``case.toml`` / Case
        Cuts in a block (``cnctwin experiment cutting``) with ``t_s``,
        ``x_mm``, ``y_mm``, ``z_mm`` (work coordinates), ``spindle_rpm`` (or
        ``spindle_ref_rpm``) and ``fx_N``, ``fy_N`` (or ``fc_N``); the case
        gives stock and tool.
    method : {"default", "paper-ga"}
    seed : int
        GA seed.
    phases : int
        Spindle-phase candidates over one tooth pitch.
    smooth_s : float
        Savitzky-Golay window on the recorded positions, s (0 = none).
    position_lag_s : float
        Age of the position the recorded force belongs to, s (default 0: the
        twin's convention, cutting load stepped after the drives). It only
        matters at tooth entry/exit (a few µm of path).
    journal : Journal, optional
        Records each batched cutting run (phase scans) and the GA for checkpoints and resume
        (see :func:`orchestrator.identify.identify`).

    Returns
    -------
    CuttingFit
    """
    start = time.perf_counter()
    data = load_inputs(cases)
    journal = journal or Journal()
    notes: list[str] = []
    prepared = [_prepare(d, phases, smooth_s, position_lag_s, journal, i, notes) for i, d in enumerate(data)]
    use_xy = all("fx" in p.measured for p in prepared)

    def stack(fn) -> np.ndarray:
        return np.concatenate([fn(p) for p in prepared])

    a_all = stack(lambda p: p.a[p.mask])
    b_all = stack(lambda p: p.b[p.mask])
    if use_xy:
        meas_all = {"fx": stack(lambda p: p.measured["fx"][p.mask]), "fy": stack(lambda p: p.measured["fy"][p.mask])}
        fc_meas = np.hypot(meas_all["fx"], meas_all["fy"])
    else:
        fc_meas = stack(lambda p: (p.measured["fc"] if "fc" in p.measured
                                   else np.hypot(p.measured["fx"], p.measured["fy"]))[p.mask])
        meas_all = {"fc": fc_meas}
    full = np.ones(a_all.shape[0], dtype=bool)
    c, _ = _linear_fit(meas_all, a_all, b_all, full)
    iterations = 1

    def fc_model(kt: np.ndarray, ke: np.ndarray) -> np.ndarray:
        return np.abs(kt)[..., None] * np.hypot(a_all[:, 0] + ke[..., None] * b_all[:, 0],
                                                a_all[:, 1] + ke[..., None] * b_all[:, 1])

    if method == "default":
        kt, ke = float(c[0]), float(c[1] / c[0]) if c[0] != 0 else 0.0
        if not use_xy:
            sol = least_squares(lambda z: fc_meas - fc_model(np.array(z[0]), np.array(z[1])), [kt, ke],
                                method="trf", x_scale=[max(abs(kt), 1e-3), 0.1])
            kt, ke, iterations = float(sol.x[0]), float(sol.x[1]), int(sol.nfev)
            # with at most one tooth in the cut |Ft + Fr| = Kt d h sqrt(1 + Ke^2): only that product is
            # identifiable from Fc; detect it from the conditioning of the scaled Jacobian
            jac = sol.jac * np.array([abs(kt), max(abs(ke), 0.1)])
            sv = np.linalg.svd(jac, compute_uv=False)
            if sv[-1] < 1e-3 * sv[0]:
                ke_prior = float(data[0].case.machine.si(f"material.{data[0].case.material}")["ke"]) \
                    if data[0].case.material else 0.5
                g = fc_model(np.array(1.0), np.array(ke_prior))
                kt_fixed = float(g @ fc_meas / (g @ g))
                notes.append(
                    f"Kt and Ke are not separately identifiable from fc alone here (at most one tooth in the cut: "
                    f"Fc = Kt d h sqrt(1 + Ke^2)); Ke kept at the machine-file value {ke_prior:g}, Kt fitted "
                    f"(Kt sqrt(1 + Ke^2) = {kt * np.hypot(1.0, ke) * KT_UNIT:.4g} N/m2 is what the data fix). "
                    "Record fx and fy to identify both."
                )
                kt, ke = kt_fixed, ke_prior
    elif method == "paper-ga":
        res = journal.memo("cutting.ga", (seed, fc_meas, a_all, b_all), lambda: run_ga(
            lambda x: paper_objective(fc_meas[None, :] - fc_model(x[:, 0], x[:, 1])),
            np.array([0.1, 0.0]), np.array([10.0, 2.0]), PAPER_GENERATIONS, PAPER_FITNESS_LIMIT, seed=seed))
        kt, ke, iterations = float(res.x[0]), float(res.x[1]), res.generations
    else:
        raise IdentificationError(f"unknown cutting method {method!r}; expected 'default' or 'paper-ga'")
    fc_fit = fc_model(np.array(kt), np.array(ke))
    e = fc_meas - fc_fit
    rms = {"fc": float(np.sqrt(np.mean(e * e)))}
    if use_xy:
        for i, name in enumerate(("fx", "fy")):
            r = meas_all[name] - kt * (a_all[:, i] + ke * b_all[:, i])
            rms[name] = float(np.sqrt(np.mean(r * r)))
    traces = []
    for p in prepared:
        sim = kt * (p.a + ke * p.b)
        meas_fc = p.measured["fc"] if "fc" in p.measured else np.hypot(p.measured["fx"], p.measured["fy"])
        traces.append({"case": p.data.name, "t": p.t, "fc_meas": meas_fc, "fc_sim": np.hypot(sim[:, 0], sim[:, 1])})
    material = data[0].case.material or "A6061"
    names = [d.name for d in data]
    source = provenance(f"cutting {method} ({'fx, fy linear least squares' if use_xy else 'fc'}, "
                        "engagement of the twin's CuttingLoad on the recorded path, Eq. 14-16)", names)
    fitted, extra = fitted_machine(data[0].case.machine, {f"material.{material}": {
        "kt_N_per_m2": kt * KT_UNIT, "ke": ke}}, source, "cutting")
    if method == "paper-ga":
        notes.append("the GA fits Fc (Eq. 16); with at most one tooth in the cut only Kt sqrt(1 + Ke^2) is "
                     "determined by Fc, so Kt and Ke individually may be far off")
    return CuttingFit(kt * KT_UNIT, ke, float(paper_objective(e)), rms, [p.phase for p in prepared], iterations,
                      fitted, extra, material, method, time.perf_counter() - start, names, traces, notes)
