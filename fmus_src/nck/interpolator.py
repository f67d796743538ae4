"""Interpolation of chains of feed blocks and of rapid moves at the interpolation period.

Both produce the *pre-filter* reference: positions (m) sampled at
``k × Ts`` for ``k = 0..n`` from rest to rest, and the path speed (m/s).
The last sample is exactly the end point.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .geometry import ChainGeometry, evaluate
from .lookahead import ChainSpeeds
from .profiles import SpeedChange


@dataclass(frozen=True)
class Segment:
    """Pre-filter samples of one motion (from rest to rest).

    Attributes
    ----------
    position : ndarray (n + 1, 3)
        Positions at sample times ``k Ts``, ``k = 0..n`` (m).
    speed : ndarray (n + 1,)
        Path speed (m/s).
    block_start : ndarray (nb,)
        Start time of each block relative to the segment start (s).
    duration : float
        Continuous-time duration (s) before rounding to samples.
    """

    position: np.ndarray
    speed: np.ndarray
    block_start: np.ndarray
    duration: float

    @property
    def n(self) -> int:
        """Number of sample periods."""
        return len(self.speed) - 1


#: Bisection steps of :func:`_times_at` (halves a piece of at most hours down to below 1e-12 s).
_BISECTIONS = 64


def _n_periods(duration: float, period: float) -> int:
    return max(int(math.ceil(duration / period - 1e-9)), 0)


@dataclass(frozen=True)
class ChainPieces:
    """Constant-jerk pieces of a chain's speed profile over its acc/dec spans (continuous time).

    Attributes
    ----------
    t0, s0, v0, a0, jerk : list of float, length P
        Start time (s), arc length (m), speed (m/s), acceleration (m/s2) and jerk (m/s3) of each piece,
        in time order.
    block_start : list of float, length nb
        Start time of each block relative to the chain start (s); a block that starts inside a span starts
        where the profile reaches it.
    duration : float
        Continuous-time duration of the chain (s).
    """

    t0: list[float]
    s0: list[float]
    v0: list[float]
    a0: list[float]
    jerk: list[float]
    block_start: list[float]
    duration: float


def chain_pieces(geo: ChainGeometry, speeds: ChainSpeeds, sc: SpeedChange) -> ChainPieces:
    """The acc/dec profile of a chain as constant-jerk pieces (the first half of :func:`interpolate_chain`).

    Each span (:mod:`.spans`) runs its entry speed → cruise → exit speed profile as one piece of the path, so
    a speed change may cross the block ends inside it; the start time of a block inside a span is where the
    profile reaches the block's start.

    Parameters
    ----------
    geo : ChainGeometry
    speeds : ChainSpeeds
        Span boundaries, junction speeds and block limits from :func:`plan_chain_speeds`.
    sc : SpeedChange
        Acc/dec law.

    Returns
    -------
    ChainPieces
    """
    v = speeds.junction.tolist()
    top = speeds.ceiling.tolist()
    L = geo.length.tolist()
    cum = geo.cum.tolist()
    starts = speeds.span_start.tolist()
    t0: list[float] = []
    s0: list[float] = []
    v0: list[float] = []
    a0: list[float] = []
    jk: list[float] = []
    block_start = [0.0] * len(L)
    inner: list[int] = []  # blocks that start inside a span: their start time is found on the profile below
    t = 0.0
    for first, end, ceiling in zip(starts[:-1], starts[1:], top):
        block_start[first] = t
        inner.extend(range(first + 1, end))
        length = cum[end] - cum[first]
        va, vb = v[first], v[end]
        vp = sc.peak(va, vb, length, ceiling)
        up = sc.pieces(va, vp)
        down = sc.pieces(vp, vb)
        cruise = length - sc.distance(va, vp) - sc.distance(vp, vb)
        plist = up + ([(cruise / vp, 0.0, 0.0)] if cruise > 0.0 and vp > 0.0 else []) + down
        s, vel = cum[first], va
        for dur, acc, jerk in plist:
            t0.append(t)
            s0.append(s)
            v0.append(vel)
            a0.append(acc)
            jk.append(jerk)
            s += vel * dur + 0.5 * acc * dur * dur + jerk * dur ** 3 / 6.0
            vel += acc * dur + 0.5 * jerk * dur * dur
            t += dur
    if inner and t0:
        times = _times_at(np.array([cum[i] for i in inner]), np.array(t0), np.array(s0), np.array(v0),
                          np.array(a0), np.array(jk), t)
        for i, tb in zip(inner, times.tolist()):
            block_start[i] = tb
    return ChainPieces(t0, s0, v0, a0, jk, block_start, t)


def interpolate_chain(geo: ChainGeometry, speeds: ChainSpeeds, sc: SpeedChange, period: float) -> Segment:
    """Sample a chain of feed blocks with acc/dec before interpolation over its acc/dec spans.

    This numpy implementation is the specification of the compiled sampling
    (:func:`.chain_sampling.interpolate_chain_compiled`, bit-identical).

    Parameters
    ----------
    geo : ChainGeometry
    speeds : ChainSpeeds
        Span boundaries, junction speeds and block limits from :func:`plan_chain_speeds`.
    sc : SpeedChange
        Acc/dec law.
    period : float
        Interpolation period Ts (s).

    Returns
    -------
    Segment
    """
    pieces = chain_pieces(geo, speeds, sc)
    return sample_chain(geo, pieces, period)


def sample_chain(geo: ChainGeometry, pieces: ChainPieces, period: float) -> Segment:
    """Sample a chain's pieces at ``k Ts`` (numpy; the second half of :func:`interpolate_chain`).

    Parameters
    ----------
    geo : ChainGeometry
    pieces : ChainPieces
        From :func:`chain_pieces`.
    period : float
        Interpolation period Ts (s).

    Returns
    -------
    Segment
    """
    t0, s0, v0, a0, jk = pieces.t0, pieces.s0, pieces.v0, pieces.a0, pieces.jerk
    block_start, duration = pieces.block_start, pieces.duration
    L = geo.length
    n = _n_periods(duration, period)
    tk = np.arange(n + 1) * period
    total = geo.cum.tolist()[-1]
    if not t0:
        pos = np.repeat(geo.start[:1], n + 1, axis=0)
        return Segment(pos, np.zeros(n + 1), np.array(block_start), duration)
    T0 = np.array(t0)
    S0, V0, A0, JK = np.array(s0), np.array(v0), np.array(a0), np.array(jk)
    idx = np.searchsorted(T0, tk, side="right") - 1
    tau = tk - T0[idx]
    s = S0[idx] + tau * (V0[idx] + tau * (0.5 * A0[idx] + tau * JK[idx] / 6.0))
    vel = V0[idx] + tau * (A0[idx] + 0.5 * tau * JK[idx])
    past = tk >= duration
    s[past] = total
    vel[past] = 0.0
    s = np.clip(np.maximum.accumulate(s), 0.0, total)
    s[-1] = total
    vel = np.maximum(vel, 0.0)
    b = np.clip(np.searchsorted(geo.cum, s, side="right") - 1, 0, len(L) - 1)
    frac = np.clip((s - geo.cum[b]) / geo.length[b], 0.0, 1.0)
    frac[-1] = 1.0
    b[-1] = len(L) - 1
    pos = evaluate(geo, b, frac)
    return Segment(pos, vel, np.array(block_start), duration)


def _times_at(target: np.ndarray, T0: np.ndarray, S0: np.ndarray, V0: np.ndarray, A0: np.ndarray,
              JK: np.ndarray, duration: float) -> np.ndarray:
    """Times (s) at which the piecewise-cubic path profile reaches the arc lengths ``target`` (m).

    The path length grows monotonically within each constant-jerk piece (the speed is >= 0), so the time in
    the piece is found by bisection to the resolution of a double.
    """
    idx = np.clip(np.searchsorted(S0, target, side="right") - 1, 0, len(S0) - 1)
    ends = np.append(T0[1:], duration)
    lo = np.zeros(len(target))
    hi = ends[idx] - T0[idx]
    for _ in range(_BISECTIONS):
        mid = 0.5 * (lo + hi)
        s = S0[idx] + mid * (V0[idx] + mid * (0.5 * A0[idx] + mid * JK[idx] / 6.0))
        below = s < target
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    return T0[idx] + 0.5 * (lo + hi)


def rapid_speed(start: np.ndarray, end: np.ndarray, rapid_feed: tuple[float, float, float]) -> float:
    """Path speed (m/s) of linear-interpolation-type positioning: the slowest axis sets the time."""
    d = np.abs(np.asarray(end, dtype=float) - np.asarray(start, dtype=float))
    length = float(np.linalg.norm(d))
    if length == 0.0:
        return 0.0
    time = max(d[a] / rapid_feed[a] for a in range(3))
    return length / time


def interpolate_rapid(start: np.ndarray, end: np.ndarray, rapid_feed: tuple[float, float, float],
                      period: float) -> Segment:
    """Sample a G0 move: constant speed along the straight line (acc/dec comes from the rapid filter)."""
    start = np.asarray(start, dtype=float)
    end = np.asarray(end, dtype=float)
    d = end - start
    length = float(np.linalg.norm(d))
    if length == 0.0:
        return Segment(start[None, :].copy(), np.zeros(1), np.zeros(1), 0.0)
    v = rapid_speed(start, end, rapid_feed)
    duration = length / v
    n = _n_periods(duration, period)
    tk = np.arange(n + 1) * period
    s = np.minimum(v * tk, length)
    pos = start + (s / length)[:, None] * d
    pos[-1] = end
    speed = np.where(tk < duration - 1e-12, v, 0.0)
    return Segment(pos, speed, np.zeros(1), duration)
