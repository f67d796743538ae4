"""Ground-truth thrust of the end edges (plunges, drilling, ramps), coded independently of the twin.

The twin's axial chip (:mod:`fmus_src.cutting.axial`) integrates the removal of its Z-map over the end disc per
communication step and averages it over a revolution. Here, on the truth's fine grid, each of the ``N`` end
edges is followed **tooth by tooth**: the edge of tooth ``j`` lies along the radius at the spindle angle
``phi_j = theta + j 2 pi / N``, sampled at :data:`RINGS` points ``r_i = (i + 1/2) R / RINGS``; a point ``p``
cuts an axial chip

    ``h(p) = max(0, min(H(p), z(t - T)) - max(z(t), z_min))``

(Altintas, *Manufacturing Automation*, 2nd ed. 2012, ch. 2: ``dFt = Kt h dr``, ``dFa = Ka dFt``), where
``z(t - T)`` is the tool tip one tooth period ``T = 2 pi / (N omega)`` ago (the previous tooth's pass),
``H`` the material top before that pass (the stock's top face, lowered by every tool-disc position older than
``t - T``; an own height grid of :data:`CELL_M`), and only where ``p`` was already under the disc at ``t - T``
(what enters the disc sideways is the periphery's chip). The thrust on the tool is
``Ka Kt sum_j sum_i h dr`` (upward); the force on the workpiece ``fz`` is its opposite.

For a plunge into solid at the axial feed per tooth ``h_a`` this is ``N Ka Kt h_a R`` at every instant, the
twin's revolution mean. The Z slide carries the tool: the load resisting its positive motion is ``fz``
(``<= 0``: the slide is pushed up, a plunge needs more downward motor force).
"""
from __future__ import annotations

import math

import numpy as np

from fmus_src.jit import njit

#: Sample points along each end edge.
RINGS = 12
#: Cell of the truth's own material-height grid, m.
CELL_M = 0.1e-3
#: A tool position lowers the height grid when it moved this far (xy, m) or went down at all since the last.
STAMP_MOVE_M = 0.025e-3
TWO_PI = 2.0 * math.pi


@njit
def _stamp(height: np.ndarray, x0: float, y0: float, cell: float, cx: float, cy: float, cz: float,
           radius: float) -> None:
    """Lower ``height`` to ``cz`` under the tool disc centred at ``(cx, cy)``."""
    nx, ny = height.shape
    i0 = max(0, int(math.floor((cx - radius - x0) / cell)))
    i1 = min(nx - 1, int(math.floor((cx + radius - x0) / cell)))
    j0 = max(0, int(math.floor((cy - radius - y0) / cell)))
    j1 = min(ny - 1, int(math.floor((cy + radius - y0) / cell)))
    r2 = radius * radius
    for i in range(i0, i1 + 1):
        px = x0 + (i + 0.5) * cell - cx
        for j in range(j0, j1 + 1):
            py = y0 + (j + 0.5) * cell - cy
            if px * px + py * py <= r2 and cz < height[i, j]:
                height[i, j] = cz


@njit
def _thrust_kernel(t: np.ndarray, pos: np.ndarray, omega: np.ndarray, theta: np.ndarray, radius: float,
                   flutes: int, kt: float, ka: float, lower: np.ndarray, upper: np.ndarray, cell: float,
                   out: np.ndarray) -> None:
    """Thrust on the tool [N, upward] at every fine instant into ``out`` (see the module docstring)."""
    n = t.size
    dt = t[1] - t[0]
    nx = max(1, int(math.ceil((upper[0] - lower[0]) / cell)))
    ny = max(1, int(math.ceil((upper[1] - lower[1]) / cell)))
    height = np.full((nx, ny), upper[2])
    dr = radius / RINGS
    pitch = TWO_PI / flutes
    applied = 0                       # positions before this index are in ``height`` (or were skipped)
    lx, ly, lz = math.inf, math.inf, math.inf
    for k in range(n):
        out[k] = 0.0
        om = omega[k]
        if om <= 1e-6:
            continue
        period = pitch / om
        back = (t[k] - period - t[0]) / dt       # fine index of t - T
        if back < 0.0:
            continue
        kb = int(math.floor(back))
        w = back - kb
        kb1 = min(kb + 1, n - 1)
        bx = pos[kb, 0] + w * (pos[kb1, 0] - pos[kb, 0])
        by = pos[kb, 1] + w * (pos[kb1, 1] - pos[kb, 1])
        bz = pos[kb, 2] + w * (pos[kb1, 2] - pos[kb, 2])
        while applied <= kb:                     # every position older than t - T lowers the material
            ax, ay, az = pos[applied, 0], pos[applied, 1], pos[applied, 2]
            if az < lz or (ax - lx) ** 2 + (ay - ly) ** 2 > STAMP_MOVE_M ** 2:
                _stamp(height, lower[0], lower[1], cell, ax, ay, az, radius)
                lx, ly, lz = ax, ay, az
            applied += 1
        cz = pos[k, 2]
        if not cz < bz:                          # not going down over the last tooth period: no axial chip
            continue
        bottom = max(cz, lower[2])
        total = 0.0
        for j in range(flutes):
            phi = theta[k] + j * pitch
            s, c = math.sin(phi), math.cos(phi)
            for i in range(RINGS):
                r = (i + 0.5) * dr
                px = pos[k, 0] + r * s
                py = pos[k, 1] + r * c
                if (px - bx) ** 2 + (py - by) ** 2 > radius * radius:
                    continue                     # entered the disc sideways: the periphery's chip
                gi = int(math.floor((px - lower[0]) / cell))
                gj = int(math.floor((py - lower[1]) / cell))
                if gi < 0 or gj < 0 or gi >= nx or gj >= ny:
                    continue
                top = min(height[gi, gj], bz)
                if top > bottom:
                    total += (top - bottom) * dr
        out[k] = ka * kt * total


def truth_thrust(t: np.ndarray, position: np.ndarray, omega: np.ndarray, theta: np.ndarray, radius_m: float,
                 flutes: int, kt: float, ka: float, stock_min_m: np.ndarray, stock_max_m: np.ndarray) -> np.ndarray:
    """Thrust of the end edges on the tool (upward, N) on a uniform fine grid.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Uniform fine grid, s.
    position : ndarray, shape (n, 3)
        Tool-tip position (work coordinates), m.
    omega, theta : ndarray, shape (n,)
        Actual spindle speed (rad/s) and angle of tooth 0 (rad) at ``t``.
    radius_m : float
        Tool radius, m.
    flutes : int
    kt : float
        Tangential cutting coefficient, N/m2 (with any hidden factor on it).
    ka : float
        Axial (thrust) / tangential force ratio of the end edges, 1.
    stock_min_m, stock_max_m : ndarray, shape (3,)
        The stock block, m.

    Returns
    -------
    ndarray, shape (n,)
        Thrust on the tool, N (>= 0); the force on the workpiece is its opposite.
    """
    out = np.zeros(t.size)
    if t.size < 2 or ka == 0.0:
        return out
    _thrust_kernel(np.ascontiguousarray(t, float), np.ascontiguousarray(position, float),
                   np.ascontiguousarray(omega, float), np.ascontiguousarray(theta, float), float(radius_m),
                   int(flutes), float(kt), float(ka), np.asarray(stock_min_m, float), np.asarray(stock_max_m, float),
                   CELL_M, out)
    return out
