"""Servo identification: scale factors Spp, Svp, Svi per axis (Sim & Lee 2023, Eq. 7-9).

The closed loop (the twin's MCU and DriveAxis, :mod:`.closed_loop`) is
replayed with the **recorded** reference positions and compared with the
recorded following error ``e = ref - actual`` and current command ``Atc``.
Friction, masses and nominal gains come from the machine file (identify
friction first and pass that file).

Residuals per sample and axis, with weights ``w1`` [1/µm] and ``w2`` [1/A]
(default: the reciprocal RMS of the measured channel, so both count alike)::

    default   r = [ w1 (e - e_sim) ; w2 (Atc - Atc_sim) ]      (stacked)
    paper-ga  eG = w1 (e - e_sim) + w2 (Atc - Atc_sim)        (Eq. 9, summed)

and the reported fitness is ``J = sum r^2 + max |r|`` (Eq. 7) of the
stacked residual for both methods. The paper's summed form lets the two
errors cancel each other; stacking them cannot, which is why the default
uses it.

``"default"``
    Trust-region least squares (scipy) on ``log S`` starting from ``Spp``
    estimated from the steady-state following error of the constant-velocity
    windows, with the Jacobian from one batched replay per iteration (members:
    the point and one perturbation per factor, all axes at once).
``"paper-ga"``
    pymoo GA, population 50, at most 100 generations, fitness limit 10
    (Section 2.3); one GA per axis in lockstep, one batched replay (B = 50)
    per generation.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np
from scipy.optimize import least_squares

from ..case import Case
from ..machine import Machine, load_machine
from .closed_loop import replay
from .common import fitted_machine, provenance, write_outputs
from .data import CaseData, check_columns, load_inputs
from .errors import IdentificationError
from .ga import paper_objective, run_ga_lockstep
from .journal import Journal
from .segments import SegmentSettings, find_segments

FACTORS = ("position_scale", "velocity_p_scale", "velocity_i_scale")
SYMBOLS = ("Spp", "Svp", "Svi")
PAPER_GENERATIONS = 100
PAPER_FITNESS_LIMIT = 10.0
#: Search box of the scale factors.
BOUNDS = (0.2, 5.0)


@dataclass
class _Series:
    """One case, prepared: times, references, measured error and current per axis."""

    data: CaseData
    t: np.ndarray
    ref: dict[str, np.ndarray]        # m
    x0: dict[str, float]              # m
    e: dict[str, np.ndarray]          # µm
    cur: dict[str, np.ndarray]        # A


@dataclass
class ServoFit:
    """Result of :func:`identify_servo` (attributes ending in ``_``).

    Attributes
    ----------
    scales_ : dict
        ``scales_[axis] = {"Spp": ..., "Svp": ..., "Svi": ...}``.
    fitness_ : dict
        Axis -> ``J = sum r^2 + max |r|`` of the stacked weighted residual.
    rms_ : dict
        Axis -> ``{"following_error_um": ..., "current_A": ...}`` residual RMS.
    weights_ : dict
        Axis -> ``(w1 [1/µm], w2 [1/A])``.
    iterations_ : int
        Optimiser iterations (generations for the GA).
    simulations_ : int
        Batched closed-loop replays run.
    machine_ : Machine
    provenance_ : dict
    method : str
    wall_time_ : float
    traces_ : list of dict
        Per case: ``t``, and per axis measured / simulated error and current (for plots).
    """

    scales_: dict[str, dict[str, float]]
    fitness_: dict[str, float]
    rms_: dict[str, dict[str, float]]
    weights_: dict[str, tuple[float, float]]
    iterations_: int
    simulations_: int
    machine_: Machine
    provenance_: dict[str, str]
    method: str
    wall_time_: float
    cases: list[str] = field(default_factory=list)
    traces_: list[dict] = field(default_factory=list, repr=False)

    def report(self) -> dict:
        """JSON-ready report."""
        return {
            "kind": "servo", "method": self.method, "cases": self.cases, "wall_time_s": self.wall_time_,
            "iterations": self.iterations_, "batched_simulations": self.simulations_,
            "axes": {a: {**self.scales_[a], "fitness_J": self.fitness_[a],
                         "residual_rms_following_error_um": self.rms_[a]["following_error_um"],
                         "residual_rms_current_A": self.rms_[a]["current_A"],
                         "w1_per_um": self.weights_[a][0], "w2_per_A": self.weights_[a][1]}
                     for a in self.scales_},
        }

    def write(self, out: str | Path, plots: bool = True) -> dict[str, Path]:
        """Write ``machine.toml``, ``report.json`` and ``servo_<axis>.png`` (Fig. 5 style)."""
        files = write_outputs(out, self.machine_, self.provenance_, self.report())
        if plots:
            from .plots import servo_png

            for a in self.scales_:
                files[f"servo_{a}"] = servo_png(self, a, Path(out) / f"servo_{a}.png")
        return files


def _prepare(data: Sequence[CaseData], axes: Sequence[str] | None) -> tuple[list[_Series], list[str]]:
    series, used = [], []
    for d in data:
        rec = d.recording
        present = [a for a in "xyz" if all(f"{a}{s}" in rec for s in ("_ref_mm", "_mm", "_tcmd_A"))]
        want = list(axes) if axes else present
        if not want:
            raise IdentificationError(
                f"{d.source}: servo identification needs '<axis>_ref_mm', '<axis>_mm' and '<axis>_tcmd_A' of at "
                f"least one axis; the recording has {rec.channels}"
            )
        moving = []
        for a in want:
            check_columns(rec, ["t_s", f"{a}_ref_mm", f"{a}_mm", f"{a}_tcmd_A"], f"servo identification of axis {a}")
            if np.ptp(rec[f"{a}_ref_mm"]) > 1e-3:
                moving.append(a)
            elif axes:
                raise IdentificationError(f"{d.source}: axis {a} does not move (reference range below 1 µm)")
        if not moving:
            continue
        t = np.asarray(rec.t, dtype=float)
        series.append(_Series(
            d, t,
            {a: np.asarray(rec[f"{a}_ref_mm"]) * 1e-3 for a in moving},
            {a: float(rec[f"{a}_mm"][0]) * 1e-3 for a in moving},
            {a: np.asarray(rec.following_error_um(a), dtype=float) for a in moving},
            {a: np.asarray(rec[f"{a}_tcmd_A"], dtype=float) for a in moving},
        ))
        used += [a for a in moving if a not in used]
    if not series:
        raise IdentificationError(
            f"{', '.join(d.source for d in data)}: no axis moves; expected reciprocating runs "
            "(`cnctwin experiment servo`)"
        )
    return series, used


def _simulate(machine: Machine, series: _Series, scales: dict[str, np.ndarray]) -> tuple[dict, dict]:
    """Replay one case with per-member scale factors ``scales[axis]`` of shape (B, 3)."""
    batch = next(iter(scales.values())).shape[0]
    mcu = {f"{a}_{name}": scales[a][:, j] for a in series.ref for j, name in enumerate(FACTORS) if a in scales}
    run = replay(machine, series.t, series.ref, batch=batch, mcu_values=mcu, initial_position=series.x0)
    e = {a: (series.ref[a][:, None] - run.position[a]) * 1e6 for a in series.ref}
    return e, run.current


def _initial_spp(machine: Machine, series: list[_Series], axis: str) -> float:
    """``Spp`` from steady following error ``e = v / (Pp Spp)`` on constant-velocity windows."""
    pp = float(machine.si(f"axis.{axis}")["position_gain"])
    gains = []
    for s in series:
        if axis not in s.ref:
            continue
        rec = s.data.recording
        for seg in find_segments(rec, axis, 1.0, SegmentSettings(settle_s=0.1)):
            sel = (s.t >= seg.t_start) & (s.t <= seg.t_end)
            e = float(np.mean(s.e[axis][sel])) * 1e-6
            if abs(seg.velocity) > 1e-5 and e * seg.velocity > 0:
                gains.append(seg.velocity / e / pp)
    return float(np.clip(np.median(gains), *BOUNDS)) if gains else 1.0


def identify_servo(
    cases: Iterable[str | Path | Case],
    method: str = "default",
    seed: int = 0,
    axes: Sequence[str] | None = None,
    machine: str | Path | Machine | None = None,
    weights: tuple[float, float] | None = None,
    max_iterations: int = 30,
    journal: Journal | None = None,
) -> ServoFit:
    """Identify the servo scale factors Spp, Svp, Svi per axis.

    Parameters
    ----------
    cases : iterable of case folders / ``case.toml`` / Case
        Reciprocating runs (``cnctwin experiment servo``) with ``t_s``,
        ``{a}_ref_mm``, ``{a}_mm``, ``{a}_tcmd_A``.
    method : {"default", "paper-ga"}
    seed : int
        GA seed.
    axes : sequence of str, optional
        Axes to identify (default: every recorded axis that moves).
    machine : name, path or Machine, optional
        Parameters used in the replay (friction, masses, nominal gains) and
        written back with the fitted factors; default the first case's.
    weights : (w1, w2), optional
        ``w1`` [1/µm], ``w2`` [1/A] of Eq. (9); default the reciprocal RMS
        of the measured following error and current of each axis.
    max_iterations : int
        Iteration cap of the default optimiser.
    journal : Journal, optional
        Records the result of every batched replay (residuals and Jacobian of a
        least-squares evaluation, fitness of a GA generation) for checkpoints
        and resume (see :func:`orchestrator.identify.identify`).

    Returns
    -------
    ServoFit
    """
    start = time.perf_counter()
    data = load_inputs(cases)
    base = machine if isinstance(machine, Machine) else (
        load_machine(machine) if machine is not None else data[0].case.machine)
    series, used = _prepare(data, axes)
    w: dict[str, tuple[float, float]] = {}
    for a in used:
        e_all = np.concatenate([s.e[a] for s in series if a in s.e])
        c_all = np.concatenate([s.cur[a] for s in series if a in s.cur])
        w[a] = weights or (1.0 / max(float(np.sqrt(np.mean(e_all ** 2))), 1e-3),
                           1.0 / max(float(np.sqrt(np.mean(c_all ** 2))), 1e-3))
    counter = {"sims": 0}
    journal = journal or Journal()

    def residuals(scales: dict[str, np.ndarray], summed: bool = False) -> dict[str, np.ndarray]:
        """Weighted residuals per axis, shape (B, m_a)."""
        parts: dict[str, list[np.ndarray]] = {a: [] for a in used}
        for s in series:
            sub = {a: scales[a] for a in s.ref}
            e_sim, c_sim = _simulate(base, s, sub)
            for a in s.ref:
                de = w[a][0] * (s.e[a][:, None] - e_sim[a]).T
                dc = w[a][1] * (s.cur[a][:, None] - c_sim[a]).T
                parts[a].append(de + dc if summed else np.concatenate([de, dc], axis=1))
        return {a: np.concatenate(p, axis=1) for a, p in parts.items()}

    def journaled(stage: str, key: object, compute):
        """One batched replay of every case, read back from the journal when a resumed job already did it."""
        counter["sims"] += len(series)
        return journal.memo(stage, key, compute)

    if method == "default":
        scales, iterations = _fit_least_squares(base, series, used, residuals, max_iterations, journaled)
    elif method == "paper-ga":
        scales, iterations = _fit_ga(used, residuals, seed, journaled)
    else:
        raise IdentificationError(f"unknown servo method {method!r}; expected 'default' or 'paper-ga'")

    counter["sims"] += len(series)
    final = residuals({a: scales[a][None, :] for a in used})
    fitness, rms = {}, {}
    for a in used:
        r = final[a][0]
        half = r.size // 2
        fitness[a] = float(paper_objective(r))
        rms[a] = {"following_error_um": float(np.sqrt(np.mean(r[:half] ** 2)) / w[a][0]),
                  "current_A": float(np.sqrt(np.mean(r[half:] ** 2)) / w[a][1])}
    traces = []
    for s in series:
        counter["sims"] += 1
        e_sim, c_sim = _simulate(base, s, {a: scales[a][None, :] for a in s.ref})
        traces.append({"case": s.data.name, "t": s.t, "ref_mm": {a: s.ref[a] * 1e3 for a in s.ref},
                       "e_meas": s.e, "e_sim": {a: e_sim[a][:, 0] for a in s.ref},
                       "cur_meas": s.cur, "cur_sim": {a: c_sim[a][:, 0] for a in s.ref}})
    names = [d.name for d in data]
    source = provenance(f"servo {method} (closed-loop replay of recorded references, Eq. 7-9)", names)
    updates = {f"axis.{a}": {f: float(scales[a][j]) for j, f in enumerate(FACTORS)} for a in used}
    fitted, extra = fitted_machine(base, updates, source, "servo")
    return ServoFit(
        {a: dict(zip(SYMBOLS, map(float, scales[a]))) for a in used}, fitness, rms, w, iterations,
        counter["sims"], fitted, extra, method, time.perf_counter() - start, names, traces,
    )


def _fit_least_squares(base, series, used, residuals, max_iterations, journaled) -> tuple[dict[str, np.ndarray], int]:
    z0 = np.concatenate([[np.log(_initial_spp(base, series, a)), 0.0, 0.0] for a in used])
    step = 1e-3
    cache: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}

    def evaluate(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        key = np.round(z, 12).tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = journaled("servo.least_squares", np.round(z, 12), lambda: residuals_and_jacobian(z))
        return cache[key]

    def residuals_and_jacobian(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residual vector at ``z`` and its forward-difference Jacobian: one batched replay of 4 members."""
        scales = {}
        for i, a in enumerate(used):
            zz = np.tile(z[3 * i:3 * i + 3], (4, 1))
            zz[1:] += step * np.eye(3)
            scales[a] = np.exp(zz)
        r = residuals(scales)
        vec = np.concatenate([r[a][0] for a in used])
        jac = np.zeros((vec.size, z.size))
        row = 0
        for i, a in enumerate(used):
            m = r[a].shape[1]
            jac[row:row + m, 3 * i:3 * i + 3] = ((r[a][1:] - r[a][0]) / step).T
            row += m
        return vec, jac

    lo, hi = np.log(BOUNDS[0]), np.log(BOUNDS[1])
    z0 = np.clip(z0, lo + 1e-6, hi - 1e-6)
    sol = least_squares(lambda z: evaluate(z)[0], z0, jac=lambda z: evaluate(z)[1], bounds=(lo, hi),
                        method="trf", x_scale=1.0, xtol=1e-8, ftol=1e-10, gtol=1e-10, max_nfev=max_iterations)
    return {a: np.exp(sol.x[3 * i:3 * i + 3]) for i, a in enumerate(used)}, int(sol.nfev)


def _fit_ga(used, residuals, seed, journaled) -> tuple[dict[str, np.ndarray], int]:
    bounds = [(np.full(3, BOUNDS[0]), np.full(3, BOUNDS[1])) for _ in used]
    def evaluate(xs: list[np.ndarray]) -> list[np.ndarray]:
        # an axis whose GA has stopped gets filler members (factors 1), evaluated and ignored
        p = max(x.shape[0] for x in xs)
        scales = {a: (np.vstack([x, np.ones((p - x.shape[0], 3))]) if x.shape[0] < p else x)
                  for a, x in zip(used, xs)}
        r = residuals(scales, summed=True)
        return [paper_objective(r[a])[: x.shape[0]] for a, x in zip(used, xs)]

    def evaluate_generation(xs: list[np.ndarray]) -> list[np.ndarray]:
        """The fitness of one generation of every axis's GA (journaled: the small fitness arrays only)."""
        return journaled("servo.ga_generation", list(xs), lambda: evaluate(xs))

    results = run_ga_lockstep(evaluate_generation, bounds, PAPER_GENERATIONS, PAPER_FITNESS_LIMIT, seed=seed)
    return {a: res.x for a, res in zip(used, results)}, max(res.generations for res in results)
