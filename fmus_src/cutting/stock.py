"""Z-map stock: a batched height field of the workpiece for 2.5D milling.

The workpiece is a block ``[x_min, x_max] x [y_min, y_max] x [z_min, z_max]``
(work coordinates, m). Its XY footprint is divided into ``nx x ny`` cells of
size ``dx x dy`` (``<= cell``, chosen so that the block edges fall exactly on
cell edges). Each cell holds one height: material fills the column
``[z_min, height]``. A flat end mill of radius ``R`` whose tip moves from ``A``
to ``B`` removes every cell whose *centre* lies within ``R + rho`` of the swept
segment down to the tip height, where ``rho = sqrt(dx^2 + dy^2) / 2`` is half
the cell diagonal. The inflation ``rho`` guarantees that any point of the tool
periphery re-tracing an already machined path falls in a removed cell (the
cell containing a point has its centre within ``rho`` of it); it biases the
walls of earlier cuts outward by ``rho`` on average (see the resolution study).

Heights are stored as ``float32`` (4 bytes per cell per batch member) and are
always rounded *down* to the next representable value, so that a pass at the
same tool-tip height reads exactly zero depth.

Every member of the batch has its own block, cell size and height field; the
arrays are padded to the largest grid in the batch.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import CncTwinError
from ..jit import njit

#: Largest height field (all batch members together) this module allocates, bytes.
MAX_STOCK_BYTES = 4 * 1024**3


class StockError(CncTwinError):
    """The stock block or its Z-map resolution is invalid."""


def round_down_f32(z: np.ndarray) -> np.ndarray:
    """Round float64 heights to float32 towards minus infinity.

    Parameters
    ----------
    z : ndarray
        Heights, m (any shape).

    Returns
    -------
    ndarray of float32
        Largest float32 values ``<= z`` (same shape).
    """
    z = np.asarray(z, dtype=np.float64)
    z32 = z.astype(np.float32)
    high = z32.astype(np.float64) > z
    if np.any(high):
        z32 = np.where(high, np.nextafter(z32, np.float32(-np.inf)), z32)
    return z32


def disc_sweep_cover(
    px: np.ndarray, py: np.ndarray,
    ax: np.ndarray, ay: np.ndarray, az: np.ndarray,
    bx: np.ndarray, by: np.ndarray, bz: np.ndarray,
    radius: np.ndarray | float, tol: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Whether a disc swept along a segment covers a point, and how deep it cut there.

    A flat end mill of radius ``radius`` moves its tip linearly from
    ``A = (ax, ay, az)`` to ``B = (bx, by, bz)``. The point ``P = (px, py)`` is
    covered when its XY distance to some centre ``A + s (B - A)``,
    ``0 <= s <= 1``, is below ``radius``; the covered parameters form the
    interval ``[s_lo, s_hi]`` (roots of a quadratic in ``s``) and, the tip
    height being linear in ``s``, the lowest tip height over it is
    ``min(z(s_lo), z(s_hi))``. All arguments broadcast together.

    Parameters
    ----------
    px, py : ndarray
        Query point, m.
    ax, ay, az, bx, by, bz : ndarray
        Segment end points of the tool tip, m.
    radius : ndarray or float
        Disc radius, m.
    tol : float
        Length tolerance, m: a point is covered only when the covered part of
        the segment is longer than ``tol`` (or, for a segment shorter than
        ``tol``, when the point is closer than ``radius - tol``). ``tol > 0``
        makes points exactly on the rim of the end disc count as uncovered.

    Returns
    -------
    covered : ndarray of bool
        Broadcast shape of the arguments.
    z_cut : ndarray of float64
        Lowest tip height over the covering part, m; ``+inf`` where not covered.
    """
    dx = bx - ax
    dy = by - ay
    wx = ax - px
    wy = ay - py
    qa = dx * dx + dy * dy
    qb = 2.0 * (wx * dx + wy * dy)
    qc = wx * wx + wy * wy - radius * radius
    length = np.sqrt(qa)
    point_tol = max(tol, 1e-15)
    moving = length > point_tol
    qa_safe = np.where(moving, qa, 1.0)
    disc = qb * qb - 4.0 * qa_safe * qc
    root = np.sqrt(np.maximum(disc, 0.0))
    s_lo = np.clip((-qb - root) / (2.0 * qa_safe), 0.0, 1.0)
    s_hi = np.clip((-qb + root) / (2.0 * qa_safe), 0.0, 1.0)
    covered_moving = (disc > 0.0) & ((s_hi - s_lo) * length > tol)
    covered_still = qc < -2.0 * radius * tol if tol > 0.0 else qc < 0.0
    covered = np.where(moving, covered_moving, covered_still)
    dz = bz - az
    z_moving = np.minimum(az + s_lo * dz, az + s_hi * dz)
    z_cut = np.where(moving, z_moving, np.minimum(az, bz))
    return covered, np.where(covered, z_cut, np.inf)


@njit
def sweep_cover_z(
    px: float, py: float, ax: float, ay: float, az: float, bx: float, by: float, bz: float, radius: float, tol: float
) -> float:
    """Lowest tip height of a disc swept from A to B over ``(px, py)``, m; ``inf`` if not covered.

    Scalar transcription of :func:`disc_sweep_cover` (one point, one segment).
    """
    dx = bx - ax
    dy = by - ay
    wx = ax - px
    wy = ay - py
    qa = dx * dx + dy * dy
    qb = 2.0 * (wx * dx + wy * dy)
    qc = wx * wx + wy * wy - radius * radius
    length = math.sqrt(qa)
    if length > max(tol, 1e-15):
        disc = qb * qb - 4.0 * qa * qc
        if not disc > 0.0:
            return math.inf
        root = math.sqrt(disc)
        s_lo = min(max((-qb - root) / (2.0 * qa), 0.0), 1.0)
        s_hi = min(max((-qb + root) / (2.0 * qa), 0.0), 1.0)
        if (s_hi - s_lo) * length > tol:
            dz = bz - az
            return min(az + s_lo * dz, az + s_hi * dz)
        return math.inf
    covered = qc < -2.0 * radius * tol if tol > 0.0 else qc < 0.0
    return min(az, bz) if covered else math.inf


class ZMapStock:
    """Batched Z-map of a rectangular stock block.

    Parameters
    ----------
    lower, upper : ndarray, shape (B, 3)
        Block corners ``(x, y, z)_min`` and ``(x, y, z)_max``, m. A block with
        zero extent along any axis has no material (air cutting only).
    cell : ndarray, shape (B,)
        Largest cell edge, m; the actual ``dx, dy`` divide the block exactly.

    Raises
    ------
    StockError
        If a corner is not finite, ``upper < lower``, ``cell <= 0`` or the height
        fields would exceed :data:`MAX_STOCK_BYTES`.

    Attributes
    ----------
    heights : ndarray of float32, shape (B, NX, NY)
        Top of material per cell, m (``z_min`` where there is no material).
    nx, ny : ndarray of int, shape (B,)
        Cells per member along x and y (0 for an empty block).
    dx, dy : ndarray, shape (B,)
        Cell edges, m.
    """

    def __init__(self, lower: np.ndarray, upper: np.ndarray, cell: np.ndarray) -> None:
        lower = np.asarray(lower, dtype=np.float64)
        upper = np.asarray(upper, dtype=np.float64)
        cell = np.asarray(cell, dtype=np.float64)
        if lower.ndim != 2 or lower.shape[1] != 3 or upper.shape != lower.shape or cell.shape != lower.shape[:1]:
            raise StockError(
                f"stock: expected corners of shape (B, 3) and cell of shape (B,), got "
                f"{lower.shape}, {upper.shape}, {cell.shape}"
            )
        names = ("x", "y", "z")
        for b in range(lower.shape[0]):
            for k in range(3):
                lo, hi = lower[b, k], upper[b, k]
                if not (math.isfinite(lo) and math.isfinite(hi)):
                    raise StockError(f"stock member {b}: stock_{names[k]}_min/max must be finite, got {lo}, {hi}")
                if hi < lo:
                    raise StockError(
                        f"stock member {b}: stock_{names[k]}_max = {hi} m is below stock_{names[k]}_min = {lo} m; "
                        "expected max >= min"
                    )
            if not (math.isfinite(cell[b]) and cell[b] > 0.0):
                raise StockError(f"stock member {b}: stock_cell must be a positive length in m, got {cell[b]}")
        self.batch = lower.shape[0]
        self.lower = lower.copy()
        self.upper = upper.copy()
        extent = upper - lower
        solid = np.all(extent > 0.0, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            nx = np.where(solid, np.maximum(np.ceil(extent[:, 0] / cell - 1e-9), 1.0), 0.0)
            ny = np.where(solid, np.maximum(np.ceil(extent[:, 1] / cell - 1e-9), 1.0), 0.0)
        self.nx = nx.astype(np.int64)
        self.ny = ny.astype(np.int64)
        self.dx = np.where(self.nx > 0, extent[:, 0] / np.maximum(self.nx, 1), cell)
        self.dy = np.where(self.ny > 0, extent[:, 1] / np.maximum(self.ny, 1), cell)
        #: Half cell diagonal, m: inflation of the removal radius.
        self.rho = 0.5 * np.hypot(self.dx, self.dy)
        big_x, big_y = int(max(self.nx.max(), 1)), int(max(self.ny.max(), 1))
        nbytes = self.batch * big_x * big_y * 4
        if nbytes > MAX_STOCK_BYTES:
            raise StockError(
                f"stock: the Z-map would need {nbytes / 1e9:.2f} GB for {self.batch} member(s) of up to "
                f"{big_x} x {big_y} cells; expected at most {MAX_STOCK_BYTES / 1e9:.1f} GB. "
                "Use a larger stock_cell or a smaller block."
            )
        self.top32 = round_down_f32(upper[:, 2])
        self.floor32 = round_down_f32(lower[:, 2])
        ix = np.arange(big_x)[None, :, None]
        iy = np.arange(big_y)[None, None, :]
        inside = (ix < self.nx[:, None, None]) & (iy < self.ny[:, None, None])
        self.heights = np.where(inside, self.top32[:, None, None], self.floor32[:, None, None]).astype(np.float32)

    # ------------------------------------------------------------------ queries
    @property
    def memory_bytes(self) -> int:
        """Bytes held by the height fields of all members."""
        return int(self.heights.nbytes)

    def sample(self, member: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        """Top of material at points (nearest cell), m.

        Parameters
        ----------
        member : ndarray of int
            Batch member of each point (broadcasts with ``px``).
        px, py : ndarray
            Points, m.

        Returns
        -------
        ndarray of float64
            Height of the cell containing each point; ``-inf`` outside the block.
        """
        member = np.broadcast_to(member, np.broadcast(px, py).shape)
        fx = np.floor((px - self.lower[member, 0]) / self.dx[member])
        fy = np.floor((py - self.lower[member, 1]) / self.dy[member])
        inside = (fx >= 0) & (fy >= 0) & (fx < self.nx[member]) & (fy < self.ny[member])
        ix = np.where(inside, fx, 0).astype(np.int64)
        iy = np.where(inside, fy, 0).astype(np.int64)
        h = self.heights[member, ix, iy].astype(np.float64)
        return np.where(inside, h, -np.inf)

    def removed_volume(self) -> np.ndarray:
        """Material removed so far per member, m3 (shape (B,))."""
        big_x, big_y = self.heights.shape[1:]
        ix = np.arange(big_x)[None, :, None]
        iy = np.arange(big_y)[None, None, :]
        inside = (ix < self.nx[:, None, None]) & (iy < self.ny[:, None, None])
        depth = np.where(inside, self.top32[:, None, None].astype(np.float64) - self.heights, 0.0)
        return depth.sum(axis=(1, 2)) * self.dx * self.dy

    # ------------------------------------------------------------------ removal
    def remove_sweep(self, start: np.ndarray, end: np.ndarray, radius: np.ndarray, active: np.ndarray) -> None:
        """Remove the material swept by the tool moving from ``start`` to ``end``.

        Cells whose centre lies within ``radius + rho`` of the segment are cut
        down to the lowest tip height over the covering part (never below
        ``z_min``).

        Parameters
        ----------
        start, end : ndarray, shape (B, 3)
            Tool-tip positions, m.
        radius : ndarray, shape (B,)
            Tool radius, m.
        active : ndarray of bool, shape (B,)
            Members that remove material in this call.
        """
        members = np.flatnonzero(np.asarray(active) & (self.nx > 0) & (self.ny > 0))
        if members.size == 0:
            return
        a = start[members]
        b = end[members]
        reach = radius[members] + self.rho[members]
        x0 = self.lower[members, 0]
        y0 = self.lower[members, 1]
        dx = self.dx[members]
        dy = self.dy[members]
        i_lo = np.floor((np.minimum(a[:, 0], b[:, 0]) - reach - x0) / dx).astype(np.int64)
        i_hi = np.floor((np.maximum(a[:, 0], b[:, 0]) + reach - x0) / dx).astype(np.int64)
        j_lo = np.floor((np.minimum(a[:, 1], b[:, 1]) - reach - y0) / dy).astype(np.int64)
        j_hi = np.floor((np.maximum(a[:, 1], b[:, 1]) + reach - y0) / dy).astype(np.int64)
        nx = self.nx[members]
        ny = self.ny[members]
        i_lo = np.clip(i_lo, 0, nx - 1)
        i_hi = np.clip(i_hi, 0, nx - 1)
        j_lo = np.clip(j_lo, 0, ny - 1)
        j_hi = np.clip(j_hi, 0, ny - 1)
        wx = int((i_hi - i_lo).max()) + 1
        wy = int((j_hi - j_lo).max()) + 1
        ii = np.minimum(i_lo[:, None] + np.arange(wx)[None, :], i_hi[:, None])[:, :, None]  # (M, wx, 1)
        jj = np.minimum(j_lo[:, None] + np.arange(wy)[None, :], j_hi[:, None])[:, None, :]  # (M, 1, wy)
        m3 = members[:, None, None]
        cx = x0[:, None, None] + (ii + 0.5) * dx[:, None, None]
        cy = y0[:, None, None] + (jj + 0.5) * dy[:, None, None]
        e = lambda v: v[:, None, None]  # noqa: E731 - broadcast helper
        covered, z_cut = disc_sweep_cover(
            cx, cy, e(a[:, 0]), e(a[:, 1]), e(a[:, 2]), e(b[:, 0]), e(b[:, 1]), e(b[:, 2]), e(reach)
        )
        if not np.any(covered):
            return
        z_new = round_down_f32(np.maximum(np.where(covered, z_cut, np.inf), self.lower[members, 2][:, None, None]))
        old = self.heights[m3, ii, jj]
        self.heights[m3, ii, jj] = np.where(covered, np.minimum(old, z_new), old)
