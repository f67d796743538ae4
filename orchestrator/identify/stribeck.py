"""Fitting the Stribeck curve of one axis and direction (Sim & Lee 2023, Eq. 3-6).

Model, for a speed ``v >= 0`` (magnitudes, one direction)::

    F(v) = mu_v v + Fc + (Fs - Fc) exp(-v / vs)

Two optimisers of the paper's fitness ``J = sum e^2 + max |e|`` (Eq. 4):

``"default"``
    *Variable projection*: for fixed ``vs`` the model is linear in
    ``(mu_v, Fc, Fs - Fc)``, solved exactly by least squares; ``vs`` is
    found by a log-spaced scan (global) followed by a bounded scalar search.
    The least-squares solution then seeds a Nelder-Mead search on ``J``
    itself (the ``max |e|`` term is not smooth). Deterministic, a few ms.
``"paper-ga"``
    The paper's method: a genetic algorithm (pymoo) on ``J`` with 500
    generations at most and a fitness limit of 100 N^2 (Section 2.2).
    ``vs`` is searched on a log scale (the one liberty taken: with a linear
    scale the GA almost never samples the sub-mm/s values that matter).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, asdict

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from .errors import IdentificationError
from .ga import paper_objective, run_ga

#: Paper settings of the friction GA (Section 2.2).
PAPER_GENERATIONS = 500
PAPER_FITNESS_LIMIT = 100.0


@dataclass(frozen=True)
class StribeckFit:
    """Fitted Stribeck branch of one axis and direction (magnitudes, SI).

    Attributes
    ----------
    coulomb, static, stribeck_velocity, viscous : float
        ``Fc`` [N], ``Fs`` [N], ``vs`` [m/s], ``mu_v`` [N.s/m].
    fitness : float
        ``J = sum e^2 + max |e|`` [N^2] at the solution.
    rms : float
        RMS residual [N].
    iterations : int
        Optimiser iterations (GA generations, or scan + polish steps).
    evaluations : int
        Model evaluations (points x candidates / points).
    wall_time : float
        Seconds.
    points : int
        Stribeck points used.
    """

    coulomb: float
    static: float
    stribeck_velocity: float
    viscous: float
    fitness: float
    rms: float
    iterations: int
    evaluations: int
    wall_time: float
    points: int

    def force(self, speed: np.ndarray) -> np.ndarray:
        """Model friction magnitude [N] at speeds ``speed`` [m/s] (>= 0)."""
        return stribeck_curve(np.asarray(speed, dtype=float), self.coulomb, self.static,
                              self.stribeck_velocity, self.viscous)

    def to_dict(self) -> dict:
        """Plain dict (JSON-ready)."""
        return asdict(self)


def stribeck_curve(speed: np.ndarray, fc: np.ndarray | float, fs: np.ndarray | float,
                   vs: np.ndarray | float, mu: np.ndarray | float) -> np.ndarray:
    """Eq. (3) for non-negative speeds; parameters broadcast against ``speed`` (e.g. (P, 1) vs (N,))."""
    return mu * speed + fc + (fs - fc) * np.exp(-speed / vs)


def _linear_solve(speed: np.ndarray, force: np.ndarray, vs: float) -> tuple[np.ndarray, float]:
    """Least squares of ``(mu_v, Fc, Fs - Fc)`` for fixed ``vs``; returns the coefficients and sum e^2."""
    a = np.column_stack([speed, np.ones_like(speed), np.exp(-speed / vs)])
    coef, *_ = np.linalg.lstsq(a, force, rcond=None)
    r = force - a @ coef
    return coef, float(r @ r)


def _check_points(speed: np.ndarray, force: np.ndarray, label: str) -> None:
    if speed.size < 4:
        raise IdentificationError(
            f"{label}: {speed.size} Stribeck point(s); fitting Fc, Fs, vs, mu_v needs at least 4 constant-velocity "
            "segments at different speeds (the experiment program runs 16 speeds from 10 to 10000 mm/min)"
        )
    if np.unique(np.round(np.log10(speed), 2)).size < 4:
        raise IdentificationError(f"{label}: the Stribeck points span fewer than 4 distinct speeds; need at least 4")


#: A Stribeck point counts as inside the Stribeck region below this multiple of ``vs``.
STRIBECK_REGION = 3.0


def _check_identified(speed: np.ndarray, force: np.ndarray, x: np.ndarray, label: str) -> None:
    """Refuse a fit whose ``Fs`` and ``vs`` the points do not determine (no residual, or no point in the hump).

    With 4 points the 4 parameters fit any data exactly; with no two points below about ``3 vs`` (a log
    that misses the slow runs: started late, or slow plateaus too short to be detected) the hump
    ``(Fs - Fc) exp(-v / vs)`` is an extrapolation, and the optimiser trades it against ``Fc`` and ``mu_v``
    (seen: Fs = 3e8 N, vs = 0.35 m/s, with a residual of 0.2 N). A hump smaller than the scatter of the
    points (``Fs = Fc``: no Stribeck effect) needs no ``vs`` and is accepted.
    """
    fc, fs, vs, mu = (float(v) for v in x)
    vmin, vmax = float(speed.min()), float(speed.max())
    slow = int(np.sum(speed <= STRIBECK_REGION * vs))
    line = np.polyfit(speed, force, 1) if speed.size >= 2 else np.array([0.0, float(np.mean(force))])
    scatter = float(np.std(force - np.polyval(line, speed)))
    hump = abs(fs - fc)
    problems = []
    if speed.size <= 4:
        problems.append(f"{speed.size} points fit the 4 parameters exactly, with no residual to judge them by; "
                        "at least 5 speeds are needed")
    elif hump > max(0.01 * abs(fc), 1e-9) and (slow < 2 or vs > vmax / STRIBECK_REGION or fs <= 0.0):
        problems.append(f"only {slow} point(s) lie in the Stribeck region (below {STRIBECK_REGION:g} vs), "
                        f"so Fs and vs are extrapolated")
    if not problems:
        return
    raise IdentificationError(
        f"{label}: Fs and vs are not determined by the constant-velocity segments found: {problems[0]} "
        f"(fitted Fc {fc:.4g} N, Fs {fs:.4g} N, vs {vs * 6e4:.4g} mm/min, mu_v {mu:.4g} N.s/m). "
        f"The segments span {vmin * 6e4:.3g} to {vmax * 6e4:.3g} mm/min "
        f"(a straight line Fc + mu_v v through them: Fc {line[1]:.4g} N, mu_v {line[0]:.4g} N.s/m, "
        f"scatter {scatter:.3g} N). Log the whole experiment, with runs down to 10 mm/min and constant-velocity "
        "windows long enough to be detected (`cnctwin experiment friction`, plateau 1 s)"
    )


def fit_stribeck(
    speed: np.ndarray,
    force: np.ndarray,
    method: str = "default",
    seed: int = 0,
    label: str = "friction",
) -> StribeckFit:
    """Fit Eq. (3) to Stribeck points of one direction.

    Parameters
    ----------
    speed : ndarray, shape (N,)
        Speed magnitudes [m/s], > 0.
    force : ndarray, shape (N,)
        Friction magnitudes [N] (driving force at constant velocity).
    method : {"default", "paper-ga"}
        Optimiser (see module docstring).
    seed : int
        Seed of the GA.
    label : str
        For error messages (``"case: axis x positive"``).

    Returns
    -------
    StribeckFit
    """
    speed = np.asarray(speed, dtype=float)
    force = np.asarray(force, dtype=float)
    _check_points(speed, force, label)
    start = time.perf_counter()
    if method == "default":
        x, iterations, evaluations = _fit_varpro(speed, force)
    elif method == "paper-ga":
        x, iterations, evaluations = _fit_ga(speed, force, seed)
    else:
        raise IdentificationError(f"unknown friction method {method!r}; expected 'default' or 'paper-ga'")
    fc, fs, vs, mu = x
    e = force - stribeck_curve(speed, fc, fs, vs, mu)
    _check_identified(speed, force, x, label)
    return StribeckFit(
        coulomb=float(fc), static=float(fs), stribeck_velocity=float(vs), viscous=float(mu),
        fitness=float(paper_objective(e)), rms=float(np.sqrt(np.mean(e * e))),
        iterations=iterations, evaluations=evaluations, wall_time=time.perf_counter() - start, points=speed.size,
    )


def _fit_varpro(speed: np.ndarray, force: np.ndarray) -> tuple[np.ndarray, int, int]:
    vmin, vmax = float(speed.min()), float(speed.max())
    lo, hi = np.log(vmin / 20.0), np.log(vmax)
    grid = np.linspace(lo, hi, 120)
    sse = np.array([_linear_solve(speed, force, np.exp(g))[1] for g in grid])
    k = int(np.argmin(sse))
    a, b = grid[max(k - 1, 0)], grid[min(k + 1, grid.size - 1)]
    res = minimize_scalar(lambda g: _linear_solve(speed, force, np.exp(g))[1], bounds=(a, b), method="bounded",
                          options={"xatol": 1e-6})
    vs = float(np.exp(res.x))
    (mu, fc, delta), _ = _linear_solve(speed, force, vs)
    x0 = np.array([fc, fc + delta, vs, mu])
    evaluations = (grid.size + int(res.nfev)) * speed.size
    # polish the paper's J in scaled coordinates (log vs), starting at the least-squares optimum
    scale = np.array([max(abs(fc), 1.0), max(abs(fc + delta), 1.0), 1.0, max(abs(mu), 1.0)])

    def unpack(z: np.ndarray) -> np.ndarray:
        return np.array([z[0] * scale[0], z[1] * scale[1], np.exp(z[2]), z[3] * scale[3]])

    def objective(z: np.ndarray) -> float:
        fc_, fs_, vs_, mu_ = unpack(z)
        return float(paper_objective(force - stribeck_curve(speed, fc_, fs_, vs_, mu_)))

    z0 = np.array([x0[0] / scale[0], x0[1] / scale[1], np.log(vs), x0[3] / scale[3]])
    polish = minimize(objective, z0, method="Nelder-Mead",
                      options={"xatol": 1e-9, "fatol": 1e-9, "maxiter": 4000, "maxfev": 8000})
    best = unpack(polish.x) if polish.fun <= objective(z0) else x0
    return best, grid.size + int(res.nit) + int(polish.nit), evaluations + int(polish.nfev) * speed.size


def _fit_ga(speed: np.ndarray, force: np.ndarray, seed: int) -> tuple[np.ndarray, int, int]:
    fmax = float(np.max(np.abs(force)))
    vmax = float(speed.max())
    lower = np.array([0.0, 0.0, np.log10(1e-5), 0.0])
    upper = np.array([1.5 * fmax, 2.0 * fmax, np.log10(0.05), 2.0 * fmax / vmax])

    def fitness(x: np.ndarray) -> np.ndarray:
        pred = stribeck_curve(speed[None, :], x[:, 0:1], x[:, 1:2], 10.0 ** x[:, 2:3], x[:, 3:4])
        return paper_objective(force[None, :] - pred)

    res = run_ga(fitness, lower, upper, PAPER_GENERATIONS, PAPER_FITNESS_LIMIT, seed=seed)
    x = res.x.copy()
    x[2] = 10.0 ** x[2]
    return x, res.generations, res.evaluations * speed.size
