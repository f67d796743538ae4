"""Refit of the cutting coefficients and the chosen cutting effects by batched force replays.

Levenberg-Marquardt as :mod:`.refit` (drives): the weighted residual of fx
and fy over the force noise floor; the Jacobian by forward differences from
one batched replay per iteration (member 0 at the current point, member
``i`` with parameter ``i`` moved); the alignment columns (dynamometer
offsets, spindle-phase drift) projected out of every residual.
``Kt``, ``Ke`` and the spindle phase (an alignment quantity, now nonlinear:
an effect that moves the force pulse, such as a helix, may have pulled the
phase scan) are always free. The spindle droop is linear in the
``spindle_rpm`` rows and is refitted by least squares on the final model's
torque. 90 % intervals: Gauss-Newton covariance inflated by
``(1 + rho) / (1 - rho)`` for the lag-1 autocorrelation ``rho`` of the
residual.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np

from .align import residual_autocorrelation
from .cutting import CuttingColumns, CuttingData, CuttingModel, lagged_torque

#: (effect, parameter) -> (step, lower, upper, relative step?)
STEPS: dict[tuple[str, str], tuple[float, float, float, bool]] = {
    ("alignment", "spindle_phase_deg"): (0.5, -30.0, 30.0, False),
    ("coefficients", "kt_N_per_m2"): (0.01, 1e7, 1e11, True),
    ("coefficients", "ke"): (0.02, 0.0, 3.0, False),
    ("runout", "eccentricity_um"): (0.5, 0.0, 500.0, False),
    ("runout", "phase_deg"): (4.0, -720.0, 720.0, False),
    ("helix_angle", "helix_deg"): (2.0, 0.0, 75.0, False),
    ("edge_force", "kte_N_per_mm"): (1.0, 0.0, 1e4, False),
    ("edge_force", "kre_N_per_mm"): (1.0, 0.0, 1e4, False),
    ("tool_deflection", "stiffness_N_per_um"): (0.05, 0.05, 1e5, True),
    ("tool_wear", "rate_percent_per_min"): (2.0, 0.0, 1e4, False),
}
MAX_ITERATIONS = 6
RTOL = 1e-3
#: Artefacts that stay linear (projected out); the coefficients are refit parameters.
PROJECTED = ("fx_N offset", "fy_N offset", "spindle phase drift")


@dataclass
class CuttingRefit:
    """Outcome of :func:`refit_cutting`.

    Attributes
    ----------
    model : CuttingModel
    parameters : list of (effect, name)
    values, ci90 : ndarray
    cost_start, cost_end : float
    log : list of str
    """

    model: CuttingModel
    parameters: list[tuple[str, str]]
    values: np.ndarray
    ci90: np.ndarray
    cost_start: float
    cost_end: float
    log: list[str] = field(default_factory=list)


def fixed_by_flutes(flutes: int) -> tuple[tuple[str, str], ...]:
    """Effect parameters the forces of a ``flutes``-tooth tool cannot tell apart, held at their start value.

    Two teeth sit half a turn apart: runout ``rho`` at phase ``lambda`` moves them by ``+-rho cos(lambda)``, so
    the chips change by ``+-2 rho cos(lambda)`` and nothing else (:func:`.cutting_library.cutting_variants`
    fits that one column). Refitting the phase too leaves a Jacobian column ``-rho sin(lambda)`` that is zero at
    the selection's start (phase 0 or 180 deg): the Gauss-Newton step along it is unbounded and the refit
    rejected every step (a 10 um runout stayed at the linear start, 8.9 um). The phase is held and ``rho`` is
    refitted as ``rho cos(lambda)``.
    """
    return (("runout", "phase_deg"),) if flutes == 2 else ()


def projector(cols: CuttingColumns) -> np.ndarray | None:
    """Force-row part of the projected artefact columns (offsets, spindle-phase drift)."""
    n = 2 * cols.rows.size
    names = [k for k in cols.artefacts if k in PROJECTED]
    return np.column_stack([cols.artefacts[k][:n] for k in names]) if names else None


def force_residual(data: CuttingData, cols: CuttingColumns, fx: np.ndarray, fy: np.ndarray,
                   proj: np.ndarray | None) -> np.ndarray:
    """Weighted force residual of one replay member on the compared rows, artefacts projected out."""
    rows = cols.rows
    r = np.concatenate([data.measured[rows, 0] - fx[rows], data.measured[rows, 1] - fy[rows]]) / data.sigma
    if proj is not None:
        coef, *_ = np.linalg.lstsq(proj, r, rcond=None)
        r = r - proj @ coef
    return r


def _get(model: CuttingModel, p: tuple[str, str]) -> float:
    return float(model.get(p[0], {}).get(p[1], 0.0))


def refit_cutting(data: CuttingData, cols: CuttingColumns, start: CuttingModel,
                  max_iterations: int = MAX_ITERATIONS, say=lambda m: None) -> CuttingRefit:
    """Levenberg-Marquardt refit of the force model (see module docstring)."""
    free = [("coefficients", "kt_N_per_m2"), ("coefficients", "ke"), ("alignment", "spindle_phase_deg")]
    start = copy.deepcopy(start)
    start.setdefault("alignment", {}).setdefault("spindle_phase_deg", 0.0)
    for e, params in start.items():
        if e in ("coefficients", "alignment", "spindle_droop", "chatter"):
            continue
        free += [(e, k) for k in params if (e, k) in STEPS and (e, k) not in fixed_by_flutes(data.flutes)]
    proj = projector(cols)
    theta = np.array([_get(start, p) for p in free])
    bounds = np.array([STEPS[p][1:3] for p in free])
    log: list[str] = []

    def step(i: int, th: np.ndarray) -> float:
        s, lo, hi, rel = STEPS[free[i]]
        s = s * abs(th[i]) if rel else s
        s = max(s, 1e-12)
        return -s if th[i] + s > hi else s

    def models(th: np.ndarray, jac: bool) -> list[CuttingModel]:
        rows = [th] + ([th + np.eye(len(free))[i] * step(i, th) for i in range(len(free))] if jac else [])
        out = []
        for row in rows:
            m = copy.deepcopy(start)
            for p, v in zip(free, row):
                m.setdefault(p[0], {})[p[1]] = float(v)
            out.append(m)
        return out

    lam = 1e-3
    best = (np.inf, theta, None, None)
    cost_start = None
    for it in range(1, max_iterations + 1):
        say(f"cutting refit, iteration {it} ({len(free) + 1} replay members)")
        sim = data.run(models(theta, True))
        r0 = force_residual(data, cols, sim.fx[:, 0], sim.fy[:, 0], proj)
        cost = float(r0 @ r0)
        cost_start = cost if cost_start is None else cost_start
        if cost < best[0]:
            improvement = (best[0] - cost) / max(cost, 1e-12) if np.isfinite(best[0]) else np.inf
            jac = np.column_stack([(force_residual(data, cols, sim.fx[:, i + 1], sim.fy[:, i + 1], proj) - r0)
                                   / step(i, theta) for i in range(len(free))])
            best = (cost, theta, jac, r0)
            lam = max(lam / 3.0, 1e-6)
            log.append(f"cutting refit {it}: cost {cost:.6g} accepted")
            if improvement < RTOL:
                break
        else:
            lam *= 10.0
            log.append(f"cutting refit {it}: cost {cost:.6g} rejected (lambda {lam:.1e})")
        _, th_b, j, r_b = best
        jtj = j.T @ j
        delta = np.linalg.solve(jtj + lam * np.diag(np.maximum(np.diag(jtj), 1e-12)), -(j.T @ r_b))
        theta = np.clip(th_b + delta, bounds[:, 0], bounds[:, 1])
    cost_end, th_b, j, r_b = best
    final = copy.deepcopy(start)
    for p, v in zip(free, th_b):
        final.setdefault(p[0], {})[p[1]] = float(v)
    ci = np.full((len(free), 2), np.nan)
    if j is not None:
        n = r_b.size
        s2 = float(r_b @ r_b) / max(n - len(free), 1)
        rho = residual_autocorrelation(r_b)
        cov = np.linalg.pinv(j.T @ j) * s2 * (1.0 + rho) / (1.0 - rho)
        sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
        ci = np.column_stack([th_b - 1.645 * sd, th_b + 1.645 * sd])
    if "runout" in final:  # one eccentricity direction: rho >= 0, phase in (-180, 180]
        ph = final["runout"].get("phase_deg", 0.0)
        final["runout"]["phase_deg"] = float(-((-ph + 180.0) % 360.0 - 180.0))
    return CuttingRefit(final, free, th_b, ci, float(cost_start or 0.0), float(cost_end), log)


def refit_droop(data: CuttingData, torque_force_rows: np.ndarray) -> tuple[float, tuple[float, float], float]:
    """Droop [rpm/N.m] by least squares on ``spindle_rpm - spindle_ref_rpm = offset - k T_lagged``.

    Returns
    -------
    k, (lo, hi), offset
        The droop, its 90 % interval and the speed offset (alignment), rpm.
    """
    t_all = np.asarray(data.recording.t, float)
    tq = np.interp(t_all[data.spindle_rows], data.t, lagged_torque(data.t, torque_force_rows))
    x = np.column_stack([-tq, np.ones_like(tq)])
    y = data.spindle_residual
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    r = y - x @ coef
    s2 = float(r @ r) / max(y.size - 2, 1)
    rho = residual_autocorrelation(r)
    cov = np.linalg.pinv(x.T @ x) * s2 * (1.0 + rho) / (1.0 - rho)
    sd = math.sqrt(max(cov[0, 0], 0.0))
    return float(coef[0]), (float(coef[0] - 1.645 * sd), float(coef[0] + 1.645 * sd)), float(coef[1])
