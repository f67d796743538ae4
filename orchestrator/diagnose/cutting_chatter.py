"""Refit of the chatter mode (natural frequency, damping ratio, modal stiffness) from what is observable.

A regenerative vibration is not replayable sample by sample: its phase grows out of the tooth-passing
excitation and is lost within a few periods, so the mode is fitted to what a recording fixes about it, per
cut with chatter (:func:`.cutting_locate.chatter_peaks`):

* the **chatter frequency** (the spectral peak);
* the **vibration envelope** at that frequency (:func:`envelope`, fx and fy band-passed around it): its
  growth within the cut (the net damping of the regenerative loop: ``A ~ exp(sigma t)`` while it is
  linear) and its limit-cycle amplitude (reached when teeth jump out of the cut; multiple regeneration);
* the **analytic stability limit** (zero-order, Altintas & Budak 1995; :func:`stability_limit`): the cut
  chatters, so its depth ``a`` is beyond ``a_lim(zeta, k)``. The search runs on ``zeta`` and the ratio
  ``r = a / a_lim`` (how far beyond the limit), which is what sets the growth rate; ``k`` follows from
  ``r`` because ``a_lim`` is proportional to ``k`` at a given ``zeta`` and natural frequency.

:func:`refit_chatter` replays the chatter cut with the twin's own tool mode (``PathCuttingLoad``,
``chatter_frequency/damping/stiffness``) on a grid of ``(zeta, r)`` in one batched run, scores each member
by the mean squared difference of the log envelopes (the twin's with the measurement's noise floor in the
band added), corrects the natural frequency by the ratio of the measured to the twin's chatter frequency,
and refines the grid once around the best member. What is reported (:class:`ChatterFit`): the mode, the
band power around the chatter frequency and the envelope of the refitted twin against the measurement,
and the sample-by-sample RMS of the cut with and without the mode (it does not improve: phase).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fmus_src.cutting import path_kernel as pk

from .cutting import CuttingData, CuttingModel
from .cutting_library import component_values
from .cutting_locate import ChatterPeak, angle_of
from .cutting_replay import ForceInputs, run_force_replay

#: Half width of the band around the chatter frequency (envelope and band power), Hz.
BAND_HZ = 30.0
#: Envelope averaging window, s.
ENVELOPE_WINDOW_S = 0.01
#: Replay starts this long before the cut (the tool enters from the air), s.
LEAD_S = 0.02
#: Damping ratios of the coarse grid.
ZETA_GRID = (0.01, 0.015, 0.022, 0.033, 0.05, 0.075, 0.11)
#: Depth over the lobe-minimum stability limit of the coarse grid (a given spindle speed may sit on a
#: lobe several times higher than the minimum).
RATIO_GRID = (1.2, 1.6, 2.2, 3.0, 4.0, 5.5, 7.5, 10.0)
#: Refinement factors around the best member (zeta and ratio).
REFINE = (0.78, 0.88, 1.0, 1.13, 1.28)
#: Weight of the squared log ratio of the growth rates (twin / measured) against the mean squared
#: log-envelope difference: a 20 % error in the growth rate costs as much as 0.13 in the envelope.
GROWTH_WEIGHT = 4.0
#: Chatter frequency of the twin searched within this fraction of the measured one.
SEARCH_REL = 0.15


@dataclass
class ChatterFit:
    """The refitted tool mode of a chatter cut and how well it reproduces the vibration.

    Attributes
    ----------
    natural_frequency_Hz, damping_ratio, stiffness_N_per_um : float
        The mode (``chatter_frequency_Hz``, ``chatter_damping_ratio``, ``chatter_stiffness_N_per_um``).
    chatter_frequency_Hz : float
        Measured chatter frequency (the spectral peak), Hz.
    twin_frequency_Hz : float
        Chatter frequency of the refitted twin, Hz.
    depth_over_limit : float
        Axial depth of the cut over the analytic stability limit of the refitted mode.
    limit_mm : float
        That limit, mm.
    band_power_ratio : float
        Band power (``BAND_HZ`` around the chatter frequency) of the refitted twin (noise floor added)
        over the measurement's, over the cut.
    band_power_before : float
        The same for the twin without a tool mode.
    growth_per_s, growth_twin_per_s : float
        Growth rate of the envelope while it rises (measured, refitted twin), 1/s.
    amplitude_N, amplitude_twin_N : float
        Limit-cycle amplitude (median envelope over the last third of the cut), N.
    envelope_rms_log : float
        RMS of the log-envelope difference (refitted twin against measurement).
    rms_with, rms_without : float
        Sample-by-sample RMS of the cut's force residual (fx, fy) with and without the mode, N.
    cut : int
        Cut index.
    t_env, env_meas, env_twin : ndarray
        Envelope window centres [s] and envelopes [N] (for plots).
    """

    natural_frequency_Hz: float
    damping_ratio: float
    stiffness_N_per_um: float
    chatter_frequency_Hz: float
    twin_frequency_Hz: float
    depth_over_limit: float
    limit_mm: float
    band_power_ratio: float
    band_power_before: float
    growth_per_s: float
    growth_twin_per_s: float
    amplitude_N: float
    amplitude_twin_N: float
    envelope_rms_log: float
    rms_with: float
    rms_without: float
    cut: int
    t_env: np.ndarray
    env_meas: np.ndarray
    env_twin: np.ndarray

    def evidence(self) -> str:
        """One sentence for ``diagnosis.json`` (the spec reports only ``frequency_Hz``)."""
        return (f"tool mode refitted from the vibration envelope: natural frequency "
                f"{self.natural_frequency_Hz:.1f} Hz, damping ratio {self.damping_ratio:.4f}, modal stiffness "
                f"{self.stiffness_N_per_um:.3g} N/um (cut at {self.depth_over_limit:.2f} x the analytic stability "
                f"limit {self.limit_mm:.3f} mm); refitted twin against measurement: band power ({BAND_HZ:.0f} Hz "
                f"around {self.chatter_frequency_Hz:.1f} Hz) ratio {self.band_power_ratio:.2f} (without the mode "
                f"{self.band_power_before:.3g}), growth {self.growth_twin_per_s:.0f} vs {self.growth_per_s:.0f} 1/s, "
                f"limit-cycle amplitude {self.amplitude_twin_N:.1f} vs {self.amplitude_N:.1f} N, log-envelope rms "
                f"{self.envelope_rms_log:.2f}; sample by sample the cut's rms is {self.rms_with:.1f} N with the mode, "
                f"{self.rms_without:.1f} N "
                "without (the vibration's phase is not replayable)")


def _bandpass_envelope(t: np.ndarray, y: np.ndarray, f0: float, half: float) -> np.ndarray:
    """|analytic signal| of ``y`` band-passed with a raised-cosine window ``f0 +- half`` (uniform ``t``)."""
    n = y.size
    spec = np.fft.fft(y - y.mean())
    f = np.fft.fftfreq(n, float(t[1] - t[0]))
    x = np.clip((np.abs(f - f0)) / half, 0.0, 1.0)
    mask = np.where(f > 0, 0.5 * (1.0 + np.cos(math.pi * x)), 0.0) * 2.0  # one-sided: analytic signal
    return np.abs(np.fft.ifft(spec * mask))


def envelope(t: np.ndarray, fx: np.ndarray, fy: np.ndarray, f0: float, half: float = BAND_HZ,
             window_s: float = ENVELOPE_WINDOW_S) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude of the vibration at ``f0`` (fx and fy combined) averaged in windows; (centres [s], N).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Uniform sample times, s.
    fx, fy : ndarray, shape (n,)
        Forces, N.
    f0, half : float
        Band centre and half width, Hz.
    window_s : float
        Averaging window, s.
    """
    e2 = _bandpass_envelope(t, fx, f0, half) ** 2 + _bandpass_envelope(t, fy, f0, half) ** 2
    per = max(int(round(window_s / float(t[1] - t[0]))), 1)
    m = e2.size // per
    e2 = e2[:m * per].reshape(m, per).mean(axis=1)
    tc = t[:m * per].reshape(m, per).mean(axis=1)
    return tc, np.sqrt(e2)


def band_power(t: np.ndarray, fx: np.ndarray, fy: np.ndarray, f0: float, half: float = BAND_HZ) -> float:
    """Power of fx and fy within ``f0 +- half`` (Hann window, mean removed), N^2 per sample."""
    w = np.hanning(t.size)
    f = np.fft.rfftfreq(t.size, float(t[1] - t[0]))
    band = np.abs(f - f0) <= half
    p = 0.0
    for y in (fx, fy):
        s = np.fft.rfft((y - y.mean()) * w)
        p += float(np.sum(np.abs(s[band]) ** 2)) / float(np.sum(w * w))
    return p


def growth_rate(tc: np.ndarray, env: np.ndarray, floor: float) -> float:
    """Growth rate of the envelope while it rises from 3 noise floors to half its final level, 1/s (0 if none)."""
    if env.size < 4:
        return 0.0
    top = float(np.median(env[-max(env.size // 3, 1):]))
    lo, hi = 3.0 * floor, 0.5 * top
    if not hi > lo:
        return 0.0
    above = np.flatnonzero(env >= hi)
    end = int(above[0]) if above.size else env.size - 1
    start = end
    while start > 0 and env[start - 1] >= lo and env[start - 1] < env[start]:
        start -= 1
    if end - start < 2:
        return 0.0
    slope = np.polyfit(tc[start:end + 1], np.log(env[start:end + 1]), 1)[0]
    return float(slope)


def stability_limit(kt: float, ke: float, flutes: int, arc: tuple[float, float], fn: float, zeta: float,
                    k: float) -> tuple[float, float]:
    """Zero-order stability limit of an isotropic x/y tool mode over an engaged arc (Altintas & Budak 1995).

    The dynamic chip ``(q(t) - q(t - T)) . u`` gives the mean force on the tool per unit depth
    ``Kt A0 dq`` with ``A0 = N / (2 pi) int w u^T dphi`` over the arc (``w = (-cos - Ke sin,
    sin - Ke cos)``, ``u = (sin, cos)``). With an eigenvalue ``lam`` of ``A0`` and the receptance ``G``,
    ``1 = Kt a (1 - exp(-i w T)) lam G`` has a real root ``a = 1 / (2 Kt Re(lam G))``; the least over
    the chatter frequencies is the limit (the lobe minima).

    Parameters
    ----------
    kt, ke : float
        N/m2, 1.
    flutes : int
    arc : (float, float)
        Engaged angles (chip > 0) [rad], phi clockwise from +y.
    fn, zeta, k : float
        Natural frequency [Hz], damping ratio, modal stiffness [N/m].

    Returns
    -------
    a_lim : float
        m (inf when no frequency is unstable).
    f_c : float
        Chatter frequency at the lobe minimum, Hz.
    """
    phi = np.linspace(arc[0], arc[1], 721)
    s, c = np.sin(phi), np.cos(phi)
    wx = np.stack([-c - ke * s, s - ke * c])           # (2, P)
    u = np.stack([s, c])
    a0 = flutes / (2 * math.pi) * np.trapezoid(wx[:, None, :] * u[None, :, :], phi, axis=2)
    lams = np.linalg.eigvals(a0)
    wn = 2 * math.pi * fn
    w = np.linspace(0.8, 1.3, 20001) * wn
    g = 1.0 / (k * (1.0 - (w / wn) ** 2 + 2j * zeta * w / wn))
    best_re, best_w = 0.0, wn
    for lam in lams:
        z = (lam * g).real
        i = int(np.argmax(z))
        if z[i] > best_re:
            best_re, best_w = float(z[i]), float(w[i])
    if not best_re > 0.0:
        return math.inf, fn
    return 1.0 / (2.0 * kt * best_re), best_w / (2 * math.pi)


def engaged_arc(data: CuttingData, i0: int, i1: int) -> tuple[tuple[float, float], float]:
    """Engaged arc (chip > 0) and axial depth in the middle of a cut, from the engagement table.

    Returns ``((phi_start, phi_exit) [rad], depth [m])``; the arc is the largest run of table angles in
    material where the feed direction gives a positive chip.
    """
    tab = data.table
    k = (i0 + i1) // 2
    p = data.inputs.position
    _, s_cur, _ = pk.locate(p[k, 0], p[k, 1], p[k, 2], 0, 0.0, math.inf, tab.vertices, tab.vertex_s)
    kmax = tab.alpha.shape[1]
    ia, ib, it = np.empty(kmax), np.empty(kmax), np.empty(kmax)
    cnt = pk.table_at(s_cur, tab.spacing, tab.count, tab.alpha, tab.beta, tab.top, ia, ib, it)
    feed = p[min(k + 5, p.shape[0] - 1)] - p[max(k - 5, 0)]
    phi = np.linspace(0.0, 2 * math.pi, 1441)
    inside = np.zeros(phi.size, bool)
    depth = 0.0
    for q in range(cnt):
        inside |= ((phi >= ia[q]) & (phi <= ib[q])) | (phi + 2 * math.pi <= ib[q])
        depth = max(depth, float(it[q] - max(p[k, 2], tab.z_floor)))
    inside &= feed[0] * np.sin(phi) + feed[1] * np.cos(phi) > 0.0
    if not inside.any():
        return (0.0, math.pi), depth
    idx = np.flatnonzero(inside)
    return (float(phi[idx[0]]), float(phi[idx[-1]])), depth


def _sub_inputs(data: CuttingData, a: int, b: int) -> ForceInputs:
    inp = data.inputs
    return ForceInputs(inp.t[a:b], inp.position[a:b], inp.omega[a:b], inp.omega_source)


def _noise_envelope(t: np.ndarray, sigma: float, f0: float) -> float:
    """Mean envelope of white noise of ``sigma`` per channel in the band (seeded), N."""
    rng = np.random.default_rng(0)
    _, e = envelope(t, rng.normal(0, sigma, t.size), rng.normal(0, sigma, t.size), f0)
    return float(np.sqrt(np.mean(e ** 2)))


def _peak_near(t: np.ndarray, fx: np.ndarray, fy: np.ndarray, f0: float, spindle_hz: float) -> float:
    """Largest spectral peak within SEARCH_REL of ``f0``, off the spindle harmonics, Hz."""
    w = np.hanning(t.size)
    f = np.fft.rfftfreq(t.size, float(t[1] - t[0]))
    p = np.abs(np.fft.rfft((fx - fx.mean()) * w)) ** 2 + np.abs(np.fft.rfft((fy - fy.mean()) * w)) ** 2
    ok = np.abs(f - f0) <= SEARCH_REL * f0
    if spindle_hz > 0:
        ok &= np.abs(f - np.round(f / spindle_hz) * spindle_hz) > max(3.0, 3 * float(f[1] - f[0]))
    if not ok.any():
        return f0
    return float(f[np.argmax(np.where(ok, p, 0.0))])


def refit_chatter(data: CuttingData, model: CuttingModel, peak: ChatterPeak) -> ChatterFit:
    """Fit the tool mode of one chatter cut (see module docstring).

    Parameters
    ----------
    data : CuttingData
    model : CuttingModel
        The refitted force model (coefficients, effects, alignment) the mode is added to.
    peak : ChatterPeak
        The cut's spectral peak.
    """
    i0, i1 = data.cuts.bounds[peak.cut]
    t = data.t
    dt = float(np.median(np.diff(t[i0:i1])))
    a = max(i0 - int(round(LEAD_S / dt)), 0)
    inputs = _sub_inputs(data, a, i1)
    phase = math.radians(model.get("alignment", {}).get("spindle_phase_deg", 0.0))
    theta_a = float(angle_of(data, phase)[a])
    step_omega = data.step_omega[a:i1 - 1]
    coef = model.get("coefficients", {})
    kt = float(coef.get("kt_N_per_m2", data.kt))
    ke = float(coef.get("ke", data.ke))
    base = {"kt": kt, "ke": ke}
    base.update(component_values({e: v for e, v in model.items() if e not in ("alignment", "chatter")}))
    arc, depth = engaged_arc(data, i0, i1)
    tc = t[i0:i1]
    meas = data.measured[i0:i1]
    f_meas = float(peak.frequency)
    floor = _noise_envelope(tc, data.sigma, f_meas)
    t_env, env_meas = envelope(tc, meas[:, 0], meas[:, 1], f_meas)
    growth = growth_rate(t_env, env_meas, floor)
    k_unit = 1e7

    def members(fn: float, grid: list[tuple[float, float]]) -> list[dict]:
        out = []
        for zeta, ratio in grid:
            a_lim, _ = stability_limit(kt, ke, data.flutes, arc, fn, zeta, k_unit)
            k = k_unit * depth / (ratio * a_lim) if math.isfinite(a_lim) and a_lim > 0 else k_unit
            out.append({**base, "chatter_frequency": fn, "chatter_damping": zeta, "chatter_stiffness": k})
        return out

    def score(sim, j: int) -> tuple[float, float, np.ndarray]:
        fx, fy = sim.fx[i0 - a:, j], sim.fy[i0 - a:, j]
        f_twin = _peak_near(tc, fx, fy, f_meas, peak.spindle_hz)
        _, env = envelope(tc, fx, fy, f_twin)
        env = np.sqrt(env ** 2 + floor ** 2)
        err = float(np.mean((np.log(env) - np.log(env_meas)) ** 2))
        sigma = growth_rate(t_env, env, floor)
        if growth > 0.0:  # the linear growth: model-robust, it tells the damping from the stiffness
            err += GROWTH_WEIGHT * math.log(max(sigma, 1e-3 * growth) / growth) ** 2
        return (err if math.isfinite(err) else math.inf), f_twin, env  # a member that blew up scores worst

    fn = f_meas
    grid = [(z, r) for z in ZETA_GRID for r in RATIO_GRID]
    best = None
    for _ in range(2):
        mem = members(fn, grid)
        sim = run_force_replay(data.case, data.table, inputs, mem, theta_a, step_omega)
        scores = [score(sim, j) for j in range(len(mem))]
        j = int(np.argmin([s[0] for s in scores]))
        best = (grid[j], mem[j], scores[j])
        zeta, ratio = grid[j]
        fn = fn * f_meas / scores[j][1]  # the twin's chatter sits where the measured one does
        grid = [(min(zeta * fz, 0.5), max(ratio * fr, 1.01)) for fz in REFINE for fr in REFINE]
    (zeta, ratio), mem, _ = best
    # final: the refined mode at the corrected frequency, and the twin without a mode
    final = {**mem, "chatter_frequency": fn}
    a_lim, _ = stability_limit(kt, ke, data.flutes, arc, fn, zeta, final["chatter_stiffness"])
    sim = run_force_replay(data.case, data.table, inputs, [final, base], theta_a, step_omega)
    err, f_twin, env_twin = score(sim, 0)
    fx, fy = sim.fx[i0 - a:, 0], sim.fy[i0 - a:, 0]
    p_meas = band_power(tc, meas[:, 0], meas[:, 1], f_meas)
    rng = np.random.default_rng(1)
    noise = [rng.normal(0.0, data.sigma, tc.size) for _ in range(2)]
    p_twin = band_power(tc, fx + noise[0], fy + noise[1], f_meas)
    p_base = band_power(tc, sim.fx[i0 - a:, 1] + noise[0], sim.fy[i0 - a:, 1] + noise[1], f_meas)
    third = max(env_meas.size // 3, 1)
    rms = [float(np.sqrt(np.mean((meas[:, 0] - sim.fx[i0 - a:, j]) ** 2 + (meas[:, 1] - sim.fy[i0 - a:, j]) ** 2)
                                 / 2.0)) for j in (0, 1)]
    return ChatterFit(
        natural_frequency_Hz=fn, damping_ratio=zeta, stiffness_N_per_um=final["chatter_stiffness"] * 1e-6,
        chatter_frequency_Hz=f_meas, twin_frequency_Hz=f_twin,
        depth_over_limit=depth / a_lim if math.isfinite(a_lim) else 0.0, limit_mm=a_lim * 1e3,
        band_power_ratio=p_twin / max(p_meas, 1e-300), band_power_before=p_base / max(p_meas, 1e-300),
        growth_per_s=growth, growth_twin_per_s=growth_rate(t_env, env_twin, floor),
        amplitude_N=float(np.median(env_meas[-third:])), amplitude_twin_N=float(np.median(env_twin[-third:])),
        envelope_rms_log=float(np.sqrt(np.mean((np.log(env_twin) - np.log(env_meas)) ** 2))),
        rms_with=rms[0], rms_without=rms[1], cut=peak.cut,
        t_env=t_env, env_meas=env_meas, env_twin=env_twin)
