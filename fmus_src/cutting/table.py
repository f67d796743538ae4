"""Engagement table: the cutter–workpiece engagement along a tool path, computed once.

A GA population runs ONE program with different F and S per line: every
member follows the same tool path, only the timing differs. The engagement
geometry met by a tooth at immersion angle ``phi`` when the tool centre is at
arc length ``s`` on the path does not depend on the timing, so it is computed
once, in a *reference pass*, and shared by all members
(:class:`~.path_component.PathCuttingLoad`).

Reference pass
--------------
The tool is moved along the path through stations ``s_i = i ds`` (uniform
3D arc length, ``ds`` about 0.01-0.05 mm). At each station the material is
exactly what :class:`~.component.CuttingLoad` sees when its tool is there:
the Z-map (:class:`.stock.ZMapStock`) minus the committed old path, minus the
recent path kept exactly as a polyline (:class:`.engagement.SweptPath`, same
spacing and lag, same rim tolerance). The top of material ``top(phi)`` at the
periphery point ``C + R (sin phi, cos phi)`` is sampled at ``angle_samples``
angles per revolution; runs of samples in material (``top`` above the tool
tip) with the same top (within :data:`TOP_TOL`) form *engagement intervals*
``[alpha, beta]`` with one material top each; the boundaries are refined by
bisection to :data:`BISECTION_STEPS` halvings of the sample spacing
(1e-11 rad at 360 samples). Slivers narrower than the sample spacing between
two samples in air are not seen.

Representation
--------------
Per station at most ``max_intervals`` intervals (more are merged across the
smallest gaps, top length-weighted), sorted by ``alpha``, with
``0 <= alpha < 2 pi`` and ``alpha < beta <= alpha + 2 pi``. A member's axial
depth is ``top - max(z_tip, z_min)`` with its own tip height, so small z
deviations from the reference pass are honoured.

The end edges (the axial chip of plunges, :mod:`.axial`): per station, the
end disc's engagement on the move from the previous station, per unit of
descent (``axial_area``, ``axial_span``; read by :mod:`.path_axial`).

Several cutters (a tool table, :mod:`.tool_table`): given the cutter of each
path point (the tool in the spindle when the reference reached it), each
station is swept with the cutter of the path segment it lies on (the tool at
the segment's end), as the Z-map mode switches cutters at a tool change: the
recent path is committed with the old radius (:func:`.zmap_numba.flush`), then
the near field's spacing and lag become the new cutter's. The table keeps each
station's radius and teeth (``cutter_radius``, ``cutter_flutes``), which the
path kernels use for the members there (:func:`.path_kernel.station_cutters`).
A table of one cutter keeps none: the one-cutter table bit for bit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from ..jit import NUMBA_AVAILABLE, njit
from ..jit_cache import guard_cache
from .component import PATH_SPACING, CuttingError, CuttingLoad
from .engagement import RIM_TOL, SweptPath, path_capacity
from . import engagement, stock
from .axial import AX_MRR, AX_THRUST, axial_cut
from .stock import ZMapStock, sweep_cover_z
from .zmap_numba import ZMapArrays, commit, flush

#: How far beyond the tool radius a path-mode table's runout ring tests the material against the tool's
#: sweeps, m (:meth:`EngagementTable.runout_ring`; against the Z-map: half of it, the long tooth of a
#: 2-flute cutter). A tooth standing out against the surfaces it cuts by up to this much (2-flute runout up to
#: 12.5 um) meets all its chips in the ring's material.
RUNOUT_RING = 25e-6
#: Tops closer than this are one interval, m.
TOP_TOL = 1e-7
#: Bisection halvings of the sample spacing when locating an interval boundary.
BISECTION_STEPS = 32
#: Consecutive path points closer than this are merged, m.
DUPLICATE_TOL = 1e-12
TWO_PI = 2.0 * math.pi


# ---------------------------------------------------------------------------- geometry kernels
@njit
def zmap_top(heights: np.ndarray, x0: float, y0: float, dx: float, dy: float, px: float, py: float) -> float:
    """Height of the Z-map cell containing ``(px, py)``, m (``-inf`` outside), as ``ZMapStock.sample``."""
    fx = math.floor((px - x0) / dx)
    fy = math.floor((py - y0) / dy)
    if fx < 0 or fy < 0 or fx >= heights.shape[0] or fy >= heights.shape[1]:
        return -math.inf
    return float(heights[int(fx), int(fy)])


@njit
def material_top(
    heights: np.ndarray, grid: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray, nseg: int,
    tail: np.ndarray, cx: float, cy: float, cz: float, radius: float, bottom: float, phi: float, reach: float,
    reach_stock: float,
) -> float:
    """Top of material at angle ``phi``, m (as :func:`.engagement.tooth_depth`).

    ``grid = (x0, y0, dx, dy)``; the near field is ``nseg`` segments
    ``seg_a -> seg_b`` plus the open segment ``tail -> C``, swept by the disc of ``radius``. Returns the
    Z-map height at the point ``reach_stock`` from the axis where it is not above ``bottom`` (no
    material), otherwise the minimum of that and the near-field sweep over the point ``reach`` from the
    axis (both ``radius``: the periphery point).
    """
    px = cx + reach_stock * math.sin(phi)
    py = cy + reach_stock * math.cos(phi)
    top = zmap_top(heights, grid[0], grid[1], grid[2], grid[3], px, py)
    if not top > bottom:
        return top
    px = cx + reach * math.sin(phi)
    py = cy + reach * math.cos(phi)
    for k in range(nseg):
        z = sweep_cover_z(px, py, seg_a[k, 0], seg_a[k, 1], seg_a[k, 2], seg_b[k, 0], seg_b[k, 1], seg_b[k, 2],
                          radius, RIM_TOL)
        if z < top:
            top = z
    z = sweep_cover_z(px, py, tail[0], tail[1], tail[2], cx, cy, cz, radius, RIM_TOL)
    return min(top, z)


@njit
def _same(top_a: float, top_b: float, bottom: float) -> bool:
    """Same engagement state: both in air, or both in material with equal tops (TOP_TOL)."""
    in_a = top_a > bottom
    in_b = top_b > bottom
    if in_a != in_b:
        return False
    return (not in_a) or abs(top_a - top_b) <= TOP_TOL


@njit
def station_intervals(
    heights: np.ndarray, grid: np.ndarray, seg_a: np.ndarray, seg_b: np.ndarray, nseg: int, tail: np.ndarray,
    cx: float, cy: float, cz: float, radius: float, bottom: float, samples: int,
    out_alpha: np.ndarray, out_beta: np.ndarray, out_top: np.ndarray, reach: float, reach_stock: float,
) -> int:
    """Engagement intervals of one station (unsorted, unmerged); returns how many were written.

    ``out_*`` must hold at least ``samples`` entries; the points tested lie ``reach`` (the near field)
    and ``reach_stock`` (the Z-map) from the axis (:func:`material_top`).
    """
    step = TWO_PI / samples
    tops = np.empty(samples)
    any_in = False
    for m in range(samples):
        tops[m] = material_top(heights, grid, seg_a, seg_b, nseg, tail, cx, cy, cz, radius, bottom, m * step, reach,
                               reach_stock)
        if tops[m] > bottom:
            any_in = True
    if not any_in:
        return 0
    # first sample that starts a new run (a state change from the previous sample, cyclically)
    m0 = -1
    for m in range(samples):
        if not _same(tops[m - 1], tops[m], bottom):  # tops[-1] is the last sample
            m0 = m
            break
    if m0 < 0:  # one state all round: full circle
        acc = 0.0
        for m in range(samples):
            acc += tops[m]
        out_alpha[0] = 0.0
        out_beta[0] = TWO_PI
        out_top[0] = acc / samples
        return 1
    count = 0
    start_angle = 0.0
    run_sum = 0.0
    run_n = 0
    for i in range(samples + 1):
        m = (m0 + i) % samples
        prev = (m0 + i - 1) % samples
        if i > 0 and i < samples and _same(tops[prev], tops[m], bottom):
            run_sum += tops[m]
            run_n += 1
            continue
        # boundary between prev and m (angles unwrapped from the start of the sweep)
        lo = (m0 + i - 1) * step
        hi = lo + step
        ref = tops[prev]
        for _ in range(BISECTION_STEPS):
            mid = 0.5 * (lo + hi)
            t_mid = material_top(heights, grid, seg_a, seg_b, nseg, tail, cx, cy, cz, radius, bottom, mid, reach,
                                 reach_stock)
            if _same(ref, t_mid, bottom):
                lo = mid
            else:
                hi = mid
        edge = 0.5 * (lo + hi)
        if i > 0 and run_n > 0 and tops[prev] > bottom:  # close the run that ended at prev
            a = start_angle % TWO_PI
            out_alpha[count] = a
            out_beta[count] = a + (edge - start_angle)
            out_top[count] = run_sum / run_n
            count += 1
        start_angle = edge
        run_sum = tops[m]
        run_n = 1
    return count


def _merge(alpha: np.ndarray, beta: np.ndarray, top: np.ndarray, limit: int) -> tuple[np.ndarray, ...]:
    """Sort intervals by alpha; merge across the smallest gaps until at most ``limit`` remain."""
    order = np.argsort(alpha, kind="stable")
    a, b, t = list(alpha[order]), list(beta[order]), list(top[order])
    while len(a) > limit:
        gaps = [a[i + 1] - b[i] for i in range(len(a) - 1)]
        i = int(np.argmin(gaps))
        la, lb = b[i] - a[i], b[i + 1] - a[i + 1]
        t[i] = (t[i] * la + t[i + 1] * lb) / (la + lb)
        b[i] = b[i + 1]
        del a[i + 1], b[i + 1], t[i + 1]
    return np.array(a), np.array(b), np.array(t)


#: Commit each station's swept material with the compiled :func:`.zmap_numba.commit` (the
#: :class:`~.component.CuttingLoad`'s own compiled commit, the same height field bit for bit) instead of
#: :meth:`.engagement.SweptPath.advance` / ``pop_ready`` / :meth:`.stock.ZMapStock.remove_sweep` in numpy,
#: whose per-station Python overhead was about two thirds of a table's build time.
use_compiled_commit: bool = NUMBA_AVAILABLE


# ---------------------------------------------------------------------------- the table
@dataclass(frozen=True)
class EngagementTable:
    """Engagement intervals along a tool path (see module docstring).

    Attributes
    ----------
    vertices : ndarray, shape (V, 3)
        Reference tool-tip path (consecutive duplicates removed), work coordinates, m.
    vertex_s : ndarray, shape (V,)
        3D arc length at each vertex, m (``vertex_s[0] = 0``).
    spacing : float
        Station spacing ``ds``, m (stations at ``s_i = i ds``, the last one at the path end).
    count : ndarray of int, shape (S,)
        Engagement intervals per station.
    alpha, beta : ndarray, shape (S, K)
        Interval start and end angles, rad (``phi`` clockwise from +y, see :mod:`.engagement`).
    top : ndarray, shape (S, K)
        Top of material over each interval, m.
    radius : float
        Tool radius the table was built for (``tool_diameter / 2``; with several cutters the default one,
        each station's own in ``cutter_radius``), m.
    z_floor : float
        Stock ``z_min``, m (axial depth is measured from ``max(z_tip, z_floor)``).
    stock_lower, stock_upper : ndarray, shape (3,)
        Stock block, m.
    stock_cell : float
        Z-map cell edge of the reference pass, m.
    ring : float
        The intervals are those of the points ``radius + ring`` from the axis against the near field's sweeps,
        m: 0 (the periphery), or a runout ring (:meth:`runout_ring`; against the Z-map ``ring / 2``).
    axial_area, axial_span : ndarray, shape (S,), optional
        The end edges' engagement per unit of descent (:mod:`.path_axial`): ``sum d dA / dz`` [m2] and
        ``sum d dA / r / dz`` [m] of the move from the previous station (0 where the path does not move
        down); zeros when absent (a table saved before they existed: no axial chip).
    cutter_radius : ndarray, shape (S,) or (0,), optional
        Radius of the cutter that sweeps each station, m (several cutters, a tool table); empty (the
        default) when the whole path is cut by the one cutter of ``radius``.
    cutter_flutes : ndarray of int64, shape (S,) or (0,), optional
        Teeth of that cutter; empty with ``cutter_radius``.
    """

    vertices: np.ndarray
    vertex_s: np.ndarray
    spacing: float
    count: np.ndarray
    alpha: np.ndarray
    beta: np.ndarray
    top: np.ndarray
    radius: float
    z_floor: float
    stock_lower: np.ndarray
    stock_upper: np.ndarray
    stock_cell: float
    axial_area: np.ndarray | None = None
    axial_span: np.ndarray | None = None
    cutter_radius: np.ndarray | None = None
    cutter_flutes: np.ndarray | None = None
    ring: float = 0.0

    def __post_init__(self) -> None:
        for name in ("axial_area", "axial_span"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.zeros(self.count.shape[0]))
        radius = np.zeros(0) if self.cutter_radius is None else np.asarray(self.cutter_radius, dtype=np.float64)
        flutes = (np.zeros(0, dtype=np.int64) if self.cutter_flutes is None
                  else np.asarray(self.cutter_flutes, dtype=np.int64))
        if radius.shape != flutes.shape or radius.size not in (0, self.count.shape[0]):
            raise CuttingError(f"engagement table: cutter_radius {radius.shape} and cutter_flutes {flutes.shape}; "
                               f"expected both empty or both of shape ({self.count.shape[0]},), one per station")
        object.__setattr__(self, "cutter_radius", np.ascontiguousarray(radius))
        object.__setattr__(self, "cutter_flutes", np.ascontiguousarray(flutes))

    @property
    def several_cutters(self) -> bool:
        """Whether the stations are swept by more than one cutter (``cutter_radius`` / ``cutter_flutes`` set)."""
        return self.cutter_radius.size > 0

    def cutters(self) -> list[tuple[float, int]]:
        """The distinct cutters of the stations, ``(radius m, teeth)``, in order of first use (``[]``: one cutter,
        :attr:`radius`)."""
        seen: dict[tuple[float, int], None] = {}
        for r, z in zip(self.cutter_radius.tolist(), self.cutter_flutes.tolist()):
            seen.setdefault((r, z), None)
        return list(seen)

    def runout_ring(self) -> "EngagementTable":
        """The engagement of the points :data:`RUNOUT_RING` beyond the radius at the same stations (built once).

        A tooth that stands out by runout (:func:`.effect_model.runout_reach` > 0) is tested for material
        there in the path mode (:func:`.path_effects.path_step_effects`): one more reference pass over the
        same path, sweeps and stations, kept with this table (not saved by :meth:`save`).

        Raises
        ------
        CuttingError
            If the table has several cutters, or the rebuilt stations do not match this table's.
        """
        built = self.__dict__.get("_runout_ring")
        if built is None:
            if self.several_cutters:  # PathCuttingLoad refuses runout with several cutters before this
                raise CuttingError("engagement table: a runout ring is built for one cutter; this table's stations "
                                   f"have {len(self.cutters())} cutters")
            built = build_engagement_table(self.vertices, 2.0 * self.radius, self.stock_lower, self.stock_upper,
                                           self.stock_cell, self.spacing, max_intervals=self.alpha.shape[1],
                                           ring=RUNOUT_RING, ring_stock=0.5 * RUNOUT_RING)
            if built.count.shape != self.count.shape:
                raise CuttingError(f"engagement table: the runout ring has {built.stations} stations against "
                                   f"{self.stations}; expected the same stations")
            object.__setattr__(self, "_runout_ring", built)
        return built

    @property
    def length(self) -> float:
        """Path length, m."""
        return float(self.vertex_s[-1])

    @property
    def stations(self) -> int:
        """Number of stations."""
        return int(self.count.shape[0])

    @property
    def nbytes(self) -> int:
        """Memory held by the table arrays, bytes."""
        return int(sum(a.nbytes for a in (self.vertices, self.vertex_s, self.count, self.alpha, self.beta, self.top,
                                          self.axial_area, self.axial_span, self.cutter_radius,
                                          self.cutter_flutes)))

    def save(self, path: str | Path) -> None:
        """Write the table to a ``.npz`` file."""
        np.savez_compressed(
            path, vertices=self.vertices, vertex_s=self.vertex_s, spacing=self.spacing, count=self.count,
            alpha=self.alpha, beta=self.beta, top=self.top, radius=self.radius, z_floor=self.z_floor,
            stock_lower=self.stock_lower, stock_upper=self.stock_upper, stock_cell=self.stock_cell,
            axial_area=self.axial_area, axial_span=self.axial_span, cutter_radius=self.cutter_radius,
            cutter_flutes=self.cutter_flutes,
        )

    @classmethod
    def load(cls, path: str | Path) -> "EngagementTable":
        """Read a table written by :meth:`save`.

        Raises
        ------
        CuttingError
            If the file is missing or lacks a field.
        """
        try:
            with np.load(path) as z:
                f = {k: z[k] for k in z.files}
        except OSError as exc:
            raise CuttingError(f"engagement table {path}: cannot read ({exc}); expected an .npz from "
                               "EngagementTable.save") from None
        names = ("vertices", "vertex_s", "spacing", "count", "alpha", "beta", "top", "radius", "z_floor",
                 "stock_lower", "stock_upper", "stock_cell")
        missing = [n for n in names if n not in f]
        if missing:
            raise CuttingError(f"engagement table {path}: missing {missing}; expected an .npz from EngagementTable.save")
        return cls(
            vertices=f["vertices"], vertex_s=f["vertex_s"], spacing=float(f["spacing"]),
            count=f["count"].astype(np.int64), alpha=f["alpha"], beta=f["beta"], top=f["top"],
            radius=float(f["radius"]), z_floor=float(f["z_floor"]), stock_lower=f["stock_lower"],
            stock_upper=f["stock_upper"], stock_cell=float(f["stock_cell"]),
            axial_area=f.get("axial_area"), axial_span=f.get("axial_span"),
            cutter_radius=f.get("cutter_radius"), cutter_flutes=f.get("cutter_flutes"),
        )

    @classmethod
    def from_parameters(
        cls, path: np.ndarray, parameters: Mapping[str, object], spacing: float = 2e-5, angle_samples: int = 360,
        max_intervals: int = 8, cutters: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> "EngagementTable":
        """Build a table from the path and a CuttingLoad parameter mapping (SI, scalar values).

        Uses ``tool_diameter``, ``stock_{x,y,z}_{min,max}`` and ``stock_cell``
        (defaults of :class:`~.component.CuttingLoad` where absent), e.g. the
        dictionary ``cutting_parameters(case)`` of the twin. ``cutters``: the
        cutter of each path point, as :func:`build_engagement_table`.
        """
        default = {v.name: v.start for v in CuttingLoad.variables if v.causality == "parameter"}

        def get(name: str) -> float:
            value = np.asarray(parameters.get(name, default[name]), dtype=float)
            if value.size != 1 and not np.all(value == value.flat[0]):
                raise CuttingError(f"engagement table: parameter {name} differs between members ({value}); "
                                   "expected one value (the table is shared by the batch)")
            return float(value.flat[0])

        lower = [get(f"stock_{a}_min") for a in "xyz"]
        upper = [get(f"stock_{a}_max") for a in "xyz"]
        return build_engagement_table(path, get("tool_diameter"), lower, upper, get("stock_cell"), spacing,
                                      angle_samples, max_intervals, cutters=cutters)


def _clean_path(path: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drop consecutive duplicates; return vertices (V, 3), cumulative 3D arc length (V,) and the kept points'
    indices (V,)."""
    p = np.asarray(path, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 1:
        raise CuttingError(f"engagement table: path must have shape (K, 3) with K >= 1, got {p.shape}")
    if not np.all(np.isfinite(p)):
        bad = int(np.flatnonzero(~np.isfinite(p).all(axis=1))[0])
        raise CuttingError(f"engagement table: path point {bad} is {p[bad].tolist()}; expected finite m")
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    keep = np.concatenate([[True], step > DUPLICATE_TOL])
    v = p[keep]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(v, axis=0), axis=1))])
    return v, s, np.flatnonzero(keep)


def _points_at(vertices: np.ndarray, vertex_s: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points at arc lengths ``s`` on the polyline, shape (len(s), 3)."""
    if vertices.shape[0] == 1:
        return np.repeat(vertices, s.size, axis=0)
    seg = np.clip(np.searchsorted(vertex_s, s, side="right") - 1, 0, vertices.shape[0] - 2)
    u = (s - vertex_s[seg]) / (vertex_s[seg + 1] - vertex_s[seg])
    return vertices[seg] + u[:, None] * (vertices[seg + 1] - vertices[seg])


def build_engagement_table(
    path: np.ndarray, tool_diameter: float, stock_lower: np.ndarray, stock_upper: np.ndarray, stock_cell: float,
    spacing: float = 2e-5, angle_samples: int = 360, max_intervals: int = 8, *, ring: float = 0.0,
    ring_stock: float = 0.0, cutters: tuple[np.ndarray, np.ndarray] | None = None,
) -> EngagementTable:
    """Reference pass: engagement intervals along ``path`` (see module docstring).

    Parameters
    ----------
    path : ndarray, shape (K, 3)
        Tool-tip path in work coordinates (the coordinates of the component's
        position inputs), m, in the order it is travelled: e.g. the programmed
        geometry finely discretised, the NC reference positions or the actual
        positions of a nominal run.
    tool_diameter : float
        Flat end mill diameter, m.
    stock_lower, stock_upper : array_like, shape (3,)
        Stock block corners, m.
    stock_cell : float
        Z-map cell edge (upper bound), m.
    spacing : float
        Station spacing along the path, m (upper bound; the stations divide the path exactly).
    angle_samples : int
        Samples of the immersion angle per revolution before bisection.
    max_intervals : int
        Intervals kept per station.
    cutters : (ndarray, ndarray), shapes (K,), optional
        Diameter [m] and teeth of the cutter in the spindle at each path point (several cutters, a tool
        table): a station is swept with the cutter of the path point that ends its segment, and the table
        keeps each station's radius and teeth. None (the default): ``tool_diameter`` everywhere and no
        per-station cutters.
    ring, ring_stock : float
        The intervals are those of the points ``radius + ring`` from the axis against the near field's
        sweeps (of ``radius``) and ``radius + ring_stock`` against the Z-map, m; ``ring > 0``: a runout ring
        (:meth:`EngagementTable.runout_ring`), without the end edges' engagement (zeros).

    Returns
    -------
    EngagementTable

    Raises
    ------
    CuttingError
        On a malformed path or non-positive spacing, diameter, sample counts or cutters.
    """
    vertices, vertex_s, kept = _clean_path(path)
    for name, value in (("tool_diameter", tool_diameter), ("spacing", spacing)):
        if not (math.isfinite(value) and value > 0.0):
            raise CuttingError(f"engagement table: {name} = {value!r}; expected a positive length in m")
    if angle_samples < 8 or max_intervals < 1:
        raise CuttingError(f"engagement table: angle_samples = {angle_samples}, max_intervals = {max_intervals}; "
                           "expected >= 8 and >= 1")
    radius = 0.5 * float(tool_diameter)
    table_radius = radius  # the default cutter's (tool_diameter), checked against the members' parameters
    lower = np.asarray(stock_lower, dtype=np.float64).reshape(1, 3)
    upper = np.asarray(stock_upper, dtype=np.float64).reshape(1, 3)
    stock = ZMapStock(lower, upper, np.array([float(stock_cell)]))
    length = float(vertex_s[-1])
    n_st = int(math.ceil(length / spacing - 1e-9)) if length > 0.0 else 0
    ds = length / n_st if n_st > 0 else float(spacing)
    s_st = np.arange(n_st + 1) * ds
    centres = _points_at(vertices, vertex_s, s_st)
    cutter_radius, cutter_flutes = _station_cutters(cutters, np.asarray(path).shape[0], kept, vertex_s, s_st)
    if cutter_radius.size:
        radius = float(cutter_radius[0])

    r_arr = np.array([radius])
    cell = 2.0 * np.maximum(stock.dx, stock.dy)
    lag = r_arr + cell
    capacity = path_capacity(lag, PATH_SPACING * r_arr)
    if cutter_radius.size:  # room for the near field of the smallest cutter (as CuttingLoad's set-up)
        smallest = np.array([float(cutter_radius.min())])
        capacity = max(capacity, path_capacity(smallest + cell, PATH_SPACING * smallest))
    swept = SweptPath(centres[:1], PATH_SPACING * r_arr, lag, capacity)
    heights = stock.heights[0]
    grid = np.array([stock.lower[0, 0], stock.lower[0, 1], stock.dx[0], stock.dy[0]])
    solid = bool(stock.nx[0] > 0 and stock.ny[0] > 0)
    z_floor = float(lower[0, 2])
    reach = radius + ring + float(stock.rho[0])

    count = np.zeros(n_st + 1, dtype=np.int64)
    axial_area = np.zeros(n_st + 1)
    axial_span = np.zeros(n_st + 1)
    zgrid = np.array([[stock.lower[0, 0], stock.lower[0, 1], stock.lower[0, 2], stock.dx[0], stock.dy[0]]])
    zcells = np.array([[stock.nx[0], stock.ny[0]]], dtype=np.int64)
    ax = np.zeros(3)
    alpha = np.zeros((n_st + 1, max_intervals))
    beta = np.zeros((n_st + 1, max_intervals))
    top = np.zeros((n_st + 1, max_intervals))
    buf = [np.zeros(angle_samples) for _ in range(3)]
    compiled = use_compiled_commit
    zmap = ZMapArrays.of(stock) if compiled or cutter_radius.size else None
    for i in range(n_st + 1):
        c = centres[i]
        if cutter_radius.size and cutter_radius[i] != r_arr[0]:
            # a tool change (the Z-map mode's switch_tool): the recent path is committed with the old radius at
            # the last station, then the near field is the new cutter's
            flush(zmap, swept, np.array([True]), centres[max(i - 1, 0)][None, :], r_arr)
            r_arr = np.array([float(cutter_radius[i])])
            radius = float(r_arr[0])
            swept.spacing = PATH_SPACING * r_arr
            swept.lag = r_arr + cell
            reach = radius + ring + float(stock.rho[0])
        near_block = solid and (
            lower[0, 0] - reach <= c[0] <= upper[0, 0] + reach and lower[0, 1] - reach <= c[1] <= upper[0, 1] + reach
            and c[2] < upper[0, 2]
        )
        if near_block:
            nf = swept.near_field()
            nseg = int(nf.valid[0].sum())
            k = station_intervals(heights, grid, nf.start[0], nf.end[0], nseg, nf.tail[0], c[0], c[1], c[2], radius,
                                  max(c[2], z_floor), angle_samples, buf[0], buf[1], buf[2], radius + ring,
                                  radius + ring_stock)
            if k:
                a, b, t = _merge(buf[0][:k], buf[1][:k], buf[2][:k], max_intervals)
                count[i] = a.size
                alpha[i, :a.size], beta[i, :a.size], top[i, :a.size] = a, b, t
            dz = centres[i - 1, 2] - c[2] if i > 0 else 0.0
            if dz > 0.0 and ring == 0.0:  # the end edges on the move from the previous station (unit Kt, ka, h, ...)
                p = centres[i - 1]
                axial_cut(stock.heights, zgrid, zcells, swept.points, swept.head, swept.count, 0, p[0], p[1], p[2],
                          c[0], c[1], c[2], radius, 1.0, 1.0, 1.0, 1.0, ax)
                axial_area[i] = ax[AX_MRR] / dz
                axial_span[i] = ax[AX_THRUST] / dz
        if compiled:
            commit(zmap, swept, c[None, :], r_arr)
            continue
        swept.advance(c[None, :])
        while True:
            start, end, mask = swept.pop_ready(force_room=True)
            if not np.any(mask):
                break
            stock.remove_sweep(start, end, r_arr, mask)
    return EngagementTable(
        vertices=vertices, vertex_s=vertex_s, spacing=ds, count=count, alpha=alpha, beta=beta, top=top,
        radius=table_radius, z_floor=z_floor, stock_lower=lower[0].copy(), stock_upper=upper[0].copy(),
        stock_cell=float(stock_cell), axial_area=axial_area, axial_span=axial_span, cutter_radius=cutter_radius,
        cutter_flutes=cutter_flutes, ring=float(ring),
    )


def _station_cutters(cutters: tuple[np.ndarray, np.ndarray] | None, points: int, kept: np.ndarray,
                     vertex_s: np.ndarray, s_st: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Radius [m] and teeth of each station's cutter: that of the path point ending the station's segment.

    ``cutters`` holds the diameter [m] and teeth of each of the ``points`` path points, ``kept`` the indices
    of the vertices (:func:`_clean_path`), ``s_st`` the stations' arc lengths [m]. Returns empty arrays when
    ``cutters`` is None.

    Raises
    ------
    CuttingError
        When the arrays do not have one entry per path point or a cutter is not a positive finite diameter
        with at least one tooth (naming the first such point).
    """
    if cutters is None:
        return np.zeros(0), np.zeros(0, dtype=np.int64)
    diameter = np.asarray(cutters[0], dtype=np.float64)
    flutes = np.asarray(cutters[1])
    if diameter.shape != (points,) or flutes.shape != (points,):
        raise CuttingError(f"engagement table: cutters of shapes {diameter.shape} and {flutes.shape}; expected "
                           f"({points},) each, one diameter and tooth count per path point")
    bad = ~(np.isfinite(diameter) & (diameter > 0.0)) | ~(flutes >= 1) | (flutes != np.round(flutes))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise CuttingError(f"engagement table: path point {k} has a cutter of {diameter[k]!r} m and {flutes[k]!r} "
                           "teeth; expected a positive diameter in m and a whole number of teeth >= 1")
    v_radius = 0.5 * diameter[kept]
    v_flutes = flutes[kept].astype(np.int64)
    if kept.size == 1:
        end = np.zeros(s_st.size, dtype=np.int64)
    else:  # the segment of each station (as _points_at), and the vertex at its end
        end = np.clip(np.searchsorted(vertex_s, s_st, side="right") - 1, 0, kept.size - 2) + 1
    return np.ascontiguousarray(v_radius[end]), np.ascontiguousarray(v_flutes[end])


# the cached kernels call stock.sweep_cover_z and read engagement.RIM_TOL: recompile when those change
for _kernel in (material_top, station_intervals):
    guard_cache(_kernel, stock, engagement)
