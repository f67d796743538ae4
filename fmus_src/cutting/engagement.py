"""Cutter–workpiece engagement: which tooth is in material, and how deep.

Angle convention (Altintas, *Manufacturing Automation*, ch. 2)
-------------------------------------------------------------
Look down on the table from the spindle (x to the right, y away from the
operator, z towards you). The tool turns clockwise (M03). The immersion angle
``phi`` of a tooth is measured **clockwise from the +y axis**: at ``phi = 0``
the tooth points to +y, at ``phi = pi/2`` to +x, at ``phi = pi`` to -y, at
``phi = 3 pi/2`` to -x. The tooth tip (periphery point) is therefore at

    P = C + R (sin phi, cos phi)

with ``C`` the tool centre. Feeding along +x, a tooth between ``0`` and
``pi/2`` is up-milling (chip thickness grows from zero), between ``pi/2`` and
``pi`` down-milling. Tooth ``j`` of ``N`` is at ``phi_j = theta + j 2 pi / N``
where ``theta`` is the spindle angle.

Engagement from the stock
-------------------------
A tooth is in material when its periphery point has material above the tool
tip. The material there is the Z-map (:mod:`.stock`) *minus* what the tool
itself removed in the recent past. The recent path (a few millimetres, at
least ``R + 2 cell``) is kept exactly as a polyline (:class:`SweptPath`): the
disc swept along it is tested analytically, so the front arc of the tool, which
lies exactly on the rim of the current disc, sees fresh material without any
grid quantisation. Older path segments are committed to the Z-map. Entry and
exit angles thus *emerge* from the geometry (slot, half and partial immersion,
entering and leaving the part, second passes).

Axial depth of a tooth = (top of material at its periphery point) -
max(tool-tip z, z_min), clipped at zero.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..jit import njit
from .stock import ZMapStock, disc_sweep_cover

#: Rim tolerance of the near-field test, m: a point within 1 nm of the rim of
#: the current tool disc counts as outside it (the front arc is in material).
RIM_TOL = 1e-9
#: XY spacing of the stored near-field path (:class:`SweptPath`), as a fraction of the tool radius.
PATH_SPACING = 0.1
#: XY distance within which a lower tool position only lowers the last stored
#: point of :class:`SweptPath` (the same axis), m.
SAME_XY_TOL = 1e-9
#: Turn tolerance of :class:`SweptPath`, m: the previous tool position is stored
#: when the last stored point lies more than this off the line of the latest
#: move (a corner of the actual path, :func:`turn_point`), so the stored
#: polyline does not cut corners and the Z-map walls it leaves contain the
#: tool's actual sweep.
TURN_TOL = 1e-6
#: Ring-buffer slots of :class:`SweptPath` beyond ``lag / spacing`` (turn points
#: and the slot holding the previous tool position).
TURN_SLOTS = 64


def path_capacity(lag: np.ndarray, spacing: np.ndarray) -> int:
    """Stored points per member of a :class:`SweptPath` with this near-field length and spacing.

    Parameters
    ----------
    lag, spacing : ndarray
        Near-field length and point spacing, m.

    Returns
    -------
    int
        ``ceil(max(lag / spacing)) + 4 + TURN_SLOTS``.
    """
    return int(np.ceil(np.max(np.asarray(lag) / np.asarray(spacing)))) + 4 + TURN_SLOTS


@njit
def turn_point(lx: float, ly: float, lz: float, qx: float, qy: float, qz: float, px: float, py: float,
               pz: float) -> bool:
    """Whether the previous tool position ``Q`` must be stored as a corner of the path.

    The stored polyline runs from the last stored point ``L``; the tool moved
    from ``Q`` (previous step's end) to ``P`` (this step's end). ``Q`` is a
    corner when ``L`` lies more than :data:`TURN_TOL` off the line through
    ``Q`` along ``Q -> P`` (the chord ``L -> P`` and its successors would cut
    the corner at ``Q`` by up to that), or when the move turns back
    (``(Q - L) . (P - Q) < 0``) with ``|LQ| > TURN_TOL``. Both in 3D: a lift
    (or a plunge) after a feed is a corner too, so a pass's last stretch is
    committed at its depth, not along a ramp from it to the retract. On an arc
    of radius ``r`` this stores a point every ``sqrt(2 r TURN_TOL)`` or so (the
    chord error then stays below about ``TURN_TOL / 4``); on a straight move
    never. Both moves must exceed :data:`SAME_XY_TOL`. (Scalars; the numpy
    :meth:`SweptPath.advance` and the compiled commit call this same test.)

    Parameters
    ----------
    lx, ly, lz, qx, qy, qz, px, py, pz : float
        ``L``, ``Q`` and ``P``, m.

    Returns
    -------
    bool
    """
    ax, ay, az = qx - lx, qy - ly, qz - lz
    bx, by, bz = px - qx, py - qy, pz - qz
    lq = math.sqrt(ax * ax + ay * ay + az * az)
    qp = math.sqrt(bx * bx + by * by + bz * bz)
    if not (lq > SAME_XY_TOL and qp > SAME_XY_TOL):
        return False
    if ax * bx + ay * by + az * bz < 0.0:
        return lq > TURN_TOL
    cx, cy, cz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    return math.sqrt(cx * cx + cy * cy + cz * cz) > TURN_TOL * qp


def periphery_points(
    cx: np.ndarray, cy: np.ndarray, radius: np.ndarray, phi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Tooth tip positions ``C + R (sin phi, cos phi)`` (all arguments broadcast), m."""
    return cx + radius * np.sin(phi), cy + radius * np.cos(phi)


@dataclass(frozen=True)
class NearField:
    """The recent tool path of every member, frozen for one communication step.

    Attributes
    ----------
    start, end : ndarray, shape (B, K, 3)
        Segment end points (tool tip), m.
    valid : ndarray of bool, shape (B, K)
        Which segments exist.
    tail : ndarray, shape (B, 3)
        Last stored point; the open segment runs from it to the current tool position.
    """

    start: np.ndarray
    end: np.ndarray
    valid: np.ndarray
    tail: np.ndarray

    def height(
        self, member: np.ndarray, px: np.ndarray, py: np.ndarray, centre: np.ndarray, radius: np.ndarray
    ) -> np.ndarray:
        """Lowest tip height of the recent sweep over each point, m (``+inf`` if not swept).

        Parameters
        ----------
        member : ndarray of int, shape (M,)
            Batch member of each query.
        px, py : ndarray, shape (M,)
            Query points, m.
        centre : ndarray, shape (M, 3)
            Current tool-tip position for each query (end of the open segment), m.
        radius : ndarray, shape (M,)
            Tool radius, m.
        """
        a = self.start[member]  # (M, K, 3)
        b = self.end[member]
        covered, z_cut = disc_sweep_cover(
            px[:, None], py[:, None], a[..., 0], a[..., 1], a[..., 2], b[..., 0], b[..., 1], b[..., 2],
            radius[:, None], RIM_TOL,
        )
        z_hist = np.where(covered & self.valid[member], z_cut, np.inf).min(axis=1)
        t = self.tail[member]
        covered_t, z_tail = disc_sweep_cover(
            px, py, t[:, 0], t[:, 1], t[:, 2], centre[:, 0], centre[:, 1], centre[:, 2], radius, RIM_TOL
        )
        return np.minimum(z_hist, np.where(covered_t, z_tail, np.inf))


class SweptPath:
    """Recent tool path per member (ring buffer), committed to the Z-map with a lag.

    A new point is stored when the tool has moved at least ``spacing`` in XY
    since the last stored point, or when it is below that point by at least
    its XY distance ``s`` to it (``0 < s < spacing``, ``s`` more than
    :data:`SAME_XY_TOL`: a plunge after an approach that ended short of the
    last point is stored on the tool's axis, not up to ``spacing`` off it; a
    ramp shallower than 45 deg still stores a point every ``spacing``). Before
    that, the previous tool position is stored where the path turns there
    (:func:`turn_point`): a chord across a corner of the actual (lagging,
    rounding) path would commit a wall up to ``spacing / 2`` inside the tool's
    sweep, and a later pass below would read that cell column at its full
    height. At the last point's XY (within :data:`SAME_XY_TOL`) the last point
    keeps the lowest tip height. The oldest segment is handed to the Z-map once
    the stored path after it is at least ``lag`` long (XY path length). The
    slot after the last point holds the previous tool position.

    Parameters
    ----------
    start : ndarray, shape (B, 3)
        Initial tool-tip position, m.
    spacing, lag : ndarray, shape (B,)
        Minimum XY distance between stored points and near-field length, m.
    capacity : int
        Stored points per member, including the slot of the previous position (the oldest segment is
        committed early when full; no turn point is stored in the last two free slots); see
        :func:`path_capacity`.
    """

    def __init__(self, start: np.ndarray, spacing: np.ndarray, lag: np.ndarray, capacity: int) -> None:
        self.batch = start.shape[0]
        self.capacity = int(max(capacity, 3))
        self.spacing = np.asarray(spacing, dtype=np.float64)
        self.lag = np.asarray(lag, dtype=np.float64)
        self.points = np.zeros((self.batch, self.capacity, 3))
        self.arc = np.zeros((self.batch, self.capacity))
        self.points[:, 0] = start
        self.points[:, 1] = start  # the previous tool position (the slot after the last point)
        self.head = np.zeros(self.batch, dtype=np.int64)
        self.count = np.ones(self.batch, dtype=np.int64)
        self._rows = np.arange(self.batch)

    def _index(self, i: np.ndarray) -> np.ndarray:
        return (self.head + i) % self.capacity

    def last(self) -> np.ndarray:
        """Last stored point per member, shape (B, 3)."""
        return self.points[self._rows, self._index(self.count - 1)]

    def near_field(self) -> NearField:
        """Freeze the stored polyline for one communication step."""
        order = (self.head[:, None] + np.arange(self.capacity)[None, :]) % self.capacity
        pts = self.points[self._rows[:, None], order]
        valid = np.arange(self.capacity - 1)[None, :] < (self.count - 1)[:, None]
        return NearField(pts[:, :-1], pts[:, 1:], valid, self.last())

    def advance(self, position: np.ndarray) -> None:
        """Record the tool position at the end of a communication step (shape (B, 3), m)."""
        # a corner at the previous position: store it first (turn_point)
        prev = self.points[self._rows, self._index(self.count)].copy()
        last = self.points[self._rows, self._index(self.count - 1)]
        for b in range(self.batch):
            # (not in the last free slots: the position itself may still need one, and the slot after it)
            if self.count[b] < self.capacity - 2 and turn_point(last[b, 0], last[b, 1], last[b, 2], prev[b, 0],
                                                               prev[b, 1], prev[b, 2], position[b, 0],
                                                               position[b, 1], position[b, 2]):
                new_b = (self.head[b] + self.count[b]) % self.capacity
                self.arc[b, new_b] = self.arc[b, (new_b - 1) % self.capacity] + math.hypot(
                    prev[b, 0] - last[b, 0], prev[b, 1] - last[b, 1])
                self.points[b, new_b] = prev[b]
                self.count[b] += 1
        last_i = self._index(self.count - 1)
        last = self.points[self._rows, last_i]
        step = np.hypot(position[:, 0] - last[:, 0], position[:, 1] - last[:, 1])
        same_xy = step <= SAME_XY_TOL
        # a plunge beside the last point (down at least as steeply as 45 deg from it) is stored on its own axis
        append = (step >= self.spacing) | (~same_xy & (last[:, 2] - position[:, 2] >= step))
        keep = same_xy & ~append
        # not moved in XY: the last point keeps the lowest tip height reached there
        self.points[self._rows[keep], last_i[keep], 2] = np.minimum(last[keep, 2], position[keep, 2])
        if np.any(append):
            rows = self._rows[append]
            new_i = (self.head[rows] + self.count[rows]) % self.capacity
            arc_last = self.arc[rows, last_i[rows]]
            self.points[rows, new_i] = position[rows]
            self.arc[rows, new_i] = arc_last + step[rows]
            self.count[rows] += 1
        self.points[self._rows, self._index(self.count)] = position

    def pop_ready(self, force_room: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Remove the oldest segment of members whose near field is long enough.

        Parameters
        ----------
        force_room : bool
            Also pop where the buffer is full (to make room for the next point).

        Returns
        -------
        start, end : ndarray, shape (B, 3)
            Oldest segment per member (meaningful where ``mask``).
        mask : ndarray of bool, shape (B,)
            Members that popped a segment.
        """
        second = self.points[self._rows, self._index(np.minimum(1, self.count - 1))]
        first = self.points[self._rows, self.head]
        arc_second = self.arc[self._rows, self._index(np.minimum(1, self.count - 1))]
        arc_last = self.arc[self._rows, self._index(self.count - 1)]
        mask = (self.count >= 2) & (arc_last - arc_second >= self.lag)
        if force_room:
            mask |= self.count >= self.capacity - 1
        self.head = np.where(mask, (self.head + 1) % self.capacity, self.head)
        self.count = np.where(mask, self.count - 1, self.count)
        return first, second, mask


def tooth_depth(
    stock: ZMapStock,
    near: NearField,
    member: np.ndarray,
    centre: np.ndarray,
    phi: np.ndarray,
    radius: np.ndarray,
    active: np.ndarray | None = None,
    reach: np.ndarray | None = None,
    reach_stock: np.ndarray | None = None,
) -> np.ndarray:
    """Axial depth of cut of teeth, m (0 when the tooth is in air).

    Parameters
    ----------
    stock : ZMapStock
        Committed material.
    near : NearField
        Recent (uncommitted) sweep.
    member : ndarray of int, shape (M,)
        Batch member of each tooth query.
    centre : ndarray, shape (M, 3)
        Tool-tip position, m.
    phi : ndarray, shape (M,)
        Tooth immersion angle (see module docstring), rad.
    radius : ndarray, shape (M,)
        Tool radius, m.
    active : ndarray of bool, shape (M,), optional
        Only these queries are evaluated (the others get 0), e.g. teeth with a
        positive chip thickness; saves the near-field test where it cannot matter.
    reach, reach_stock : ndarray, shape (M,), optional
        Distance from the tool axis of the point tested against the recent sweep (the nominal disc of
        ``radius`` swept along the near field) and of the point tested against the Z-map, m; default
        ``radius`` (the periphery point). A tooth that stands out by runout is tested beyond the radius
        (:func:`.effect_model.runout_reach`).

    Returns
    -------
    ndarray, shape (M,)
        ``max(top - max(z_tip, z_min), 0)``: ``top`` the Z-map at ``C + reach_stock (sin phi, cos phi)``,
        lowered to the recent sweep's bottom over ``C + reach (sin phi, cos phi)``.
    """
    px, py = periphery_points(centre[:, 0], centre[:, 1], radius if reach is None else reach, phi)
    if reach_stock is None:
        top = stock.sample(member, px, py)
    else:
        qx, qy = periphery_points(centre[:, 0], centre[:, 1], reach_stock, phi)
        top = stock.sample(member, qx, qy)
    bottom = np.maximum(centre[:, 2], stock.lower[member, 2])
    todo = top > bottom
    if active is not None:
        todo &= active
    idx = np.flatnonzero(todo)
    depth = np.zeros(phi.shape)
    if idx.size:
        near_top = near.height(member[idx], px[idx], py[idx], centre[idx], radius[idx])
        depth[idx] = np.maximum(np.minimum(top[idx], near_top) - bottom[idx], 0.0)
    return depth
