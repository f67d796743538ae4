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

from dataclasses import dataclass

import numpy as np

from .stock import ZMapStock, disc_sweep_cover

#: Rim tolerance of the near-field test, m: a point within 1 nm of the rim of
#: the current tool disc counts as outside it (the front arc is in material).
RIM_TOL = 1e-9
#: XY spacing of the stored near-field path (:class:`SweptPath`), as a fraction of the tool radius.
PATH_SPACING = 0.1
#: XY distance within which a lower tool position only lowers the last stored
#: point of :class:`SweptPath` (the same axis), m.
SAME_XY_TOL = 1e-9


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
    ramp shallower than 45 deg still stores a point every ``spacing``). At the
    last point's XY (within :data:`SAME_XY_TOL`) the last point keeps the
    lowest tip height. The oldest segment is handed to the Z-map once the
    stored path after it is at least ``lag`` long (XY path length).

    Parameters
    ----------
    start : ndarray, shape (B, 3)
        Initial tool-tip position, m.
    spacing, lag : ndarray, shape (B,)
        Minimum XY distance between stored points and near-field length, m.
    capacity : int
        Stored points per member (the oldest segment is committed early when full).
    """

    def __init__(self, start: np.ndarray, spacing: np.ndarray, lag: np.ndarray, capacity: int) -> None:
        self.batch = start.shape[0]
        self.capacity = int(max(capacity, 3))
        self.spacing = np.asarray(spacing, dtype=np.float64)
        self.lag = np.asarray(lag, dtype=np.float64)
        self.points = np.zeros((self.batch, self.capacity, 3))
        self.arc = np.zeros((self.batch, self.capacity))
        self.points[:, 0] = start
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

    Returns
    -------
    ndarray, shape (M,)
        ``max(top - max(z_tip, z_min), 0)`` at the periphery point.
    """
    px, py = periphery_points(centre[:, 0], centre[:, 1], radius, phi)
    top = stock.sample(member, px, py)
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
