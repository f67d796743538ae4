"""Alignment: logger time offset, noise floor, gaps — recording artefacts, never physics.

* :func:`time_offset_from_lines` matches the block transitions of the
  recording's ``line`` channel to those of the twin's NC run (a pure timing
  marker, independent of servo physics), :func:`time_offset_from_signal`
  matches a velocity (commanded, else actual) in least squares when there is
  no ``line``;
* :func:`noise_floor` estimates the white-noise level of a residual from its
  first differences (robust to a smooth model error);
* :func:`fill_gaps` interpolates commanded positions over empty cells;
* :func:`time_offset_from_forces` aligns a dynamometer's own clock by the
  envelope of the cutting load when the recording has nothing else.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from typing import Callable

import numpy as np

from fmus_src.threads import usable_cores

from .correlate import correlation_peak, least_squares_lag


def fill_gaps(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``y`` with NaN replaced by linear interpolation in ``t`` (ends held); all-NaN stays NaN."""
    y = np.asarray(y, dtype=float)
    ok = np.isfinite(y)
    if ok.all() or not ok.any():
        return y.copy()
    return np.interp(t, t[ok], y[ok])


def _transitions(t: np.ndarray, line: np.ndarray) -> list[tuple[float, float, float, float]]:
    """(before, after, from, to) of every change of ``line``: the change lies in ``(before, after]``, s."""
    ok = np.isfinite(line)
    t, line = t[ok], line[ok]
    k = np.flatnonzero(np.diff(line) != 0)
    return [(float(t[i]), float(t[i + 1]), float(line[i]), float(line[i + 1])) for i in k]


def offset_bracket_from_lines(t_rec: np.ndarray, line_rec: np.ndarray, t_nc: np.ndarray,
                              line_nc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of the logger offset from each matched block transition, s.

    Transitions are matched in order by their (from, to) line pair. The twin's NC changes line at an
    interpolation tick: its first sample of the new line, ``nc_after``. The logger saw the change between
    two of its samples, so each transition brackets the offset:
    ``rec_before - nc_after < offset <= rec_after - nc_after``.

    Returns
    -------
    lows, highs : ndarray, shape (matched,)
    """
    rec = _transitions(np.asarray(t_rec, float), np.asarray(line_rec, float))
    nc = _transitions(np.asarray(t_nc, float), np.asarray(line_nc, float))
    lows, highs = [], []
    j = 0
    for r0, r1, a, b in rec:
        k = j
        while k < len(nc) and (nc[k][2], nc[k][3]) != (a, b):
            k += 1
        if k < len(nc):
            lows.append(r0 - nc[k][1])
            highs.append(r1 - nc[k][1])
            j = k + 1
    return np.asarray(lows, float), np.asarray(highs, float)


def time_offset_from_lines(t_rec: np.ndarray, line_rec: np.ndarray, t_nc: np.ndarray,
                           line_nc: np.ndarray) -> tuple[float, int]:
    """Logger clock minus program clock from matched block transitions.

    When the brackets of the matched transitions (:func:`offset_bracket_from_lines`) overlap, the offset
    is the middle of their intersection (a logger whose samples fall at varied phases of the program's
    ticks pins it to a fraction of its sample period); when a few do not (a controller changing some
    blocks a tick off the twin), the middle of the stretch most of them share (:func:`consensus_bracket`);
    else (a controller whose block changes differ from the twin's throughout) the median of the bracket
    midpoints.

    Returns
    -------
    offset : float
        s (NaN when nothing matched).
    matched : int
        Number of matched transitions.
    """
    lows, highs = offset_bracket_from_lines(t_rec, line_rec, t_nc, line_nc)
    if not lows.size:
        return float("nan"), 0
    bracket = consensus_bracket(lows, highs)
    if bracket is not None:
        return 0.5 * (bracket[0] + bracket[1]), int(lows.size)
    return float(np.median(0.5 * (lows + highs))), int(lows.size)


#: Fraction of the matched transitions whose brackets must share the offset for it to be their consensus.
CONSENSUS_FRACTION = 0.75


def consensus_bracket(lows: np.ndarray, highs: np.ndarray) -> tuple[float, float] | None:
    """The offsets ``[lo, hi]`` inside the most brackets, when that is at least 75 % of them, else None.

    All brackets overlap for a controller that changes block at the twin's ticks: the result is their
    intersection. A controller that changes some blocks a tick earlier or later than the twin (a different
    look-ahead, a block that ends in position) puts a few brackets off the others: they are outvoted
    instead of the offset falling back to the median of the midpoints (good only to half a sample).
    Among equally covered stretches, the one nearest the median midpoint is taken.
    """
    lows, highs = np.asarray(lows, float), np.asarray(highs, float)
    if not lows.size:
        return None
    edges = np.concatenate([lows, highs])
    step = np.concatenate([np.ones(lows.size, int), -np.ones(highs.size, int)])
    order = np.lexsort((-step, edges))          # at equal times, a bracket opens before one closes
    cover = np.cumsum(step[order])
    best = int(cover.max())
    if best < CONSENSUS_FRACTION * lows.size:
        return None
    at = np.flatnonzero(cover == best)
    spans = [(float(edges[order][i]), float(edges[order][i + 1])) for i in at if i + 1 < edges.size]
    if not spans:
        return None
    centre = float(np.median(0.5 * (lows + highs)))
    return min(spans, key=lambda sp: abs(0.5 * (sp[0] + sp[1]) - centre))


def _offset_residual(t_rec: np.ndarray, rec: np.ndarray, t_nc: np.ndarray, ref: np.ndarray,
                     shift: float) -> np.ndarray | None:
    """Recorded minus twin positions at clock ``shift`` (median removed), or None with fewer than 10 samples."""
    ok = np.isfinite(rec)
    tp = t_rec[ok] - shift
    inside = (tp >= t_nc[0]) & (tp <= t_nc[-1])
    if inside.sum() < 10:
        return None
    d = rec[ok][inside] - np.interp(tp[inside], t_nc, ref)
    return d - np.median(d)


def _offset_cost(t_rec: np.ndarray, rec: np.ndarray, t_nc: np.ndarray, ref: np.ndarray, shift: float) -> float:
    """Mean square of recorded minus twin positions at clock ``shift`` (median removed), or inf."""
    d = _offset_residual(t_rec, rec, t_nc, ref, shift)
    return float("inf") if d is None else float(np.mean(d * d))


def _offset_costs(t_rec: np.ndarray, rec: np.ndarray, t_nc: np.ndarray, ref: np.ndarray,
                  shifts: np.ndarray) -> np.ndarray:
    """:func:`_offset_cost` at every clock shift, shape (len(shifts),), the same numbers.

    The finite samples are taken out once, and the shifts are spread over threads (numpy's
    interpolation and partition release the GIL): a 10-minute log has 350 000 samples per axis and
    the refinement tries 401 shifts.
    """
    ok = np.isfinite(rec)
    t_ok, rec_ok = np.asarray(t_rec)[ok], np.asarray(rec)[ok]
    workers = usable_cores()
    if workers < 2 or shifts.size < 8:
        return np.array([_offset_cost(t_ok, rec_ok, t_nc, ref, float(s)) for s in shifts])
    with ThreadPoolExecutor(max_workers=workers) as pool:
        return np.array(list(pool.map(lambda s: _offset_cost(t_ok, rec_ok, t_nc, ref, float(s)), shifts)))


#: Times the search of :func:`refine_offset_by_axes` is re-centred when no axis finds its clock inside it.
MAX_RECENTRES = 2
#: Standard errors by which two axes' clocks may differ and still be one clock (two-sided p = 6e-5 per pair).
CLOCK_AGREEMENT_SIGMA = 4.0


def _axis_clock(t_rec: np.ndarray, rec: np.ndarray, t_nc: np.ndarray, ref: np.ndarray, centre: float,
                span_s: float, step_s: float) -> tuple[float, float] | None:
    """One axis's clock inside ``centre +- span_s`` and its standard error, s; None at the span's edge.

    Least squares ``rec(t) = ref(t - s) + c``: the estimate's variance is ``2 c0 / (n k)`` (``c0`` the mean
    square residual at the best shift, ``k`` the curvature of the mean square there, ``n`` the samples),
    inflated by ``(1 + rho) / (1 - rho)`` for the residual's lag-1 correlation ``rho`` (what the twin leaves
    of a real drive's response is smooth, not white).
    """
    o = refine_offset(t_rec, {"a": rec}, t_nc, {"a": ref}, centre, span_s, step_s)
    if abs(o - centre) >= span_s - 1.5 * step_s:
        return None
    h = 0.5 * step_s
    c0, cp, cm = (_offset_cost(t_rec, rec, t_nc, ref, o + d) for d in (0.0, h, -h))
    curvature = (cp - 2.0 * c0 + cm) / h ** 2
    r = _offset_residual(t_rec, rec, t_nc, ref, o)
    if r is None or not (np.isfinite(curvature) and curvature > 0.0):
        return None
    rho = residual_autocorrelation(r)
    variance = 2.0 * max(c0, 1e-30) / (r.size * curvature) * (1.0 + rho) / (1.0 - rho)
    return o, float(np.sqrt(variance))


def agreeing_axes(est: dict[str, tuple[float, float]], sigma: float = CLOCK_AGREEMENT_SIGMA) -> list[str]:
    """The axes whose clocks are one clock: the largest group agreeing pairwise, when it is the only one.

    Two axes agree when their clocks differ by at most ``sigma`` standard errors of the difference. A clock
    is common to all axes; an axis whose positions differ from the twin's by (nearly) a shift of its own -- a
    feed-forward, a servo delay, a backlash or compliance on that axis alone -- gives a clock that the others
    do not share. When no group is larger than every other (two axes that disagree, or a chain x~y, y~z,
    x!~z), the axes cannot tell which is off and all are kept.

    Parameters
    ----------
    est : dict axis -> (clock, standard error)
        s.
    sigma : float
        Agreement threshold in standard errors.
    """
    from itertools import combinations

    names = sorted(est)

    def agree(a: str, b: str) -> bool:
        (oa, sa), (ob, sb) = est[a], est[b]
        return abs(oa - ob) <= sigma * float(np.hypot(sa, sb))

    for size in range(len(names), 0, -1):
        groups = [g for g in combinations(names, size) if all(agree(a, b) for a, b in combinations(g, 2))]
        if len(groups) == 1:
            return list(groups[0])
        if groups:
            return names
    return names


def refine_offset_by_axes(t_rec: np.ndarray, ref_rec: dict[str, np.ndarray], t_nc: np.ndarray,
                          ref_nc: dict[str, np.ndarray], offset: float, span_s: float = 0.005,
                          step_s: float = 2.5e-5, max_recentres: int = MAX_RECENTRES) -> tuple[float, list[str]]:
    """:func:`refine_offset` axis by axis; the clock is the weighted mean of the axes that agree on it.

    Each axis is refined on its own (:func:`_axis_clock`), with its standard error. An axis whose best shift
    lies at the edge of the search span has no clock of its own there and is left out (a feed-forward of 0.3
    on X alone takes 6 ms off its lag). Of the others, the largest group agreeing within
    :data:`CLOCK_AGREEMENT_SIGMA` standard errors is kept (:func:`agreeing_axes`), and the clock is their
    inverse-variance weighted mean. Weighting alone let an axis with an effect of its own pull the clock: a
    feed-forward of 0.05 on X (1 ms less lag, inside the span, and a shift fits it closely) moved an XY
    contour's clock by 49 µs, and inertia mismatches of 17-25 kg on all three axes followed; a 3 µm X backlash
    moved it 11 µs within a ``line`` bracket (inertia on X and Z).

    When no axis finds its clock inside the span, the starting ``offset`` itself is off (a coarse estimate
    beyond ``span_s``): the search is re-centred on the joint optimum at the span's edge and repeated, at
    most ``max_recentres`` times (a clock up to ``(1 + max_recentres) span_s`` away), and the joint optimum
    is returned when it lies inside a span. Before, that edge (5 ms off the start) was returned as the
    clock, and the rest of the lag read as a feed-forward.

    Returns
    -------
    offset : float
        s.
    used : list of str
        The axes the offset rests on.
    """
    centre = float(offset)
    for _ in range(max_recentres + 1):
        est = {a: e for a in sorted(ref_rec)
               if (e := _axis_clock(t_rec, ref_rec[a], t_nc, ref_nc[a], centre, span_s, step_s)) is not None}
        if est:
            used = agreeing_axes(est)
            weights = np.array([est[a][1] ** -2 for a in used])
            return float(np.dot([est[a][0] for a in used], weights) / weights.sum()), used
        joint = refine_offset(t_rec, ref_rec, t_nc, ref_nc, centre, span_s, step_s)
        if abs(joint - centre) < span_s - 1.5 * step_s:
            return joint, sorted(ref_rec)
        centre = joint
    return centre, sorted(ref_rec)


def time_offset_from_signal(t_rec: np.ndarray, y_rec: np.ndarray, t_nc: np.ndarray, y_nc: np.ndarray,
                            max_offset_s: float = 5.0, grid_s: float = 1e-3) -> float:
    """Logger clock minus program clock by matching the velocities of two position signals.

    Both are resampled on a ``grid_s`` grid and differentiated. The lag is the least-squares match of the
    recorded velocity with the twin's (:func:`.correlate.least_squares_lag`), refined by a parabola through
    its neighbours (sub-grid resolution). The plain correlation peak used before is biased for a log that
    starts or stops while an axis moves: the twin's velocity energy inside the sliding window of the log then
    grows with the lag on one side. A Servo Guide log cut a third into a 500 mm/min move came out 14 ms off,
    beyond the +-5 ms of :func:`refine_offset_by_axes`, and the remaining lag was named a feed-forward.
    Without the mean removal of the correlation (a log's mean velocity is its net travel over its length,
    which a cut log does not share with the twin's run) and with the window's energy, the match is unbiased.

    Parameters
    ----------
    t_rec, y_rec : ndarray, shape (n,)
        Logger times [s] and the recorded position [any unit; NaN where not measured].
    t_nc, y_nc : ndarray, shape (m,)
        The twin's run (program clock) and the same position.
    max_offset_s : float
        The twin's run is padded with its end values by this much on both sides, s.
    grid_s : float
        Resampling grid, s.

    Returns
    -------
    float
        Offset, s.
    """
    t_rec = np.asarray(t_rec, float)
    ok = np.isfinite(y_rec)
    grid = np.arange(t_nc[0] - max_offset_s, t_nc[-1] + max_offset_s, grid_s)
    g_nc = np.gradient(np.interp(grid, t_nc, y_nc), grid_s)
    g_rec_t = np.arange(t_rec[ok][0], t_rec[ok][-1], grid_s)
    g_rec = np.gradient(np.interp(g_rec_t, t_rec[ok], np.asarray(y_rec, float)[ok]), grid_s)
    i, c_m, c_0, c_p = least_squares_lag(g_nc, g_rec)
    frac = 0.0
    if np.isfinite(c_m) and np.isfinite(c_p):
        den = c_m - 2.0 * c_0 + c_p
        frac = float(np.clip(0.5 * (c_m - c_p) / den, -0.5, 0.5)) if den > 0 else 0.0
    lag = (i - g_rec.size + 1) + frac
    # g_rec[k] (time g_rec_t[0] + k grid) lines up with g_nc[k + lag] (time grid[0] + (k + lag) grid)
    return float(g_rec_t[0] - (grid[0] + lag * grid_s))


def recorded_quantum(values: np.ndarray, tolerance: float = 1e-3) -> float:
    """Resolution of a recorded channel whose values lie on a grid (an encoder's 1 µm), else 0.

    The grid step is the smallest positive difference between distinct finite values; it is the
    resolution only when every value is a multiple of it within ``tolerance`` of a step (a logger
    that writes 0.001 mm steps), so smooth or noisy channels give 0.
    """
    v = np.asarray(values, float)
    u = np.unique(v[np.isfinite(v)])
    if u.size < 10:  # a few distinct values (an axis that only stood) say nothing about a grid
        return 0.0
    d = np.diff(u)
    q = float(d.min())
    if q <= 0.0:
        return 0.0
    k = u / q
    return q if float(np.max(np.abs(k - np.round(k)))) < tolerance else 0.0


def residual_autocorrelation(r: np.ndarray) -> float:
    """Lag-1 correlation of a residual, clipped to [0, 0.98] (the CI inflation ``(1 + rho) / (1 - rho)``).

    0 for fewer than 4 samples or a constant residual (an exact fit: ``np.corrcoef`` would give NaN and the
    intervals NaN with it).
    """
    r = np.asarray(r, dtype=float)
    if r.size < 4 or np.ptp(r[:-1]) == 0.0 or np.ptp(r[1:]) == 0.0:
        return 0.0
    return float(np.clip(np.corrcoef(r[:-1], r[1:])[0, 1], 0.0, 0.98))


def noise_floor(residual: np.ndarray, quantum: float = 0.0) -> float:
    """White-noise standard deviation of a residual from its first differences.

    ``sigma^2 = mean(d^2) / 2`` over the 80 % smallest differences ``d``,
    rescaled for that trimming (Gaussian), so that edges of model errors and
    bursts of an unmodelled vibration do not inflate it; never below the
    quantisation noise ``quantum / sqrt(12)``.
    """
    r = np.asarray(residual, float)
    r = r[np.isfinite(r)]
    if r.size < 10:
        return max(quantum / np.sqrt(12.0), 1e-12)
    d = np.diff(r)
    cut = np.quantile(np.abs(d), 0.80)
    kept = d[np.abs(d) <= cut]
    # E[d^2 | |d| <= q80] = 0.4377 E[d^2] for Gaussian d (truncation at 1.2816 sigma)
    sigma = float(np.sqrt(np.mean(kept ** 2) / 0.4377 / 2.0)) if kept.size else 0.0
    return max(sigma, quantum / np.sqrt(12.0), 1e-12)


def refine_offset(t_rec: np.ndarray, ref_rec: dict[str, np.ndarray], t_nc: np.ndarray,
                  ref_nc: dict[str, np.ndarray], offset: float, span_s: float = 0.005,
                  step_s: float = 2.5e-5) -> float:
    """Offset minimising the spread of recorded minus twin positions (constant part removed).

    A grid search over ``offset +- span_s`` with ``step_s`` resolution, refined by a parabola. With
    commanded positions (``{a}_ref_mm`` against the twin's commands) this is the program's timing
    exactly, up to the NC-kernel differences that the median removal and the squared error tolerate;
    with actual positions (``{a}_mm`` against the twin's servo response) it is the timing that makes the
    twin's drives follow as the machine's did.
    """
    shifts = offset + np.arange(-span_s, span_s + step_s / 2, step_s)
    cost = np.zeros(shifts.size)
    for a, rec in ref_rec.items():
        cost += _offset_costs(t_rec, rec, t_nc, ref_nc[a], shifts)
    i = int(np.argmin(cost))
    if 0 < i < shifts.size - 1 and np.all(np.isfinite(cost[i - 1:i + 2])):
        den = cost[i - 1] - 2 * cost[i] + cost[i + 1]
        if den > 0:
            return float(shifts[i] + 0.5 * (cost[i - 1] - cost[i + 1]) / den * step_s)
    return float(shifts[i])


#: Spindle revolutions averaged by the cutting-load envelope (whole revolutions: runout and the tooth
#: phase average out, the edges of the cuts stay sharp to this width).
ENVELOPE_REVOLUTIONS = 2
#: Half-width of the least-squares refinement around the coarse correlation peak, s.
FORCE_REFINE_SPAN_S = 3e-3


def load_envelope(t: np.ndarray, load: np.ndarray, window_s: float) -> Callable[[np.ndarray], np.ndarray]:
    """Centred moving mean of a cutting load over ``window_s``, as a function of time.

    The mean of the linear interpolation of ``load`` between its (possibly uneven) samples, taken from
    its running integral, so it can be read at any time (a clock shift is continuous, not a whole
    sample); zero outside the samples. The mean of ``|F|`` over whole spindle revolutions is nearly
    linear in the chip, so a runout or the tooth phase leave it unchanged.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times, increasing, s.
    load : ndarray, shape (n,)
        Load at those times (finite), N.
    window_s : float
        Averaging window, s.

    Returns
    -------
    callable
        ``f(q)`` -> envelope at times ``q`` (any shape), N.
    """
    t = np.asarray(t, float)
    y = np.asarray(load, float)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(t))])
    half = 0.5 * float(window_s)

    def envelope(q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, float)
        return (np.interp(q + half, t, integral) - np.interp(q - half, t, integral)) / (2.0 * half)

    return envelope


def _affine_misfit(y: np.ndarray, x: np.ndarray) -> float:
    """Residual sum of squares of ``y ~ a + b x`` (least squares in ``a``, ``b``)."""
    xc, yc = x - x.mean(), y - y.mean()
    sxx = float(xc @ xc)
    b = float(xc @ yc) / sxx if sxx > 0.0 else 0.0
    r = yc - b * xc
    return float(r @ r)


def time_offset_from_forces(t_rec: np.ndarray, f_rec: np.ndarray, t_twin: np.ndarray, f_twin: np.ndarray,
                            window_s: float, grid_s: float = 1e-3) -> float:
    """Logger clock minus program clock from the cutting load ``|F|`` alone (see :func:`force_clock`), s."""
    return force_clock(t_rec, f_rec, t_twin, f_twin, window_s, grid_s)[0]


def force_clock(t_rec: np.ndarray, f_rec: np.ndarray, t_twin: np.ndarray, f_twin: np.ndarray,
                window_s: float, grid_s: float = 1e-3) -> tuple[float, float]:
    """Logger clock minus program clock from the cutting load ``|F|`` alone (a dynamometer's own clock).

    Both loads are smoothed by :func:`load_envelope`. The level of an envelope within a cut is not
    trusted: a logger that samples a tooth pulse at a few fixed phases (a 2-flute tool at 6000 rpm seen
    every 1 ms: 5 samples per tooth, phase-locked) sees a mean that depends on where its samples fall,
    and so does the twin's own 1 ms run, at another phase (12.1 N against the truth's 18.6 N on a 1 mm
    side pass of :mod:`.scorecard_part`). So the coarse offset is the cross-correlation
    (:func:`.correlate.correlation_peak`, every lag of the two records, on a ``grid_s`` grid) of where each
    load cuts (:func:`cutting_indicator`: its envelope above a tenth of its cutting level), and it is refined
    by least squares with an affine map of its own per cut: the shift ``s`` minimising the misfit of
    ``E_rec(t) ~ a_k + b_k E_twin(t - s)`` over the recorded samples of each cut ``k`` (dilated by the
    window), within ``window_s`` + :data:`FORCE_REFINE_SPAN_S` of the coarse offset. One affine map for
    the whole record, as before, put the clock of that part's 1 ms dynamometer 14 ms off (then named a
    helix angle and missed every hidden cutting effect).

    Parameters
    ----------
    t_rec, f_rec : ndarray, shape (n,)
        Recorded sample times [s] and load ``hypot(fx, fy)`` [N] (finite).
    t_twin, f_twin : ndarray, shape (m,)
        The twin's run (program clock) and its predicted load [N].
    window_s : float
        Envelope window (a few tooth periods), s.
    grid_s : float
        Grid of the coarse correlation, s.

    Returns
    -------
    (float, float)
        Offset, s, and the misfit there (sum of squares of the recorded envelope about its affine maps, N²:
        comparable between twin loads of the same recording).
    """
    from scipy.optimize import minimize_scalar

    t_rec, t_twin = np.asarray(t_rec, float), np.asarray(t_twin, float)
    e_rec = load_envelope(t_rec, f_rec, window_s)
    e_twin = load_envelope(t_twin, f_twin, window_s)
    g_rec_t = np.arange(t_rec[0], t_rec[-1], grid_s)
    g_twin_t = np.arange(t_twin[0], t_twin[-1], grid_s)
    g_rec = cutting_indicator(e_rec(g_rec_t))
    g_twin = cutting_indicator(e_twin(g_twin_t))
    i, c_m, c_0, c_p = correlation_peak(g_twin - g_twin.mean(), g_rec - g_rec.mean())
    frac = 0.0
    if np.isfinite(c_m) and np.isfinite(c_p):
        den = c_m - 2.0 * c_0 + c_p
        frac = float(np.clip(0.5 * (c_m - c_p) / den, -0.5, 0.5)) if den < 0 else 0.0
    coarse = float(g_rec_t[0] - (g_twin_t[0] + (i - g_rec.size + 1 + frac) * grid_s))
    y = e_rec(t_rec)
    groups = cut_groups(t_rec, cutting_indicator(y) > 0.5, window_s)
    if not groups:
        groups = [np.arange(t_rec.size)]
    span = float(window_s) + FORCE_REFINE_SPAN_S

    def misfit(s: float) -> float:
        x = e_twin(t_rec - s)
        return sum(_affine_misfit(y[g], x[g]) for g in groups)

    best = minimize_scalar(misfit, method="bounded", bounds=(coarse - span, coarse + span),
                           options={"xatol": 1e-7})
    # a bounded scalar search may stop in a local minimum over so wide a span: take the best of a scan too
    grid = np.linspace(coarse - span, coarse + span, 81)
    costs = [misfit(float(s)) for s in grid]
    k = int(np.argmin(costs))
    if costs[k] < misfit(float(best.x)):
        step = grid[1] - grid[0]
        best = minimize_scalar(misfit, method="bounded", bounds=(grid[k] - step, grid[k] + step),
                               options={"xatol": 1e-7})
    return float(best.x), float(misfit(float(best.x)))


def cutting_indicator(envelope: np.ndarray) -> np.ndarray:
    """1 where a load envelope cuts (above a tenth of its cutting level over its air level), else 0.

    The air level is the envelope's 5th percentile, the cutting level its 95th percentile of what lies
    above twice the air level's spread (the noise's mean ``|F|``).
    """
    e = np.asarray(envelope, float)
    if e.size == 0:
        return e
    air = float(np.percentile(e, 5))
    high = e[e > air + 2.0 * (float(np.percentile(e, 25)) - air) + 1e-12]
    level = float(np.percentile(high, 95)) if high.size else float(np.max(e))
    return (e > air + 0.1 * (level - air)).astype(float)


def cut_groups(t: np.ndarray, cutting: np.ndarray, dilate_s: float) -> list[np.ndarray]:
    """Sample indices of each run of ``cutting`` samples, widened by ``dilate_s`` either side (merged if they meet)."""
    t = np.asarray(t, float)
    idx = np.flatnonzero(np.asarray(cutting, bool))
    if idx.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(idx) > 1)
    starts = np.r_[idx[0], idx[breaks + 1]]
    ends = np.r_[idx[breaks], idx[-1]]
    spans = []
    for a, b in zip(starts, ends):
        lo, hi = t[a] - dilate_s, t[b] + dilate_s
        if spans and lo <= spans[-1][1]:
            spans[-1][1] = hi
        else:
            spans.append([lo, hi])
    return [np.flatnonzero((t >= lo) & (t <= hi)) for lo, hi in spans]
