"""Path geometry of a chain of feed blocks: lengths, tangents and vectorised evaluation."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .blocks import Arc, Linear


@dataclass(frozen=True)
class ChainGeometry:
    """Geometry of consecutive feed blocks, as arrays of length n (blocks).

    Attributes
    ----------
    length : ndarray (n,)
        Block path lengths (m).
    cum : ndarray (n + 1,)
        Cumulative arc length at block starts, ``cum[0] = 0`` (m).
    start, end, center : ndarray (n, 3)
        Start, end and (arcs) centre points (m).
    is_arc : ndarray (n,) of bool
    axes : ndarray (n, 3) of int
        In-plane axes and normal axis of arcs (``(0, 1, 2)`` for lines).
    r0, r1, theta0, sweep : ndarray (n,)
        Arc radius at start/end (m), start angle and signed sweep (rad).
    radius : ndarray (n,)
        Smallest arc radius (m); ``inf`` for lines.
    t_in, t_out : ndarray (n, 3)
        Unit tangents at block start and end.
    """

    length: np.ndarray
    cum: np.ndarray
    start: np.ndarray
    end: np.ndarray
    center: np.ndarray
    is_arc: np.ndarray
    axes: np.ndarray
    r0: np.ndarray
    r1: np.ndarray
    theta0: np.ndarray
    sweep: np.ndarray
    radius: np.ndarray
    t_in: np.ndarray
    t_out: np.ndarray


def _arc_tangent(sweep: float, r: float, phi: float, helix: float, axes: tuple[int, int, int]) -> np.ndarray:
    t = np.zeros(3)
    i, j, k = axes
    t[i] = -sweep * r * math.sin(phi)
    t[j] = sweep * r * math.cos(phi)
    t[k] = helix
    n = float(np.linalg.norm(t))
    return t / n if n > 0 else t


def chain_geometry(blocks: Sequence[Linear | Arc]) -> ChainGeometry:
    """Build the geometry arrays of a chain of feed blocks (zero-length blocks must be removed)."""
    n = len(blocks)
    start = np.array([b.start for b in blocks], dtype=float).reshape(n, 3)
    end = np.array([b.end for b in blocks], dtype=float).reshape(n, 3)
    center = np.zeros((n, 3))
    is_arc = np.zeros(n, dtype=bool)
    axes = np.tile(np.array([0, 1, 2]), (n, 1))
    r0 = np.zeros(n)
    r1 = np.zeros(n)
    theta0 = np.zeros(n)
    sweep = np.zeros(n)
    radius = np.full(n, np.inf)
    length = np.zeros(n)
    t_in = np.zeros((n, 3))
    t_out = np.zeros((n, 3))
    for i, b in enumerate(blocks):
        if isinstance(b, Arc):
            is_arc[i] = True
            ax = b.axes
            axes[i] = ax
            center[i] = b.center
            r0[i], r1[i] = b.radius_start, b.radius_end
            theta0[i] = b.start_angle
            sweep[i] = b.sweep
            radius[i] = min(r0[i], r1[i])
            length[i] = b.length
            t_in[i] = _arc_tangent(sweep[i], r0[i], theta0[i], b.helix, ax)
            t_out[i] = _arc_tangent(sweep[i], r1[i], theta0[i] + sweep[i], b.helix, ax)
        else:
            d = end[i] - start[i]
            length[i] = float(np.linalg.norm(d))
            t_in[i] = t_out[i] = d / length[i] if length[i] > 0 else d
    cum = np.concatenate(([0.0], np.cumsum(length)))
    return ChainGeometry(length, cum, start, end, center, is_arc, axes, r0, r1, theta0, sweep, radius, t_in, t_out)


def evaluate(geo: ChainGeometry, idx: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """Positions at fraction ``frac`` in [0, 1] of blocks ``idx``.

    Parameters
    ----------
    geo : ChainGeometry
    idx : ndarray (m,) of int
        Block index of each sample.
    frac : ndarray (m,)
        Fraction of the block's length travelled.

    Returns
    -------
    ndarray (m, 3)
        Positions (m); exactly the block end point where ``frac == 1``.
    """
    s = geo.start[idx]
    e = geo.end[idx]
    f = frac[:, None]
    p = s + f * (e - s)
    arc = geo.is_arc[idx]
    if arc.any():
        ia = np.nonzero(arc)[0]
        b = idx[ia]
        fa = frac[ia]
        phi = geo.theta0[b] + geo.sweep[b] * fa
        r = geo.r0[b] + (geo.r1[b] - geo.r0[b]) * fa
        ax = geo.axes[b]
        c = geo.center[b]
        rows = ia
        p[rows, ax[:, 0]] = c[np.arange(len(b)), ax[:, 0]] + r * np.cos(phi)
        p[rows, ax[:, 1]] = c[np.arange(len(b)), ax[:, 1]] + r * np.sin(phi)
        # normal axis already linear in frac (helix)
    done = frac >= 1.0
    if done.any():
        p[done] = e[done]
    return p
