"""Compiled assembly of a member's reference: the full-length steps of :func:`.planner.plan_member`, bit for bit.

After its items are interpolated, a member's plan is built over all its K samples (tens of thousands): the
increments of every segment summed per kind, the acc/dec filters after interpolation (:func:`.filters.apply_fir`,
two cumulative sums per box), the final cumulative sum, the in-position distance, the spindle samples
(:func:`.spindle.sample_spindle`) and the executing line and tool. In numpy each of these is a pass over
(K, 3) temporaries; here the positions are one streamed loop over the samples (:func:`_assemble_streamed`) and
the rest one compiled loop each, with the same floating-point operations in the same order (numpy's
``cumsum`` is sequential; ``np.sign``/``np.minimum`` keep their signed-zero rules, :mod:`.numpy_ops`).

The in-position tests ``np.linalg.norm(p - target, axis=1) > width`` are not recomputed: numpy's sum of the
three squares need not be sequential. A sample is decided here only when its sequential squared distance is
outside ``width² (1 ± 1e-9)``; any order of summing three non-negative squares is within a relative
5 × 2⁻⁵³ of any other, so the decision is numpy's. Samples inside that band (or NaN) are decided by numpy's
own ``norm`` of that row (:func:`last_outside`).
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from ..jit_cache import guard_cache
from . import numpy_ops
from .numpy_ops import np_minimum, np_sign

#: Relative band around ``width²`` inside which numpy's ``norm`` decides an in-position test.
NORM_BAND = 1e-9
#: :func:`_last_outside` status: no sample outside / the returned sample is outside / numpy must decide it.
NONE, OUTSIDE, AMBIGUOUS = 0, 1, 2


@njit
def fir(x: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """:func:`.filters.apply_fir` of increments ``x`` (K, 3) with box lengths ``boxes`` (int64), as a new array."""
    if boxes.shape[0] == 0:
        return x.copy()
    y = x
    K = x.shape[0]
    for nb in boxes:
        c = np.empty((K, 3))
        out = np.empty((K, 3))
        for a in range(3):
            acc = y[0, a]
            c[0, a] = acc
            for k in range(1, K):
                acc = acc + y[k, a]
                c[k, a] = acc
            z_prev = 0.0
            for k in range(K):
                z = c[k, a] - c[k - nb, a] if (nb < K and k >= nb) else c[k, a]
                z = z / nb
                out[k, a] = (z * 0.5) if k == 0 else ((z + z_prev) * 0.5)
                z_prev = z
        y = out
    return y


@njit
def _assemble(K: int, seg_k0: np.ndarray, seg_kind: np.ndarray, seg_offset: np.ndarray, flat_position: np.ndarray,
              flat_speed: np.ndarray, cut_boxes: np.ndarray, rapid_boxes: np.ndarray, initial: np.ndarray,
              final: np.ndarray):
    """Reference positions and feed of a member from its segments.

    Parameters
    ----------
    K : int
        Samples.
    seg_k0, seg_kind : ndarray (S,) of int64
        First sample and kind (0 cut, 1 rapid, 2 synchronised tapping) of each segment, in plan order.
    seg_offset : ndarray (S + 1,) of int64
        Segment ``s`` holds rows ``seg_offset[s] .. seg_offset[s + 1] - 1`` of the flat arrays.
    flat_position : ndarray (N, 3)
        Pre-filter positions of all segments (m).
    flat_speed : ndarray (N,)
        Their path speed (m/s).
    cut_boxes, rapid_boxes : ndarray of int64
        Filter boxes (:func:`.filters.box_lengths`).
    initial, final : ndarray (3,)
        Position before the program and end point of the last segment (m).

    Returns
    -------
    position : ndarray (K, 3)
        ``initial + cumsum(fir(cut) + fir(rapid) + sync)``, held at ``final`` from the last moving sample (m).
    feed : ndarray (K,)
        Path speed (m/s).
    """
    inc_cut = np.zeros((K, 3))
    inc_rapid = np.zeros((K, 3))
    inc_sync = np.zeros((K, 3))
    feed = np.zeros(K)
    for s in range(seg_k0.shape[0]):
        o = seg_offset[s]
        n = seg_offset[s + 1] - o - 1
        if n == 0:
            continue
        k0 = seg_k0[s]
        kind = seg_kind[s]
        inc = inc_cut if kind == 0 else (inc_rapid if kind == 1 else inc_sync)
        for i in range(n):
            for a in range(3):
                inc[k0 + 1 + i, a] += flat_position[o + i + 1, a] - flat_position[o + i, a]
        for i in range(n + 1):
            feed[k0 + i] = flat_speed[o + i]
    y_cut = fir(inc_cut, cut_boxes)
    y_rapid = fir(inc_rapid, rapid_boxes)
    position = np.empty((K, 3))
    last_moving = -1
    acc = np.empty(3)
    for k in range(K):
        for a in range(3):
            y = y_cut[k, a] + y_rapid[k, a] + inc_sync[k, a]
            if y != 0.0:
                last_moving = k
            acc[a] = y if k == 0 else acc[a] + y
            position[k, a] = initial[a] + acc[a]
    if last_moving >= 0:
        for k in range(last_moving, K):
            for a in range(3):
                position[k, a] = final[a]
    return position, feed


@njit
def _fir_sample(x: float, k: int, a: int, boxes: np.ndarray, slot0: np.ndarray, ring: np.ndarray, acc: np.ndarray,
                z_prev: np.ndarray) -> float:
    """Sample ``k`` of column ``a`` of :func:`fir`, streamed from its input sample ``x`` (same operations).

    ``acc`` (boxes, 3) holds each box's cumulative sum, ``ring`` rows ``slot0[i] .. slot0[i + 1] - 1`` box ``i``'s
    last ``nb`` sums (``c[k - nb]`` in slot ``k % nb``), ``z_prev`` (boxes, 3) each box's previous average.
    """
    for i in range(boxes.shape[0]):
        nb = boxes[i]
        c = x if k == 0 else acc[i, a] + x
        acc[i, a] = c
        slot = slot0[i] + k % nb
        z = c - ring[slot, a] if k >= nb else c
        ring[slot, a] = c
        z = z / nb
        x = (z * 0.5) if k == 0 else ((z + z_prev[i, a]) * 0.5)
        z_prev[i, a] = z
    return x


@njit
def _at_rest(boxes: np.ndarray, slot0: np.ndarray, ring: np.ndarray, acc: np.ndarray, z_prev: np.ndarray) -> bool:
    """Whether streamed boxes are at a fixed point: for an input of +0.0 they output +0.0 and keep their state.

    That holds when every box's sum ``C`` is finite and not -0.0 (so ``C + 0.0`` is ``C``), all its last ``nb``
    sums equal ``C`` (so ``(C - C) / nb`` is +0.0) and its previous average is a zero (so the two-tap average is
    +0.0). Only valid once ``k >= max(boxes)``.
    """
    for i in range(boxes.shape[0]):
        for a in range(3):
            C = acc[i, a]
            if not math.isfinite(C) or (C == 0.0 and math.copysign(1.0, C) < 0.0) or z_prev[i, a] != 0.0:
                return False
            for j in range(slot0[i], slot0[i + 1]):
                if ring[j, a] != C:
                    return False
    return True


@njit
def _is_plus_zero(x: float) -> bool:
    return x == 0.0 and math.copysign(1.0, x) > 0.0


@njit
def _assemble_streamed(K: int, seg_k0: np.ndarray, seg_kind: np.ndarray, seg_offset: np.ndarray,
                       flat_position: np.ndarray, flat_speed: np.ndarray, cut_boxes: np.ndarray,
                       rapid_boxes: np.ndarray, initial: np.ndarray, final: np.ndarray):
    """:func:`_assemble` in one pass over the samples, without (K, 3) temporaries.

    Parameters and returns as :func:`_assemble`; the moving segments must follow one another
    (``seg_k0[s] + n_s <= seg_k0[s']`` for the next moving segment ``s'``), as the planner's items do, so each
    sample takes the increment of at most one segment. A filter whose input is +0.0 while it rests at a fixed
    point (:func:`_at_rest`) outputs +0.0 without being stepped: the rapid filter between rapids, the cutting
    filter during rapids and waits.
    """
    feed = np.zeros(K)
    S = seg_k0.shape[0]
    for s in range(S):
        o = seg_offset[s]
        n = seg_offset[s + 1] - o - 1
        if n == 0:
            continue
        for i in range(n + 1):
            feed[seg_k0[s] + i] = flat_speed[o + i]
    c_slot0 = np.zeros(cut_boxes.shape[0] + 1, dtype=np.int64)
    for i in range(cut_boxes.shape[0]):
        c_slot0[i + 1] = c_slot0[i] + cut_boxes[i]
    r_slot0 = np.zeros(rapid_boxes.shape[0] + 1, dtype=np.int64)
    for i in range(rapid_boxes.shape[0]):
        r_slot0[i + 1] = r_slot0[i] + rapid_boxes[i]
    c_ring = np.zeros((c_slot0[-1], 3))
    r_ring = np.zeros((r_slot0[-1], 3))
    c_acc = np.zeros((cut_boxes.shape[0], 3))
    c_z = np.zeros((cut_boxes.shape[0], 3))
    r_acc = np.zeros((rapid_boxes.shape[0], 3))
    r_z = np.zeros((rapid_boxes.shape[0], 3))
    c_warm = cut_boxes.max() + 1 if cut_boxes.shape[0] else 1  # rest needs k >= every nb
    r_warm = rapid_boxes.max() + 1 if rapid_boxes.shape[0] else 1
    c_rest = False
    r_rest = False
    position = np.empty((K, 3))
    acc = np.zeros(3)
    x = np.zeros(3)
    y_cut = np.zeros(3)
    y_rapid = np.zeros(3)
    last_moving = -1
    s = 0
    for k in range(K):
        while s < S and seg_k0[s] + (seg_offset[s + 1] - seg_offset[s] - 1) < k:  # segments ended before k
            s += 1
        kind = -1
        row = 0
        if s < S and seg_k0[s] + 1 <= k:
            kind = seg_kind[s]
            row = seg_offset[s] + (k - seg_k0[s] - 1)
        for a in range(3):
            x[a] = (0.0 + (flat_position[row + 1, a] - flat_position[row, a])) if kind >= 0 else 0.0
        # cutting filter
        if kind != 0 and c_rest:
            y_cut[:] = 0.0
        else:
            zero_in = True
            for a in range(3):
                xa = x[a] if kind == 0 else 0.0
                zero_in = zero_in and _is_plus_zero(xa)
                y_cut[a] = _fir_sample(xa, k, a, cut_boxes, c_slot0, c_ring, c_acc, c_z)
            c_rest = zero_in and k >= c_warm and _at_rest(cut_boxes, c_slot0, c_ring, c_acc, c_z)
        # rapid filter
        if kind != 1 and r_rest:
            y_rapid[:] = 0.0
        else:
            zero_in = True
            for a in range(3):
                xa = x[a] if kind == 1 else 0.0
                zero_in = zero_in and _is_plus_zero(xa)
                y_rapid[a] = _fir_sample(xa, k, a, rapid_boxes, r_slot0, r_ring, r_acc, r_z)
            r_rest = zero_in and k >= r_warm and _at_rest(rapid_boxes, r_slot0, r_ring, r_acc, r_z)
        for a in range(3):
            y = y_cut[a] + y_rapid[a] + (x[a] if kind == 2 else 0.0)
            if y != 0.0:
                last_moving = k
            acc[a] = y if k == 0 else acc[a] + y
            position[k, a] = initial[a] + acc[a]
    if last_moving >= 0:
        for k in range(last_moving, K):
            for a in range(3):
                position[k, a] = final[a]
    return position, feed


@njit
def _in_position_path(position: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """A segment's own filtered reference: ``position[0] + cumsum(fir(increments))`` (m), ``n + ext + 1`` rows.

    Parameters
    ----------
    position : ndarray (n + 1, 3)
        Pre-filter positions of the segment, ``n >= 1`` (m).
    boxes : ndarray of int64
        Its filter boxes.
    """
    n = position.shape[0] - 1
    m = n + boxes.sum() + 1
    inc = np.zeros((m, 3))
    for i in range(n):
        for a in range(3):
            inc[i + 1, a] = position[i + 1, a] - position[i, a]
    y = fir(inc, boxes)
    out = np.empty((m, 3))
    for a in range(3):
        acc = y[0, a]
        out[0, a] = position[0, a] + acc
        for k in range(1, m):
            acc = acc + y[k, a]
            out[k, a] = position[0, a] + acc
    return out


@njit
def _last_outside(position: np.ndarray, target: np.ndarray, width: float, upto: int) -> tuple[int, int]:
    """Last row ``k < upto`` whose distance to ``target`` may exceed ``width`` (see the module docstring).

    Returns
    -------
    k : int
        The row (-1 with status NONE).
    status : int
        :data:`OUTSIDE` (surely farther than ``width``), :data:`AMBIGUOUS` (numpy's norm decides) or :data:`NONE`.
    """
    w2 = width * width
    hi = w2 * (1.0 + NORM_BAND)
    lo = w2 * (1.0 - NORM_BAND)
    for k in range(upto - 1, -1, -1):
        d0 = position[k, 0] - target[0]
        d1 = position[k, 1] - target[1]
        d2 = position[k, 2] - target[2]
        s = d0 * d0 + d1 * d1 + d2 * d2
        if s > hi:
            return k, OUTSIDE
        if not s < lo:  # in the band, or NaN
            return k, AMBIGUOUS
    return -1, NONE


@njit
def _speed_after(w_start: float, w_cmd: float, ramp: float, dt: float) -> float:
    """:func:`.spindle.speed_after`."""
    d = w_cmd - w_start
    step = ramp * dt
    return w_cmd if abs(d) <= step else w_start + np_sign(d) * step


@njit
def sample_spindle_compiled(event_k: np.ndarray, event_cmd: np.ndarray, n_samples: int, period: float,
                            ramp: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`.spindle.sample_spindle` of events ``event_k`` (int64, samples) and ``event_cmd`` (rad/s).

    Returns
    -------
    ref, actual : ndarray (n_samples,)
        Commanded and actual spindle speed (rad/s).
    """
    ref = np.zeros(n_samples)
    act = np.zeros(n_samples)
    w = 0.0
    E = event_k.shape[0]
    for i in range(E):
        k = event_k[i]
        cmd = event_cmd[i]
        k_next = event_k[i + 1] if i + 1 < E else n_samples
        if k_next <= k:
            continue
        d = cmd - w
        sg = np_sign(d)
        ad = abs(d)
        for kk in range(k, min(k_next, n_samples)):
            ref[kk] = cmd
            act[kk] = w + sg * np_minimum(ad, ramp * ((kk - k) * period))
        w = _speed_after(w, cmd, ramp, (k_next - k) * period)
    return ref, act


@njit
def step_values(keys: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """``values[searchsorted(keys, arange(n), "right") - 1]`` for sorted ``keys`` with ``keys[0] <= 0`` (int64)."""
    out = np.empty(n, dtype=np.int64)
    j = 0
    m = keys.shape[0]
    for g in range(n):
        while j + 1 < m and keys[j + 1] <= g:
            j += 1
        out[g] = values[j]
    return out


guard_cache(_assemble, numpy_ops)
guard_cache(_speed_after, numpy_ops)
guard_cache(sample_spindle_compiled, numpy_ops)


def last_outside(position: np.ndarray, target: np.ndarray, width: float) -> int:
    """Last row of ``position`` (K, 3) with ``np.linalg.norm(row - target) > width``, -1 if none (numpy's decision).

    Parameters
    ----------
    position : ndarray (K, 3)
        Positions (m).
    target : ndarray (3,)
        Target point (m).
    width : float
        In-position width (m).
    """
    if not 1e-100 < width < 1e100:  # the band needs a normal width²: numpy decides every row
        out = np.nonzero(np.linalg.norm(position - target, axis=1) > width)[0]
        return int(out[-1]) if len(out) else -1
    upto = position.shape[0]
    while True:
        k, status = _last_outside(position, target, float(width), upto)
        if status != AMBIGUOUS:
            return int(k)
        if np.linalg.norm(position[k:k + 1] - target, axis=1)[0] > width:
            return int(k)
        upto = k


def filtered_path_compiled(position: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """:func:`.planner._filtered_path` of a segment with pre-filter ``position`` (n + 1, 3), ``n >= 1``, and
    filter ``boxes`` (int64), compiled (bit-identical)."""
    return _in_position_path(position, boxes)


def in_position_compiled(position: np.ndarray, boxes: np.ndarray, width: float) -> int:
    """:func:`.planner._in_position` of a segment with pre-filter ``position`` (n + 1, 3) and filter ``boxes``."""
    n = position.shape[0] - 1
    if n == 0:
        return 0
    path = _in_position_path(position, boxes)
    return max(n, last_outside(path, position[-1], width) + 1)


def assemble_positions(segments: list, K: int, cut_boxes: list[int], rapid_boxes: list[int], initial: np.ndarray,
                       final: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Reference positions (K, 3) (m) and feed (K,) (m/s) of a member: the numpy steps of
    :func:`.planner.plan_member` compiled (bit-identical).

    Parameters
    ----------
    segments : list of (int, str, Segment)
        First sample, kind ("cut", "rapid", "sync") and pre-filter samples of each motion, in plan order.
    K : int
        Samples of the member before any spindle run-down.
    cut_boxes, rapid_boxes : list of int
        After-interpolation filter boxes.
    initial, final : ndarray (3,)
        Position before the program and end point of the last segment (m).
    """
    kinds = {"cut": 0, "rapid": 1, "sync": 2}
    S = len(segments)
    seg_k0 = np.array([s[0] for s in segments], dtype=np.int64)
    seg_kind = np.array([kinds[s[1]] for s in segments], dtype=np.int64)
    seg_offset = np.zeros(S + 1, dtype=np.int64)
    seg_offset[1:] = np.cumsum([s[2].speed.shape[0] for s in segments])
    if S:
        flat_position = np.concatenate([s[2].position for s in segments])
        flat_speed = np.concatenate([s[2].speed for s in segments])
    else:
        flat_position, flat_speed = np.zeros((0, 3)), np.zeros(0)
    n = seg_offset[1:] - seg_offset[:-1] - 1
    moving = n > 0
    ends = (seg_k0 + n)[moving]
    in_turn = bool(np.all(seg_k0[1:] >= seg_k0[:-1])) and bool(np.all(ends[:-1] <= seg_k0[moving][1:]))
    kernel = _assemble_streamed if in_turn else _assemble  # the items run one after the other: always streamed
    return kernel(K, seg_k0, seg_kind, seg_offset, np.ascontiguousarray(flat_position, dtype=float),
                     np.ascontiguousarray(flat_speed, dtype=float), np.asarray(cut_boxes, dtype=np.int64),
                     np.asarray(rapid_boxes, dtype=np.int64), np.asarray(initial, dtype=float),
                     np.asarray(final, dtype=float))
