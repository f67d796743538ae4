"""Locating residuals and effects: time windows, program lines, motion events, frequencies, evidence text."""
from __future__ import annotations

from typing import Any

import numpy as np

from .columns import AxisColumns
from .library import EFFECT_EVENTS
from .model import Simulated
from .prepare import Prepared
from .select import Choice, Selection

#: Smoothing window of the residual RMS that decides "above the noise floor", s.
RMS_WINDOW_S = 0.05
#: At most this many time windows are listed per entry.
MAX_WINDOWS = 10


def residual_windows(t: np.ndarray, mask: np.ndarray, gap_s: float = 0.05, min_s: float = 0.01
                     ) -> list[list[float]]:
    """Time windows ``[[t0, t1], ...]`` where ``mask`` holds, gaps below ``gap_s`` bridged, shorter than ``min_s`` dropped."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    windows: list[list[float]] = []
    start = prev = idx[0]
    for i in idx[1:]:
        if t[i] - t[prev] > gap_s:
            windows.append([float(t[start]), float(t[prev])])
            start = i
        prev = i
    windows.append([float(t[start]), float(t[prev])])
    return [[round(a, 4), round(b, 4)] for a, b in windows if b - a >= min_s]


def moving_rms(t: np.ndarray, r: np.ndarray, window_s: float = RMS_WINDOW_S) -> np.ndarray:
    """Centred moving RMS of ``r`` over about ``window_s``."""
    dt = float(np.median(np.diff(t))) if t.size > 1 else window_s
    w = max(1, int(round(window_s / dt)))
    kernel = np.ones(w) / w
    return np.sqrt(np.convolve(r * r, kernel, mode="same"))


def dominant_frequency(t: np.ndarray, r: np.ndarray, share: float = 0.3) -> float | None:
    """Frequency [Hz] holding at least ``share`` of the residual power (uniform resample, Hann window), else None."""
    if t.size < 64:
        return None
    dt = float(np.median(np.diff(t)))
    grid = np.arange(t[0], t[-1], dt)
    y = np.interp(grid, t, r)
    y = (y - y.mean()) * np.hanning(y.size)
    p = np.abs(np.fft.rfft(y)) ** 2
    f = np.fft.rfftfreq(y.size, dt)
    p[0] = 0.0
    k = int(np.argmax(p))
    band = p[max(k - 2, 0):k + 3].sum()
    if p.sum() <= 0 or band < share * p.sum() or f[k] < 2.0 / (t[-1] - t[0]):
        return None
    return round(float(f[k]), 2)


class Locator:
    """Where effects and residuals sit in one prepared case."""

    def __init__(self, prep: Prepared, cols: dict[str, AxisColumns]) -> None:
        self.prep = prep
        self.cols = cols
        self.velocity = {a: np.gradient(prep.commands[a], prep.t) for a in prep.axes}
        self.accel = {a: np.gradient(self.velocity[a], prep.t) for a in prep.axes}

    def lines_in(self, windows: list[list[float]]) -> list[int]:
        """Program lines executed inside the windows (sorted, at most 50)."""
        t, line = self.prep.t, self.prep.line
        inside = np.zeros(t.size, bool)
        for a, b in windows:
            inside |= (t >= a) & (t <= b)
        vals = line[inside & np.isfinite(line)]
        return sorted({int(v) for v in vals})[:50]

    def event(self, axis: str, mask: np.ndarray) -> str | None:
        """Dominant motion state of ``axis`` in the samples ``mask``."""
        if not mask.any():
            return None
        v = self.velocity[axis][mask]
        acc = self.accel[axis][mask]
        sign = np.sign(np.where(np.abs(v) > 1e-4, v, 0.0))
        nz = sign[sign != 0]
        if nz.size and np.any(np.diff(nz) != 0):
            return "reversals"
        if np.mean(np.abs(acc) > 0.2) > 0.3:
            return "accelerations"
        if np.mean(np.abs(v) > 1e-3) > 0.5:
            return "constant velocity"
        return "at rest"

    def _signals(self, axis: str, sim: Simulated, member: int) -> dict[str, np.ndarray]:
        out = {f"{axis}_fe_um": sim.fe[axis][:, member]}
        if self.prep.current[axis] is not None:
            out[f"{axis}_tcmd_A"] = sim.current[axis][:, member]
        return out

    def effect_where(self, axis: str, effect: str, sim: Simulated, final: int, without: int,
                     params: dict[str, float]) -> tuple[dict[str, Any], list[str]]:
        """``where`` and ``channels`` of an effect from its contribution (final minus final-without-it)."""
        c = self.cols[axis]
        sigmas = {f"{axis}_fe_um": c.sigma_fe, f"{axis}_tcmd_A": c.sigma_tc}
        with_, wo = self._signals(axis, sim, final), self._signals(axis, sim, without)
        mask = np.zeros(self.prep.t.size, bool)
        ranked = []
        for ch in with_:
            contrib = (with_[ch] - wo[ch])[self.prep.valid]
            rms = float(np.sqrt(np.mean(contrib ** 2)))
            ranked.append((rms / sigmas[ch], ch))
            mask[self.prep.valid] |= np.abs(contrib) > 2.0 * sigmas[ch]
        ranked.sort(reverse=True)
        channels = [ch for score, ch in ranked if score >= 0.3] or [ranked[0][1]]
        windows = residual_windows(self.prep.t, mask)
        freq = None
        period = params.get("period_mm", 0.0)
        if effect in ("torque_ripple", "pitch_error") and period > 0 and mask.any():
            speed = float(np.median(np.abs(self.velocity[axis][mask]))) * 1e3
            freq = round(speed / period, 2) if speed > 0 else None
        event = EFFECT_EVENTS.get(effect)
        where = {"time_s": windows[:MAX_WINDOWS], "lines": self.lines_in(windows), "event": event,
                 "frequency_Hz": freq}
        return where, channels

    def evidence(self, axis: str, effect: str, choice: Choice, sim: Simulated, final: int, without: int,
                 selection: Selection) -> str:
        """One sentence: the distinguishing signature, the share of residual power, the BIC change."""
        share = choice.gain / max(selection.rss_before - selection.n, 1e-9)
        text = _signature(self, axis, effect, sim, final, without)
        return (f"{text}; explains {min(share, 1.0):.0%} of the residual power above noise; "
                f"BIC {-choice.delta_bic:.0f} (variant {choice.variant.label})")

    def unexplained(self, sim: Simulated, member: int, art: dict[str, dict[str, float]]) -> list[dict[str, Any]]:
        """Residual left by the final model above :data:`core.UNEXPLAINED_SIGMA` noise floors (smoothed)."""
        from .core import UNEXPLAINED_SIGMA, _artefact_signal

        out = []
        t = self.prep.t
        for a, c in self.cols.items():
            fe_art, tc_art = _artefact_signal(c, art[a])
            items = [(f"{a}_fe_um", c.rows_fe, self.prep.fe[a][c.rows_fe] - sim.fe[a][c.rows_fe, member] - fe_art,
                      c.sigma_fe)]
            if c.rows_tc.size:
                items.append((f"{a}_tcmd_A", c.rows_tc,
                              self.prep.current[a][c.rows_tc] - sim.current[a][c.rows_tc, member] - tc_art,
                              c.sigma_tc))
            for ch, rows, r, sigma in items:
                smooth = moving_rms(t[rows], r)
                flagged = smooth > UNEXPLAINED_SIGMA * sigma
                windows = residual_windows(t[rows], flagged, gap_s=0.1, min_s=0.03)
                if not windows:
                    continue
                inside = np.zeros(rows.size, bool)
                for w0, w1 in windows:
                    inside |= (t[rows] >= w0) & (t[rows] <= w1)
                full = np.zeros(t.size, bool)
                full[rows[inside]] = True
                out.append({"channels": [ch],
                            "where": {"time_s": windows[:MAX_WINDOWS], "lines": self.lines_in(windows),
                                      "event": self.event(a, full), "frequency_Hz": dominant_frequency(t[rows], r)},
                            "rms": round(float(np.sqrt(np.mean(r[inside] ** 2))), 4)})
        return out


def _signature(loc: Locator, axis: str, effect: str, sim: Simulated, final: int, without: int) -> str:
    prep = loc.prep
    v = loc.velocity[axis]
    ok = prep.valid
    up = ok & (v > 1e-4)
    down = ok & (v < -1e-4)
    d_fe = sim.fe[axis][:, final] - sim.fe[axis][:, without]
    d_tc = sim.current[axis][:, final] - sim.current[axis][:, without]
    has_tc = prep.current[axis] is not None

    def mean(x: np.ndarray, m: np.ndarray) -> float:
        return float(np.mean(x[m])) if m.any() else 0.0

    if effect == "gravity":
        return (f"current offset of the same sign on up- and down-strokes ({mean(d_tc, up):+.3f} A up, "
                f"{mean(d_tc, down):+.3f} A down), following error {mean(d_fe, up):+.2f} / {mean(d_fe, down):+.2f} µm")
    if effect in ("backlash", "pitch_error", "thermal_drift", "screw_compliance"):
        return (f"following error only, current unchanged (motor-to-table effect): {mean(d_fe, up):+.2f} µm on "
                f"positive, {mean(d_fe, down):+.2f} µm on negative moves")
    if effect == "friction_mismatch":
        return (f"current changes with the sign of the velocity ({mean(d_tc, up):+.3f} A positive, "
                f"{mean(d_tc, down):+.3f} A negative), opposite signs" if has_tc else
                "following-error change with the sign of the velocity")
    if effect == "reversal_friction":
        return "current and following-error spikes right after each reversal, decaying with travel"
    if effect == "torque_ripple":
        return "current oscillation periodic in axis position, at constant velocity"
    if effect == "inertia_mismatch":
        return "current change proportional to the commanded acceleration"
    if effect == "velocity_feedforward":
        return (f"following error proportional to velocity ({mean(d_fe, up):+.2f} µm up, {mean(d_fe, down):+.2f} µm "
                "down) without a matching current offset")
    if effect == "servo_delay":
        return "current lags the position loop: larger following-error and current transients at accelerations"
    if effect == "current_saturation":
        return "measured current flat-tops below the modelled peak current during accelerations"
    return effect
