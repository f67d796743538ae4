"""Naming the missing physics: sparse regression of the residual on a library of effect columns.

Per axis, rows are the compared samples of the following error and of the
current command, each divided by its noise floor (so both channels count in
units of their noise). Columns are the linearised responses of the candidate
effects (:mod:`.library`); recording artefacts (channel offsets, a residual
time shift) are always in the model and never reported as physics.

Forward stepwise selection over effects (one variant per effect) with the
Bayesian information criterion **and** two minimum gains, then a backward
pass that drops any effect the others made redundant:

* ``BIC = n ln(RSS / n) + p ln n`` must fall by more than :data:`BIC_MARGIN`;
* the RSS must fall by at least :data:`MIN_GAIN` x ``n`` (the effect must
  explain ``sqrt(MIN_GAIN)`` noise floors RMS, whatever the file length — the
  BIC alone would accept irrelevant terms on 10^5 correlated samples);
* and by at least :data:`MIN_SHARE` of the residual power above the noise
  (``RSS - n``), so that fragments of a large unexplained residual are not
  mistaken for small effects.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .library import Variant

BIC_MARGIN = 10.0
MIN_GAIN = 0.03
MIN_SHARE = 0.05

#: Coefficients that must be positive to be physical.
POSITIVE = {("backlash", "width_um"), ("screw_compliance", "compliance_um_per_N"),
            ("reversal_friction", "peak_N"), ("servo_delay", "delay_ms"),
            ("helix_angle", "scale"), ("edge_force", "kte_N_per_mm"), ("tool_deflection", "compliance_um_per_N"),
            ("tool_wear", "rate_percent_per_min"), ("spindle_droop", "rpm_per_Nm")}


@dataclass
class Choice:
    """A selected effect variant with its linear coefficients and evidence.

    Attributes
    ----------
    variant : Variant
    coefficients : dict
        Linear parameter -> value (spec units).
    delta_bic : float
        BIC without this effect minus BIC with it (all others kept), > 0.
    gain : float
        RSS reduction (in noise-floor units) when added last.
    contribution : ndarray
        Its fitted part of the stacked, weighted residual (rows as the design).
    """

    variant: Variant
    coefficients: dict[str, float]
    delta_bic: float = 0.0
    gain: float = 0.0
    contribution: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)


@dataclass
class Selection:
    """Outcome of :func:`select` for one axis."""

    choices: list[Choice]
    artefacts: dict[str, float]
    rss_before: float
    rss_after: float
    n: int
    log: list[str]


def _fit(y: np.ndarray, cols: list[np.ndarray]) -> tuple[np.ndarray, float]:
    if not cols:
        return np.zeros(0), float(y @ y)
    x = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(x, y, rcond=None)
    r = y - x @ coef
    return coef, float(r @ r)


def _bic(rss: float, n: int, p: int) -> float:
    return n * np.log(max(rss, 1e-300) / n) + p * np.log(n)


def select(y: np.ndarray, artefacts: dict[str, np.ndarray], variants: list[Variant],
           columns: dict[str, np.ndarray], rows: int | None = None) -> Selection:
    """Forward-backward selection of effects explaining the weighted residual ``y``.

    Parameters
    ----------
    y : ndarray, shape (n,)
        Weighted residual (measured - simulated, divided by the noise floor).
    artefacts : dict name -> ndarray (n,)
        Always-fitted artefact columns.
    variants : list of Variant
        Candidates.
    columns : dict column key -> ndarray (n,)
        Weighted columns of the variants (per unit of their parameter).
    rows : int, optional
        The number of samples the minimum gains are counted per (default ``y.size``): rows left out of
        ``y`` (the held current of loaded axes) still count, so that leaving them out does not lower the
        bar for the rest.
    """
    n = y.size if rows is None else int(rows)
    art_names = list(artefacts)
    art_cols = [artefacts[k] for k in art_names]
    log: list[str] = []

    fits: dict[tuple[str, ...], tuple[np.ndarray, float]] = {}

    def fit_set(chosen: list[Variant]) -> tuple[np.ndarray, float]:
        key = tuple(c.key for v in chosen for c in v.columns)
        if key not in fits:  # the forward, backward and final passes fit some sets twice
            fits[key] = _fit(y, art_cols + [columns[k] for k in key])
        return fits[key]

    def admissible(chosen: list[Variant], coef: np.ndarray) -> bool:
        i = len(art_cols)
        for v in chosen:
            for c in v.columns:
                if (c.effect, c.parameter) in POSITIVE and coef[i] <= 0.0:
                    return False
                i += 1
        return True

    chosen: list[Variant] = []
    _, rss0 = fit_set([])
    rss = rss0
    p0 = len(art_cols)
    while True:
        best = None
        taken = {v.effect for v in chosen}
        for v in variants:
            if v.effect in taken or any(c.key not in columns for c in v.columns):
                continue
            coef, r = fit_set(chosen + [v])
            if not admissible(chosen + [v], coef):
                continue
            b = _bic(r, n, p0 + sum(len(w.columns) for w in chosen) + len(v.columns))
            if best is None or b < best[0]:
                best = (b, v, r)
        if best is None:
            break
        b, v, r = best
        b_now = _bic(rss, n, p0 + sum(len(w.columns) for w in chosen))
        gain = rss - r
        excess = rss - n
        ok = (b < b_now - BIC_MARGIN) and gain >= MIN_GAIN * n and gain >= MIN_SHARE * max(excess, 0.0)
        share = f"{gain / excess:.2f}" if excess > 1e-6 * n else "- (no excess over the noise)"
        log.append(f"best next {v.label}: dBIC {b - b_now:.1f}, gain {gain / n:.3f} n, "
                   f"share {share} -> {'accept' if ok else 'stop'}")
        if not ok:
            break
        chosen.append(v)
        rss = r
    # backward pass: drop effects made redundant by later ones
    changed = True
    while changed and chosen:
        changed = False
        for v in list(chosen):
            rest = [w for w in chosen if w is not v]
            coef, r = fit_set(rest)
            p_rest = p0 + sum(len(w.columns) for w in rest)
            loss = r - rss
            if (_bic(r, n, p_rest) - _bic(rss, n, p_rest + len(v.columns)) < BIC_MARGIN
                    or loss < MIN_GAIN * n) and admissible(rest, coef):
                log.append(f"drop {v.label}: redundant (loss {loss / n:.3f} n)")
                chosen = rest
                rss = r
                changed = True
                break
    coef, rss = fit_set(chosen)
    artefact_values = {k: float(coef[i]) for i, k in enumerate(art_names)}
    out: list[Choice] = []
    i = len(art_cols)
    p_all = p0 + sum(len(w.columns) for w in chosen)
    for v in chosen:
        coefs = {c.parameter: float(coef[i + j]) for j, c in enumerate(v.columns)}
        contribution = sum(coef[i + j] * columns[c.key] for j, c in enumerate(v.columns))
        i += len(v.columns)
        rest = [w for w in chosen if w is not v]
        _, r_without = fit_set(rest)
        delta = _bic(r_without, n, p_all - len(v.columns)) - _bic(rss, n, p_all)
        out.append(Choice(v, coefs, float(delta), float(r_without - rss), np.asarray(contribution)))
    out.sort(key=lambda c: -c.delta_bic)
    return Selection(out, artefact_values, rss0, rss, n, log)
