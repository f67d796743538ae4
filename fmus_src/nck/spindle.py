"""Spindle: speed ramp and speed-arrival wait (FANUC SAR signal).

The actual speed moves toward the (signed) command at the constant ramp rate
``spindle_ramp``. Cutting feed waits until ``|actual - command| <=
tolerance × |command|``; from ``w0`` to ``w1`` that takes
``max(0, |w1 - w0| - tol |w1|) / ramp`` (from standstill: ``|w1| (1 - tol) / ramp``).
"""
from __future__ import annotations

import numpy as np


def arrival_time(w_now: float, w_cmd: float, ramp: float, tolerance: float) -> float:
    """Time (s) until the speed-arrival condition holds; 0 for a stop command."""
    if w_cmd == 0.0:
        return 0.0
    return max(0.0, abs(w_cmd - w_now) - tolerance * abs(w_cmd)) / ramp


def speed_after(w_start: float, w_cmd: float, ramp: float, dt: float) -> float:
    """Speed (rad/s) ``dt`` seconds after a command ``w_cmd`` given at speed ``w_start``."""
    d = w_cmd - w_start
    step = ramp * dt
    return w_cmd if abs(d) <= step else w_start + np.sign(d) * step


def sample_spindle(events: list[tuple[int, float]], n_samples: int, period: float, ramp: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Commanded and actual spindle speed at every sample.

    Parameters
    ----------
    events : list of (sample index, signed command rad/s)
        Commands in time order; the speed is 0 before the first.
    n_samples : int
        Number of samples K.
    period : float
        Sample period (s).
    ramp : float
        Ramp rate (rad/s2).

    Returns
    -------
    ref, actual : ndarray (K,)
    """
    ref = np.zeros(n_samples)
    act = np.zeros(n_samples)
    w = 0.0
    for i, (k, cmd) in enumerate(events):
        k_next = events[i + 1][0] if i + 1 < len(events) else n_samples
        if k_next <= k:
            continue
        kk = np.arange(k, min(k_next, n_samples))
        dt = (kk - k) * period
        ref[kk] = cmd
        d = cmd - w
        act[kk] = w + np.sign(d) * np.minimum(abs(d), ramp * dt)
        w = speed_after(w, cmd, ramp, (k_next - k) * period)
    return ref, act
