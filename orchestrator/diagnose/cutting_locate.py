"""Where cutting effects and force residuals sit: chatter in the spectrum, windows, lines, evidence.

* :func:`chatter_peaks` — per cut, the largest spectral peak of the
  measured force that is not a spindle harmonic (tooth passing and runout
  are harmonics of the spindle frequency): chatter when it stands
  :data:`CHATTER_SNR` above the spectrum's floor, holds
  :data:`CHATTER_SHARE` of the non-harmonic power, and is absent in the air
  (a vibration that is there while nothing cuts is not regenerative: it is
  left to ``unexplained``);
* :func:`windows_where` — time windows where an effect's contribution
  exceeds two noise floors, and the program lines there;
* :func:`force_unexplained` — what the final model leaves above
  :data:`.core.UNEXPLAINED_SIGMA` noise floors (smoothed), with its dominant
  frequency.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .cutting import CuttingData
from .locate import MAX_WINDOWS, dominant_frequency, moving_rms, residual_windows

#: Peak band power over the median non-harmonic bin power (x band width) for chatter.
CHATTER_SNR = 30.0
#: Least share of the non-harmonic power (above the floor) in the peak's band.
CHATTER_SHARE = 0.25
#: Distance to a spindle harmonic below which a peak is forced vibration: max(Hz, fraction of f).
HARMONIC_TOL_HZ = 3.0
HARMONIC_TOL_REL = 0.005
#: ... and at least this many spectral bins (the Hann window's skirt around a strong harmonic).
HARMONIC_BINS = 6
#: Lowest frequency considered for chatter, Hz.
CHATTER_MIN_HZ = 150.0


@dataclass
class ChatterPeak:
    """A non-harmonic spectral peak of one cut.

    Attributes
    ----------
    cut : int
    frequency : float
        Hz.
    amplitude : float
        Amplitude of the force oscillation, N (fx and fy combined).
    snr : float
        Band power over the floor.
    growth : float
        Amplitude in the second half of the cut over the first half.
    resolution : float
        Frequency resolution of the cut's spectrum, Hz.
    spindle_hz : float
    in_air : bool
        Whether the same peak is in the air (then it is not chatter).
    """

    cut: int
    frequency: float
    amplitude: float
    snr: float
    growth: float
    resolution: float
    spindle_hz: float
    in_air: bool


def _spectrum(t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """One-sided power spectrum of a uniformly resampled, detrended, Hann-windowed signal; (f, p, dt)."""
    dt = float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1], dt)
    s = np.interp(grid, t, y)
    s = s - np.polyval(np.polyfit(grid - grid[0], s, 1), grid - grid[0])
    w = np.hanning(s.size)
    p = np.abs(np.fft.rfft(s * w)) ** 2 / max(float(np.sum(w * w)), 1e-12)
    return np.fft.rfftfreq(s.size, dt), p, dt


def _harmonic(f: np.ndarray, f_spindle: float) -> np.ndarray:
    """Bins near a spindle harmonic: within max(HARMONIC_TOL_HZ, HARMONIC_TOL_REL f, HARMONIC_BINS bins)."""
    if f_spindle <= 0:
        return np.zeros(f.size, bool)
    df = float(f[1] - f[0]) if f.size > 1 else 0.0
    tol = np.maximum(np.maximum(HARMONIC_TOL_HZ, HARMONIC_TOL_REL * f), HARMONIC_BINS * df)
    return np.abs(f - np.round(f / f_spindle) * f_spindle) <= tol


def _band_amplitude(t: np.ndarray, y: np.ndarray, f0: float) -> float:
    """Amplitude of the component at ``f0`` (least squares sine + cosine)."""
    x = np.column_stack([np.sin(2 * np.pi * f0 * t), np.cos(2 * np.pi * f0 * t), np.ones_like(t)])
    c, *_ = np.linalg.lstsq(x, y, rcond=None)
    return float(np.hypot(c[0], c[1]))


def chatter_peaks(data: CuttingData) -> list[ChatterPeak]:
    """Chatter candidates per cut (see module docstring)."""
    t, f = data.t, data.measured
    inside = data.cuts.mask(t.size)
    out = []
    air_spec = None
    air = np.flatnonzero(~inside & np.isfinite(f).all(axis=1))
    if air.size > 256:
        fa, pa, _ = _spectrum(t[air], f[air, 0])
        fb, pb, _ = _spectrum(t[air], f[air, 1])
        air_spec = (fa, pa + pb)
    for s, (i0, i1) in enumerate(data.cuts.bounds):
        if i1 - i0 < 256:
            continue
        tt = t[i0:i1]
        f_sp = float(np.mean(data.inputs.omega[i0:i1])) / (2 * math.pi)
        fx_, px, _ = _spectrum(tt, f[i0:i1, 0])
        _, py, _ = _spectrum(tt, f[i0:i1, 1])
        p = px + py
        ok = (fx_ >= CHATTER_MIN_HZ) & ~_harmonic(fx_, f_sp)
        if not ok.any():
            continue
        floor = float(np.median(p[ok]))
        cand = np.where(ok, p, 0.0)
        k = int(np.argmax(cand))
        band = float(cand[max(k - 2, 0):k + 3].sum())
        excess = float(np.sum(np.maximum(cand - floor, 0.0)))
        snr = band / max(5 * floor, 1e-300)
        share = (band - 5 * floor) / max(excess, 1e-300)
        if snr < CHATTER_SNR or share < CHATTER_SHARE:
            continue
        f0 = float(fx_[k])
        # refine the frequency by a parabola through the log power
        if 0 < k < p.size - 1 and cand[k - 1] > 0 and cand[k + 1] > 0:
            lm, l0, lp = np.log(cand[k - 1]), np.log(cand[k]), np.log(cand[k + 1])
            den = lm - 2 * l0 + lp
            if den < 0:
                f0 += float(0.5 * (lm - lp) / den) * float(fx_[1] - fx_[0])
        half = (i0 + i1) // 2
        amp = [math.hypot(_band_amplitude(t[a:b], f[a:b, 0], f0), _band_amplitude(t[a:b], f[a:b, 1], f0))
               for a, b in ((i0, half), (half, i1))]
        in_air = False
        if air_spec is not None:
            fa, pa = air_spec
            j = int(np.argmin(np.abs(fa - f0)))
            floor_air = float(np.median(pa[fa >= CHATTER_MIN_HZ]))
            in_air = float(pa[max(j - 2, 0):j + 3].sum()) > CHATTER_SNR * 5 * floor_air
        out.append(ChatterPeak(s, round(f0, 2), float(np.mean(amp)), snr, amp[1] / max(amp[0], 1e-9),
                               float(fx_[1] - fx_[0]), f_sp, in_air))
    return out


def windows_where(data: CuttingData, rows: np.ndarray, contrib_x: np.ndarray, contrib_y: np.ndarray,
                  lines_of) -> tuple[list[list[float]], list[int]]:
    """Windows where an effect's contribution exceeds two noise floors, and the lines there."""
    mag = np.hypot(contrib_x[rows], contrib_y[rows])
    windows = residual_windows(data.t[rows], mag > 2.0 * data.sigma, gap_s=0.1, min_s=0.02)
    return windows[:MAX_WINDOWS], lines_of(windows)


def force_unexplained(data: CuttingData, rows: np.ndarray, rx: np.ndarray, ry: np.ndarray, threshold: float,
                      lines_of) -> list[dict]:
    """Force residual above ``threshold`` noise floors (moving RMS), per channel, with its dominant frequency."""
    out = []
    t = data.t[rows]
    for name, r in (("fx_N", rx), ("fy_N", ry)):
        smooth = moving_rms(t, r)
        windows = residual_windows(t, smooth > threshold * data.sigma, gap_s=0.1, min_s=0.03)
        if not windows:
            continue
        inside = np.zeros(t.size, bool)
        for w0, w1 in windows:
            inside |= (t >= w0) & (t <= w1)
        share = float(np.mean(data.cuts.mask(data.t.size)[rows][inside]))
        event = "while cutting" if share > 0.8 else ("tool in the air" if share < 0.2 else
                                                     "in the air and while cutting (not the cutting process)")
        out.append({"channels": [name],
                    "where": {"time_s": windows[:MAX_WINDOWS], "lines": lines_of(windows), "event": event,
                              "frequency_Hz": dominant_frequency(t, r, share=0.2)},
                    "rms": round(float(np.sqrt(np.mean(r[inside] ** 2))), 4)})
    return out


def angle_of(data: CuttingData, phase_rad: float = 0.0) -> np.ndarray:
    """Spindle angle of tooth 0 at each force sample in the replay's convention, rad in [0, 2 pi)."""
    steps = np.concatenate([[0.0], np.cumsum(data.step_omega * np.diff(data.t))])
    return np.mod(data.theta0 + phase_rad + steps, 2 * math.pi)


def harmonic_ratio(t: np.ndarray, y: np.ndarray, f_tooth: float) -> float:
    """Amplitude of the 2nd over the 1st tooth-passing harmonic (a helix smooths the pulse: lower)."""
    a1 = _band_amplitude(t, y, f_tooth)
    a2 = _band_amplitude(t, y, 2 * f_tooth)
    return a2 / max(a1, 1e-12)
