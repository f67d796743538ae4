"""Cutting-process effect terms (diagnosis, issue 8), as pure functions beyond the paper's Eq. (10)-(13).

Angles and signs follow :mod:`fmus_src.cutting.force` (``phi`` clockwise from
+y, chip thickness ``h = max(dx sin phi + dy cos phi, 0)``, ``Ft = Kt d h``,
``Fr = Ke Ft``). Every term is off at its default (0), which is the paper's
model. All functions are vectorised (numpy broadcasting); SI units inside.
The components use them through the compiled kernels of :mod:`.chip`
(:mod:`.kernel_effects`, :mod:`.path_effects`); parameters in
:mod:`.effect_model`.

=================  ===========================================================
effect             function(s)
=================  ===========================================================
``runout``         :func:`runout_radius_offsets`, :func:`runout_chip_thickness`
``helix_angle``    :func:`helix_lag_angle`, :func:`helix_smoothed`
``edge_force``     :func:`edge_forces`
``tool_deflection`` :func:`deflected_chip_thickness`
``tool_wear``      :func:`wear_factor`
``spindle_droop``  :func:`drooped_speed`
``chatter``        :func:`chatter_frequency`
=================  ===========================================================
"""
from __future__ import annotations

import math

import numpy as np

TWO_PI = 2.0 * math.pi


def runout_radius_offsets(flutes: int, eccentricity: float, phase: float) -> np.ndarray:
    """Radius change of each tooth from a cutter eccentricity, m, shape (flutes,).

    Tooth ``j`` sits at angle ``2 pi j / N`` on the cutter; an eccentricity
    ``rho`` at angle ``lambda`` changes its cutting radius by
    ``rho cos(lambda - 2 pi j / N)`` (Kline & DeVor).
    """
    j = np.arange(int(flutes))
    return eccentricity * np.cos(phase - TWO_PI * j / flutes)


def runout_chip_thickness(h_nominal: np.ndarray, flutes: int, eccentricity: float, phase: float) -> np.ndarray:
    """Chip thickness of each tooth with runout, m (same shape as ``h_nominal``).

    Parameters
    ----------
    h_nominal : ndarray
        Chip thickness without runout, one value per tooth, last axis of length ``flutes`` [m].
    flutes : int
    eccentricity : float
        ``rho`` [m].
    phase : float
        ``lambda`` [rad].

    Returns
    -------
    ndarray
        ``max(h + r_j - r_{j+1}, 0)``: a tooth standing out by ``r_j - r_{j+1}`` against the tooth that
        passed before it cuts that much more (tooth ``j`` is at ``theta + j pitch``, so tooth ``j + 1`` passes
        each point one pitch earlier). Single-tooth memory, valid while no tooth loses contact; the twin's
        components also take the older surfaces into account (``min`` over the last teeth, see
        :meth:`fmus_src.cutting.effect_model.EffectParameters.runout_offsets`).
    """
    r = runout_radius_offsets(flutes, eccentricity, phase)
    return np.maximum(np.asarray(h_nominal) + (r - np.roll(r, -1)), 0.0)


def helix_lag_angle(axial_depth: np.ndarray, diameter: float, helix: float) -> np.ndarray:
    """Angle [rad] by which the bottom of a flute leads its top: ``2 d tan(beta) / D``."""
    return 2.0 * np.asarray(axial_depth) * math.tan(helix) / diameter


def helix_smoothed(phi: np.ndarray, per_angle: np.ndarray, lag: float) -> np.ndarray:
    """Force of a helical flute: the straight-flute force averaged over the lag ``[phi - lag, phi]``.

    Parameters
    ----------
    phi : ndarray, shape (n,)
        Uniform grid of one revolution, rad (``phi[k] = 2 pi k / n``).
    per_angle : ndarray, shape (n,) or (n, m)
        Straight-flute force (or chip load) at each grid angle.
    lag : float
        Helix lag angle [rad]; 0 returns ``per_angle``.

    Returns
    -------
    ndarray
        Circular moving mean over ``lag`` (fractional window by linear weight at its far end).
    """
    values = np.asarray(per_angle, dtype=float)
    n = values.shape[0]
    if lag <= 0.0:
        return values.copy()
    width = lag / (TWO_PI / n)  # samples
    whole = int(math.floor(width))
    frac = width - whole
    acc = values.copy()
    for k in range(1, whole + 1):
        acc = acc + np.roll(values, k, axis=0)
    acc = acc + frac * np.roll(values, whole + 1, axis=0)
    return acc / (1.0 + whole + frac)


def edge_forces(kte: float, kre: float, depth: np.ndarray, engaged: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ploughing (edge) forces of engaged teeth, N: ``Fte = Kte d``, ``Fre = Kre d``, independent of ``h``.

    Parameters
    ----------
    kte, kre : float
        Edge coefficients [N/m] (machine keys ``kte_N_per_mm``, ``kre_N_per_mm``).
    depth : ndarray
        Axial depth per tooth [m].
    engaged : ndarray of bool
        Tooth in the material (``h > 0``).

    Returns
    -------
    ft, fr : ndarray
        Tangential and radial edge forces, to be added to ``Kt d h`` and ``Ke Kt d h``
        before projecting on x, y as in :func:`fmus_src.cutting.force.tooth_forces_on_tool`.
    """
    on = np.asarray(engaged, dtype=bool)
    d = np.asarray(depth, dtype=float)
    return np.where(on, kte * d, 0.0), np.where(on, kre * d, 0.0)


def deflected_chip_thickness(h_nominal: np.ndarray, kt: float, ke: float, depth: np.ndarray,
                             stiffness: float) -> np.ndarray:
    """Chip thickness with a static tool deflection under the tooth's own force, m.

    The radial force ``Fr = Ke Kt d h`` pushes the tool away from the surface
    by ``Fr / k`` and removes that much chip (quasi-static, one tooth in cut,
    the deflection along the tooth's radial direction)::

        h = h0 - Ke Kt d h / k   ->   h = h0 / (1 + Ke Kt d / k)

    ``stiffness`` <= 0 means a rigid tool.
    """
    h0 = np.asarray(h_nominal, dtype=float)
    if stiffness <= 0.0:
        return h0.copy()
    return h0 / (1.0 + ke * kt * np.asarray(depth, dtype=float) / stiffness)


def wear_factor(cutting_time: np.ndarray, rate_per_s: float) -> np.ndarray:
    """Force growth with tool wear: ``1 + rate t`` (``rate`` = ``rate_percent_per_min`` / 100 / 60), >= 1."""
    return 1.0 + rate_per_s * np.maximum(np.asarray(cutting_time, dtype=float), 0.0)


def drooped_speed(speed_cmd: np.ndarray, torque: np.ndarray, droop_per_Nm: float) -> np.ndarray:
    """Spindle speed under load [rad/s]: ``omega_cmd - k T``, never below 0 (``rpm_per_Nm`` -> rad/s per N.m)."""
    return np.maximum(np.asarray(speed_cmd, dtype=float) - droop_per_Nm * np.asarray(torque, dtype=float), 0.0)


def chatter_frequency(t: np.ndarray, force: np.ndarray, spindle_rpm: float,
                      min_share: float = 0.2, tolerance_hz: float = 2.0) -> float | None:
    """Frequency [Hz] of a force component that is not a harmonic of the spindle: regenerative chatter.

    Forced milling vibrates at multiples of the spindle frequency (tooth
    passing and runout); chatter appears near a structural mode, off those
    harmonics. The force is resampled uniformly, windowed (Hann), and the
    largest spectral peak farther than ``tolerance_hz`` from every spindle
    harmonic is returned if its band (+-2 bins) holds at least ``min_share``
    of the total power, else None.

    Parameters
    ----------
    t : ndarray
        Sample times [s], increasing.
    force : ndarray
        A force channel [N] (e.g. ``fx_N``).
    spindle_rpm : float
        Spindle speed during the window (tooth passing is a spindle harmonic).
    min_share : float
        Least share of the total (non-DC) power in the peak's +-2 bins.
    tolerance_hz : float
        Distance to a spindle harmonic below which a peak counts as forced.
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(force, dtype=float)
    ok = np.isfinite(y)
    t, y = t[ok], y[ok]
    if t.size < 64:
        return None
    dt = float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1], dt)
    s = np.interp(grid, t, y)
    s = (s - s.mean()) * np.hanning(s.size)
    p = np.abs(np.fft.rfft(s)) ** 2
    f = np.fft.rfftfreq(s.size, dt)
    p[0] = 0.0
    total = p.sum()
    if total <= 0.0:
        return None
    f_spindle = spindle_rpm / 60.0
    if f_spindle > 0:
        harmonic = np.abs(f / f_spindle - np.round(f / f_spindle)) * f_spindle <= tolerance_hz
    else:
        harmonic = np.zeros(f.size, dtype=bool)
    off = np.where(harmonic, 0.0, p)
    k = int(np.argmax(off))
    band = off[max(k - 2, 0):k + 3].sum()
    return round(float(f[k]), 2) if band >= min_share * total else None
