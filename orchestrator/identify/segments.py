"""Automatic detection of constant-velocity segments in a recording.

A friction (Stribeck) point is the mean driving force over a window in which
an axis moves at constant velocity: there the drive force equals the friction
force (Sim & Lee 2023, Section 2.2). The windows are found in the recording
itself, without knowing the program:

1. axis velocity from the reference position ``{a}_ref_mm`` when recorded
   (noise-free controller output), else from the actual position ``{a}_mm``,
   as a centred difference over ``smooth_s`` (uneven sampling is fine);
2. *moving runs*: contiguous samples moving in one direction faster than
   ``v_floor``;
3. in each run the cruise speed is the 95th percentile of ``|v|``; the
   *plateau* is the longest stretch within ``rel_tol`` of it;
4. transients are trimmed: ``settle_s`` after the plateau starts (position
   and velocity loops settling, integrator taking up the friction) and
   ``end_trim_s`` before it ends;
5. in the remaining window the velocity is the slope of a straight line
   fitted to the **actual** position, the force is the mean current command
   times ``kt 2 pi / Lb``.
"""
from __future__ import annotations

from dataclasses import dataclass, asdict

import numpy as np

from ..recording import Recording
from .errors import IdentificationError


@dataclass(frozen=True)
class Segment:
    """One constant-velocity window of one axis.

    Attributes
    ----------
    axis : str
        ``"x"``, ``"y"`` or ``"z"``.
    direction : int
        +1 or -1.
    t_start, t_end : float
        Window in recording time, s.
    velocity : float
        Mean actual velocity (signed), m/s.
    force : float
        Mean driving force ``Atc kt 2 pi / Lb`` (signed), N.
    force_std : float
        Sample standard deviation of the force in the window, N.
    samples : int
        Samples in the window.
    source : str
        Recording file.
    """

    axis: str
    direction: int
    t_start: float
    t_end: float
    velocity: float
    force: float
    force_std: float
    samples: int
    source: str

    def to_dict(self) -> dict:
        """Plain dict (JSON-ready)."""
        return asdict(self)


@dataclass(frozen=True)
class SegmentSettings:
    """Tuning of :func:`find_segments`.

    Attributes
    ----------
    smooth_s : float
        Window of the centred velocity difference, s (doubled when the
        velocity comes from the actual position).
    v_floor_mm_s : float
        Slowest speed counted as motion, mm/s.
    rel_tol : float
        Plateau: ``| |v| - v_cruise | <= rel_tol v_cruise + abs_tol``.
    abs_tol_mm_s : float
        Absolute part of the plateau tolerance, mm/s.
    settle_s : float
        Trimmed after the plateau starts, s.
    end_trim_s : float
        Trimmed before the plateau ends, s.
    min_window_s : float
        Shortest window kept after trimming, s.
    min_samples : int
        Fewest samples kept in a window.
    """

    smooth_s: float = 0.01
    v_floor_mm_s: float = 0.05
    rel_tol: float = 0.01
    abs_tol_mm_s: float = 0.01
    settle_s: float = 0.15
    end_trim_s: float = 0.02
    min_window_s: float = 0.05
    min_samples: int = 5


def centred_velocity(t: np.ndarray, x: np.ndarray, window: float) -> np.ndarray:
    """Velocity ``(x(t + w/2) - x(t - w/2)) / w`` with linear interpolation, clipped at the ends.

    Parameters
    ----------
    t : ndarray, shape (n,)
        Strictly increasing times, s.
    x : ndarray, shape (n,)
        Positions (any unit).
    window : float
        ``w``, s.

    Returns
    -------
    ndarray, shape (n,)
        Velocity in units of ``x`` per s.
    """
    lo = np.clip(t - 0.5 * window, t[0], t[-1])
    hi = np.clip(t + 0.5 * window, t[0], t[-1])
    span = hi - lo
    span = np.where(span > 0.0, span, np.inf)
    return (np.interp(hi, t, x) - np.interp(lo, t, x)) / span


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Half-open index ranges ``[i, j)`` of the True runs of ``mask``."""
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _densest(speed: np.ndarray, rel_tol: float, abs_tol: float) -> float:
    """The median of the most populated band ``|speed - c| <= rel_tol c + abs_tol`` over candidates ``c``."""
    order = np.sort(speed)
    cand = np.quantile(order, np.linspace(0.0, 1.0, min(order.size, 201)))
    tol = rel_tol * cand + abs_tol
    count = np.searchsorted(order, cand + tol, side="right") - np.searchsorted(order, cand - tol, side="left")
    c = float(cand[int(np.argmax(count))])
    band = order[np.abs(order - c) <= rel_tol * c + abs_tol]
    return float(np.median(band))


def _bridge(mask: np.ndarray, t: np.ndarray, width: float) -> np.ndarray:
    """``mask`` with its False gaps shorter than ``width`` [s] between two True runs set True."""
    out = mask.copy()
    runs = _runs(mask)
    for (_, end), (start, _) in zip(runs[:-1], runs[1:]):
        if t[start] - t[end - 1] <= width:
            out[end:start] = True
    return out


#: A sample of a window farther than this many robust standard deviations from the rest is a logger glitch.
OUTLIER_SIGMAS = 8.0


def _inliers(t: np.ndarray, pos: np.ndarray, cur: np.ndarray) -> np.ndarray:
    """Samples of a constant-velocity window without isolated glitches (a current spike, a position jump).

    A logger's bad sample (50 A in one row of a 0.3 s window moves its mean force by 100 N and more) lies
    far outside the scatter of the others: more than :data:`OUTLIER_SIGMAS` robust standard deviations
    (1.4826 MAD, at least 0.5 % of the median current and 1 um) from the median current or from the
    straight line through the positions. Such samples are left out; the rest (constant velocity: the
    current is constant) is kept.
    """
    keep = np.ones(t.size, dtype=bool)
    if t.size < 5:
        return keep
    dev = cur - np.median(cur)
    scale = max(1.4826 * float(np.median(np.abs(dev))), 0.005 * abs(float(np.median(cur))), 1e-6)
    keep &= np.abs(dev) <= OUTLIER_SIGMAS * scale
    tc = t - t.mean()
    line = np.polyfit(tc[keep], pos[keep], 1)
    res = pos - np.polyval(line, tc)
    scale = max(1.4826 * float(np.median(np.abs(res[keep] - np.median(res[keep])))), 1e-3)
    keep &= np.abs(res) <= OUTLIER_SIGMAS * scale
    return keep


def find_segments(
    recording: Recording,
    axis: str,
    force_per_amp: float,
    settings: SegmentSettings | None = None,
) -> list[Segment]:
    """Constant-velocity windows of one axis with their velocity and driving force.

    Parameters
    ----------
    recording : Recording
        Needs ``t_s``, ``{axis}_mm`` and ``{axis}_tcmd_A``; uses
        ``{axis}_ref_mm`` for detection when present.
    axis : str
        ``"x"``, ``"y"`` or ``"z"``.
    force_per_amp : float
        ``kt 2 pi / Lb``, N/A.
    settings : SegmentSettings, optional

    Returns
    -------
    list of Segment
        In time order; empty when the axis never moves at constant speed.
    """
    s = settings or SegmentSettings()
    t = np.asarray(recording.t, dtype=float)
    pos = np.asarray(recording[f"{axis}_mm"], dtype=float)
    cur = np.asarray(recording[f"{axis}_tcmd_A"], dtype=float)
    ref_col = f"{axis}_ref_mm"
    if ref_col in recording and np.all(np.isfinite(recording[ref_col])):
        detect, window, abs_tol = np.asarray(recording[ref_col], dtype=float), s.smooth_s, s.abs_tol_mm_s
        exact = True
    else:
        exact = False
        # actual position: quantised and noisy, smooth more and widen the tolerance
        detect, window, abs_tol = pos, 5.0 * s.smooth_s, 4.0 * s.abs_tol_mm_s
    v = centred_velocity(t, detect, window)  # mm/s
    moving = np.abs(v) > s.v_floor_mm_s
    out: list[Segment] = []
    for sign in (1, -1):
        for i, j in _runs(moving & (np.sign(v) == sign)):
            speed = np.abs(v[i:j])
            cruise = float(np.percentile(speed, 95))
            if not exact:
                # the actual velocity overshoots at slow speeds (0.28 mm/s for 10 mm/min) and is noisy: its 95th
                # percentile is not the cruise speed; take the speed the axis holds longest (the densest band
                # of the tolerance's width), and bridge dips shorter than the window (one quantisation step of
                # a 1 um encoder at 10 mm/min broke every slow plateau)
                cruise = _densest(speed, s.rel_tol, abs_tol)
            flat = np.abs(speed - cruise) <= s.rel_tol * cruise + abs_tol
            if not exact:
                flat = _bridge(flat, t[i:j], window)
            runs = _runs(flat)
            if not runs:
                continue
            a, b = max(runs, key=lambda r: t[i + r[1] - 1] - t[i + r[0]])
            # from the actual position, the flat stretch starts once the axis has settled (at 10 mm/min it
            # overshoots for 0.1 s after the command's plateau begins): a third of the settling time is left
            t0 = t[i + a] + (s.settle_s if exact else s.settle_s / 3.0) + 0.5 * window
            t1 = t[i + b - 1] - s.end_trim_s - 0.5 * window
            sel = (t >= t0) & (t <= t1)
            n = int(sel.sum())
            if t1 - t0 < s.min_window_s or n < s.min_samples:
                continue
            keep = _inliers(t[sel], pos[sel], cur[sel])
            if int(keep.sum()) < s.min_samples:
                continue
            tw = t[sel][keep]
            n = tw.size
            slope = np.polyfit(tw - tw.mean(), pos[sel][keep], 1)[0]  # mm/s
            force = cur[sel][keep] * force_per_amp
            out.append(Segment(
                axis=axis, direction=sign, t_start=float(tw[0]), t_end=float(tw[-1]),
                velocity=float(slope) * 1e-3, force=float(force.mean()),
                force_std=float(force.std(ddof=1)) if n > 1 else 0.0, samples=n, source=str(recording.source),
            ))
    out.sort(key=lambda seg: seg.t_start)
    return out


def require_segments(segments: list[Segment], axis: str, source: str, settings: SegmentSettings) -> None:
    """Raise when an axis has no usable constant-velocity window in both directions."""
    dirs = {seg.direction for seg in segments}
    if not segments:
        raise IdentificationError(
            f"{source}: no constant-velocity segment found for axis {axis}; expected reciprocating runs "
            f"(`cnctwin experiment friction`) with constant-velocity windows longer than "
            f"{s_total(settings):.2f} s at speeds above {settings.v_floor_mm_s} mm/s"
        )
    missing = {1: "positive", -1: "negative"}
    lacking = [missing[d] for d in (1, -1) if d not in dirs]
    if lacking:
        raise IdentificationError(
            f"{source}: axis {axis} has constant-velocity segments only in one direction; "
            f"no {lacking[0]} segment (friction is identified per direction: run the axis both ways)"
        )


def s_total(settings: SegmentSettings) -> float:
    """Shortest plateau that survives trimming, s."""
    return settings.settle_s + settings.end_trim_s + settings.min_window_s + settings.smooth_s
