"""Where cutting effects and force residuals sit: chatter in the spectrum, windows, lines, evidence.

* :func:`chatter_peaks` — per cut, the largest spectral peak of the
  measured force that is not a spindle harmonic (tooth passing and runout
  are harmonics of the spindle frequency): chatter when it stands
  :data:`CHATTER_SNR` above the spectrum's floor, holds
  :data:`CHATTER_SHARE` of the non-harmonic power, and is absent in the air
  (a vibration that is there while nothing cuts is not regenerative: it is
  left to ``unexplained``). A peak that is a spindle harmonic folded by the
  actual sampling (:func:`alias_frequency`: at 1.7 ms the 400 Hz tooth
  harmonic of a 2-flute tool at 6000 rpm lands at 188.2 Hz, off the 100 Hz
  grid) is forced, not chatter: it follows the sampled spindle angle (fitting
  that harmonic in the angle leaves < :data:`FORCED_LEFT` of it), or the
  twin's own forces at the same samples carry it (:func:`chatter_search`); so
  is a peak off every alias that the twin's own forces carry
  (:data:`FORCED_TWIN` of its band power: a short cut's modulation);
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
#: Highest spindle harmonic whose alias is considered, Hz (a force pulse's harmonics above it are far below
#: any dynamometer's noise floor; without an anti-alias filter every lower one may fold onto the band).
FORCED_MAX_HZ = 20e3
#: Half width of a line in the Hann-windowed spectrum (main lobe), bins: a harmonic's alias within it of a peak
#: (plus the harmonic's spread with the spindle speed) may be that peak.
ALIAS_LOBE_BINS = 2.0
#: A peak is a forced harmonic's alias when fitting that harmonic in the spindle angle and removing it leaves
#: less than this share of the peak's band power (or less than the chatter threshold). A forced line leaves
#: its amplitude's change over the cut (entry, exit: a few %); a chatter vibration 0.9 Hz from an alias, growing
#: 18-fold within a 1 s cut, left 52 % (2-flute slot, 1.7 ms).
FORCED_LEFT = 0.25
#: Share of a peak's band power that, in the twin's own forces at the same samples, makes the peak forced.
FORCED_TWIN = 0.25
#: Orders whose fit gains this share of the best one's are taken as the same alias (the lowest is named).
ALIKE = 0.95
#: Most peaks set aside as forced aliases in one cut before the search gives up on it.
MAX_FORCED_ALIASES = 8


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
    spacing : float
        Median sample spacing of the cut, s (the spectrum reaches ``1 / (2 spacing)``).
    """

    cut: int
    frequency: float
    amplitude: float
    snr: float
    growth: float
    resolution: float
    spindle_hz: float
    in_air: bool
    spacing: float = float("nan")


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


def alias_frequency(f: np.ndarray | float, spacing: float) -> np.ndarray | float:
    """Where a component at ``f`` appears in the spectrum of samples ``spacing`` apart.

    The alias is ``|f - k / T|`` for the ``k`` that brings it into ``[0, 1 / (2 T)]`` (``T`` the spacing): the
    frequency folded at the Nyquist frequency.

    Parameters
    ----------
    f : float or ndarray
        Frequency of the component, Hz (>= 0).
    spacing : float
        Sample spacing ``T``, s (> 0).

    Returns
    -------
    float or ndarray
        The alias, Hz, in ``[0, 1 / (2 T)]``.
    """
    fs = 1.0 / float(spacing)
    r = np.mod(np.asarray(f, float), fs)
    out = np.minimum(r, fs - r)
    return float(out) if np.ndim(out) == 0 else out


def forced_orders(f0: float, f_spindle: float, spacing: float, tol_hz: float, spread_hz: float = 0.0,
                  f_max: float = FORCED_MAX_HZ) -> np.ndarray:
    """Spindle-harmonic orders ``m`` whose alias through the sampling lies within reach of ``f0``.

    Parameters
    ----------
    f0 : float
        Frequency of a spectral peak, Hz.
    f_spindle : float
        Mean spindle frequency over the samples, Hz.
    spacing : float
        Sample spacing, s.
    tol_hz : float
        Half width of a line in the spectrum (the window's main lobe), Hz.
    spread_hz : float
        Half range of the spindle frequency over the samples, Hz: harmonic ``m`` spreads over ``m`` times it
        (and so does its alias).
    f_max : float
        Highest harmonic considered, Hz.

    Returns
    -------
    ndarray of int
        Orders ``m >= 1`` (tooth passing: multiples of the flute count; runout: every order).
    """
    if f_spindle <= 0 or spacing <= 0:
        return np.zeros(0, np.int64)
    m = np.arange(1, max(int(f_max / f_spindle), 1) + 1)
    a = alias_frequency(m * f_spindle, spacing)
    return m[np.abs(a - f0) <= tol_hz + m * spread_hz]


def _locked_fit(t: np.ndarray, y: np.ndarray, theta: np.ndarray, order: int) -> tuple[np.ndarray, float]:
    """Least-squares fit of spindle harmonic ``order`` (in the spindle angle) with an offset and a trend.

    Returns the harmonic's part of ``y`` (N, shape of ``y``) and the fall of the residual sum of squares.
    """
    base = np.column_stack([np.ones_like(t), t - t.mean()])
    full = np.column_stack([base, np.cos(order * theta), np.sin(order * theta)])
    c0, *_ = np.linalg.lstsq(base, y, rcond=None)
    c1, *_ = np.linalg.lstsq(full, y, rcond=None)
    r0, r1 = y - base @ c0, y - full @ c1
    return full[:, 2:] @ c1[2:], float(np.sum(r0 * r0) - np.sum(r1 * r1))


def forced_share(t: np.ndarray, y: np.ndarray, theta: np.ndarray, f0: float, order: int) -> float:
    """How much of the component at ``f0`` follows the spindle angle as harmonic ``order``.

    A spindle harmonic ``m`` is locked to the spindle angle, ``cos(m theta)``, wherever the sampling folds it;
    a chatter vibration is not. The share is the fall of the residual sum of squares when harmonic ``order``
    in the sampled spindle angle is fitted, over its fall when a sinusoid at ``f0`` in time is (both with an
    offset and a trend, summed over the columns of ``y``).

    Parameters
    ----------
    t : ndarray
        Sample times, s.
    y : ndarray, shape (n,) or (n, c)
        Force samples, N.
    theta : ndarray
        Spindle angle at the samples, rad.
    f0 : float
        Frequency of the peak, Hz.
    order : int
        Harmonic order (:func:`forced_orders`).

    Returns
    -------
    float
        About 1 for that harmonic's alias, well below 1 for a vibration at its own frequency.
    """
    y = np.asarray(y, float).reshape(t.size, -1)
    _, locked = _locked_fit(t, y, theta, order)
    base = np.column_stack([np.ones_like(t), t - t.mean()])
    tim = np.column_stack([base, np.cos(2 * np.pi * f0 * t), np.sin(2 * np.pi * f0 * t)])
    c0, *_ = np.linalg.lstsq(base, y, rcond=None)
    c1, *_ = np.linalg.lstsq(tim, y, rcond=None)
    free = float(np.sum((y - base @ c0) ** 2) - np.sum((y - tim @ c1) ** 2))
    return locked / max(free, 1e-300)


@dataclass
class ForcedAlias:
    """A spectral peak of a cut that is a spindle harmonic folded by the sampling (not chatter).

    Attributes
    ----------
    cut : int
    frequency : float
        Where the peak is, Hz.
    order : int
        The spindle harmonic ``m`` it is (the one explaining most of it); 0: no alias, but the twin's own
        forces at the same samples carry it.
    harmonic_hz : float
        ``m`` times the spindle frequency, Hz: where the forced vibration really is.
    spacing : float
        Median sample spacing of the cut, s.
    share : float
        :func:`forced_share` of the peak (order 0: the twin's share of its band power).
    snr : float
        Band power over the floor.
    """

    cut: int
    frequency: float
    order: int
    harmonic_hz: float
    spacing: float
    share: float
    snr: float

    def text(self, flutes: int) -> str:
        """One sentence for the log and the evidence."""
        if self.order == 0:
            return (f"cut {self.cut + 1}: the peak at {self.frequency:.1f} Hz is off the spindle harmonics and "
                    f"their aliases, but the machine file's own forces at the same samples carry {self.share:.0%} "
                    "of its band power: forced vibration (the cut's entry and exit), not chatter")
        what = (f"tooth-passing harmonic {self.order // flutes}" if flutes > 0 and self.order % flutes == 0
                else f"spindle harmonic {self.order}")
        return (f"cut {self.cut + 1}: the peak at {self.frequency:.1f} Hz is the {what} ({self.harmonic_hz:.0f} Hz) "
                f"folded by the {1e3 * self.spacing:.3g} ms sampling; {self.share:.0%} of it follows the spindle "
                "angle: forced vibration, not chatter")


def _peak_frequency(f: np.ndarray, cand: np.ndarray, k: int) -> float:
    """Frequency of bin ``k`` refined by a parabola through the log power, Hz."""
    f0 = float(f[k])
    if 0 < k < cand.size - 1 and cand[k - 1] > 0 and cand[k + 1] > 0:
        lm, l0, lp = np.log(cand[k - 1]), np.log(cand[k]), np.log(cand[k + 1])
        den = lm - 2 * l0 + lp
        if den < 0:
            f0 += float(0.5 * (lm - lp) / den) * float(f[1] - f[0])
    return f0


def chatter_search(data: CuttingData, twin: np.ndarray | None = None) -> tuple[list[ChatterPeak], list[ForcedAlias]]:
    """Chatter candidates per cut and the forced harmonics' aliases set aside (see module docstring).

    Parameters
    ----------
    data : CuttingData
        The aligned force recording (its spindle angle at each sample from :func:`angle_of`).
    twin : ndarray, shape (n, 2), optional
        The twin's forces (fx, fy) at the force samples, N: its forced vibration folded by the same sampling,
        amplitude changes at entries and exits included. A peak the twin has at least :data:`FORCED_TWIN` of
        is forced too.

    Returns
    -------
    peaks : list of ChatterPeak
        At most one a cut: the largest peak off the spindle harmonics and off their aliases.
    aliases : list of ForcedAlias
        Peaks above the chatter threshold that the sampling folded from a spindle harmonic.
    """
    t, f = data.t, data.measured
    inside = data.cuts.mask(t.size)
    theta = angle_of(data)
    out: list[ChatterPeak] = []
    aliases: list[ForcedAlias] = []
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
        omega = data.inputs.omega[i0:i1]
        f_sp = float(np.mean(omega)) / (2 * math.pi)
        spread = 2.0 * float(np.std(omega)) / (2 * math.pi)  # the speed's wander (droop, noise), Hz
        fx_, px, dt = _spectrum(tt, f[i0:i1, 0])
        _, py, _ = _spectrum(tt, f[i0:i1, 1])
        p = px + py
        p_twin = None
        if twin is not None:
            p_twin = _spectrum(tt, twin[i0:i1, 0])[1] + _spectrum(tt, twin[i0:i1, 1])[1]
        df = float(fx_[1] - fx_[0])
        ok = (fx_ >= CHATTER_MIN_HZ) & ~_harmonic(fx_, f_sp)
        found = None
        for _ in range(MAX_FORCED_ALIASES + 1):
            if not ok.any():
                break
            floor = float(np.median(p[ok]))
            cand = np.where(ok, p, 0.0)
            k = int(np.argmax(cand))
            band = float(cand[max(k - 2, 0):k + 3].sum())
            snr = band / max(5 * floor, 1e-300)
            if snr < CHATTER_SNR:
                break
            f0 = _peak_frequency(fx_, cand, k)
            orders = forced_orders(f0, f_sp, dt, ALIAS_LOBE_BINS * df, spread)
            forced = None
            if orders.size:
                # the order explaining most of the cut's force, removed: does the peak still stand out?
                gains = np.array([_locked_fit(tt, f[i0:i1], theta[i0:i1], int(m))[1] for m in orders])
                # orders the sampling cannot tell apart fit alike: name the lowest (the strongest harmonic)
                m = int(np.min(orders[gains >= ALIKE * np.max(gains)]))
                part, _ = _locked_fit(tt, f[i0:i1], theta[i0:i1], m)
                rest = f[i0:i1] - part
                _, rx, _ = _spectrum(tt, rest[:, 0])
                _, ry, _ = _spectrum(tt, rest[:, 1])
                left = float((rx + ry)[max(k - 2, 0):k + 3].sum()) / max(5 * floor, 1e-300)
                in_twin = (float(p_twin[max(k - 2, 0):k + 3].sum()) / max(band, 1e-300)
                           if p_twin is not None else 0.0)
                if left < CHATTER_SNR or left < FORCED_LEFT * snr or in_twin >= FORCED_TWIN:
                    forced = (m, forced_share(tt, f[i0:i1], theta[i0:i1], f0, m))
            elif p_twin is not None:
                # off every alias too, but in the twin's own forces at the same samples: a tooth harmonic
                # modulated by a short cut's entry and exit (its sidebands), forced; on a 1 kHz dynamometer a
                # 0.2 s contour cut showed one at 193.5 Hz, carried 1:1 by the twin, named chatter
                in_twin = float(p_twin[max(k - 2, 0):k + 3].sum()) / max(band, 1e-300)
                if in_twin >= FORCED_TWIN:
                    forced = (0, in_twin)
            if forced is None:
                found = (k, f0, band, floor, cand)
                break
            m, share = forced
            aliases.append(ForcedAlias(s, round(f0, 2), m, m * f_sp, dt, share, snr))
            ok &= np.abs(fx_ - f0) > HARMONIC_BINS * df
        if found is None:
            continue
        k, f0, band, floor, cand = found
        excess = float(np.sum(np.maximum(cand - floor, 0.0)))
        snr = band / max(5 * floor, 1e-300)
        share = (band - 5 * floor) / max(excess, 1e-300)
        if share < CHATTER_SHARE:
            continue
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
                               df, f_sp, in_air, dt))
    return out, aliases


def chatter_peaks(data: CuttingData) -> list[ChatterPeak]:
    """Chatter candidates per cut (:func:`chatter_search` without the aliases set aside)."""
    return chatter_search(data)[0]


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
