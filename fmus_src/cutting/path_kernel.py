"""Compiled (numba) step of the path mode: all members, one communication step.

Used by :class:`.path_component.PathCuttingLoad`; the mechanics are those of
:mod:`.force` and the time discretisation that of :mod:`.kernel`, with the
engagement read from an :class:`.table.EngagementTable` instead of the Z-map.

Per member and step ``[t, t + h]``:

1. **Where on the path** — the new position is projected onto the reference
   polyline, searching forward from the member's cursor (its current segment
   and arc length ``s``) over an arc-length window ``2 |dp| + margin``;
   ``s`` never decreases (a reversal on the same line is not mistaken for the
   way back), among equally near candidates the smallest ``s`` wins.
   When that finds no point ahead of the cursor and the tool moved away from
   the path (the servo turned back short of a reversal of the commanded path,
   as the pecks of G83 do at the R plane), the member is re-found across the
   reversal (:func:`across_reversal`): on the stretch after the first segment
   ahead that runs against the cursor's, within :data:`REVERSAL_REACH`. The
   cursor jumps only to a strictly nearer point, and only when no station from
   the cursor to that point holds material (:func:`no_material`), or when the
   tool's move retraces the cursor's segment within :data:`REVERSAL_LAG` of
   the reversal (a slot cut out and back on one line: the stretch skipped is
   the one the servo did not reach).
   The chip is the tool-centre displacement over the last tooth period (the
   member's chip history in its state rows, :func:`.kernel.chord_feed`).
2. **Substeps** — as the Z-map mode, per member: the spindle turns at most
   ``pitch / angle_steps_per_tooth`` (and at most ``pi / 2``) and the tool
   moves at most ``R / 20`` per substep; ``s`` and the tip height are linear
   in time over the step.
3. **Means** — in each substep the table is read at the substep mid-point
   (intervals linearly interpolated between stations when the two stations
   have the same interval structure, extrapolated from one side where it
   changes, else the nearest station; an interval or gap opening or closing
   where the periphery is tangent to an edge of the material, e.g. a block's
   entry or exit face, follows ``cos(half-width)`` linear in ``s``: see
   :func:`_pair`); each tooth
   sweeps ``[phi_a, phi_b]``; its intersection with every engagement interval
   is integrated in closed form (chip thickness clipped at zero), so entry and
   exit angles are exact to the table, with no sampling of the jumps.
4. **Peak** — ``Fc`` at the ``n`` substep instants (table at each instant)
   and at every entry/exit instant inside a substep (engaged side), as the
   Z-map mode.

Cost: a step whose stations hold no material above the tool's lowest point
(:func:`material_near`) skips the substeps, with the same outputs. In the
substeps one ``sin``/``cos`` pair per instant is computed; the teeth and the
substep end are rotations of it (:func:`tooth_rotations`, the span), and the
integrals reuse the sines and cosines of their ends, so only entry/exit angles
and zero-chip crossings call ``sin``/``cos`` (within a few units in the last
place of direct calls).
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit, njit_borrowed, njit_inline
from ..jit_cache import guard_cache
from . import kernel
from .kernel import CHIP_HISTORY_WIDTH, H_COUNT, chord_advance, chord_feed, stalled_cut

TWO_PI = 2.0 * math.pi
#: An immersion angle within this of an interval end counts as inside, rad.
INCLUSIVE_TOL = 1e-9
#: Largest boundary change between stations that is still interpolated, rad.
MAX_INTERP_JUMP = 0.5
#: Tops closer than this are the same interval when interpolating, m.
INTERP_TOP_TOL = 1e-7
#: A feature (interval or gap) whose width changes by more than this between two stations, rad ...
TANGENT_MIN_CHANGE = 1e-3
#: ... while it is narrower than this many times that change at one of them (the first few stations
#: after the tangency; beyond, a linear interpolation of the square-root opening is within 1/256 of
#: the half-width one station after the tangency) ...
TANGENT_NEAR = 8.0
#: ... and its centre moves by less than this fraction of the width change, opens or closes at a
#: tangency (:func:`_pair`).
TANGENT_CENTRE = 0.25
#: Distance margin below which two projection candidates tie (smallest s wins), m.
TIE_TOL = 1e-9
#: Margin [m] of :func:`locate`'s bounding-box test over the rounding of a computed distance (about 1e-16 m at
#: coordinates below 1 m): a segment whose box lies farther than ``best - TIE_TOL + margin`` cannot become the
#: nearest, so its exact distance is not computed.
LOCATE_PRUNE_MARGIN = 1e-9
#: Farthest the first reversal of the path (a segment running against the cursor's) may lie ahead of the
#: cursor for :func:`across_reversal`, m: the servo lag at a reversal (0.14-0.83 mm at the R plane of the
#: tested G83 pecks) with room to spare; it bounds the scan, the material check bounds the jump.
REVERSAL_REACH = 0.01
#: Farthest short of a reversal inside material that a member may turn back and still be re-found after it, m:
#: the servo's shortfall at a reversal (0.59 mm at the out-and-back slot of the SolidCAM post's O5002 in the
#: optimiser's members) with room to spare. Beyond it only a jump over stations without material is taken.
REVERSAL_LAG = 0.002
#: A step's move retraces the cursor's segment when its cosine with that segment is below minus this (within
#: 60 degrees of straight back).
RETRACE_COS = 0.5

#: Per-member error kinds written to ``status`` by :func:`path_step`: too many substeps, off the table's
#: path, fed into material with a stalled spindle (:func:`.kernel.stalled_cut`, a crash).
ERR_SUBSTEPS, ERR_OFF_PATH, ERR_STALLED = 2, 3, 4

#: Rows of the output array of :func:`path_step`.
OUT_FX, OUT_FY, OUT_FC, OUT_PEAK, OUT_FX_MEAN, OUT_FY_MEAN, OUT_TORQUE, OUT_POWER, OUT_MRR, OUT_ANGLE, \
    OUT_DEPTH, OUT_CHIP = range(12)
#: Rows of the state array: spindle angle, previous position (3), arc length, segment, last distance to path,
#: then from ``ST_HISTORY`` the chip history (:func:`.kernel.chord_advance`), :data:`ST_ROWS` rows in all.
ST_THETA, ST_X, ST_Y, ST_Z, ST_S, ST_SEG, ST_DIST, ST_HISTORY = range(8)
ST_ROWS = ST_HISTORY + CHIP_HISTORY_WIDTH
#: Rows of the parameter array.
PAR_RADIUS, PAR_FLUTES, PAR_KT, PAR_KE, PAR_STEPS = range(5)


@njit_inline
def _bound(alpha: np.ndarray, beta: np.ndarray, i: int, c: int, f: int) -> float:
    """Boundary ``f`` (``0 .. 2c``) of station ``i``: ``alpha[k]`` at ``2k``, ``beta[k]`` at ``2k + 1``, rad.

    ``f = 2c`` is ``alpha[0] + 2 pi``, so feature ``f`` (interval for even ``f``, the gap after it for odd
    ``f``) spans boundaries ``f`` and ``f + 1``.
    """
    if f == 2 * c:
        return alpha[i, 0] + TWO_PI
    k = f // 2
    return alpha[i, k] if f % 2 == 0 else beta[i, k]


@njit_inline
def _tangent_move(d_lo: float, d_hi: float) -> bool:
    """A feature whose boundaries change by ``d_lo``, ``d_hi`` [rad] between two stations may open or
    close at a tangency: its width changes by ``dw`` > :data:`TANGENT_MIN_CHANGE` and its centre by at
    most :data:`TANGENT_CENTRE` ``dw`` (:func:`_tangent` adds the width test)."""
    dw = abs(d_hi - d_lo)
    return dw > TANGENT_MIN_CHANGE and abs(0.5 * (d_lo + d_hi)) <= TANGENT_CENTRE * dw


@njit_inline
def _tangent(d_lo: float, d_hi: float, w_i: float, w_j: float) -> bool:
    """A feature whose boundaries change by ``d_lo``, ``d_hi`` [rad] between two stations, where it is
    ``w_i``, ``w_j`` [rad] wide, opens or closes at a tangency (see :func:`_pair`):
    :func:`_tangent_move`, and it is narrower than :data:`TANGENT_NEAR` times its width change at one of
    the stations."""
    return _tangent_move(d_lo, d_hi) and min(w_i, w_j) < TANGENT_NEAR * abs(d_hi - d_lo)


@njit_inline
def _pair_lean(
    i: int, j: int, u: float, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray, top: np.ndarray,
    out_a: np.ndarray, out_b: np.ndarray, out_t: np.ndarray,
) -> int:
    """The hot part of :func:`_pair`: boundaries linear in ``u`` into ``out_*`` and a cheap test for tangencies.

    Returns the number of intervals when that is all (``u`` in ``[0, 1]``, no feature whose two ends
    move apart or together by more than :data:`TANGENT_MIN_CHANGE` while it is narrower than
    :data:`TANGENT_NEAR` times that change: a superset of :func:`_tangent`); -1 when the stations do not
    have the same structure; -2 (extrapolated) or -3 (a tangency candidate) when :func:`_pair` must
    complete ``out_*``. Kept small and free of calls: it is inlined into :func:`table_at`, which runs
    twice per substep and member (the rare part behind a call costs nothing until it is needed).
    """
    c = count[i]
    if count[j] != c:
        return -1
    for k in range(c):
        if (abs(top[i, k] - top[j, k]) > INTERP_TOP_TOL or abs(alpha[i, k] - alpha[j, k]) > MAX_INTERP_JUMP
                or abs(beta[i, k] - beta[j, k]) > MAX_INTERP_JUMP):
            return -1
    uc = min(max(u, 0.0), 1.0)
    # candidates for a tangency (:func:`_tangent`): a feature whose two ends move apart or together, the
    # interval k and the gap before it (before the first: the gap across 2 pi); branch-free
    tangent = False
    for k in range(c):
        da = alpha[j, k] - alpha[i, k]
        db = beta[j, k] - beta[i, k]
        out_a[k] = alpha[i, k] + u * da
        out_b[k] = beta[i, k] + u * db
        out_t[k] = top[i, k] + uc * (top[j, k] - top[i, k])
        # the gap before interval k (before the first: the gap across 2 pi)
        kp = k - 1 if k > 0 else c - 1
        shift = 0.0 if k > 0 else TWO_PI
        db_prev = beta[j, kp] - beta[i, kp]
        gap_i = alpha[i, k] + shift - beta[i, kp]
        w_i = beta[i, k] - alpha[i, k]
        tangent |= ((da * db < 0.0) & (abs(db - da) > TANGENT_MIN_CHANGE)
                    & (min(w_i, w_i + db - da) < TANGENT_NEAR * abs(db - da))) \
            | ((db_prev * da < 0.0) & (abs(da - db_prev) > TANGENT_MIN_CHANGE)
               & (min(gap_i, gap_i + da - db_prev) < TANGENT_NEAR * abs(da - db_prev)))
    extrapolated = u < 0.0 or u > 1.0  # extrapolated boundaries may cross; interpolated ones cannot
    if not (extrapolated or tangent):
        return c
    return -3 if tangent else -2


@njit_borrowed
def _pair(
    i: int, j: int, u: float, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray, top: np.ndarray,
    out_a: np.ndarray, out_b: np.ndarray, out_t: np.ndarray,
) -> int:
    """Intervals at ``u`` from stations ``i`` (u = 0) and ``j`` (u = 1) into ``out_*``; returns their number.

    Boundaries are linear in ``u`` (``u`` outside ``[0, 1]`` extrapolates), except for a feature (an
    interval, or the gap between two neighbours, the last one across 2 pi) that opens or closes at a
    *tangency* (:func:`_tangent`): its width changes by more than :data:`TANGENT_MIN_CHANGE`
    between the stations, it is narrower than :data:`TANGENT_NEAR` times that change at one of them,
    and its centre moves by at most :data:`TANGENT_CENTRE` of that change. There the periphery meets an
    edge of the material tangentially and the half-width ``w`` follows ``cos w = d / R`` with ``d``, the
    edge's distance from the tool centre, linear along the path (exact for a straight path through a
    straight face; ``w`` grows like the square root of the distance travelled: from a tangency at a
    station, a linear interpolation is up to a quarter of the width ``W`` at the next station off, and
    a linear extrapolation from the next two stations still has 0.59 ``W`` open at the tangency). So
    ``cos w`` is linear in ``u``, and the centre too. A feature closing linearly (at a corner) that is
    taken for a tangency closes early, by less than its width at the nearer station.

    Intervals that close up are dropped; neighbours whose gap closes are merged (equal tops within
    :data:`INTERP_TOP_TOL`) or clipped to meet. Tops: station ``i``'s moved linearly towards station
    ``j``'s, clamped to the two. ``out_*`` serve as work space also when -1 is returned.
    Returns -1 when the two stations do not have the same interval structure (count, tops, boundaries
    within :data:`MAX_INTERP_JUMP`).
    """
    n = _pair_lean(i, j, u, count, alpha, beta, top, out_a, out_b, out_t)
    if n >= -1:
        return n
    return _tangents_and_merge(i, j, u, count[i], n == -3, u < 0.0 or u > 1.0, alpha, beta, out_a, out_b,
                               out_t)


@njit_borrowed
def _tangents_and_merge(
    i: int, j: int, u: float, c: int, tangents: bool, extrapolated: bool, alpha: np.ndarray, beta: np.ndarray,
    out_a: np.ndarray, out_b: np.ndarray, out_t: np.ndarray,
) -> int:
    """The rare part of :func:`_pair`: tangent features (if ``tangents``) and, when a boundary was moved
    or extrapolated, dropping, merging and clipping; ``out_*`` hold the ``c`` linear intervals."""
    # features opening or closing at a tangency: cos(half-width) and centre linear in u
    adjusted = extrapolated
    prev_set = False
    first_set = False
    for f in range(2 * c if tangents else 0):
        lo_i, hi_i = _bound(alpha, beta, i, c, f), _bound(alpha, beta, i, c, f + 1)
        lo_j, hi_j = _bound(alpha, beta, j, c, f), _bound(alpha, beta, j, c, f + 1)
        w_i = hi_i - lo_i
        w_j = hi_j - lo_j
        if prev_set or (f == 2 * c - 1 and first_set) or not _tangent(lo_j - lo_i, hi_j - hi_i, w_i, w_j):
            prev_set = False
            continue
        cos_i = math.cos(0.5 * w_i)
        cos_u = cos_i + u * (math.cos(0.5 * w_j) - cos_i)
        half = 0.0 if cos_u >= 1.0 else (math.pi if cos_u <= -1.0 else math.acos(cos_u))
        mid = 0.5 * (lo_i + hi_i) + u * 0.5 * (lo_j + hi_j - lo_i - hi_i)
        k = f // 2
        if f % 2 == 0:  # interval k
            out_a[k] = mid - half
            out_b[k] = mid + half
        else:  # gap after interval k, before interval k + 1 (interval 0 shifted by 2 pi after the last)
            out_b[k] = mid - half
            if k + 1 < c:
                out_a[k + 1] = mid + half
            else:
                out_a[0] = mid + half - TWO_PI
        prev_set = True
        adjusted = True
        if f == 0:
            first_set = True
    if not adjusted:
        return c
    # drop closed intervals; merge or clip neighbours whose gap closed (in place: n <= k)
    n = 0
    for k in range(c):
        a, b, t = out_a[k], out_b[k], out_t[k]
        if n > 0 and a <= out_b[n - 1]:
            if abs(t - out_t[n - 1]) <= INTERP_TOP_TOL:
                out_b[n - 1] = max(out_b[n - 1], b)
                continue
            a = out_b[n - 1]
        if b > a:
            out_a[n], out_b[n], out_t[n] = a, b, t
            n += 1
    # across 2 pi: the last interval reaching into the first
    while n > 1 and out_b[n - 1] >= out_a[0] + TWO_PI:
        if abs(out_t[n - 1] - out_t[0]) <= INTERP_TOP_TOL:  # merge the first into the last
            out_b[n - 1] = max(out_b[n - 1], out_b[0] + TWO_PI)
            for q in range(n - 1):
                out_a[q], out_b[q], out_t[q] = out_a[q + 1], out_b[q + 1], out_t[q + 1]
            n -= 1
        else:  # clip the last
            out_b[n - 1] = out_a[0] + TWO_PI
            if not out_b[n - 1] > out_a[n - 1]:
                n -= 1
            break
    if n == 1 and out_b[0] > out_a[0] + TWO_PI:
        out_b[0] = out_a[0] + TWO_PI
    return n


@njit_inline
def _station(
    i: int, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray, top: np.ndarray, out_a: np.ndarray,
    out_b: np.ndarray, out_t: np.ndarray,
) -> int:
    """The intervals of station ``i`` into ``out_*``; returns their number."""
    c = count[i]
    for k in range(c):
        out_a[k] = alpha[i, k]
        out_b[k] = beta[i, k]
        out_t[k] = top[i, k]
    return c


@njit_borrowed
def _table_between(
    i: int, u: float, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray, top: np.ndarray,
    out_a: np.ndarray, out_b: np.ndarray, out_t: np.ndarray,
) -> int:
    """:func:`table_at` at ``u`` in ``(0, 1)`` between stations ``i`` and ``i + 1`` where the lean
    interpolation does not apply (a tangency, or a structure change: see :func:`table_at`)."""
    last = count.shape[0] - 1
    n = _pair(i, i + 1, u, count, alpha, beta, top, out_a, out_b, out_t)
    if n >= 0:
        return n
    # structure changes between the stations: extrapolate the side that keeps more intervals open
    n_lo = _pair(i, i - 1, -u, count, alpha, beta, top, out_a, out_b, out_t) if i >= 1 else -1
    n_hi = _pair(i + 1, i + 2, u - 1.0, count, alpha, beta, top, out_a, out_b, out_t) \
        if i + 2 <= last else -1
    use_lo = n_lo > n_hi or (n_lo == n_hi and u < 0.5)
    if use_lo and n_lo >= 0:
        return _pair(i, i - 1, -u, count, alpha, beta, top, out_a, out_b, out_t)
    if not use_lo and n_hi >= 0:
        return _pair(i + 1, i + 2, u - 1.0, count, alpha, beta, top, out_a, out_b, out_t)
    if u >= 0.5:
        i = i + 1
    return _station(i, count, alpha, beta, top, out_a, out_b, out_t)


@njit_inline
def _station_fraction(s: float, ds: float, last: int) -> tuple[int, float]:
    """Station ``i`` at or before arc length ``s`` [m] (stations ``ds`` apart, clamped to ``0 .. last``) and the
    fraction ``u`` in ``[0, 1)`` of the way to station ``i + 1`` (0 before the first and at or past the last)."""
    x = s / ds
    i = int(math.floor(x))
    if i < 0:
        i = 0
        x = 0.0
    if i >= last:
        return last, 0.0
    return i, x - i


@njit_borrowed
def table_at(
    s: float, ds: float, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray, top: np.ndarray,
    out_a: np.ndarray, out_b: np.ndarray, out_t: np.ndarray,
) -> int:
    """Engagement intervals at arc length ``s`` into ``out_*``; returns their number.

    Between stations ``i`` and ``i + 1`` with the same interval structure the
    boundaries are interpolated (:func:`_pair`: linearly, except for an
    interval or gap opening or closing at a tangency). Where the structure
    changes between them (an interval appears, vanishes or splits) one side is
    extrapolated from its outer neighbour the same way: the side that keeps
    more intervals open at ``s`` (so an interval that opens or closes between
    two stations does so at the extrapolated place), the nearer one on a tie;
    the nearest station is used when neither side has the same structure on
    its two stations.
    """
    i, u = _station_fraction(s, ds, count.shape[0] - 1)
    if u > 0.0:
        n = _pair_lean(i, i + 1, u, count, alpha, beta, top, out_a, out_b, out_t)
        if n >= 0:
            return n
        return _table_between(i, u, count, alpha, beta, top, out_a, out_b, out_t)
    return _station(i, count, alpha, beta, top, out_a, out_b, out_t)


@njit_inline
def _lean_known(
    i: int, u: float, c: int, alpha: np.ndarray, beta: np.ndarray, top: np.ndarray, out_a: np.ndarray,
    out_b: np.ndarray, out_t: np.ndarray,
) -> int:
    """:func:`_pair_lean`'s intervals between stations ``i`` and ``i + 1`` (``c`` each) at ``u`` in ``(0, 1)``,
    for a pair already known to pass its tests: the same boundary and top arithmetic without the tests."""
    j = i + 1
    uc = min(max(u, 0.0), 1.0)
    for k in range(c):
        da = alpha[j, k] - alpha[i, k]
        db = beta[j, k] - beta[i, k]
        out_a[k] = alpha[i, k] + u * da
        out_b[k] = beta[i, k] + u * db
        out_t[k] = top[i, k] + uc * (top[j, k] - top[i, k])
    return c


@njit_borrowed
def table_at_from(
    s: float, ds: float, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray, top: np.ndarray,
    out_a: np.ndarray, out_b: np.ndarray, out_t: np.ndarray, known: np.ndarray,
) -> int:
    """:func:`table_at`, remembering the last station pair that interpolates plainly; the same results.

    Whether stations ``i`` and ``i + 1`` have the same structure and no tangency candidate
    (:func:`_pair_lean`'s tests) depends on the table only, not on ``s``: ``known[0]`` holds the last
    ``i`` that passed them (-1: none), and a read between the same two stations only interpolates.
    A step's substep reads mostly fall between the same two stations.

    Parameters
    ----------
    s, ds, count, alpha, beta, top, out_a, out_b, out_t
        As :func:`table_at` (``s``, ``ds`` in m).
    known : ndarray of int64, shape (>= 1,)
        ``known[0]``: a station whose pair with the next passed :func:`_pair_lean`'s tests **in this
        table**, or -1; updated. Reset it to -1 before reading another table.
    """
    i, u = _station_fraction(s, ds, count.shape[0] - 1)
    if u > 0.0:
        if i == known[0]:
            return _lean_known(i, u, count[i], alpha, beta, top, out_a, out_b, out_t)
        n = _pair_lean(i, i + 1, u, count, alpha, beta, top, out_a, out_b, out_t)
        if n >= 0:
            known[0] = i
            return n
        return _table_between(i, u, count, alpha, beta, top, out_a, out_b, out_t)
    return _station(i, count, alpha, beta, top, out_a, out_b, out_t)


@njit_borrowed
def locate(
    px: float, py: float, pz: float, seg0: int, s_cur: float, reach: float, verts: np.ndarray, vs: np.ndarray,
) -> tuple[int, float, float]:
    """Nearest point of the polyline at arc length in ``[s_cur, s_cur + reach]`` (see module docstring).

    Returns
    -------
    seg : int
        Segment of the nearest point.
    s : float
        Its arc length, m.
    dist : float
        Distance from ``p`` to it, m.
    """
    nv = verts.shape[0]
    if nv == 1:
        return 0, 0.0, math.sqrt((px - verts[0, 0]) ** 2 + (py - verts[0, 1]) ** 2 + (pz - verts[0, 2]) ** 2)
    best_d = math.inf
    best_s = s_cur
    best_seg = seg0
    seg = seg0
    while seg < nv - 1:
        s_a = vs[seg]
        if s_a > s_cur + reach:
            break
        ax, ay, az = verts[seg, 0], verts[seg, 1], verts[seg, 2]
        bx, by, bz = verts[seg + 1, 0], verts[seg + 1, 1], verts[seg + 1, 2]
        # the segment's bounding box is farther than the best distance can improve: its distance cannot win
        # (a lower bound with LOCATE_PRUNE_MARGIN for rounding; the same result without the division and sqrt)
        gx = max(min(ax, bx) - px, px - max(ax, bx), 0.0)
        gy = max(min(ay, by) - py, py - max(ay, by), 0.0)
        gz = max(min(az, bz) - pz, pz - max(az, bz), 0.0)
        bound = best_d - TIE_TOL + LOCATE_PRUNE_MARGIN
        length = vs[seg + 1] - s_a
        if length > 0.0 and bound >= 0.0 and gx * gx + gy * gy + gz * gz > bound * bound:
            seg += 1
            continue
        dx, dy, dz = bx - ax, by - ay, bz - az
        u = ((px - ax) * dx + (py - ay) * dy + (pz - az) * dz) / (length * length)
        u_min = max((s_cur - s_a) / length, 0.0)
        u = min(max(u, u_min), 1.0)
        d = math.sqrt((px - ax - u * dx) ** 2 + (py - ay - u * dy) ** 2 + (pz - az - u * dz) ** 2)
        if d < best_d - TIE_TOL:
            best_d = d
            best_s = s_a + u * length
            best_seg = seg
        seg += 1
    return best_seg, best_s, best_d


@njit_borrowed
def _depth_at(phi: float, ia: np.ndarray, ib: np.ndarray, it: np.ndarray, cnt: int, bottom: float) -> float:
    """Axial depth at immersion angle ``phi`` in ``[0, 2 pi)`` (0 in air); interval ends inclusive."""
    best = 0.0
    for k in range(cnt):
        a = ia[k]
        b = ib[k]
        inside = (a - INCLUSIVE_TOL <= phi <= b + INCLUSIVE_TOL) or (phi + TWO_PI <= b + INCLUSIVE_TOL) \
            or (phi - TWO_PI >= a - INCLUSIVE_TOL)
        if inside:
            d = it[k] - bottom
            if d > best:
                best = d
    return best


@njit_inline
def _add_integral(
    kt: float, ke: float, depth: float, dx: float, dy: float, psi: float, pa: float, pb: float, s_a: float,
    c_a: float, s_b: float, c_b: float, radius: float, omega: float, scale: float, acc: np.ndarray,
) -> None:
    """``acc += scale * integral over [pa, pb] of (Fx, Fy, torque, MRR) d phi`` (as :func:`.force.interval_mean_quantities`).

    Chip thickness clipped at zero. Takes ``psi = atan2(dy, dx)`` and the
    sines and cosines of ``pa`` and ``pb``; only where the chip thickness
    changes sign inside ``[pa, pb]`` is a sine and cosine computed (at the
    zero crossing).
    """
    h_a = dx * s_a + dy * c_a
    h_b = dx * s_b + dy * c_b
    if (h_a < 0.0 and h_b < 0.0) or (h_b < 0.0 and not h_a > 0.0):
        return  # no chip, or a chip at the single instant pa
    s_lo, c_lo, s_hi, c_hi = s_a, c_a, s_b, c_b
    lo = pa
    hi = pb
    if h_a < 0.0 or h_b < 0.0:  # the chip changes sign inside [pa, pb]: integrate its positive side
        zero = pa + ((-psi - pa) % math.pi)
        if zero < pb:
            s_z, c_z = math.sin(zero), math.cos(zero)
            if h_a < 0.0:
                lo, s_lo, c_lo = zero, s_z, c_z
            else:
                hi, s_hi, c_hi = zero, s_z, c_z
        elif h_a < 0.0:
            return  # it turns positive only at pb
    if hi <= lo:
        return
    s2_lo, s2_hi = 2.0 * s_lo * c_lo, 2.0 * s_hi * c_hi
    i_hcos = dx * 0.5 * (s_hi * s_hi - s_lo * s_lo) + dy * (0.5 * (hi - lo) + 0.25 * (s2_hi - s2_lo))
    i_hsin = dx * (0.5 * (hi - lo) - 0.25 * (s2_hi - s2_lo)) + dy * 0.5 * (s_hi * s_hi - s_lo * s_lo)
    i_h = -dx * (c_hi - c_lo) + dy * (s_hi - s_lo)
    k = scale * kt * depth
    acc[0] += -k * (i_hcos + ke * i_hsin)
    acc[1] += k * (i_hsin - ke * i_hcos)
    acc[2] += k * radius * i_h
    acc[3] += scale * depth * radius * omega * i_h


@njit_inline
def force_at(
    phi0: float, s0: float, c0: float, tooth: int, flutes: int, pitch: float, rot_c: np.ndarray,
    rot_s: np.ndarray, ia: np.ndarray, ib: np.ndarray, it: np.ndarray, cnt: int, bottom: float, fxt: float,
    fyt: float, kt: float, ke: float,
) -> tuple[float, float, float, float, int]:
    """Force on the tool at the instant tooth ``tooth`` is at ``phi0`` [rad], given ``s0 = sin(phi0)``, ``c0 = cos(phi0)``.

    Returns ``(fx, fy, depth, chip, engaged)``: force on the tool [N], largest
    axial depth and chip thickness over engaged teeth [m], teeth in material
    with a positive chip. Tooth ``j`` is at ``phi0 + ((j - tooth) mod flutes) pitch``; its sine and
    cosine come from ``(s0, c0)`` rotated by ``rot_c[i] = cos(i pitch)``,
    ``rot_s[i] = sin(i pitch)`` (no ``sin``/``cos`` call; within a few units
    in the last place of the direct values).
    """
    fx = 0.0
    fy = 0.0
    dmax = 0.0
    hmax = 0.0
    n_in = 0
    if cnt == 0:
        return fx, fy, dmax, hmax, n_in
    for j in range(flutes):
        i = j - tooth
        if i < 0:
            i += flutes
        phi = phi0 + i * pitch
        phi = phi - math.floor(phi / TWO_PI) * TWO_PI
        s = s0 * rot_c[i] + c0 * rot_s[i]
        c = c0 * rot_c[i] - s0 * rot_s[i]
        hc = fxt * s + fyt * c
        if not hc > 0.0:
            continue
        d = _depth_at(phi, ia, ib, it, cnt, bottom)
        if d > 0.0:
            ft = kt * d * hc
            fr = ke * ft
            fx += -ft * c - fr * s
            fy += ft * s - fr * c
            dmax = max(dmax, d)
            hmax = max(hmax, hc)
            n_in += 1
    return fx, fy, dmax, hmax, n_in


@njit_borrowed
def blank_member(out: np.ndarray, engaged: np.ndarray, m: int) -> None:
    """Outputs of member ``m`` whose inputs are not finite: NaN (the angle kept), no engaged tooth, state kept.

    Non-finite inputs come from a member that failed or diverged upstream (its
    outputs are NaN from then on); the master reports that member with the
    reason, and the other members are not held up by it.
    """
    for r in range(out.shape[0]):
        if r != OUT_ANGLE:
            out[r, m] = math.nan
    engaged[m] = 0


@njit
def interval_buffers(kmax: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Work space for two sets of engagement intervals (start, end [rad], top [m]) of ``kmax`` entries each."""
    return np.empty(kmax), np.empty(kmax), np.empty(kmax), np.empty(kmax), np.empty(kmax), np.empty(kmax)


@njit_inline
def drop_history(st: np.ndarray, m: int) -> None:
    """Clear member ``m``'s chip history (a step not cut: its next chips fall back to the step velocity)."""
    st[ST_HISTORY + H_COUNT, m] = 0.0


@njit_borrowed
def fail_member(status: np.ndarray, out: np.ndarray, engaged: np.ndarray, m: int, kind: int) -> int:
    """Member ``m`` fails in this step with error ``kind`` (``ERR_*``): status set, outputs blanked; returns 1."""
    status[m] = kind
    blank_member(out, engaged, m)
    return 1


@njit_inline
def no_material(s_a: float, s_b: float, ds: float, count: np.ndarray) -> bool:
    """True when no station of the table that :func:`table_at` reads between arc lengths ``s_a`` and ``s_b``
    [m] has an engagement interval: the reference pass removed no material there.

    The stations are those :func:`material_near` looks at (``floor(s / ds) - 2 .. floor(s / ds) + 3``).
    """
    last = count.shape[0] - 1
    lo = max(int(math.floor(min(s_a, s_b) / ds)) - 2, 0)
    hi = min(int(math.floor(max(s_a, s_b) / ds)) + 3, last)
    for i in range(lo, hi + 1):
        if count[i] > 0:
            return False
    return True


@njit_borrowed
def across_reversal(
    px: float, py: float, pz: float, seg0: int, s0: float, d0: float, reach: float, verts: np.ndarray,
    vs: np.ndarray, ds: float, count: np.ndarray, mx: float, my: float, mz: float,
) -> tuple[int, float, float]:
    """The member at ``p`` [m] re-found after the next reversal of the path, or ``seg = -1``.

    For a member whose forward projection (:func:`locate`) stays at its cursor ``(seg0, s0)`` while the tool
    moves away from the path (``d0`` [m] from it): the servo turned back before the commanded motion did
    (a G83 peck returns to R before its retract reaches R). The reversal is the first segment after
    ``seg0`` that runs against it (negative dot product of the directions) and starts within
    :data:`REVERSAL_REACH` of ``s0``; the tool, ``d0`` back from the cursor, is then near the stretch after it
    up to ``s_rev + (s_rev - s0) + d0 + reach`` (the mirror image of the cursor plus the window ``reach``
    [m]), where the nearest point is taken (:func:`locate`).

    ``(mx, my, mz)`` [m] is the tool's move over the step.

    Returns
    -------
    seg, s, dist : int, float, float
        That point, when it is nearer than ``d0`` by more than :data:`TIE_TOL` and either no station from
        ``s0`` to it holds material (:func:`no_material`: the jump skips nothing the reference pass cut; the
        pecks of G83 at R), or the tool turned back in material within :data:`REVERSAL_LAG` of the reversal
        (the reversal starts at most that far ahead of ``s0`` and the move retraces the cursor's segment,
        :data:`RETRACE_COS`: a slot cut out and back on one line). The stretch skipped then is the one the
        servo did not reach: the tool never cuts it, and the way back runs in the reference pass's cut.
        Otherwise ``(-1, s0, d0)``, the forward projection stands.
    """
    nv = verts.shape[0]
    if seg0 >= nv - 1:
        return -1, s0, d0
    tx = verts[seg0 + 1, 0] - verts[seg0, 0]
    ty = verts[seg0 + 1, 1] - verts[seg0, 1]
    tz = verts[seg0 + 1, 2] - verts[seg0, 2]
    k = seg0 + 1
    while k < nv - 1 and vs[k] <= s0 + REVERSAL_REACH:
        if ((verts[k + 1, 0] - verts[k, 0]) * tx + (verts[k + 1, 1] - verts[k, 1]) * ty
                + (verts[k + 1, 2] - verts[k, 2]) * tz) < 0.0:
            break
        k += 1
    if k >= nv - 1 or vs[k] > s0 + REVERSAL_REACH:
        return -1, s0, d0
    s_rev = vs[k]
    seg, s, d = locate(px, py, pz, k, s_rev, (s_rev - s0) + d0 + reach, verts, vs)
    if not d < d0 - TIE_TOL:
        return -1, s0, d0
    if s_rev - s0 <= REVERSAL_LAG:
        along_t = mx * tx + my * ty + mz * tz
        size = math.sqrt((mx * mx + my * my + mz * mz) * (tx * tx + ty * ty + tz * tz))
        if along_t < -RETRACE_COS * size:  # turned back short of the reversal: the stretch ahead is never cut
            return seg, s, d
    if no_material(s0, s, ds, count):
        return seg, s, d
    return -1, s0, d0


@njit_inline
def member_motion(
    st: np.ndarray, m: int, x1: float, y1: float, z1: float, reach_margin: float, verts: np.ndarray,
    vs: np.ndarray, ds: float, count: np.ndarray,
) -> tuple[float, float, float, float, float, float, int, float, float]:
    """Move of member ``m`` over the step and where its new position ``(x1, y1, z1)`` [m] lies on the path.

    ``ds``, ``count``: the table's station spacing [m] and interval counts (for :func:`across_reversal`).

    Returns
    -------
    z0, ddx, ddy, ddz : float
        Tip height at the step start and the move, m.
    move : float
        XY length of the move, m.
    s0 : float
        Arc length at the step start, m.
    seg, s1, dist : int, float, float
        :func:`locate` of the new position (forward window ``2 |dp| + reach_margin``); when that stays at
        the cursor (``s1 - s0 <= TIE_TOL``) while the tool moves away from the path (``dist`` grows by more
        than :data:`TIE_TOL` over the last step's), :func:`across_reversal` where it finds the member.
    """
    x0, y0, z0 = st[ST_X, m], st[ST_Y, m], st[ST_Z, m]
    ddx, ddy, ddz = x1 - x0, y1 - y0, z1 - z0
    move = math.sqrt(ddx * ddx + ddy * ddy)
    s0 = st[ST_S, m]
    reach = 2.0 * math.sqrt(move * move + ddz * ddz) + reach_margin
    seg0 = int(st[ST_SEG, m])
    seg, s1, dist = locate(x1, y1, z1, seg0, s0, reach, verts, vs)
    if s1 - s0 <= TIE_TOL and dist > st[ST_DIST, m] + TIE_TOL:  # no progress, moving away: a reversal ahead?
        seg_r, s_r, d_r = across_reversal(x1, y1, z1, seg, s0, dist, reach, verts, vs, ds, count, ddx, ddy, ddz)
        if seg_r >= 0:
            seg, s1, dist = seg_r, s_r, d_r
    return z0, ddx, ddy, ddz, move, s0, seg, s1, dist


@njit_inline
def substeps(om: float, h: float, pitch: float, steps: float, move: float, radius: float) -> float:
    """Substeps the spindle turn (``pitch / steps``, at most ``pi / 2``) and the move (``R / 20``) need, >= 1."""
    n_angle = math.ceil(om * h / min(pitch / steps, 0.5 * math.pi) - 1e-9)
    n_move = math.ceil(move / (0.05 * radius) - 1e-9)
    return max(1.0, n_angle, n_move)


@njit_inline
def write_member(
    out: np.ndarray, st: np.ndarray, engaged: np.ndarray, m: int, f_end_x: float, f_end_y: float, peak: float,
    acc: np.ndarray, n: int, om: float, d_end: float, h_end: float, n_end: int, theta0: float, h: float,
    x1: float, y1: float, z1: float, s1: float, seg: int, dist: float,
) -> None:
    """Outputs (rows ``OUT_*``, forces on the workpiece) and new state (rows ``ST_*``) of member ``m``.

    ``f_end_*`` [N] is the force on the tool at ``t + h``, ``acc`` the substep sums of
    (Fx, Fy, torque, MRR) over ``n`` substeps, ``d_end``, ``h_end`` [m] and ``n_end`` the depth, chip
    and engaged teeth at ``t + h``; the spindle angle advances by ``om h`` [rad]; the step's move is
    recorded in the chip history (:func:`.kernel.chord_advance`).
    """
    out[OUT_FX, m] = -f_end_x
    out[OUT_FY, m] = -f_end_y
    out[OUT_FC, m] = math.sqrt(f_end_x * f_end_x + f_end_y * f_end_y)
    out[OUT_PEAK, m] = peak
    out[OUT_FX_MEAN, m] = -acc[0] / n
    out[OUT_FY_MEAN, m] = -acc[1] / n
    out[OUT_TORQUE, m] = acc[2] / n
    out[OUT_POWER, m] = acc[2] / n * om
    out[OUT_MRR, m] = acc[3] / n
    out[OUT_DEPTH, m] = d_end
    out[OUT_CHIP, m] = h_end
    engaged[m] = n_end
    theta = (theta0 + om * h) % TWO_PI
    out[OUT_ANGLE, m] = theta
    st[ST_THETA, m] = theta
    chord_advance(st[ST_HISTORY:, m], h, x1 - st[ST_X, m], y1 - st[ST_Y, m], om)
    st[ST_X, m] = x1
    st[ST_Y, m] = y1
    st[ST_Z, m] = z1
    st[ST_S, m] = s1
    st[ST_SEG, m] = seg
    st[ST_DIST, m] = dist


#: :func:`material_near` codes: no station has an interval; intervals, all below the tool; material to cut.
NEAR_NONE, NEAR_BELOW, NEAR_CUT = 0, 1, 2


@njit_inline
def material_near(s_a: float, s_b: float, z_low: float, ds: float, count: np.ndarray, top: np.ndarray) -> int:
    """What :func:`table_at` can return for an arc length between ``s_a`` and ``s_b`` [m] (``NEAR_*``).

    Looks at the stations ``floor(s / ds) - 1 .. floor(s / ds) + 2`` that
    interpolation and extrapolation read, with one more on each side for
    rounding. ``NEAR_BELOW``: every interval's top is at or below ``z_low``
    [m], the lowest tool bottom of the step, so no tooth has an axial depth
    (tops are interpolated between stations, never beyond them).
    """
    last = count.shape[0] - 1
    lo = max(int(math.floor(min(s_a, s_b) / ds)) - 2, 0)
    hi = min(int(math.floor(max(s_a, s_b) / ds)) + 3, last)
    code = NEAR_NONE
    for i in range(lo, hi + 1):
        for q in range(count[i]):
            if top[i, q] > z_low:
                return NEAR_CUT
            code = NEAR_BELOW
    return code


@njit
def tooth_rotations(flutes: int, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """``cos(i pitch)`` and ``sin(i pitch)`` for ``i = 0 .. flutes - 1``, shapes (flutes,)."""
    rot_c = np.empty(flutes)
    rot_s = np.empty(flutes)
    for i in range(flutes):
        rot_c[i] = math.cos(i * pitch)
        rot_s[i] = math.sin(i * pitch)
    return rot_c, rot_s


@njit
def path_work(kmax: int, flutes_max: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Work space of :func:`path_step_into`, allocated once by a caller that steps many times.

    Parameters
    ----------
    kmax : int
        Intervals per station of the table (``alpha.shape[1]``).
    flutes_max : int
        Largest flute count the rotation cache holds (:func:`max_flutes` of the members' parameters;
        :func:`path_step_into` refuses members with more).

    Returns
    -------
    intervals : ndarray, shape (6, kmax)
        Two sets of engagement intervals (start, end [rad], top [m]), as :func:`interval_buffers`.
    acc : ndarray, shape (4,)
        Substep sums (Fx, Fy, torque, MRR).
    rot : ndarray, shape (2, flutes_max)
        ``cos(i pitch)`` and ``sin(i pitch)`` of the flute count ``rot_key[0]`` (:func:`tooth_rotations`).
    rot_key : ndarray of int64, shape (2,)
        Flute count ``rot`` holds (-1: none yet), then the station :func:`table_at_from` knows
        (-1: none yet; the work space serves one engagement table).
    """
    return (np.empty((6, kmax)), np.zeros(4), np.empty((2, max(flutes_max, 1))),
            np.full(2, -1, dtype=np.int64))


@njit
def station_cutters(par: np.ndarray, st: np.ndarray, radius: np.ndarray, flutes: np.ndarray, ds: float) -> None:
    """Each member takes the cutter of the station at or just ahead of its cursor (a table of several cutters).

    Called before each step of :func:`path_step` / :func:`path_step_into` /
    :func:`.path_effects.path_step_effects`: the station ``ceil(s / ds)`` (the one that ends the stretch the
    member is on, as :func:`.path_axial.path_axial` reads it) gives the member's radius and teeth, as the tool
    in the spindle gives them in the Z-map mode (:func:`.zmap_numba.switch_tool`). The chip history is kept
    (the tooth period follows the new teeth).

    Parameters
    ----------
    par : ndarray, shape (5, B)
        The members' parameters (rows ``PAR_*``); ``PAR_RADIUS`` [m] and ``PAR_FLUTES`` written.
    st : ndarray, shape (ST_ROWS, B)
        The members' state (arc length ``ST_S`` [m] read).
    radius, flutes : ndarray, shape (S,) or (0,)
        The table's ``cutter_radius`` [m] and ``cutter_flutes``; empty (one cutter): nothing is written.
    ds : float
        Station spacing, m.
    """
    n_st = radius.shape[0]
    if n_st == 0:
        return
    for m in range(par.shape[1]):
        s = st[ST_S, m]
        if not math.isfinite(s):
            continue
        i = min(max(int(math.ceil(s / ds - 1e-9)), 0), n_st - 1)
        par[PAR_RADIUS, m] = radius[i]
        par[PAR_FLUTES, m] = flutes[i]


@njit
def path_step(
    h: float, inp: np.ndarray, par: np.ndarray, st: np.ndarray, out: np.ndarray, engaged: np.ndarray,
    verts: np.ndarray, vs: np.ndarray, ds: float, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
    top: np.ndarray, z_floor: float, reach_margin: float, tolerance: float, max_substeps: int,
    status: np.ndarray,
) -> int:
    """Advance every member by one step ``h`` (see module docstring); write outputs and state in place.

    Parameters
    ----------
    h : float
        Step, s.
    inp : ndarray, shape (4, B)
        Tool-tip x, y, z at ``t + h`` (m) and spindle speed (rad/s).
    par : ndarray, shape (5, B)
        Radius (m), flutes, Kt (N/m2), Ke, angle steps per tooth.
    st : ndarray, shape (ST_ROWS, B)
        State (rows ``ST_*``), updated; a member that is blanked or fails has its chip history cleared.
    out : ndarray, shape (12, B)
        Outputs (rows ``OUT_*``; forces on the **workpiece**), written.
    engaged : ndarray of int64, shape (B,)
        Engaged teeth at ``t + h``, written.
    verts, vs, ds, count, alpha, beta, top, z_floor
        The :class:`.table.EngagementTable` arrays.
    reach_margin : float
        Arc-length margin of the forward search, m.
    tolerance : float
        Largest distance to the path where the table has material, m.
    max_substeps : int
        Refuse steps needing more substeps.

    status : ndarray of int64, shape (B,)
        Set to the error kind (``ERR_*``) of each member that fails in this
        step (too many substeps, off the table's path, fed into material with
        a stalled spindle); that member's outputs are blanked
        (:func:`blank_member`) and the others are advanced.

    Returns
    -------
    int
        Number of members that failed in this step (0: all advanced). A member
        with non-finite inputs (failed upstream) is blanked, not counted.
    """
    intervals, acc, rot, rot_key = path_work(alpha.shape[1], max_flutes(par))
    return path_step_into(h, inp, par, st, out, engaged, verts, vs, ds, count, alpha, beta, top, z_floor,
                          reach_margin, tolerance, max_substeps, status, intervals, acc, rot, rot_key)


@njit_inline
def max_flutes(par: np.ndarray) -> int:
    """Largest flute count ``int(par[PAR_FLUTES, m])`` over the members (at least 1): the rotation cache
    :func:`path_step_into` needs (``par``: shape (5, B), the parameters of :func:`path_step`)."""
    n = 1
    for m in range(par.shape[1]):
        f = par[PAR_FLUTES, m]
        if math.isfinite(f) and int(f) > n:
            n = int(f)
    return n


@njit_borrowed
def path_step_into(
    h: float, inp: np.ndarray, par: np.ndarray, st: np.ndarray, out: np.ndarray, engaged: np.ndarray,
    verts: np.ndarray, vs: np.ndarray, ds: float, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
    top: np.ndarray, z_floor: float, reach_margin: float, tolerance: float, max_substeps: int,
    status: np.ndarray, intervals: np.ndarray, acc: np.ndarray, rot: np.ndarray, rot_key: np.ndarray,
) -> int:
    """:func:`path_step` on the caller's work space (:func:`path_work`): no allocation per call.

    The same floating-point operations as :func:`path_step` (the work space only holds
    intermediate values, and the cached tooth rotations are those :func:`tooth_rotations` computes).

    Parameters
    ----------
    h, inp, par, st, out, engaged, verts, vs, ds, count, alpha, beta, top, z_floor, reach_margin, tolerance, \
max_substeps, status
        As :func:`path_step`.
    intervals : ndarray, shape (6, >= alpha.shape[1])
        Interval work space, overwritten.
    acc : ndarray, shape (4,)
        Substep sums, overwritten.
    rot, rot_key : ndarray, shapes (2, F), (2,) of int64
        Tooth rotations of ``rot_key[0]`` flutes (filled here, :func:`tooth_rotations`'s values);
        ``F >= max_flutes(par)``. ``rot_key[1:]``: :func:`table_at_from`'s known station, valid for this
        engagement table only (:func:`path_work` starts it at -1).

    Returns
    -------
    int
        As :func:`path_step`; -1 (nothing done) when ``F < max_flutes(par)``.
    """
    batch = inp.shape[1]
    if max_flutes(par) > rot.shape[1]:
        return -1
    ia, ib, it, ja, jb, jt = intervals[0], intervals[1], intervals[2], intervals[3], intervals[4], intervals[5]
    rot_c = rot[0]
    rot_s = rot[1]
    known = rot_key[1:]
    bad = 0
    for m in range(batch):
        x1, y1, z1 = inp[0, m], inp[1, m], inp[2, m]
        om = max(inp[3, m], 0.0)
        if not (math.isfinite(x1) and math.isfinite(y1) and math.isfinite(z1) and math.isfinite(om)):
            blank_member(out, engaged, m)  # an upstream failure: this member is out, the others go on
            drop_history(st, m)
            continue
        radius = par[PAR_RADIUS, m]
        flutes = int(par[PAR_FLUTES, m])
        kt = par[PAR_KT, m]
        ke = par[PAR_KE, m]
        steps = par[PAR_STEPS, m]
        z0, ddx, ddy, ddz, move, s0, seg, s1, dist = member_motion(st, m, x1, y1, z1, reach_margin, verts, vs, ds,
                                                                   count)
        pitch = TWO_PI / flutes
        n = int(substeps(om, h, pitch, steps, move, radius))
        if n > max_substeps:
            bad += fail_member(status, out, engaged, m, ERR_SUBSTEPS)  # this member fails; the others go on
            drop_history(st, m)
            continue
        if flutes != rot_key[0]:  # tooth-to-tooth rotations (tooth_rotations' values), kept from call to call
            for i in range(flutes):
                rot[0, i] = math.cos(i * pitch)
                rot[1, i] = math.sin(i * pitch)
            rot_key[0] = flutes
        fxt, fyt = chord_feed(st[ST_HISTORY:, m], ddx, ddy, h, om, flutes)  # the tooth-period chord
        psi = math.atan2(fyt, fxt)
        theta0 = st[ST_THETA, m]
        span = om * h / n
        c_span = math.cos(span)
        s_span = math.sin(span)
        inv_span = 1.0 / span if span >= 1e-9 else 0.0  # the integrals' mean over a substep (span >= 1e-9)
        acc[:] = 0.0
        peak = 0.0
        f_end_x = 0.0
        f_end_y = 0.0
        d_end = 0.0
        h_end = 0.0
        n_end = 0
        near = material_near(s0, s1, max(min(z0, z0 + ddz), z_floor), ds, count, top)
        any_material = near != NEAR_NONE
        phi_k = theta0
        s_k = math.sin(phi_k) if near == NEAR_CUT else 0.0
        c_k = math.cos(phi_k) if near == NEAR_CUT else 1.0
        for k in range(n if near == NEAR_CUT else 0):  # no axial depth anywhere in this step: no force
            f_mid = (k + 0.5) / n
            s_mid = s0 + f_mid * (s1 - s0)
            bottom = max(z0 + f_mid * ddz, z_floor)
            cm = table_at_from(s_mid, ds, count, alpha, beta, top, ia, ib, it, known)
            if cm > 0:
                any_material = True
                if span < 1e-9:
                    for j in range(flutes):
                        phi = phi_k + 0.5 * span + j * pitch
                        phi = phi - math.floor(phi / TWO_PI) * TWO_PI
                        d = _depth_at(phi, ia, ib, it, cm, bottom)
                        hc = fxt * math.sin(phi) + fyt * math.cos(phi)
                        if d > 0.0 and hc > 0.0:
                            ft = kt * d * hc
                            acc[0] += -ft * math.cos(phi) - ke * ft * math.sin(phi)
                            acc[1] += ft * math.sin(phi) - ke * ft * math.cos(phi)
                            acc[2] += ft * radius
                            acc[3] += hc * d * radius * om
                else:
                    for j in range(flutes):
                        pa = phi_k + j * pitch
                        pa = pa - math.floor(pa / TWO_PI) * TWO_PI
                        pb = pa + span
                        s_a = s_k * rot_c[j] + c_k * rot_s[j]
                        c_a = c_k * rot_c[j] - s_k * rot_s[j]
                        s_b = s_a * c_span + c_a * s_span
                        c_b = c_a * c_span - s_a * s_span
                        for q in range(cm):
                            depth = it[q] - bottom
                            if not depth > 0.0:
                                continue
                            for shift in (-TWO_PI, 0.0, TWO_PI):
                                lo = max(pa, ia[q] + shift)
                                hi = min(pb, ib[q] + shift)
                                if not hi > lo:
                                    continue
                                if lo == pa:
                                    s_lo, c_lo = s_a, c_a
                                else:
                                    s_lo, c_lo = math.sin(lo), math.cos(lo)
                                if hi == pb:
                                    s_hi, c_hi = s_b, c_b
                                else:
                                    s_hi, c_hi = math.sin(hi), math.cos(hi)
                                _add_integral(kt, ke, depth, fxt, fyt, psi, lo, hi, s_lo, c_lo, s_hi, c_hi,
                                                   radius, om, inv_span, acc)
                                # both ends of the engaged stretch (engaged side): entry/exit instants,
                                # and boundaries that move past a substep end between two frozen tables
                                # (not the step start t: it belongs to the previous step)
                                if not (lo == pa and k == 0) and fxt * s_lo + fyt * c_lo > 0.0:
                                    fx, fy, _, _, _ = force_at(lo, s_lo, c_lo, j, flutes, pitch, rot_c,
                                                                       rot_s, ia, ib, it, cm, bottom, fxt, fyt,
                                                                       kt, ke)
                                    peak = max(peak, math.sqrt(fx * fx + fy * fy))
                                if fxt * s_hi + fyt * c_hi > 0.0:
                                    fx, fy, _, _, _ = force_at(hi, s_hi, c_hi, j, flutes, pitch, rot_c,
                                                                       rot_s, ia, ib, it, cm, bottom, fxt, fyt,
                                                                       kt, ke)
                                    peak = max(peak, math.sqrt(fx * fx + fy * fy))
            # the instant t + (k + 1) h / n: also the start of the next substep
            f1 = (k + 1.0) / n
            phi_k = theta0 + om * h * (k + 1) / n
            s_k = math.sin(phi_k)
            c_k = math.cos(phi_k)
            cj = table_at_from(s0 + f1 * (s1 - s0), ds, count, alpha, beta, top, ja, jb, jt, known)
            if cj > 0:
                any_material = True
                fx, fy, dm, hm, ne = force_at(phi_k, s_k, c_k, 0, flutes, pitch, rot_c, rot_s, ja, jb,
                                                      jt, cj, max(z0 + f1 * ddz, z_floor), fxt, fyt, kt, ke)
            else:
                fx, fy, dm, hm, ne = 0.0, 0.0, 0.0, 0.0, 0
            peak = max(peak, math.sqrt(fx * fx + fy * fy))
            if k == n - 1:
                f_end_x, f_end_y, d_end, h_end, n_end = fx, fy, dm, hm, ne
        if any_material and dist > tolerance:
            bad += fail_member(status, out, engaged, m, ERR_OFF_PATH)  # this member fails; the others go on
            drop_history(st, m)
            continue
        if stalled_cut(om, peak, acc[0], acc[1]):
            bad += fail_member(status, out, engaged, m, ERR_STALLED)  # a crash: this member fails
            drop_history(st, m)
            continue
        write_member(out, st, engaged, m, f_end_x, f_end_y, peak, acc, n, om, d_end, h_end, n_end, theta0, h,
                     x1, y1, z1, s1, seg, dist)
    return bad


# the cached step calls kernel.stalled_cut: recompile it when that module changes
guard_cache(path_step, kernel)
guard_cache(path_step_into, kernel)
