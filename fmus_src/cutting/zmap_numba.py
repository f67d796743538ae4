"""Compiled (numba) Z-map cutting step: :func:`.kernel.cut_step` member by member in scalar loops.

The numpy kernel (:func:`.kernel.cut_step`) stays the reference; this module
does exactly the same arithmetic for the members **without effect terms**,
one member at a time, on the underlying arrays of the stock
(:class:`.stock.ZMapStock`) and of the near field (:class:`.engagement.NearField`):

* kinematics (:func:`.kernel.step_kinematics`), chip thickness, tooth depth
  from the Z-map and the near field (:func:`.engagement.tooth_depth`,
  :meth:`.engagement.NearField.height`, :meth:`.stock.ZMapStock.sample`,
  :func:`.stock.disc_sweep_cover`), per-tooth quantities and closed-form
  interval means (:mod:`.force`), the entry/exit search
  (:data:`.kernel.SECTIONS` x :data:`.kernel.SECTION_ROUNDS`), the peak and the
  step means;
* the removal of committed path segments from the Z-map
  (:meth:`.stock.ZMapStock.remove_sweep`, :func:`remove_sweep`);
* the whole component step with its effect terms off (:func:`zmap_component_step`:
  ``CuttingLoad._do_step``, used by the compiled master loop, :mod:`orchestrator.compiled`).

Every floating-point operation is the numpy one, in the same order (no
fastmath; the sums over teeth and over substeps are sequential, as numpy's
reductions over these small axes are), so the results equal those of the
numpy kernel bit for bit on the tested programs (checked by
``tests/test_cutting_zmap_numba.py``). Each member is computed from its own
arrays only, so a member's figures do not depend on the other members.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import CncTwinError
from ..jit import njit
from ..jit_cache import guard_cache
from . import axial, engagement, kernel, stock, tool_table
from .axial import AX_MRR, AX_THRUST, AX_TORQUE, axial_cut, stalled_plunge
from .engagement import PATH_SPACING, RIM_TOL, SAME_XY_TOL, SweptPath, turn_point
from .kernel import (H_COUNT, OMEGA_FLOOR, SECTION_ROUNDS, SECTIONS, StepResult, chord_advance, chord_feed,
                     stalled_cut, substep_counts)
from .stock import StockError, ZMapStock, sweep_cover_z
from .tool_table import slot_of

#: Columns of the per-member float parameters of :func:`zmap_step`.
MP_X0, MP_Y0, MP_Z0, MP_X1, MP_Y1, MP_Z1, MP_THETA, MP_OMEGA, MP_RADIUS, MP_KT, MP_KE, MP_FX, MP_FY = range(13)
#: Columns of the per-member integer parameters: row in stock / near field, substeps, teeth.
MI_ROW, MI_SUBSTEPS, MI_FLUTES = range(3)
#: Columns of the stock grid: block lower corner (x, y, z), cell size dx, dy, m.
G_X, G_Y, G_Z, G_DX, G_DY = range(5)
#: Columns of the output: force on the tool (x, y), peak, means (Fx, Fy, torque, MRR), depth, chip, teeth.
OUT_FX, OUT_FY, OUT_PEAK, OUT_MFX, OUT_MFY, OUT_TORQUE, OUT_MRR, OUT_DEPTH, OUT_CHIP, OUT_TEETH = range(10)


@njit
def _depth(heights: np.ndarray, grid: np.ndarray, cells: np.ndarray, points: np.ndarray, head: np.ndarray,
           count: np.ndarray, m: int, cx: float, cy: float, cz: float, phi: float, radius: float) -> float:
    """:func:`.engagement.tooth_depth` of one active tooth of member row ``m`` (0 in air), m.

    The near field (:meth:`.engagement.NearField.height`) is read from the ring buffer of
    :class:`.engagement.SweptPath` (``points``, ``head``, ``count``): the segments between its
    consecutive stored points, then the open segment from the last one to the tool.
    """
    px = cx + radius * math.sin(phi)
    py = cy + radius * math.cos(phi)
    # ZMapStock.sample
    fx = np.floor((px - grid[m, G_X]) / grid[m, G_DX])
    fy = np.floor((py - grid[m, G_Y]) / grid[m, G_DY])
    if fx >= 0 and fy >= 0 and fx < cells[m, 0] and fy < cells[m, 1]:
        top = np.float64(heights[m, int(fx), int(fy)])
    else:
        top = -np.inf
    bottom = np.maximum(cz, grid[m, G_Z])
    if not top > bottom:
        return 0.0
    # NearField.height
    cap = points.shape[1]
    z_hist = np.inf
    for i in range(count[m] - 1):
        a = (head[m] + i) % cap
        e = (head[m] + i + 1) % cap
        z = sweep_cover_z(px, py, points[m, a, 0], points[m, a, 1], points[m, a, 2],
                   points[m, e, 0], points[m, e, 1], points[m, e, 2], radius, RIM_TOL)
        z_hist = np.minimum(z_hist, z)
    t = (head[m] + count[m] - 1) % cap
    z_tail = sweep_cover_z(px, py, points[m, t, 0], points[m, t, 1], points[m, t, 2], cx, cy, cz, radius, RIM_TOL)
    near_top = np.minimum(z_hist, z_tail)
    return np.maximum(np.minimum(top, near_top) - bottom, 0.0)


@njit
def _chip(fx_t: float, fy_t: float, phi: float) -> float:
    """:func:`.force.chip_thickness`, m."""
    return np.maximum(fx_t * math.sin(phi) + fy_t * math.cos(phi), 0.0)


@njit
def _quantities(kt: float, ke: float, depth: float, hc: float, phi: float, radius: float, omega: float,
                out: np.ndarray) -> None:
    """:func:`.force.tooth_quantities` into ``out[:4]`` (Fx, Fy on the tool N, torque N.m, MRR m3/s)."""
    ft = kt * depth * hc
    fr = ke * ft
    s = math.sin(phi)
    c = math.cos(phi)
    out[0] = -ft * c - fr * s
    out[1] = ft * s - fr * c
    out[2] = ft * radius
    out[3] = hc * depth * radius * omega


@njit
def _primitives(p: float, dx: float, dy: float) -> tuple[float, float, float]:
    """Primitives of ``h cos``, ``h sin`` and ``h`` at ``p`` (:func:`.force.interval_mean_quantities`)."""
    s = math.sin(p)
    c = math.cos(p)
    s2 = math.sin(2.0 * p)
    half_sq = 0.5 * s * s
    return (dx * half_sq + dy * (0.5 * p + 0.25 * s2), dx * (0.5 * p - 0.25 * s2) + dy * half_sq,
            -dx * c + dy * s)


@njit
def _interval(kt: float, ke: float, depth: float, dx: float, dy: float, phi_a: float, phi_b: float,
              radius: float, omega: float, out: np.ndarray) -> None:
    """:func:`.force.interval_mean_quantities` of one tooth into ``out[:4]``."""
    span = phi_b - phi_a
    if span < 1e-9:
        phi_m = 0.5 * (phi_a + phi_b)
        _quantities(kt, ke, depth, _chip(dx, dy, phi_m), phi_m, radius, omega, out)
        return
    h_a = dx * math.sin(phi_a) + dy * math.cos(phi_a)
    h_b = dx * math.sin(phi_b) + dy * math.cos(phi_b)
    psi = math.atan2(dy, dx)
    phi_zero = phi_a + np.mod(-psi - phi_a, np.pi)
    if h_a >= 0.0 or h_b < 0.0:
        lo = phi_a
    else:
        lo = np.minimum(phi_zero, phi_b)
    if h_b >= 0.0:
        hi = phi_b
    elif h_a > 0.0:
        hi = np.minimum(phi_zero, phi_b)
    else:
        hi = phi_a
    if h_a < 0.0 and h_b < 0.0:
        hi = lo
    u_cos, u_sin, u_h = _primitives(lo, dx, dy)
    w_cos, w_sin, w_h = _primitives(hi, dx, dy)
    i_hcos = (w_cos - u_cos) / span
    i_hsin = (w_sin - u_sin) / span
    i_h = (w_h - u_h) / span
    out[0] = -kt * depth * (i_hcos + ke * i_hsin)
    out[1] = kt * depth * (i_hsin - ke * i_hcos)
    out[2] = kt * depth * radius * i_h
    out[3] = depth * radius * omega * i_h


@njit
def zmap_step(heights: np.ndarray, grid: np.ndarray, cells: np.ndarray, points: np.ndarray, head: np.ndarray,
              count: np.ndarray, mp: np.ndarray, mi: np.ndarray, h: float, out: np.ndarray) -> None:
    """One communication step of :func:`.kernel.cut_step` for every member, into ``out``.

    Parameters
    ----------
    heights : ndarray of float32, shape (S, NX, NY)
        Z-map heights (:attr:`.stock.ZMapStock.heights`), m.
    grid : ndarray, shape (S, 5)
        Block lower corner x, y, z and cell size dx, dy per stock row, m (``G_*`` columns).
    cells : ndarray of int64, shape (S, 2)
        Cells ``nx, ny`` per stock row.
    points : ndarray, shape (S, P, 3)
        Stored tool-tip path per stock row (ring buffer of :class:`.engagement.SweptPath`), m.
    head, count : ndarray of int64, shape (S,)
        First stored point and number of stored points per row.
    mp : ndarray, shape (B, 13)
        Per member: position at the start and end of the step (m), spindle angle (rad), spindle
        speed (rad/s), tool radius (m), Kt (N/m2), Ke (1), feed per tooth vector (m, the
        tooth-period chord, :func:`.kernel.chord_feed`) (``MP_*`` columns).
    mi : ndarray of int64, shape (B, 3)
        Per member: stock / near-field row, substeps (>= 1), teeth (``MI_*`` columns).
    h : float
        Step length, s.
    out : ndarray, shape (B, 10)
        Results (``OUT_*`` columns): force on the tool at the end of the step (N), peak cutting
        load (N), step means of Fx, Fy (N), torque (N.m), MRR (m3/s), largest axial depth and chip
        thickness over engaged teeth (m), engaged teeth.
    """
    q = np.empty(4)
    for b in range(mp.shape[0]):
        m = mi[b, MI_ROW]
        n = mi[b, MI_SUBSTEPS]
        nt = mi[b, MI_FLUTES]
        x0, y0, z0 = mp[b, MP_X0], mp[b, MP_Y0], mp[b, MP_Z0]
        dpx, dpy, dpz = mp[b, MP_X1] - x0, mp[b, MP_Y1] - y0, mp[b, MP_Z1] - z0
        theta0 = mp[b, MP_THETA]
        omega = mp[b, MP_OMEGA]
        radius = mp[b, MP_RADIUS]
        kt = mp[b, MP_KT]
        ke = mp[b, MP_KE]
        # step_kinematics
        pitch = 2.0 * math.pi / np.float64(nt)
        wh = omega * h
        fx_t = mp[b, MP_FX]
        fy_t = mp[b, MP_FY]
        phi = np.empty((n + 1, nt))
        hc = np.empty((n + 1, nt))
        depth = np.empty((n + 1, nt))
        qx = np.empty((n + 1, nt))
        qy = np.empty((n + 1, nt))
        tot_x = np.empty(n + 1)
        tot_y = np.empty(n + 1)
        peak = 0.0
        for k in range(n + 1):
            frac = k / n
            cx = x0 + frac * dpx
            cy = y0 + frac * dpy
            cz = z0 + frac * dpz
            theta = theta0 + wh * frac
            sx = 0.0
            sy = 0.0
            for j in range(nt):
                p = theta + j * pitch
                phi[k, j] = p
                c = _chip(fx_t, fy_t, p)
                hc[k, j] = c
                d = 0.0
                if c > 0.0:
                    d = _depth(heights, grid, cells, points, head, count, m, cx, cy, cz, p, radius)
                depth[k, j] = d
                _quantities(kt, ke, d, c, p, radius, omega, q)
                qx[k, j] = q[0]
                qy[k, j] = q[1]
                if j == 0:
                    sx = q[0]
                    sy = q[1]
                else:
                    sx += q[0]
                    sy += q[1]
            tot_x[k] = sx
            tot_y[k] = sy
            if k >= 1:
                peak = np.maximum(peak, math.hypot(sx, sy))
        # exact means over the substeps where a tooth stays in material
        acc = np.zeros(4)
        for k in range(n):
            for j in range(nt):
                if depth[k, j] > 0.0 and depth[k + 1, j] > 0.0:
                    _interval(kt, ke, 0.5 * (depth[k, j] + depth[k + 1, j]), fx_t, fy_t, phi[k, j], phi[k + 1, j],
                              radius, omega, q)
                    for i in range(4):
                        acc[i] += q[i]
        # entry / exit inside a substep: located to 1 / SECTIONS**SECTION_ROUNDS of it
        for k in range(n):
            for j in range(nt):
                e_lo = depth[k, j] > 0.0
                if e_lo == (depth[k + 1, j] > 0.0):
                    continue
                lo = 0.0
                width = 1.0
                for _ in range(SECTION_ROUNDS):
                    first = SECTIONS - 1
                    for i in range(1, SECTIONS):
                        s_try = lo + width * (i / SECTIONS)
                        f = (k + s_try) / n
                        p = theta0 + wh * f + j * pitch
                        e_try = False
                        if _chip(fx_t, fy_t, p) > 0.0:
                            e_try = _depth(heights, grid, cells, points, head, count, m,
                                           x0 + f * dpx, y0 + f * dpy, z0 + f * dpz, p, radius) > 0.0
                        if e_try != e_lo:
                            first = i - 1
                            break
                    lo = lo + width * first / SECTIONS
                    width /= SECTIONS
                s_star = lo + 0.5 * width
                f = (k + s_star) / n
                phi_star = theta0 + wh * f + j * pitch
                d_eng = depth[k, j] if e_lo else depth[k + 1, j]
                h_star = _chip(fx_t, fy_t, phi_star)
                if e_lo:
                    _interval(kt, ke, d_eng, fx_t, fy_t, phi[k, j], phi_star, radius, omega, q)
                    length = s_star
                else:
                    _interval(kt, ke, d_eng, fx_t, fy_t, phi_star, phi[k + 1, j], radius, omega, q)
                    length = 1.0 - s_star
                for i in range(4):
                    acc[i] += length * q[i]
                others0x = tot_x[k] - qx[k, j]
                others0y = tot_y[k] - qy[k, j]
                others1x = tot_x[k + 1] - qx[k + 1, j]
                others1y = tot_y[k + 1] - qy[k + 1, j]
                _quantities(kt, ke, d_eng, h_star, phi_star, radius, omega, q)
                fbx = q[0] + (1.0 - s_star) * others0x + s_star * others1x
                fby = q[1] + (1.0 - s_star) * others0y + s_star * others1y
                peak = np.maximum(peak, math.hypot(fbx, fby))
        out[b, OUT_FX] = tot_x[n]
        out[b, OUT_FY] = tot_y[n]
        out[b, OUT_PEAK] = peak
        for i in range(4):
            out[b, OUT_MFX + i] = acc[i] / n
        d_max = 0.0
        c_max = 0.0
        teeth = 0
        for j in range(nt):
            d_max = np.maximum(d_max, depth[n, j])
            if depth[n, j] > 0.0:
                c_max = np.maximum(c_max, hc[n, j])
                teeth += 1
        out[b, OUT_DEPTH] = d_max
        out[b, OUT_CHIP] = c_max
        out[b, OUT_TEETH] = teeth


@dataclass(frozen=True)
class ZMapArrays:
    """The arrays of a :class:`.stock.ZMapStock` the compiled kernels work on (built once per setup).

    Attributes
    ----------
    heights : ndarray of float32, shape (S, NX, NY)
        The stock's own height field (the same array: removals update the stock), m.
    grid : ndarray, shape (S, 5)
        Block lower corner x, y, z and cell size dx, dy, m (``G_*`` columns).
    cells : ndarray of int64, shape (S, 2)
        Cells ``nx, ny``.
    rho : ndarray, shape (S,)
        Half cell diagonal, m.
    """

    heights: np.ndarray
    grid: np.ndarray
    cells: np.ndarray
    rho: np.ndarray

    @classmethod
    def of(cls, stock: ZMapStock) -> ZMapArrays:
        """The arrays of ``stock`` (its height field itself, the grid as copies)."""
        if stock.heights.dtype != np.float32 or not stock.heights.flags.c_contiguous:
            raise StockError("compiled Z-map kernel: the stock heights must be a C-contiguous float32 array, got "
                               f"{stock.heights.dtype} (contiguous: {stock.heights.flags.c_contiguous})")
        grid = np.ascontiguousarray(np.column_stack([stock.lower, stock.dx, stock.dy]), dtype=np.float64)
        cells = np.ascontiguousarray(np.column_stack([stock.nx, stock.ny]), dtype=np.int64)
        return cls(stock.heights, grid, cells, np.ascontiguousarray(stock.rho, dtype=np.float64))


def _ring(path: SweptPath) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ring buffer of ``path`` as the kernels take it: points (S, P, 3) float64, head and count (S,) int64."""
    return (np.ascontiguousarray(path.points, dtype=np.float64), np.ascontiguousarray(path.head, dtype=np.int64),
            np.ascontiguousarray(path.count, dtype=np.int64))


def cut_step_compiled(
    zmap: ZMapArrays, path: SweptPath, p_old: np.ndarray, p_new: np.ndarray, theta0: np.ndarray,
    omega: np.ndarray, h: float, n: int | np.ndarray, radius: np.ndarray, flutes: np.ndarray, kt: np.ndarray,
    ke: np.ndarray, rows: np.ndarray | None = None, feed: np.ndarray | None = None,
) -> StepResult:
    """:func:`.kernel.cut_step` through the compiled :func:`zmap_step` (same results).

    Parameters
    ----------
    zmap : ZMapArrays
        Arrays of the committed stock (:meth:`ZMapArrays.of`).
    path : SweptPath
        Recent tool path (its near field is that of :meth:`.engagement.SweptPath.near_field`).
    p_old, p_new, theta0, omega, h, n, radius, flutes, kt, ke, rows, feed
        As :func:`.kernel.cut_step` (positions m, angles rad, speeds rad/s,
        ``kt`` N/m2; shapes (B, 3) and (B,), ``feed`` (B, 2) m); ``rows`` index ``zmap`` and ``path``.

    Returns
    -------
    StepResult
        Shapes (B, ...) with B = ``p_old.shape[0]``.
    """
    B = p_old.shape[0]
    rows = np.arange(B, dtype=np.int64) if rows is None else np.asarray(rows, dtype=np.int64)
    ns = n if isinstance(n, np.ndarray) and n.dtype == np.int64 and n.shape == (B,) else substep_counts(n, B)
    if B and ns.min() < 1:
        raise CncTwinError(f"compiled cutting kernel: substep counts must be integers >= 1, got {ns.min()}")
    if feed is None:  # kernel.step_kinematics' default: the step velocity times the tooth period
        period = 2.0 * math.pi / (flutes * np.maximum(omega, OMEGA_FLOOR))
        feed = (p_new - p_old)[:, :2] / h * period[:, None]
    mp = np.empty((B, 13))
    mp[:, MP_FX:MP_FY + 1] = feed
    mp[:, MP_X0:MP_Z0 + 1] = p_old
    mp[:, MP_X1:MP_Z1 + 1] = p_new
    mp[:, MP_THETA] = theta0
    mp[:, MP_OMEGA] = omega
    mp[:, MP_RADIUS] = radius
    mp[:, MP_KT] = kt
    mp[:, MP_KE] = ke
    mi = np.empty((B, 3), dtype=np.int64)
    mi[:, MI_ROW] = rows
    mi[:, MI_SUBSTEPS] = ns
    mi[:, MI_FLUTES] = flutes
    out = np.empty((B, 10))
    points, head, count = _ring(path)
    zmap_step(zmap.heights, zmap.grid, zmap.cells, points, head, count, mp, mi, float(h), out)
    return StepResult(
        force=out[:, OUT_FX:OUT_FY + 1].copy(),
        fc_peak=out[:, OUT_PEAK].copy(),
        mean=out[:, OUT_MFX:OUT_MRR + 1].copy(),
        axial_depth=out[:, OUT_DEPTH].copy(),
        chip_thickness=out[:, OUT_CHIP].copy(),
        engaged_teeth=out[:, OUT_TEETH].astype(np.int64),
    )


@njit
def _round_down_f32(z: float) -> np.float32:
    """:func:`.stock.round_down_f32` of one height: the largest float32 ``<= z``."""
    z32 = np.float32(z)
    if np.float64(z32) > z:
        z32 = np.nextafter(z32, np.float32(-np.inf))
    return z32


@njit
def _remove_segment(heights: np.ndarray, grid: np.ndarray, cells: np.ndarray, rho: np.ndarray, b: int,
                    points: np.ndarray, ia: int, ib: int, radius: float) -> None:
    """:meth:`.stock.ZMapStock.remove_sweep` of member ``b`` for the segment ``points[b, ia] -> points[b, ib]``."""
    nx, ny = cells[b, 0], cells[b, 1]
    if nx <= 0 or ny <= 0:
        return
    ax, ay, az = points[b, ia, 0], points[b, ia, 1], points[b, ia, 2]
    bx, by, bz = points[b, ib, 0], points[b, ib, 1], points[b, ib, 2]
    reach = radius + rho[b]
    x0, y0, dx, dy = grid[b, G_X], grid[b, G_Y], grid[b, G_DX], grid[b, G_DY]
    floor_z = grid[b, G_Z]
    i_lo = min(max(int(np.floor((np.minimum(ax, bx) - reach - x0) / dx)), 0), nx - 1)
    i_hi = min(max(int(np.floor((np.maximum(ax, bx) + reach - x0) / dx)), 0), nx - 1)
    j_lo = min(max(int(np.floor((np.minimum(ay, by) - reach - y0) / dy)), 0), ny - 1)
    j_hi = min(max(int(np.floor((np.maximum(ay, by) + reach - y0) / dy)), 0), ny - 1)
    for i in range(i_lo, i_hi + 1):
        cx = x0 + (i + 0.5) * dx
        for j in range(j_lo, j_hi + 1):
            cy = y0 + (j + 0.5) * dy
            z = sweep_cover_z(cx, cy, ax, ay, az, bx, by, bz, reach, 0.0)
            if z < np.inf:
                z_new = _round_down_f32(np.maximum(z, floor_z))
                if z_new < heights[b, i, j]:
                    heights[b, i, j] = z_new


@njit
def commit_rows(heights: np.ndarray, grid: np.ndarray, cells: np.ndarray, rho: np.ndarray, points: np.ndarray,
                arc: np.ndarray, head: np.ndarray, count: np.ndarray, spacing: np.ndarray, lag: np.ndarray,
                position: np.ndarray, radius: np.ndarray) -> None:
    """:meth:`.engagement.SweptPath.advance`, then pop and remove the ready segments, for every member.

    The ring buffer (``points``, ``arc``, ``head``, ``count``) and ``heights`` are updated in
    place exactly as :meth:`.engagement.SweptPath.advance`, repeated
    :meth:`.engagement.SweptPath.pop_ready` (``force_room=True``) and
    :meth:`.stock.ZMapStock.remove_sweep` do (:meth:`.component.CuttingLoad._commit`).

    Parameters
    ----------
    heights, grid, cells, rho
        As :class:`ZMapArrays` (``heights`` modified).
    points : ndarray, shape (B, P, 3)
        Stored tool-tip points, m (modified).
    arc : ndarray, shape (B, P)
        XY path length at the stored points, m (modified).
    head, count : ndarray of int64, shape (B,)
        Ring buffer start and fill (modified).
    spacing, lag : ndarray, shape (B,)
        Minimum XY distance between stored points and near-field length, m.
    position : ndarray, shape (B, >= 3)
        Tool-tip position at the end of the step (first three columns), m.
    radius : ndarray, shape (B,)
        Tool radius, m.
    """
    cap = points.shape[1]
    for b in range(points.shape[0]):
        # advance: a corner at the previous position first (SweptPath.advance, engagement.turn_point)
        last_i = (head[b] + count[b] - 1) % cap
        prev_i = (head[b] + count[b]) % cap
        if count[b] < cap - 2 and turn_point(points[b, last_i, 0], points[b, last_i, 1], points[b, last_i, 2],
                                             points[b, prev_i, 0], points[b, prev_i, 1], points[b, prev_i, 2],
                                             position[b, 0], position[b, 1], position[b, 2]):
            arc[b, prev_i] = arc[b, last_i] + math.hypot(points[b, prev_i, 0] - points[b, last_i, 0],
                                                         points[b, prev_i, 1] - points[b, last_i, 1])
            count[b] += 1
        last_i = (head[b] + count[b] - 1) % cap
        lx, ly, lz = points[b, last_i, 0], points[b, last_i, 1], points[b, last_i, 2]
        step = math.hypot(position[b, 0] - lx, position[b, 1] - ly)
        if step >= spacing[b] or (step > SAME_XY_TOL and lz - position[b, 2] >= step):
            new_i = (head[b] + count[b]) % cap
            for c in range(3):
                points[b, new_i, c] = position[b, c]
            arc[b, new_i] = arc[b, last_i] + step
            count[b] += 1
        elif step <= SAME_XY_TOL:
            points[b, last_i, 2] = np.minimum(lz, position[b, 2])
        prev_i = (head[b] + count[b]) % cap
        for c in range(3):
            points[b, prev_i, c] = position[b, c]
        # pop_ready(force_room=True) until nothing is ready, each popped segment removed from the Z-map
        while True:
            i_second = (head[b] + min(1, count[b] - 1)) % cap
            arc_last = arc[b, (head[b] + count[b] - 1) % cap]
            ready = (count[b] >= 2 and arc_last - arc[b, i_second] >= lag[b]) or count[b] >= cap - 1
            if not ready:
                break
            i_first = head[b]
            head[b] = (head[b] + 1) % cap
            count[b] -= 1
            _remove_segment(heights, grid, cells, rho, b, points, i_first, i_second, radius[b])


@njit
def flush_member(heights: np.ndarray, grid: np.ndarray, cells: np.ndarray, rho: np.ndarray, points: np.ndarray,
                 arc: np.ndarray, head: np.ndarray, count: np.ndarray, b: int, px: float, py: float, pz: float,
                 radius: float) -> None:
    """Commit member ``b``'s whole recent path, to the tool at ``(px, py, pz)``, to the Z-map (a tool change).

    The tool position is appended to the ring buffer (the open segment from the last stored point becomes a
    stored one), then every stored segment is removed from the Z-map with ``radius`` (the tool that swept
    them, :func:`_remove_segment`), oldest first, leaving the position as the only stored point (and as the
    previous position, in the slot after it). The numpy reference is :meth:`.component.CuttingLoad._flush_path`.
    """
    cap = points.shape[1]
    last_i = (head[b] + count[b] - 1) % cap
    new_i = (head[b] + count[b]) % cap
    step = math.hypot(px - points[b, last_i, 0], py - points[b, last_i, 1])
    points[b, new_i, 0] = px
    points[b, new_i, 1] = py
    points[b, new_i, 2] = pz
    arc[b, new_i] = arc[b, last_i] + step
    count[b] += 1
    while count[b] >= 2:
        i_first = head[b]
        i_second = (head[b] + 1) % cap
        head[b] = i_second
        count[b] -= 1
        _remove_segment(heights, grid, cells, rho, b, points, i_first, i_second, radius)
    # the previous tool position (engagement.SweptPath: the slot after the last point) is the tool's
    prev_i = (head[b] + count[b]) % cap
    points[b, prev_i, 0] = px
    points[b, prev_i, 1] = py
    points[b, prev_i, 2] = pz


@njit
def switch_tool(heights: np.ndarray, grid: np.ndarray, cells: np.ndarray, rho: np.ndarray, points: np.ndarray,
                arc: np.ndarray, head: np.ndarray, count: np.ndarray, spacing: np.ndarray, lag: np.ndarray,
                b: int, px: float, py: float, pz: float, radius: np.ndarray, flutes: np.ndarray,
                table_number: np.ndarray, table_radius: np.ndarray, table_flutes: np.ndarray, tool: float) -> None:
    """Member ``b`` takes the cutter of tool ``tool`` from the tool table (:mod:`.tool_table`).

    When its radius or teeth differ from the member's current ones, the recent path is committed with the
    old radius (:func:`flush_member`, the tool at ``(px, py, pz)``), then ``radius``, ``flutes`` and the
    path's ``spacing`` and ``lag`` (:data:`.engagement.PATH_SPACING` of the radius; the radius plus two cells)
    become the new tool's. Nothing changes otherwise (a one-tool table leaves every number as it was).
    """
    k = slot_of(table_number, b, tool)
    r_new = table_radius[b, k]
    z_new = table_flutes[b, k]
    if r_new == radius[b] and z_new == flutes[b]:
        return
    flush_member(heights, grid, cells, rho, points, arc, head, count, b, px, py, pz, radius[b])
    radius[b] = r_new
    flutes[b] = z_new
    spacing[b] = PATH_SPACING * r_new
    lag[b] = r_new + 2.0 * np.maximum(grid[b, G_DX], grid[b, G_DY])


def commit(zmap: ZMapArrays, path: SweptPath, position: np.ndarray, radius: np.ndarray) -> None:
    """Store the new tool position in ``path`` and commit its old segments to the Z-map (compiled).

    Same effect as :meth:`.engagement.SweptPath.advance` followed by
    :meth:`.engagement.SweptPath.pop_ready` / :meth:`.stock.ZMapStock.remove_sweep`
    until no member pops (:meth:`.component.CuttingLoad._commit`).

    Parameters
    ----------
    zmap : ZMapArrays
        Arrays of the stock (its height field is updated).
    path : SweptPath
        Recent tool path (updated in place).
    position : ndarray, shape (B, 3)
        Tool-tip position at the end of the step, m.
    radius : ndarray, shape (B,)
        Tool radius, m.
    """
    for name, dtype in (("points", np.float64), ("arc", np.float64), ("head", np.int64), ("count", np.int64)):
        value = getattr(path, name)
        if value.dtype != dtype or not value.flags.c_contiguous or not value.flags.writeable:
            setattr(path, name, np.array(value, dtype=dtype))
    commit_rows(zmap.heights, zmap.grid, zmap.cells, zmap.rho, path.points, path.arc, path.head, path.count,
                np.ascontiguousarray(path.spacing, dtype=np.float64), np.ascontiguousarray(path.lag, dtype=np.float64),
                np.ascontiguousarray(position, dtype=np.float64), np.ascontiguousarray(radius, dtype=np.float64))


def flush(zmap: ZMapArrays, path: SweptPath, mask: np.ndarray, position: np.ndarray, radius: np.ndarray) -> None:
    """:func:`flush_member` for every member in ``mask`` (shape (B,) bool): the tool changes at ``position``
    (shape (B, 3), m); ``radius`` (B,) is the radius of the cutter that swept the path, m."""
    for name, dtype in (("points", np.float64), ("arc", np.float64), ("head", np.int64), ("count", np.int64)):
        value = getattr(path, name)
        if value.dtype != dtype or not value.flags.c_contiguous or not value.flags.writeable:
            setattr(path, name, np.array(value, dtype=dtype))
    for b in np.flatnonzero(mask):
        flush_member(zmap.heights, zmap.grid, zmap.cells, zmap.rho, path.points, path.arc, path.head, path.count,
                     int(b), float(position[b, 0]), float(position[b, 1]), float(position[b, 2]), float(radius[b]))


#: Rows of the ``io`` block of :func:`zmap_component_step`: the inputs and outputs of
#: :class:`.component.CuttingLoad`, in this order (``engaged_teeth`` and the ``tool`` input as floats): the
#: four motion inputs, the outputs ``IO_FX`` .. ``IO_FZ``, then the tool in the spindle.
IO_ROWS = ("x_position", "y_position", "z_position", "spindle_speed", "fx", "fy", "fc", "fc_peak", "fx_mean",
           "fy_mean", "spindle_torque", "spindle_power", "mrr", "spindle_angle", "axial_depth", "chip_thickness",
           "engaged_teeth", "spindle_speed_actual", "tool_vibration_x", "tool_vibration_y", "cutting_time", "fz",
           "tool")
(IO_X, IO_Y, IO_Z, IO_SPEED, IO_FX, IO_FY, IO_FC, IO_PEAK, IO_MFX, IO_MFY, IO_TORQUE, IO_POWER, IO_MRR, IO_ANGLE,
 IO_DEPTH, IO_CHIP, IO_TEETH, IO_ACTUAL, IO_VIBX, IO_VIBY, IO_TIME, IO_FZ, IO_TOOL) = range(len(IO_ROWS))
#: The input rows of ``io`` (the others are outputs).
IO_INPUTS = (IO_X, IO_Y, IO_Z, IO_SPEED, IO_TOOL)
#: ``status`` of :func:`zmap_component_step`: the member needs more than ``max_substeps`` substeps.
ERR_SUBSTEPS = 1
#: ``status`` of :func:`zmap_component_step`: the member fed into material with a stalled spindle
#: (:func:`.kernel.stalled_cut`; a crash: its step is computed, then the component fails it).
ERR_STALLED = 2


@njit
def zmap_component_step(
    h: float, io: np.ndarray, heights: np.ndarray, grid: np.ndarray, cells: np.ndarray, rho: np.ndarray,
    points: np.ndarray, arc: np.ndarray, head: np.ndarray, count: np.ndarray, spacing: np.ndarray, lag: np.ndarray,
    p_prev: np.ndarray, theta: np.ndarray, radius: np.ndarray, flutes: np.ndarray, steps: np.ndarray,
    kt: np.ndarray, ke: np.ndarray, ka: np.ndarray, failed: np.ndarray, cutting_time: np.ndarray,
    torque: np.ndarray, angle: np.ndarray, status: np.ndarray, diag: np.ndarray, max_substeps: int,
    table_number: np.ndarray, table_radius: np.ndarray, table_flutes: np.ndarray,
) -> int:
    """``CuttingLoad._do_step`` with every effect term off and the compiled kernels, for every member.

    The same floating-point operations in the same order as the component
    (:meth:`.component.CuttingLoad._step_inputs`, ``_substeps``, the cut through
    :func:`zmap_step` and :func:`.axial.axial_cut` (the end edges), the outputs, the spindle
    angle, ``_finish_effects``, ``_commit`` through :func:`commit_rows`, ``_blank``), so the results are its
    own bit for bit. Members with a non-finite input, failed earlier (``failed``)
    or needing more than ``max_substeps`` substeps are held (not cut, spindle
    stopped) and their outputs blanked; the last ones are reported in ``status``
    (``ERR_SUBSTEPS``, with their spindle speed and XY move in ``diag``) for the
    component to fail them (``CuttingLoad._fail_substeps``). Members that fed into
    material with a stalled spindle (:func:`.kernel.stalled_cut`) are stepped, then
    reported as ``ERR_STALLED`` (``CuttingLoad._fail_stalled`` fails them).

    Parameters
    ----------
    h : float
        Step length, s.
    io : ndarray, shape (22, B)
        Inputs (m, rad/s) and outputs (N, N.m, W, m3/s, rad, m, teeth, s) in :data:`IO_ROWS` order;
        inputs read, outputs written.
    heights, grid, cells, rho
        As :class:`ZMapArrays` (``heights`` modified).
    points, arc, head, count, spacing, lag
        Ring buffer of the :class:`.engagement.SweptPath` (first four modified), as :func:`commit_rows`.
    p_prev : ndarray, shape (B, 3 + CHIP_HISTORY_WIDTH)
        Motion state (``CuttingLoad._motion``): tool-tip position at the start of the step, m (set to
        the end position), then the chip history (:func:`.kernel.chord_advance`; cleared for held
        members).
    theta : ndarray, shape (B,)
        Spindle angle of tooth 0 in ``[0, 2 pi)``, rad (advanced).
    radius, flutes, steps, kt, ke, ka : ndarray, shape (B,)
        Tool radius (m), teeth (int64), angle steps per tooth (float), Kt (N/m2), Ke (1), end-edge thrust
        ratio Ka (1).
    failed : ndarray of bool, shape (B,)
        Members the component failed earlier.
    cutting_time, torque, angle : ndarray, shape (B,)
        Effect-state clocks (:class:`.effect_model.EffectState`): s, N.m, rad (advanced).
    status : ndarray of int64, shape (B,)
        Set to ``ERR_SUBSTEPS`` for the members needing too many substeps, ``ERR_STALLED`` for those
        that fed into material with a stalled spindle (others untouched).
    diag : ndarray, shape (2, B)
        Spindle speed (rad/s) and XY tool move (m) of those members.
    max_substeps : int
        Most substeps a step may take.
    table_number, table_radius, table_flutes : ndarray, shape (B, 1 + n)
        The tool table (:class:`.tool_table.ToolTable`): at the start of each member's step, the cutter of
        the ``tool`` input replaces ``radius`` and ``flutes`` (and the path's ``spacing`` and ``lag``) when
        it differs, after the recent path is committed with the old one (:func:`switch_tool`).

    Returns
    -------
    int
        Number of members newly reported in ``status``.
    """
    B = io.shape[1]
    if table_number.shape[1] > 1:  # a tool table: each member cuts with the cutter of the tool in its spindle
        for b in range(B):
            switch_tool(heights, grid, cells, rho, points, arc, head, count, spacing, lag, b, p_prev[b, 0],
                        p_prev[b, 1], p_prev[b, 2], radius, flutes, table_number, table_radius, table_flutes,
                        io[IO_TOOL, b])
    two_pi = 2.0 * math.pi
    mp = np.empty((1, 13))
    mi = np.empty((1, 3), dtype=np.int64)
    out = np.empty((1, 10))
    ax = np.zeros(3)
    n_bad = 0
    for b in range(B):
        # _step_inputs
        px, py, pz = io[IO_X, b], io[IO_Y, b], io[IO_Z, b]
        actual = io[IO_SPEED, b]
        hold = not (math.isfinite(px) and math.isfinite(py) and math.isfinite(pz) and math.isfinite(actual))
        if hold or failed[b]:
            px, py, pz = p_prev[b, 0], p_prev[b, 1], p_prev[b, 2]
            actual = 0.0
            hold = True
        omega = actual if actual >= 0.0 else 0.0  # np.maximum(actual, 0.0)
        move = math.hypot(px - p_prev[b, 0], py - p_prev[b, 1])
        # _substeps (the chatter term is off: its count is -0.0, below 1)
        pitch = two_pi / flutes[b]
        lim = pitch / steps[b]
        if not lim <= 0.5 * math.pi:
            lim = 0.5 * math.pi
        n_angle = np.ceil(omega * h / lim - 1e-9)
        n_move = np.ceil(move / (0.05 * radius[b]) - 1e-9)
        n_f = n_angle if n_angle >= n_move else n_move
        if not n_f >= 1.0:
            n_f = 1.0
        if not n_f <= max_substeps + 1.0:
            n_f = max_substeps + 1.0
        n = int(n_f)
        if n > max_substeps and not hold:  # _fail_substeps by the component; held meanwhile
            status[b] = ERR_SUBSTEPS
            diag[0, b] = omega
            diag[1, b] = move
            n_bad += 1
            px, py, pz = p_prev[b, 0], p_prev[b, 1], p_prev[b, 2]
            actual = 0.0
            omega = 0.0
            hold = True
        # _cut: zmap_step of this member alone (held: zero results)
        f0 = f1 = peak = m0 = m1 = m2 = m3 = depth = chip = 0.0
        teeth = 0.0
        a_thrust = a_torque = a_mrr = 0.0
        if not hold:
            mp[0, MP_X0] = p_prev[b, 0]
            mp[0, MP_Y0] = p_prev[b, 1]
            mp[0, MP_Z0] = p_prev[b, 2]
            mp[0, MP_X1] = px
            mp[0, MP_Y1] = py
            mp[0, MP_Z1] = pz
            mp[0, MP_THETA] = theta[b]
            mp[0, MP_OMEGA] = omega
            mp[0, MP_RADIUS] = radius[b]
            mp[0, MP_KT] = kt[b]
            mp[0, MP_KE] = ke[b]
            mp[0, MP_FX], mp[0, MP_FY] = chord_feed(p_prev[b, 3:], px - p_prev[b, 0], py - p_prev[b, 1], h, omega,
                                                    flutes[b])
            mi[0, MI_ROW] = b
            mi[0, MI_SUBSTEPS] = n
            mi[0, MI_FLUTES] = flutes[b]
            zmap_step(heights, grid, cells, points, head, count, mp, mi, h, out)
            f0, f1, peak = out[0, OUT_FX], out[0, OUT_FY], out[0, OUT_PEAK]
            m0, m1, m2, m3 = out[0, OUT_MFX], out[0, OUT_MFY], out[0, OUT_TORQUE], out[0, OUT_MRR]
            depth, chip, teeth = out[0, OUT_DEPTH], out[0, OUT_CHIP], out[0, OUT_TEETH]
            axial_cut(heights, grid, cells, points, head, count, b, p_prev[b, 0], p_prev[b, 1], p_prev[b, 2],
                      px, py, pz, radius[b], omega, kt[b], ka[b], h, ax)
            a_thrust, a_torque, a_mrr = ax[AX_THRUST], ax[AX_TORQUE], ax[AX_MRR]
            if stalled_cut(omega, peak, m0, m1) or stalled_plunge(omega, a_mrr):
                status[b] = ERR_STALLED
                n_bad += 1
        io[IO_FX, b] = -f0
        io[IO_FY, b] = -f1
        io[IO_FC, b] = math.hypot(f0, f1)
        io[IO_PEAK, b] = peak
        io[IO_MFX, b] = -m0
        io[IO_MFY, b] = -m1
        m2 = m2 + a_torque
        m3 = m3 + a_mrr
        io[IO_TORQUE, b] = m2
        io[IO_POWER, b] = m2 * omega
        io[IO_MRR, b] = m3
        io[IO_FZ, b] = -a_thrust
        io[IO_DEPTH, b] = depth
        io[IO_CHIP, b] = chip
        io[IO_TEETH, b] = teeth
        theta[b] = np.mod(theta[b] + omega * h, two_pi)
        io[IO_ANGLE, b] = theta[b]
        # _finish_effects (no wear, droop or chatter: the tool mode stays at rest)
        cutting_time[b] += h if m3 > 0.0 else 0.0
        torque[b] = m2
        angle[b] += omega * h
        io[IO_ACTUAL, b] = actual
        io[IO_VIBX, b] = 0.0
        io[IO_VIBY, b] = 0.0
        io[IO_TIME, b] = cutting_time[b]
        if hold:  # chip history: CuttingLoad._do_step's chord_advance_all
            p_prev[b, 3 + H_COUNT] = 0.0
        else:
            chord_advance(p_prev[b, 3:], h, px - p_prev[b, 0], py - p_prev[b, 1], omega)
        p_prev[b, 0] = px
        p_prev[b, 1] = py
        p_prev[b, 2] = pz
        if hold:  # _blank: NaN outputs, spindle angle kept, no engaged tooth
            for r in range(IO_FX, IO_FZ + 1):
                if r != IO_ANGLE:
                    io[r, b] = math.nan
            io[IO_TEETH, b] = 0.0
    # _commit: path advance and Z-map removal (members are independent: after all the cuts, as the component)
    commit_rows(heights, grid, cells, rho, points, arc, head, count, spacing, lag, p_prev, radius)
    return n_bad


# the cached kernels call stock.sweep_cover_z and hold constants of kernel and engagement: recompile on change
for _kernel in (_depth, zmap_step, _remove_segment, commit_rows, flush_member, switch_tool, zmap_component_step):
    guard_cache(_kernel, stock, kernel, engagement, axial, tool_table)
