"""Whether the force samples can resolve a cutting effect whose signature is periodic in the spindle angle.

Runout repeats once per spindle revolution; the shape of the tooth pulse (what tells a helix and an edge
force from a ``Kt`` error) repeats once per tooth pitch; chatter is a vibration told from the tooth-passing
harmonics in the spectrum. The diagnosis compares the recorded forces with a replay of the twin *at the
sample instants*, so a sample spacing above the Nyquist interval of these signatures is not by itself a
problem (a 1 kHz dynamometer sees a 2-flute tool at 6000 rpm at 10 spindle angles per revolution; over many
revolutions it samples the whole pulse, as an equivalent-time oscilloscope does). What matters is where the
samples fall **in the spindle angle**:

* the angles ``theta_i mod P`` of the compared samples in the cuts (``P`` the signature's period: one
  revolution for runout, one tooth pitch for the pulse shape) must spread over the period. A logger whose
  spacing is a whole number of revolutions (10 ms at 6000 rpm) sees every sample at the same angle: the
  spindle harmonic aliases to a constant, which ``Kt`` already is, and no amount of samples separates them;
* the criterion is Nyquist *in the folded angle*: the largest gap between the sorted folded angles
  (around the circle) must be below half the period of the highest harmonic the signature needs,
  ``P / (2 K)``: ``K = 1`` for runout (the first spindle harmonic: the samples may not all lie within half a
  revolution), ``K = 2`` for the pulse shape (the 1st and 2nd tooth harmonics: more than 4 spread angles
  per pitch). It depends on the spacing and the spindle speed together, not on the spacing alone
  (:func:`largest_gap`);
* chatter is found in the spectrum of the samples of a cut, which must resolve the tooth-passing frequency
  (``f_tooth`` below the Nyquist frequency of the cut's median spacing), else the tooth harmonics fold over
  the whole band and a peak off them means nothing.

An effect that the sampling cannot resolve is not offered to the selection, and the report says so
(:func:`unresolved_effects`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .cutting import CuttingData
from .cutting_locate import angle_of

#: Effects whose signature is periodic in the spindle angle -> (period in tooth pitches or revolutions, K).
#: ``"revolution"``: period 2 pi; ``"pitch"``: 2 pi / flutes. ``K``: highest harmonic of that period needed.
ANGLE_SIGNATURES: dict[str, tuple[str, int]] = {
    "runout": ("revolution", 1),
    "helix_angle": ("pitch", 2),
    "edge_force": ("pitch", 2),
}
#: Fewest compared samples in the cuts for any angle criterion to be judged.
MIN_SAMPLES = 20
#: The largest gap must stay below this fraction of its limit: a logger at exactly half a revolution sees two
#: opposite angles, a gap of exactly the limit, which rounding must not turn into "resolved".
GAP_MARGIN = 0.99


@dataclass
class Resolution:
    """Whether the force sampling resolves one effect's signature.

    Attributes
    ----------
    effect : str
    resolved : bool
    gap_deg : float
        Largest gap between the folded sample angles, deg of the spindle angle (NaN for chatter).
    limit_deg : float
        The largest gap allowed, deg (for chatter: NaN).
    text : str
        One sentence for the log and the report.
    """

    effect: str
    resolved: bool
    gap_deg: float
    limit_deg: float
    text: str


def largest_gap(angles: np.ndarray, period: float) -> float:
    """Largest gap between ``angles`` folded into ``[0, period)``, around the circle, in the unit of ``angles``.

    Parameters
    ----------
    angles : ndarray
        Spindle angles of the samples, rad.
    period : float
        Period of the signature, rad.

    Returns
    -------
    float
        ``period`` for fewer than two samples or for samples all at one angle; ``period / n`` for ``n`` evenly
        spread angles.
    """
    a = np.sort(np.mod(np.asarray(angles, float), period))
    if a.size < 2:
        return float(period)
    gaps = np.diff(a)
    return float(max(float(np.max(gaps)), period - float(a[-1] - a[0])))


def _compared_in_cuts(data: CuttingData, rows: np.ndarray) -> np.ndarray:
    inside = data.cuts.mask(data.t.size)
    return rows[inside[rows]]


def resolution(data: CuttingData, rows: np.ndarray) -> dict[str, Resolution]:
    """How the force samples ``rows`` (compared rows of the recording's force samples) resolve each effect.

    Parameters
    ----------
    data : CuttingData
        The aligned force recording (spindle angle of each sample from its initial angle and speed).
    rows : ndarray of int
        Indices into the force samples that are compared (``CuttingColumns.rows``).

    Returns
    -------
    dict
        Effect -> :class:`Resolution` for ``runout``, ``helix_angle``, ``edge_force`` and ``chatter``.
    """
    out: dict[str, Resolution] = {}
    used = _compared_in_cuts(data, np.asarray(rows, dtype=np.int64))
    theta = angle_of(data)[used]
    pitch = 2.0 * math.pi / max(int(data.flutes), 1)
    rpm = float(np.mean(data.inputs.omega[data.cuts.mask(data.t.size)])) * 60.0 / (2.0 * math.pi) \
        if data.cuts.bounds else float("nan")
    spacing = _median_spacing(data)
    for effect, (kind, harmonics) in ANGLE_SIGNATURES.items():
        period = 2.0 * math.pi if kind == "revolution" else pitch
        limit = period / (2.0 * harmonics)
        gap = largest_gap(theta, period) if used.size >= MIN_SAMPLES else period
        ok = used.size >= MIN_SAMPLES and gap < GAP_MARGIN * limit
        what = "spindle revolution" if kind == "revolution" else "tooth pitch"
        text = (f"{effect}: the {used.size} compared force samples in the cuts (median spacing "
                f"{1e3 * spacing:.3g} ms at {rpm:.0f} rpm) fall at spindle angles whose largest gap over the "
                f"{what} ({math.degrees(period):.0f} deg) is {math.degrees(gap):.1f} deg; resolving its signature "
                f"needs less than {math.degrees(limit):.1f} deg")
        out[effect] = Resolution(effect, ok, math.degrees(gap), math.degrees(limit),
                                 text + ("" if ok else ": not offered (the sampling cannot resolve it)"))
    f_tooth = rpm / 60.0 * data.flutes
    nyquist = 0.5 / spacing if spacing > 0 else float("inf")
    ok = bool(np.isfinite(f_tooth) and f_tooth < nyquist)
    out["chatter"] = Resolution(
        "chatter", ok, float("nan"), float("nan"),
        f"chatter: the force spectrum of a cut reaches {nyquist:.4g} Hz (Nyquist of the {1e3 * spacing:.3g} ms "
        f"median spacing), the tooth-passing frequency is {f_tooth:.4g} Hz"
        + ("" if ok else ": not offered (a peak cannot be told from the folded tooth harmonics)"))
    return out


def _median_spacing(data: CuttingData) -> float:
    """Median spacing of the force samples within the cuts, s (of all samples when there is no cut)."""
    steps = [np.diff(data.t[i0:i1]) for i0, i1 in data.cuts.bounds if i1 - i0 > 1]
    d = np.concatenate(steps) if steps else np.diff(data.t)
    return float(np.median(d)) if d.size else 0.0


def unresolved_effects(res: dict[str, Resolution]) -> list[str]:
    """Effects the sampling cannot resolve, in the order of :data:`ANGLE_SIGNATURES` (chatter last)."""
    return [e for e, r in res.items() if not r.resolved]


def sinusoid_amplitude(angle: np.ndarray, y: np.ndarray, min_spread: float = 0.25) -> float:
    """Amplitude of the first harmonic of ``y`` in ``angle`` (least squares ``a sin + b cos + c``), or NaN.

    Parameters
    ----------
    angle : ndarray
        Phase of the harmonic at each sample, rad (e.g. the spindle angle).
    y : ndarray
        Signal, any unit (the amplitude has its unit).
    min_spread : float
        Smallest eigenvalue of the covariance of ``(cos, sin)`` over the samples, relative to its value
        1/2 for angles spread evenly over the circle, below which the harmonic cannot be told from a
        constant: the amplitude is then NaN rather than the huge number an ill-conditioned fit gives.
    """
    angle = np.asarray(angle, float)
    y = np.asarray(y, float)
    ok = np.isfinite(angle) & np.isfinite(y)
    angle, y = angle[ok], y[ok]
    if y.size < 3:
        return float("nan")
    cs = np.column_stack([np.cos(angle), np.sin(angle)])
    cov = np.cov(cs, rowvar=False, bias=True)
    if float(np.min(np.linalg.eigvalsh(cov))) < 0.5 * min_spread:
        return float("nan")
    x = np.column_stack([cs, np.ones_like(angle)])
    c, *_ = np.linalg.lstsq(x, y, rcond=None)
    return float(np.hypot(c[0], c[1]))
