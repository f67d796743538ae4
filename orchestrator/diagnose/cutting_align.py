"""Alignment of a force recording with the twin's cutting model: spindle phase per cut, noise floors.

The spindle angle is not logged: the angle of tooth 0 at the first force
sample is an **alignment** quantity, estimated from the cuts (runs of
samples with the tool in material, :func:`cut_segments`):

1. a coarse scan of :data:`PHASE_STEPS` phases over one tooth pitch (one
   batched replay), least squares of the forces with ``Kt``, ``Ke`` free per
   cut and phase, summed over the cuts (which tooth is "tooth 0" is a
   convention: the scan fixes it);
2. a parabola through the best phase and its neighbours;
3. a fine scan of :data:`FINE_OFFSETS` around it (one batched replay),
   leaving out the samples where a tooth enters or leaves the material
   within the scan (force jumps), and a parabola again.

One phase for the whole recording, not one per cut: the helix lag shifts the
force pulse by an amount that depends on the depth of each cut, which a phase
per cut would absorb. What integrating a logged speed leaves (a constant after
a ramp, a drift from a speed bias) is taken up by the phase and
phase-drift columns of the regression (:mod:`.cutting`). :func:`phase_speed`
can turn the spindle on by a phase step in the air between cuts, where
nothing depends on the spindle angle.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


#: Coarse phase trials per tooth pitch.
PHASE_STEPS = 12
#: Fine phase offsets around each cut's coarse phase, rad.
FINE_OFFSETS = np.radians(np.arange(-5.0, 5.5, 1.25))
#: Gaps in the cut shorter than this belong to the cut, s.
CUT_GAP_S = 0.03
#: Cuts shorter than this are not aligned on their own (they take the previous cut's phase), s.
MIN_CUT_S = 0.05


@dataclass
class Cuts:
    """Cut segments of a force recording.

    Attributes
    ----------
    bounds : list of (int, int)
        Sample index ranges ``[i0, i1)`` of each cut (model force non-zero, short gaps bridged).
    phase : ndarray, shape (S,)
        Spindle-phase correction of each cut, rad (added to the replay's angle from the cut on).
    """

    bounds: list[tuple[int, int]]
    phase: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def mask(self, n: int) -> np.ndarray:
        """Samples inside any cut."""
        m = np.zeros(n, bool)
        for i0, i1 in self.bounds:
            m[i0:i1] = True
        return m

    def index(self, n: int) -> np.ndarray:
        """Cut number of each sample (-1 outside)."""
        out = np.full(n, -1)
        for s, (i0, i1) in enumerate(self.bounds):
            out[i0:i1] = s
        return out


def cut_segments(t: np.ndarray, engaged: np.ndarray) -> Cuts:
    """Runs of engaged samples, gaps below :data:`CUT_GAP_S` bridged, runs below :data:`MIN_CUT_S` dropped."""
    idx = np.flatnonzero(engaged)
    bounds: list[tuple[int, int]] = []
    if idx.size:
        start = prev = idx[0]
        for i in idx[1:]:
            if t[i] - t[prev] > CUT_GAP_S:
                bounds.append((int(start), int(prev) + 1))
                start = i
            prev = i
        bounds.append((int(start), int(prev) + 1))
    bounds = [(a, b) for a, b in bounds if t[b - 1] - t[a] >= MIN_CUT_S]
    return Cuts(bounds, np.zeros(len(bounds)))


def phase_speed(step_omega: np.ndarray, t: np.ndarray, cuts: Cuts) -> np.ndarray:
    """Step speed inputs [rad/s] that add ``cuts.phase[s] - cuts.phase[s - 1]`` in the air before cut ``s``.

    ``step_omega[k]`` turns the spindle over ``[t_k, t_k+1]``. The first cut's phase goes into the
    initial angle (:func:`initial_angle`); each later change is spread evenly over the steps from the
    last sample of the previous cut to the first sample of the cut.
    """
    om = np.array(step_omega, dtype=float)
    for s in range(1, len(cuts.bounds)):
        delta = float(cuts.phase[s] - cuts.phase[s - 1])
        if delta == 0.0:
            continue
        steps = np.arange(cuts.bounds[s - 1][1] - 1, cuts.bounds[s][0])
        dt = t[steps + 1] - t[steps]
        om[steps] += delta / float(dt.sum())
    return om


def initial_angle(theta0: float, cuts: Cuts) -> float:
    """Initial spindle angle of the replay with the first cut's phase correction."""
    return float(theta0 + (cuts.phase[0] if cuts.phase.size else 0.0))


def parabola_min(x: np.ndarray, y: np.ndarray, periodic: bool = True) -> float:
    """Abscissa of the minimum of the parabola through the lowest sample and its neighbours (equal spacing)."""
    j = int(np.argmin(y))
    n = y.size
    if not periodic and (j == 0 or j == n - 1):
        return float(x[j])
    ym, y0, yp = y[(j - 1) % n], y[j], y[(j + 1) % n]
    den = ym - 2.0 * y0 + yp
    shift = 0.5 * (ym - yp) / den if den > 0 else 0.0
    step = float(x[1] - x[0])
    return float(x[j] + np.clip(shift, -1.0, 1.0) * step)


def _cut_sse(measured: np.ndarray, basis: list[np.ndarray], rows: np.ndarray, trim: bool) -> float:
    """SSE of fx, fy on ``rows`` after a least-squares fit of ``F = sum c_i basis_i`` (optionally trimmed)."""
    y = measured[rows].reshape(-1)
    x = np.column_stack([q[rows].reshape(-1) for q in basis])
    ok = np.isfinite(y)
    coef, *_ = np.linalg.lstsq(x[ok], y[ok], rcond=None)
    r = y[ok] - x[ok] @ coef
    if trim:  # tooth entries and exits are force jumps
        r2 = np.sort(r * r)
        return float(r2[: max(1, int(0.95 * r2.size))].sum())
    return float(r @ r)


def best_phase(measured: np.ndarray, basis: list[np.ndarray], cuts: Cuts, trial: np.ndarray) -> float:
    """Spindle phase from the coarse scan: the trial minimising the summed (trimmed) SSE of the cuts.

    Parameters
    ----------
    measured : ndarray, shape (n, 2)
        Measured fx, fy at the force samples, N.
    basis : list of ndarray, shape (n, P, 2)
        Replayed unit forces per trial phase (the ``Kt`` part, the ``Kt Ke`` part, the edge-force
        parts): their coefficients are fitted per cut and trial, so that a coefficient error or edge
        forces (which change the pulse shape) do not pull the phase.
    cuts : Cuts
    trial : ndarray, shape (P,)
        Trial phases (uniform over one pitch), rad.
    """
    sse = np.zeros(trial.size)
    for i0, i1 in cuts.bounds:
        rows = np.arange(i0, i1)
        for p in range(trial.size):
            sse[p] += _cut_sse(measured, [q[:, p] for q in basis], rows, True)
    return parabola_min(trial, sse)


def fine_phase(measured: np.ndarray, basis: list[np.ndarray], engaged: np.ndarray, cuts: Cuts,
               offsets: np.ndarray) -> float:
    """Phase correction from a fine scan around the coarse phase, rad.

    Parameters
    ----------
    measured : ndarray, shape (n, 2)
    basis : list of ndarray, shape (n, K, 2)
        Unit forces per offset (as :func:`best_phase`).
    engaged : ndarray, shape (n, K)
        Engaged teeth per offset; samples where it changes over the scan (tooth entries and exits,
        force jumps) are left out.
    offsets : ndarray, shape (K,)
        Uniform offsets, rad.
    """
    steady = np.all(engaged == engaged[:, :1], axis=1)
    sse = np.zeros(offsets.size)
    for i0, i1 in cuts.bounds:
        rows = np.arange(i0, i1)[steady[i0:i1]]
        if rows.size < 20:
            continue
        for k in range(offsets.size):
            sse[k] += _cut_sse(measured, [q[:, k] for q in basis], rows, False)
    return parabola_min(offsets, sse, periodic=False)


def force_noise(residual: np.ndarray) -> float:
    """White-noise level of a force residual, N: first differences of the samples outside the cuts.

    Outside the cuts the dynamometer sees only its noise (and what the model misses there, which the
    trimming of :func:`.align.noise_floor` keeps out).
    """
    from .align import noise_floor

    return noise_floor(residual)


def spindle_samples(t_all: np.ndarray, rpm: np.ndarray, ref_rpm: np.ndarray | None,
                    settle_rpm: float = 2.0) -> np.ndarray:
    """Rows of a logged ``spindle_rpm`` usable for droop: finite, with the commanded speed constant and reached.

    A row counts when the commanded speed has not changed within 0.2 s and the actual speed is within
    5 % of it (a ramp in progress is not droop).
    """
    ok = np.isfinite(rpm)
    if ref_rpm is None:
        return np.flatnonzero(ok & (rpm > 0))
    ref = np.asarray(ref_rpm, float)
    fin = np.isfinite(ref)
    idx = np.flatnonzero(ok & fin & (ref > 0))
    if idx.size == 0:
        return idx
    tr, rr = t_all[fin], ref[fin]
    changed = np.flatnonzero(np.abs(np.diff(rr)) > settle_rpm)
    change_t = tr[changed + 1] if changed.size else np.zeros(0)
    keep = []
    for i in idx:
        if change_t.size and np.any((t_all[i] - change_t >= 0) & (t_all[i] - change_t < 0.2)):
            continue
        if abs(rpm[i] - ref[i]) > 0.05 * ref[i]:
            continue
        keep.append(i)
    return np.asarray(keep, dtype=int)


def wrap_deg(x: float) -> float:
    """An angle in degrees wrapped to ``(-180, 180]``."""
    return float(-((-x + 180.0) % 360.0 - 180.0))


TWO_PI = 2.0 * math.pi
