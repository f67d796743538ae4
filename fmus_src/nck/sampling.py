"""Reading the planned samples (shared by the NC kernel component and the compiled master loop, so both read
the plan identically).

The plan is stored ragged (:class:`.batch_plan.BatchPlan`): member ``b`` owns the global samples
``offset[b] .. offset[b] + length[b]`` (the last one a sentinel holding the "after the end" values), the
positions are stored per sample and the piecewise-constant quantities (feed, spindle reference and speed,
line, tool) as runs starting at global sample ``run_key[i]``.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit, njit_inline


@njit_inline
def sample_position(kf: float, n_samples: int) -> tuple[int, int, float]:
    """Samples around the fractional index ``kf`` of a plan with ``n_samples`` samples per member.

    ``kf`` is clamped to ``[0, n_samples - 1]``; fractions below 1e-9 count as 0 (a
    sample instant read by a step end that rounding put just past it).

    Parameters
    ----------
    kf : float
        Fractional sample index, ``(t - t0) / period`` [1].
    n_samples : int
        Samples per member of the plan (the longest member's count).

    Returns
    -------
    k0, k1 : int
        The sample at or before ``kf`` and the next one (``k0`` at the end of the plan).
    frac : float
        Linear interpolation weight of ``k1`` in ``[0, 1)``.
    """
    kf = min(max(kf, 0.0), n_samples - 1.0)
    k0 = int(math.floor(kf + 1e-9))
    frac = kf - k0
    if frac < 1e-9:
        frac = 0.0
    k1 = min(k0 + 1, n_samples - 1)
    return k0, k1, frac


@njit_inline
def find_run(run_key: np.ndarray, g: int) -> int:
    """Index of the run holding global sample ``g``: the last ``i`` with ``run_key[i] <= g``.

    Parameters
    ----------
    run_key : ndarray of int64, shape (R,)
        Strictly increasing first global sample of each run.
    g : int
        Global sample index (``>= run_key[0]``).
    """
    lo = 0
    hi = run_key.shape[0]
    while lo < hi:
        mid = (lo + hi) // 2
        if run_key[mid] <= g:
            lo = mid + 1
        else:
            hi = mid
    return lo - 1


@njit_inline
def find_run_from(run_key: np.ndarray, g: int, i: int) -> int:
    """:func:`find_run` starting from a guess ``i`` (the run of an earlier, nearby sample): the same index.

    When ``run_key[i] <= g`` the search walks forward over at most 8 runs and returns the last ``i``
    with ``run_key[i] <= g``; otherwise (a guess past ``g``, out of range, or more than 8 runs to walk)
    it is :func:`find_run`'s binary search. A sample read step by step moves forward a run at a time, so
    the walk stops after one or two comparisons.

    Parameters
    ----------
    run_key : ndarray of int64, shape (R,)
        Strictly increasing first global sample of each run.
    g : int
        Global sample index (``>= run_key[0]``).
    i : int
        Guess (any integer).
    """
    n = run_key.shape[0]
    if i < 0 or i >= n or run_key[i] > g:
        return find_run(run_key, g)
    for _ in range(8):
        if i + 1 < n and run_key[i + 1] <= g:
            i += 1
        else:
            return i
    return find_run(run_key, g)


@njit_inline
def read_member(b: int, k0: int, k1: int, frac: float, position: np.ndarray, offset: np.ndarray,
                length: np.ndarray, run_key: np.ndarray, run_feed: np.ndarray, run_sref: np.ndarray,
                run_sact: np.ndarray, run_line: np.ndarray, run_tool: np.ndarray
                ) -> tuple[float, float, float, float, float, float, int, int]:
    """Outputs of member ``b`` between samples ``k0`` and ``k1`` (weight ``frac`` of ``k1``).

    A sample past the member's end reads its sentinel (position, spindle, line and tool held, feed 0),
    exactly what a plan padded to the longest member held there.

    Returns
    -------
    x, y, z : float
        Reference position, m.
    feed, spindle_ref, spindle_speed : float
        m/s, rad/s, rad/s (``spindle_ref`` at ``k0``, not interpolated).
    line, tool : int
        At ``k0``.
    """
    g0 = offset[b] + min(k0, length[b])
    return read_run(b, g0, find_run(run_key, g0), k1, frac, position, offset, length, run_key, run_feed,
                    run_sref, run_sact, run_line, run_tool)


@njit_inline
def read_run(b: int, g0: int, i0: int, k1: int, frac: float, position: np.ndarray, offset: np.ndarray,
             length: np.ndarray, run_key: np.ndarray, run_feed: np.ndarray, run_sref: np.ndarray,
             run_sact: np.ndarray, run_line: np.ndarray, run_tool: np.ndarray
             ) -> tuple[float, float, float, float, float, float, int, int]:
    """:func:`read_member` given its global sample ``g0`` (``offset[b] + min(k0, length[b])``) and that
    sample's run ``i0`` (:func:`find_run`, or :func:`find_run_from` with a cursor); same outputs."""
    px = position[g0, 0]
    py = position[g0, 1]
    pz = position[g0, 2]
    fd = run_feed[i0]
    sa = run_sact[i0]
    if frac > 0.0:
        g1 = offset[b] + min(k1, length[b])
        i1 = i0
        if i0 + 1 < run_key.shape[0] and run_key[i0 + 1] <= g1:
            i1 = i0 + 1
        px = px + frac * (position[g1, 0] - px)
        py = py + frac * (position[g1, 1] - py)
        pz = pz + frac * (position[g1, 2] - pz)
        fd = fd + frac * (run_feed[i1] - fd)
        sa = sa + frac * (run_sact[i1] - sa)
    return px, py, pz, fd, run_sref[i0], sa, run_line[i0], run_tool[i0]


@njit
def read_plan(kf: float, n_samples: int, position: np.ndarray, offset: np.ndarray, length: np.ndarray,
              run_key: np.ndarray, run_feed: np.ndarray, run_sref: np.ndarray, run_sact: np.ndarray,
              run_line: np.ndarray, run_tool: np.ndarray, done_index: np.ndarray, x: np.ndarray, y: np.ndarray,
              z: np.ndarray, feed: np.ndarray, sref: np.ndarray, sact: np.ndarray, line: np.ndarray,
              tool: np.ndarray, done: np.ndarray) -> None:
    """Every member's outputs at fractional sample ``kf``, written in place into ``x .. done`` (shape (B,)).

    Parameters
    ----------
    kf : float
        Fractional sample index, ``(t - t0) / period`` [1].
    n_samples : int
        The longest member's sample count (``kf`` is clamped to it, as :func:`sample_position` does).
    position, offset, length, run_key, run_feed, run_sref, run_sact, run_line, run_tool, done_index : ndarray
        The arrays of :class:`.batch_plan.BatchPlan` (see :func:`read_member`).
    x, y, z, feed, sref, sact : ndarray of float64, shape (B,)
        m, m, m, m/s, rad/s, rad/s.
    line, tool : ndarray of int64, shape (B,)
    done : ndarray of bool, shape (B,)
        ``k0 >= done_index``.
    """
    k0, k1, frac = sample_position(kf, n_samples)
    for b in range(done_index.shape[0]):
        px, py, pz, fd, sr, sa, ln, tl = read_member(b, k0, k1, frac, position, offset, length, run_key, run_feed,
                                                     run_sref, run_sact, run_line, run_tool)
        x[b] = px
        y[b] = py
        z[b] = pz
        feed[b] = fd
        sref[b] = sr
        sact[b] = sa
        line[b] = ln
        tool[b] = tl
        done[b] = k0 >= done_index[b]
