"""Compiled assembly of a member's reference: the full-length steps of :func:`.planner.plan_member`, bit for bit.

After its items are interpolated, a member's plan is built over all its K samples (tens of thousands): the
increments of every segment summed per kind, the acc/dec filters after interpolation (:func:`.filters.apply_fir`,
two cumulative sums per box), the final cumulative sum, the in-position distance, the spindle samples
(:func:`.spindle.sample_spindle`) and the executing line and tool. In numpy each of these is a pass over
(K, 3) temporaries; here each is one compiled loop with the same floating-point operations in the same order
(numpy's ``cumsum`` is sequential; ``np.sign``/``np.minimum`` keep their signed-zero rules, :mod:`.numpy_ops`).

The in-position tests ``np.linalg.norm(p - target, axis=1) > width`` are not recomputed: numpy's sum of the three
squares need not be sequential. A sample is decided here only when its sequential squared distance is outside
``width² (1 ± 1e-9)``; any order of summing three non-negative squares is within a relative 5 × 2⁻⁵³ of any other,
so the decision is numpy's. Samples inside that band (or NaN) are decided by numpy's own ``norm`` of that row
(:func:`last_outside`).
"""
from __future__ import annotations

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
    return _assemble(K, seg_k0, seg_kind, seg_offset, np.ascontiguousarray(flat_position, dtype=float),
                     np.ascontiguousarray(flat_speed, dtype=float), np.asarray(cut_boxes, dtype=np.int64),
                     np.asarray(rapid_boxes, dtype=np.int64), np.asarray(initial, dtype=float),
                     np.asarray(final, dtype=float))
