"""Compiled sampling of a chain of feed blocks: :func:`.interpolator.sample_chain`, bit for bit.

The numpy specification (:func:`.interpolator.sample_chain`) evaluates the constant-jerk pieces at every
sample, takes the running maximum of the arc length, finds each sample's block and evaluates the geometry,
through a dozen full-length temporaries. :func:`_sample_path` does the same element by element in one
compiled loop, with the same floating-point operations in the same order (numpy's ``searchsorted`` on sorted
arrays, ``maximum.accumulate``, ``clip`` and ``maximum`` with their signed-zero rules from :mod:`.numpy_ops`).
The arcs' ``cos``/``sin`` stay in numpy (numpy's SIMD ``cos``/``sin`` need not round as libm does), evaluated
on the same array of angles as the specification.

When the pieces' start times are not sorted or a sample's arc length is NaN (neither happens for a valid
chain), the numpy specification runs instead.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from ..jit_cache import guard_cache
from . import numpy_ops
from .geometry import ChainGeometry
from .interpolator import ChainPieces, Segment, _n_periods, sample_chain
from .numpy_ops import np_clip, np_maximum


@njit
def _sample_path(t0: np.ndarray, s0: np.ndarray, v0: np.ndarray, a0: np.ndarray, jerk: np.ndarray,
                 duration: float, period: float, n: int, total: float, cum: np.ndarray, length: np.ndarray,
                 start: np.ndarray, end: np.ndarray, is_arc: np.ndarray, theta0: np.ndarray, sweep: np.ndarray,
                 r0: np.ndarray, r1: np.ndarray):
    """Samples ``k = 0..n`` of a chain up to the arcs' trigonometry.

    Parameters
    ----------
    t0, s0, v0, a0, jerk : ndarray (P,)
        Pieces (:class:`.interpolator.ChainPieces`), ``t0`` sorted, ``t0[0] = 0``.
    duration, period : float
        Chain duration and Ts (s).
    n : int
        Sample periods.
    total : float
        Chain length ``cum[-1]`` (m).
    cum, length : ndarray (nb + 1,), (nb,)
        Geometry (:class:`.geometry.ChainGeometry`), m.
    start, end : ndarray (nb, 3)
        Block end points (m).
    is_arc, theta0, sweep, r0, r1 : ndarray (nb,)
        Arc data (rad, m).

    Returns
    -------
    ok : bool
        False when an arc length was NaN (the caller then uses the numpy specification).
    block : ndarray (n + 1,) of int64
        Block of each sample.
    frac : ndarray (n + 1,)
        Fraction of the block travelled.
    vel : ndarray (n + 1,)
        Path speed (m/s).
    pos : ndarray (n + 1, 3)
        Straight-line positions ``start + frac (end - start)`` (m); arcs are finished by :func:`_finish_arcs`.
    arc_rows : ndarray (m,) of int64
        Samples on arcs (increasing).
    phi, radius : ndarray (m,)
        Their angle (rad) and radius (m).
    """
    m = n + 1
    P = t0.shape[0]
    nb = length.shape[0]
    s = np.empty(m)
    vel = np.empty(m)
    j = 0
    for k in range(m):
        tk = k * period
        while j + 1 < P and t0[j + 1] <= tk:  # searchsorted(t0, tk, "right") - 1 on sorted t0
            j += 1
        tau = tk - t0[j]
        if tk >= duration:
            s[k] = total
            vel[k] = 0.0
        else:
            s[k] = s0[j] + tau * (v0[j] + tau * (0.5 * a0[j] + tau * jerk[j] / 6.0))
            vel[k] = v0[j] + tau * (a0[j] + 0.5 * tau * jerk[j])
    block = np.empty(m, dtype=np.int64)
    frac = np.empty(m)
    pos = np.empty((m, 3))
    n_arc = 0
    run = s[0]
    for k in range(m):
        if k > 0:
            run = np_maximum(run, s[k])  # maximum.accumulate
        sk = np_clip(run, 0.0, total)
        if k == m - 1:
            sk = total
        if math.isnan(sk):
            return False, block, frac, vel, pos, np.empty(0, dtype=np.int64), np.empty(0), np.empty(0)
        vel[k] = np_maximum(vel[k], 0.0)
        lo = 0  # searchsorted(cum, sk, "right"): the number of entries <= sk
        hi = cum.shape[0]
        while lo < hi:
            mid = (lo + hi) >> 1
            if cum[mid] <= sk:
                lo = mid + 1
            else:
                hi = mid
        b = min(max(lo - 1, 0), nb - 1)
        f = np_clip((sk - cum[b]) / length[b], 0.0, 1.0)
        if k == m - 1:
            f = 1.0
            b = nb - 1
        block[k] = b
        frac[k] = f
        for a in range(3):
            pos[k, a] = start[b, a] + f * (end[b, a] - start[b, a])
        if is_arc[b]:
            n_arc += 1
    arc_rows = np.empty(n_arc, dtype=np.int64)
    phi = np.empty(n_arc)
    radius = np.empty(n_arc)
    i = 0
    for k in range(m):
        b = block[k]
        if is_arc[b]:
            arc_rows[i] = k
            phi[i] = theta0[b] + sweep[b] * frac[k]
            radius[i] = r0[b] + (r1[b] - r0[b]) * frac[k]
            i += 1
    return True, block, frac, vel, pos, arc_rows, phi, radius


@njit
def _finish_arcs(pos: np.ndarray, block: np.ndarray, frac: np.ndarray, end: np.ndarray, center: np.ndarray,
                 axes: np.ndarray, arc_rows: np.ndarray, radius: np.ndarray, cos_phi: np.ndarray,
                 sin_phi: np.ndarray) -> None:
    """Arc samples' in-plane coordinates ``center + r (cos, sin)``, then block ends where ``frac >= 1`` (in place).

    Parameters
    ----------
    pos : ndarray (n + 1, 3)
        From :func:`_sample_path` (m), overwritten.
    block, frac : ndarray (n + 1,)
        From :func:`_sample_path`.
    end, center : ndarray (nb, 3)
        Block end and arc centre points (m).
    axes : ndarray (nb, 3) of int
        In-plane axes and normal axis of each block.
    arc_rows, radius : ndarray (m,)
        From :func:`_sample_path`.
    cos_phi, sin_phi : ndarray (m,)
        ``numpy.cos``/``numpy.sin`` of its ``phi``.
    """
    for i in range(arc_rows.shape[0]):
        k = arc_rows[i]
        b = block[k]
        pos[k, axes[b, 0]] = center[b, axes[b, 0]] + radius[i] * cos_phi[i]
        pos[k, axes[b, 1]] = center[b, axes[b, 1]] + radius[i] * sin_phi[i]
    for k in range(pos.shape[0]):
        if frac[k] >= 1.0:
            b = block[k]
            for a in range(3):
                pos[k, a] = end[b, a]


guard_cache(_sample_path, numpy_ops)


def sample_chain_compiled(geo: ChainGeometry, pieces: ChainPieces, period: float) -> Segment:
    """:func:`.interpolator.sample_chain` through the compiled kernels (bit-identical).

    Parameters
    ----------
    geo : ChainGeometry
    pieces : ChainPieces
        From :func:`.interpolator.chain_pieces`.
    period : float
        Interpolation period Ts (s).

    Returns
    -------
    Segment
    """
    if not pieces.t0:
        return sample_chain(geo, pieces, period)
    t0 = np.array(pieces.t0)
    if not (t0[0] == 0.0 and bool(np.all(t0[1:] >= t0[:-1]))):
        return sample_chain(geo, pieces, period)
    n = _n_periods(pieces.duration, period)
    total = geo.cum.tolist()[-1]
    ok, block, frac, vel, pos, arc_rows, phi, radius = _sample_path(
        t0, np.array(pieces.s0), np.array(pieces.v0), np.array(pieces.a0), np.array(pieces.jerk),
        float(pieces.duration), float(period), n, float(total), geo.cum, geo.length, geo.start, geo.end,
        geo.is_arc, geo.theta0, geo.sweep, geo.r0, geo.r1)
    if not ok:
        return sample_chain(geo, pieces, period)
    _finish_arcs(pos, block, frac, geo.end, geo.center, geo.axes.astype(np.int64), arc_rows, radius,
                 np.cos(phi), np.sin(phi))
    return Segment(pos, vel, np.array(pieces.block_start), pieces.duration)
