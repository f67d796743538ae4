"""Refit: the selected effects' parameters together with the identified ones, by closed-loop replay.

Levenberg-Marquardt on the weighted, stacked residual of every diagnosed
axis (following error and current over their noise floors), with the
Jacobian by forward differences from **one batched replay per iteration**
(member 0 at the current point, member ``i`` with parameter ``i`` moved).
Recording artefacts (channel offsets, a residual time shift) are projected
out of the residual at every evaluation (variable projection), so they never
compete with physics. Nonlinear grid parameters chosen by the selection
(ripple and pitch periods) stay fixed; the reversal-friction decay, the
delay and the stiffness are free.

Confidence intervals (90 %) come from the Gauss-Newton covariance
``s^2 (J^T J)^-1`` inflated by ``(1 + rho) / (1 - rho)`` for the lag-1
autocorrelation ``rho`` of the final residual (correlated samples carry less
information than white ones).
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, field

import numpy as np

from .align import residual_autocorrelation
from .columns import AxisColumns
from .model import Model, Simulated, simulate
from .prepare import Prepared

#: Parameter -> (finite-difference step, lower bound, upper bound) in spec units.
STEPS: dict[tuple[str, str], tuple[float, float, float]] = {
    ("gravity", "force_N"): (5.0, -1e5, 1e5),
    ("gravity", "spring_N_per_mm"): (0.1, -1e3, 1e3),
    ("reversal_friction", "peak_N"): (5.0, 0.0, 1e5),
    ("reversal_friction", "decay_mm"): (0.005, 0.002, 10.0),
    ("friction_mismatch", "coulomb_N"): (5.0, -1e4, 1e4),
    ("friction_mismatch", "viscous_Ns_per_m"): (100.0, -1e5, 1e5),
    ("inertia_mismatch", "mass_kg"): (5.0, -1e4, 1e5),
    ("torque_ripple", "amplitude_N"): (2.0, -1e4, 1e4),
    ("velocity_feedforward", "gain"): (0.01, -1.0, 1.5),
    ("servo_delay", "delay_ms"): (0.05, 0.0, 20.0),
    ("backlash", "width_um"): (0.2, 0.0, 1e4),
    ("screw_compliance", "stiffness_N_per_um"): (5.0, 1.0, 1e5),
    ("pitch_error", "slope_um_per_m"): (1.0, -1e4, 1e4),
    ("pitch_error", "amplitude_um"): (0.2, -1e3, 1e3),
    ("thermal_drift", "rate_um_per_min"): (0.1, -1e4, 1e4),
    ("current_saturation", "limit_A"): (0.05, 0.1, 1e3),
    ("servo_scales", "Spp"): (0.005, 0.2, 5.0),
    ("servo_scales", "Svp"): (0.005, 0.2, 5.0),
    ("servo_scales", "Svi"): (0.005, 0.2, 5.0),
    ("command_shift", "shift_ms"): (0.02, -5.0, 5.0),
}

MAX_ITERATIONS = 8
#: Stop when an accepted step lowers the cost by less than this fraction.
RTOL = 1e-3


@dataclass(frozen=True)
class Parameter:
    """One refitted parameter."""

    axis: str
    effect: str
    name: str


@dataclass
class RefitResult:
    """Outcome of :func:`refit`.

    Attributes
    ----------
    model : Model
        Final model (spec units; mismatches as differences).
    parameters : list of Parameter
    values : ndarray
    ci90 : ndarray, shape (P, 2)
    cost_start, cost_end : float
        Weighted residual sum of squares at the start and at the end.
    iterations : int
    replays : int
    """

    model: Model
    parameters: list[Parameter]
    values: np.ndarray
    ci90: np.ndarray
    cost_start: float
    cost_end: float
    iterations: int
    replays: int
    log: list[str] = field(default_factory=list)
    projectors: dict = field(default_factory=dict, repr=False)


def _set(model: Model, p: Parameter, value: float) -> None:
    model.setdefault(p.axis, {}).setdefault(p.effect, {})[p.name] = float(value)


def projectors(cols: dict[str, AxisColumns], nonlinear_shift: tuple[str, ...] = ()) -> dict[str, np.ndarray | None]:
    """Artefact columns per axis; the linear time shift is left out where the shift is a refit parameter."""
    out: dict[str, np.ndarray | None] = {}
    for a, c in cols.items():
        names = [k for k in c.artefacts if not (k == "time shift ms" and a in nonlinear_shift)]
        out[a] = np.column_stack([c.artefacts[k] for k in names]) if names else None
    return out


def residuals(prep: Prepared, cols: dict[str, AxisColumns], sim: Simulated, member: int,
              projectors: dict[str, np.ndarray | None]) -> np.ndarray:
    """Weighted residual of one member, all axes stacked, artefacts projected out."""
    parts = []
    for a, c in cols.items():
        r_fe = (prep.fe[a][c.rows_fe] - sim.fe[a][c.rows_fe, member]) / c.sigma_fe
        if c.rows_tc.size:
            r_tc = (prep.current[a][c.rows_tc] - sim.current[a][c.rows_tc, member]) / c.sigma_tc
            r = np.concatenate([r_fe, r_tc])
        else:
            r = r_fe
        x = projectors[a]
        if x is not None:
            coef, *_ = np.linalg.lstsq(x, r, rcond=None)
            r = r - x @ coef
        parts.append(r)
    return np.concatenate(parts)


def artefact_values(prep: Prepared, cols: dict[str, AxisColumns], sim: Simulated, member: int = 0
                    ) -> dict[str, dict[str, float]]:
    """Fitted artefacts per axis (name -> value) for a simulation member."""
    out = {}
    for a, c in cols.items():
        r_fe = (prep.fe[a][c.rows_fe] - sim.fe[a][c.rows_fe, member]) / c.sigma_fe
        r = np.concatenate([r_fe, (prep.current[a][c.rows_tc] - sim.current[a][c.rows_tc, member]) / c.sigma_tc]
                           ) if c.rows_tc.size else r_fe
        if not c.artefacts:
            out[a] = {}
            continue
        coef, *_ = np.linalg.lstsq(np.column_stack(list(c.artefacts.values())), r, rcond=None)
        out[a] = dict(zip(c.artefacts, map(float, coef)))
    return out


#: Smallest moving mass a refit may give an axis, as a fraction of the parameter set's mass.
MIN_MASS_FRACTION = 0.1


def _bounds(prep: Prepared, p: Parameter) -> tuple[float, float]:
    """Box of a refitted parameter (spec units): :data:`STEPS`, and a mass difference that keeps the axis's
    moving mass above :data:`MIN_MASS_FRACTION` of the parameter set's (the replay rejects a mass <= 0)."""
    lo, hi = STEPS[(p.effect, p.name)][1:]
    if (p.effect, p.name) == ("inertia_mismatch", "mass_kg"):
        mass = float(prep.machine.values["axis"][p.axis]["mass_kg"])
        lo = max(lo, -(1.0 - MIN_MASS_FRACTION) * mass)
    return lo, hi


#: Trial delays per velocity-loop tick in :func:`_scan_delays`, on each side of the start value.
DELAY_SCAN_STEPS = 4


def _scan_delays(prep: Prepared, cols: dict[str, AxisColumns], start: Model, free: list[Parameter],
                 theta: np.ndarray, bounds: np.ndarray, steps: np.ndarray, proj: dict, twin: dict,
                 log: list[str]) -> tuple[np.ndarray, int]:
    """Start values of the servo delays: the best of a grid one velocity-loop tick either side, ``theta`` updated.

    The replays apply a delay of ``j + f`` velocity ticks as the commands of ticks ``j`` and ``j + 1`` back,
    mixed ``1 - f`` to ``f``. The residual is smooth in the delay within a tick and has a kink at every
    whole tick, where the mixing changes its pair. The selection's linear delay column is the response to one
    whole tick, so a delay between ticks comes out of it short, and another effect of the axis (an inertia)
    takes up the difference: a 0.3 ms delay on Y of an XY contour started the refit at 0.235 ms, a local
    minimum below the kink at 0.25 ms, and stopped there (22 % low, with a false 0.009 Z feed-forward; on
    other seeds 0.22 ms with a false -32 kg Y inertia). Each delay is tried at :data:`DELAY_SCAN_STEPS` points
    per tick, ``tv / 4``, up to one tick either side of its start, in one batched replay with one member per
    other free parameter stepped as in the refit's Jacobian: each trial's cost is its residual with the
    other parameters' linearised best correction projected out (so the inertia that made up for a short
    delay does not keep the delay short). The refit starts from the best trial, the other values unchanged.

    Returns
    -------
    theta : ndarray
        The start values with each delay at its best trial.
    replays : int
        Batched replays run.
    """
    tv_ms = float(prep.machine.si("servo")["velocity_loop_period"]) * 1e3
    replays = 0

    def model_at(values: np.ndarray) -> Model:
        m = copy.deepcopy(start)
        for q, v in zip(free, values):
            _set(m, q, v)
        return m

    for i, p in enumerate(free):
        if (p.effect, p.name) != ("servo_delay", "delay_ms"):
            continue
        trials = np.unique(np.clip(theta[i] + tv_ms / DELAY_SCAN_STEPS * np.arange(-DELAY_SCAN_STEPS,
                                                                                  DELAY_SCAN_STEPS + 1),
                                   bounds[i, 0], bounds[i, 1]))
        members = []
        for value in trials:
            row = theta.copy()
            row[i] = value
            members.append(model_at(row))
        others = [q for q in range(len(free)) if q != i]
        moved = []
        for q in others:
            row = theta.copy()
            h = -steps[q] if row[q] + steps[q] > bounds[q, 1] else steps[q]
            row[q] += h
            moved.append(h)
            members.append(model_at(row))
        sim = simulate(prep.machine, prep.t, prep.commands, members, prep.t_start, twin=twin,
                       disturbance=prep.disturbance, start=prep.start)
        replays += 1
        res = [residuals(prep, cols, sim, j, proj) for j in range(len(members))]
        at = int(np.flatnonzero(trials == theta[i])[0])
        jac = (np.column_stack([(res[trials.size + k] - res[at]) / moved[k] for k in range(len(others))])
               if others else None)
        costs = []
        for j in range(trials.size):
            r = res[j]
            if jac is not None:
                coef, *_ = np.linalg.lstsq(jac, r, rcond=None)
                r = r - jac @ coef
            costs.append(float(r @ r))
        best = int(np.argmin(costs))
        if best != at:
            log.append(f"[{p.axis}] servo delay start {theta[i]:.4g} ms -> {trials[best]:.4g} ms (best of "
                       f"{trials.size} trials a quarter velocity tick apart, the other parameters' linear "
                       "correction projected out)")
            theta = theta.copy()
            theta[i] = trials[best]
    return theta, replays


def refit(prep: Prepared, cols: dict[str, AxisColumns], start: Model, free: list[Parameter],
          max_iterations: int = MAX_ITERATIONS) -> RefitResult:
    """Levenberg-Marquardt refit of ``free`` parameters of ``start`` (see module docstring)."""
    proj = projectors(cols, tuple(p.axis for p in free if p.effect == "command_shift"))
    twin = prep.twin_commands()
    theta = np.array([start.get(p.axis, {}).get(p.effect, {}).get(p.name, 0.0) for p in free], dtype=float)
    bounds = np.array([_bounds(prep, p) for p in free]).reshape(-1, 2)
    steps = np.array([STEPS[(p.effect, p.name)][0] for p in free])
    theta = np.clip(theta, bounds[:, 0], bounds[:, 1])  # a selection estimate can lie outside (e.g. a mass < 0)
    log: list[str] = []
    theta, scans = _scan_delays(prep, cols, start, free, theta, bounds, steps, proj, twin, log)

    def models(th: np.ndarray, with_jacobian: bool) -> list[Model]:
        out = []
        rows = [th] + ([th + np.eye(len(free))[i] * _step(i, th) for i in range(len(free))] if with_jacobian else [])
        for row in rows:
            m = copy.deepcopy(start)
            for p, v in zip(free, row):
                _set(m, p, v)
            out.append(m)
        return out

    def _step(i: int, th: np.ndarray) -> float:
        s = steps[i]
        # step towards the inside of the box
        return -s if th[i] + s > bounds[i, 1] else s

    replays = scans
    lam = 1e-3
    cost_start = None
    best_theta, best_cost, best_jac, best_r = theta, np.inf, None, None
    it = 0
    for it in range(1, max_iterations + 1):
        if not free:
            break
        sim = simulate(prep.machine, prep.t, prep.commands, models(theta, True), prep.t_start, twin=twin,
                       disturbance=prep.disturbance, start=prep.start)
        replays += 1
        r0 = residuals(prep, cols, sim, 0, proj)
        cost = float(r0 @ r0)
        if cost_start is None:
            cost_start = cost
        if cost < best_cost:
            improvement = (best_cost - cost) / max(cost, 1e-12) if np.isfinite(best_cost) else np.inf
            best_theta, best_cost, best_r = theta, cost, r0
            best_jac = np.column_stack([(residuals(prep, cols, sim, i + 1, proj) - r0) / _step(i, theta)
                                        for i in range(len(free))])
            lam = max(lam / 3.0, 1e-6)
            log.append(f"iteration {it}: cost {cost:.6g} accepted")
            if improvement < RTOL:
                break
        else:
            lam *= 10.0
            log.append(f"iteration {it}: cost {cost:.6g} rejected (lambda {lam:.1e})")
        j = best_jac
        jtj = j.T @ j
        g = j.T @ best_r
        delta = np.linalg.solve(jtj + lam * np.diag(np.maximum(np.diag(jtj), 1e-12)), -g)
        theta = np.clip(best_theta + delta, bounds[:, 0], bounds[:, 1])
    final = copy.deepcopy(start)
    for p, v in zip(free, best_theta):
        _set(final, p, v)
    ci = np.full((len(free), 2), np.nan)
    if free and best_jac is not None:
        n = best_r.size
        dof = max(n - len(free), 1)
        s2 = float(best_r @ best_r) / dof
        rho = residual_autocorrelation(best_r)
        inflation = (1.0 + rho) / (1.0 - rho)
        try:
            cov = np.linalg.pinv(best_jac.T @ best_jac) * s2 * inflation
            sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
            ci = np.column_stack([best_theta - 1.645 * sd, best_theta + 1.645 * sd])
        except np.linalg.LinAlgError:
            pass
    return RefitResult(final, free, best_theta, ci, float(cost_start or 0.0),
                       float(best_cost if np.isfinite(best_cost) else 0.0), it, replays, log, proj)
