"""The axial chip: the end (bottom) edges of a flat end mill cutting while the tool moves down its axis.

The peripheral model (:mod:`.force`, Sim & Lee 2023 Eq. 10-13) takes the chip from the XY feed only, so a
plunge, a drilling cycle's feed or a ramp's Z share would remove nothing. Here the end edges cut too
(Altintas, *Manufacturing Automation*, 2nd ed. 2012, ch. 2 mechanics of milling and the drilling section:
an edge element of width ``dr`` cutting a chip ``h`` carries ``dFt = Kt h dr`` and ``dFa = Ka dFt``).

Per tooth the axial chip thickness is the axial feed per tooth ``h_a = vz / (N n) = 2 pi vz / (N omega)``
(``vz`` the downward tool speed, m/s; ``omega`` rad/s). Each of the ``N`` end edges runs from the axis to the
radius ``R`` and cuts where it meets material. Averaged over a revolution, an element of the end disc at
radius ``r`` with area ``dA`` that removes a depth ``d`` in a step of ``h`` seconds carries (all ``N`` teeth):

* tangential force ``Kt (d / h) dA / (omega r)``, i.e. a torque ``Kt (d / h) dA / omega``;
* axial force (thrust) ``Ka Kt (d / h) dA / (omega r)``;
* removal ``(d / h) dA``.

So torque = ``Kt MRR_a / omega`` (power = ``Kt MRR_a``, the specific cutting energy), thrust =
``Ka Kt / omega * integral (d / h) dA / r``. For a plunge into solid (``d = vz h`` over the whole disc) this is
exactly ``N Kt h_a R^2 / 2`` (torque), ``N Ka Kt h_a R`` (thrust) and ``pi R^2 vz`` (removal).

The lateral (x, y) resultant of the end edges cancels for a symmetric engagement (a full disc); for an
asymmetric one (a ramp, a plunge at a wall) it is neglected: ``fx``, ``fy``, ``fc`` stay the peripheral load.

Engagement from the stock: the end disc at the step's end position is sampled at
:data:`RINGS` x :data:`SECTORS` polar points (midpoint rule in ``r`` and angle: exact area ``pi R^2`` and
``integral dA / r = 2 pi R`` for the full disc). A point counts where it is also under the disc at the step's
start (what enters the disc sideways is the periphery's, :mod:`.force`); it removes
``d = max(min(top, z_old) - max(z_new, z_min), 0)``, ``top`` the material there before the step (Z-map minus
the recent path up to the step's start, as :func:`.engagement.tooth_depth`). A G83 peck re-entering its hole
thus removes each layer once.

The path mode reads the same quadrature from its engagement table (:mod:`.path_axial`).
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from ..jit_cache import guard_cache
from . import engagement, kernel, stock
from .engagement import RIM_TOL
from .kernel import OMEGA_FLOOR, OMEGA_STOPPED
from .stock import sweep_cover_z

#: Default axial (thrust) / tangential force ratio of the end edges, 1: Kac / Ktc = 222 / 796 N/mm2 of a carbide
#: end mill in Al 7050-T7451 (Altintas, *Manufacturing Automation*, 2nd ed. 2012, ch. 2 mechanistic
#: coefficients); no value for A6061 is published with the paper (the machine file's ``ka`` cites it).
AXIAL_RATIO_DEFAULT = 0.28
#: Radial rings of the end-disc quadrature.
RINGS = 8
#: Angular sectors of the end-disc quadrature.
SECTORS = 32
#: Columns of :func:`axial_cut`'s result: thrust on the tool (+z, N), torque (N.m), removal rate (m3/s).
AX_THRUST, AX_TORQUE, AX_MRR = range(3)
#: Grid columns (as :mod:`.zmap_numba`): block lower corner x, y, z and cell size dx, dy, m.
_G_X, _G_Y, _G_Z, _G_DX, _G_DY = range(5)


#: Sector mid-angle ``(j + 1/2) 2 pi / SECTORS`` of the quadrature, rad, and its sine and cosine (the values
#: ``math.sin`` / ``math.cos`` give, as the point loop computed them per point before; a table, not 2 x 256 calls).
_DTH = 2.0 * math.pi / SECTORS
_SIN = np.array([math.sin((j + 0.5) * _DTH) for j in range(SECTORS)])
_COS = np.array([math.cos((j + 0.5) * _DTH) for j in range(SECTORS)])
#: Columns of :func:`_near_segments`' rows: start and end of a path segment (x, y, z), then the box, in x and
#: y, outside which its swept disc covers no point (:data:`_S_XLO` .. :data:`_S_YHI`), m.
_S_AX, _S_AY, _S_AZ, _S_BX, _S_BY, _S_BZ, _S_XLO, _S_XHI, _S_YLO, _S_YHI = range(10)
#: Relative margin of that box on the tool radius, 1: far above the rounding of :func:`.stock.sweep_cover_z`
#: (about 1e-16 relative), so a point outside the box is provably not covered (the sweep would give ``inf``).
_REACH_MARGIN = 1e-6


@njit
def _add_segment(seg: np.ndarray, n: int, ax: float, ay: float, az: float, bx: float, by: float, bz: float,
                 reach: float, xlo: float, xhi: float, ylo: float, yhi: float) -> int:
    """Append segment A-B to ``seg`` (row ``n``) if its swept disc can reach the box ``xlo..xhi, ylo..yhi``, m.

    ``reach`` is the tool radius with :data:`_REACH_MARGIN` (m). Returns the new row count.
    """
    sxlo = min(ax, bx) - reach
    sxhi = max(ax, bx) + reach
    sylo = min(ay, by) - reach
    syhi = max(ay, by) + reach
    if sxhi < xlo or sxlo > xhi or syhi < ylo or sylo > yhi:
        return n
    seg[n, _S_AX] = ax
    seg[n, _S_AY] = ay
    seg[n, _S_AZ] = az
    seg[n, _S_BX] = bx
    seg[n, _S_BY] = by
    seg[n, _S_BZ] = bz
    seg[n, _S_XLO] = sxlo
    seg[n, _S_XHI] = sxhi
    seg[n, _S_YLO] = sylo
    seg[n, _S_YHI] = syhi
    return n + 1


@njit
def _near_segments(points: np.ndarray, head: np.ndarray, count: np.ndarray, m: int, tx: float, ty: float,
                   tz: float, radius: float, xlo: float, xhi: float, ylo: float, yhi: float,
                   seg: np.ndarray) -> int:
    """The near-field segments (:meth:`.engagement.NearField.height`) whose sweep can cover a point of the box.

    The open segment from the last stored point to the tool at the step's start ``t`` first, then the stored
    segments of the ring buffer in order (the order of a minimum does not change it). A segment is left out
    when the box ``xlo..xhi, ylo..yhi`` (m) lies outside its XY bounding box grown by the tool radius (and
    :data:`_REACH_MARGIN`): :func:`.stock.sweep_cover_z` gives ``inf`` (not covered) at every such point.

    Returns
    -------
    int
        Rows of ``seg`` filled (columns :data:`_S_AX` .. :data:`_S_YHI`).
    """
    reach = radius * (1.0 + _REACH_MARGIN)
    cap = points.shape[1]
    last = (head[m] + count[m] - 1) % cap
    n = _add_segment(seg, 0, points[m, last, 0], points[m, last, 1], points[m, last, 2], tx, ty, tz, reach,
                     xlo, xhi, ylo, yhi)
    for i in range(count[m] - 1):
        a = (head[m] + i) % cap
        e = (head[m] + i + 1) % cap
        n = _add_segment(seg, n, points[m, a, 0], points[m, a, 1], points[m, a, 2], points[m, e, 0],
                         points[m, e, 1], points[m, e, 2], reach, xlo, xhi, ylo, yhi)
    return n


@njit
def _top_before(heights: np.ndarray, grid: np.ndarray, cells: np.ndarray, seg: np.ndarray, n_seg: int, m: int,
                px: float, py: float, radius: float, bottom: float) -> float:
    """Top of material at ``(px, py)`` before the step, m, where it is above ``bottom``; else some value <= it.

    The Z-map height of stock row ``m``, lowered by the near field (``seg[:n_seg]`` of :func:`_near_segments`:
    the open segment to the tool at the step's start and the stored path segments), as
    :meth:`.engagement.NearField.height`. The walk stops once the top is at or below ``bottom`` (the point
    then removes nothing whatever the remaining segments give) and skips the segments whose box excludes the
    point (they cover it nowhere): above ``bottom`` the value is the minimum over all of them, bit for bit.
    ``-inf`` off the grid.
    """
    fx = math.floor((px - grid[m, _G_X]) / grid[m, _G_DX])
    fy = math.floor((py - grid[m, _G_Y]) / grid[m, _G_DY])
    if not (fx >= 0 and fy >= 0 and fx < cells[m, 0] and fy < cells[m, 1]):
        return -math.inf
    top = np.float64(heights[m, int(fx), int(fy)])
    if not top > bottom:
        return top
    for k in range(n_seg):
        if px < seg[k, _S_XLO] or px > seg[k, _S_XHI] or py < seg[k, _S_YLO] or py > seg[k, _S_YHI]:
            continue
        z = sweep_cover_z(px, py, seg[k, _S_AX], seg[k, _S_AY], seg[k, _S_AZ], seg[k, _S_BX], seg[k, _S_BY],
                          seg[k, _S_BZ], radius, RIM_TOL)
        if z < top:
            top = z
            if not top > bottom:
                return top
    return top


@njit
def _disc_off_grid(grid: np.ndarray, cells: np.ndarray, m: int, x: float, y: float, radius: float) -> bool:
    """The disc of ``radius`` around ``(x, y)`` (m) lies more than a cell outside stock row ``m``'s grid.

    Then no quadrature point of :func:`axial_cut` falls on a cell (each is within ``radius`` of the centre).
    """
    gx, gy = grid[m, _G_X], grid[m, _G_Y]
    dx, dy = grid[m, _G_DX], grid[m, _G_DY]
    return (x + radius < gx - dx or y + radius < gy - dy or x - radius > gx + (cells[m, 0] + 1) * dx
            or y - radius > gy + (cells[m, 1] + 1) * dy)


@njit
def axial_cut(heights: np.ndarray, grid: np.ndarray, cells: np.ndarray, points: np.ndarray, head: np.ndarray,
              count: np.ndarray, m: int, x0: float, y0: float, z0: float, x1: float, y1: float, z1: float,
              radius: float, omega: float, kt: float, ka: float, h: float, out: np.ndarray) -> None:
    """End-edge (axial chip) thrust, torque and removal rate of one member over one step, into ``out[:3]``.

    Parameters
    ----------
    heights : ndarray of float32, shape (S, NX, NY)
        Z-map heights, m.
    grid : ndarray, shape (S, 5)
        Block lower corner x, y, z and cell size dx, dy per stock row, m.
    cells : ndarray of int64, shape (S, 2)
        Cells per stock row.
    points : ndarray, shape (S, P, 3)
        Ring buffer of the recent path (:class:`.engagement.SweptPath`), m; read before this step's commit.
    head, count : ndarray of int64, shape (S,)
        Ring buffer start and fill.
    m : int
        Stock / path row of the member.
    x0, y0, z0, x1, y1, z1 : float
        Tool tip at the start and end of the step, m.
    radius : float
        Tool radius, m.
    omega : float
        Spindle speed over the step, rad/s (>= 0; below :data:`.kernel.OMEGA_FLOOR` taken at it).
    kt : float
        Tangential cutting coefficient, N/m2 (wear included).
    ka : float
        Axial (thrust) / tangential force ratio of the end edges, 1.
    h : float
        Step length, s.
    out : ndarray, shape (>= 3,)
        ``AX_THRUST``: thrust on the tool along +z (the force on the workpiece is its negative), N;
        ``AX_TORQUE``: torque on the spindle, N.m; ``AX_MRR``: removal rate, m3/s. All 0 when the tool does
        not move down or its end disc meets no material.

    Notes
    -----
    Exits that cannot change a sum (each point's ``d`` would be ``<= 0``): the tool not above the floor of
    the stock (``z0 <= bottom``), the end disc more than a cell off the grid; per point, the near-field walk
    stops once the top is at or below ``bottom`` and skips segments that cannot cover the point
    (:func:`_top_before`). The results are those of the full quadrature bit for bit.
    """
    out[AX_THRUST] = 0.0
    out[AX_TORQUE] = 0.0
    out[AX_MRR] = 0.0
    if not z1 < z0:
        return
    bottom = max(z1, grid[m, _G_Z])
    if not z0 > bottom:  # d = min(top, z0) - bottom <= 0 at every point
        return
    if _disc_off_grid(grid, cells, m, x1, y1, radius):  # every point off the grid: top = -inf
        return
    seg = np.empty((points.shape[1], 10))  # count - 1 stored segments and the open one
    n_seg = _near_segments(points, head, count, m, x0, y0, z0, radius, x1 - radius, x1 + radius, y1 - radius,
                           y1 + radius, seg)
    dr = radius / RINGS
    dth = _DTH
    r_old2 = radius * radius
    vol = 0.0  # sum d r dr dth, m3
    per_r = 0.0  # sum d dr dth, m2
    for i in range(RINGS):
        r = (i + 0.5) * dr
        ring_per_r = 0.0  # sum of d over the ring's sectors, m
        for j in range(SECTORS):
            px = x1 + r * _SIN[j]
            py = y1 + r * _COS[j]
            ox = px - x0
            oy = py - y0
            if not ox * ox + oy * oy < r_old2:  # entered the disc sideways: the periphery's chip
                continue
            top = _top_before(heights, grid, cells, seg, n_seg, m, px, py, radius, bottom)
            d = min(top, z0) - bottom
            if d > 0.0:
                ring_per_r += d
        vol += ring_per_r * r * dr * dth
        per_r += ring_per_r * dr * dth
    if not vol > 0.0:
        return
    w = max(omega, OMEGA_FLOOR)  # a plunge with a stalled spindle is refused by the components
    out[AX_MRR] = vol / h
    out[AX_TORQUE] = kt * out[AX_MRR] / w
    out[AX_THRUST] = ka * kt * per_r / (h * w)


@njit
def stalled_plunge(omega: float, mrr_axial: float) -> bool:
    """The tool feeds down into material with the spindle stopped (below :data:`.kernel.OMEGA_STOPPED`): a crash.

    The end-edge counterpart of :func:`.kernel.stalled_cut` (one member, one step; ``mrr_axial`` m3/s).
    """
    return omega < OMEGA_STOPPED and mrr_axial > 0.0


def stalled_plunges(omega: np.ndarray, mrr_axial: np.ndarray) -> np.ndarray:
    """:func:`stalled_plunge` of every member, shape (B,) bool."""
    return (omega < OMEGA_STOPPED) & (mrr_axial > 0.0)


@njit
def axial_cuts(heights: np.ndarray, grid: np.ndarray, cells: np.ndarray, points: np.ndarray, head: np.ndarray,
               count: np.ndarray, p_old: np.ndarray, p_new: np.ndarray, radius: np.ndarray, omega: np.ndarray,
               kt: np.ndarray, ka: np.ndarray, h: float, held: np.ndarray) -> np.ndarray:
    """:func:`axial_cut` of every member (row ``b`` of the stock and path), shape (B, 3); held members get 0.

    ``p_old``, ``p_new`` (B, >= 3) m; ``radius``, ``omega``, ``kt``, ``ka`` (B,); ``held`` (B,) bool.
    """
    B = p_old.shape[0]
    res = np.zeros((B, 3))
    for b in range(B):
        if held[b]:
            continue
        axial_cut(heights, grid, cells, points, head, count, b, p_old[b, 0], p_old[b, 1], p_old[b, 2],
                  p_new[b, 0], p_new[b, 1], p_new[b, 2], radius[b], omega[b], kt[b], ka[b], h, res[b])
    return res


# the cached kernels call stock.sweep_cover_z and hold constants of engagement and kernel: recompile on change
for _kernel in (_add_segment, _near_segments, _top_before, _disc_off_grid, axial_cut, stalled_plunge,
                axial_cuts):
    guard_cache(_kernel, stock, engagement, kernel)
