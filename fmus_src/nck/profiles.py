"""Tangential acc/dec before interpolation: trapezoidal or bell-shaped (jerk-limited).

A speed change ``dv`` at acceleration ``a`` with acceleration change time
``tc`` (jerk ``j = a / tc``) takes

* ``dv / a``                      when ``tc = 0`` (trapezoidal),
* ``dv / a + tc``                 when ``dv >= a tc`` (acceleration reaches ``a``),
* ``2 sqrt(dv tc / a)``           otherwise (triangular acceleration),

and, the speed being point-symmetric about its mid-point, covers
``(v_lo + v_hi) / 2 × time``. These closed forms are used by the look-ahead
(speed reachable within a distance) and by the block profile builder.
Each speed change is confined to one acc/dec span (:mod:`.spans`): a run of
blocks without a binding limit inside, often a single block.
"""
from __future__ import annotations

import math

from .errors import NCParameterError

_MAX_ITER = 100


class SpeedChange:
    """Closed-form speed change laws for one acceleration and change time.

    Parameters
    ----------
    accel : float
        Tangential acceleration limit ``a`` (m/s2), > 0.
    change_time : float
        Acceleration change time ``tc`` (s), >= 0; 0 gives trapezoidal acc/dec.
    """

    def __init__(self, accel: float, change_time: float) -> None:
        if not accel > 0.0:
            raise NCParameterError(f"accel_before_interp must be > 0 m/s2, got {accel!r}")
        if not change_time >= 0.0:
            raise NCParameterError(f"accel_change_time_before_interp must be >= 0 s, got {change_time!r}")
        self.a = float(accel)
        self.tc = float(change_time)
        self.j = self.a / self.tc if self.tc > 0.0 else math.inf
        self.dv_full = self.a * self.tc  # speed change at which the acceleration reaches a

    # ------------------------------------------------------------------ laws
    def time(self, dv: float) -> float:
        """Duration (s) of a speed change of magnitude ``dv`` (m/s)."""
        dv = abs(dv)
        if self.tc == 0.0:
            return dv / self.a
        if dv >= self.dv_full:
            return dv / self.a + self.tc
        return 2.0 * math.sqrt(dv / self.j)

    def distance(self, v1: float, v2: float) -> float:
        """Distance (m) covered while changing speed between ``v1`` and ``v2`` (m/s)."""
        return 0.5 * (v1 + v2) * self.time(v2 - v1)

    def earliest_distance(self, v0: float, v1: float) -> float:
        """Shortest distance (m) in which any speed change starting at ``v0`` with zero acceleration attains ``v1``.

        The fastest way there raises the acceleration at jerk ``a / tc`` to ``a`` and holds it (no jerk-down
        phase), so no ramp of this law, wherever it ends, is faster than ``v1`` before this distance.

        Parameters
        ----------
        v0, v1 : float
            Start speed and speed to attain (m/s), ``v1 >= v0 >= 0``; 0 when ``v1 <= v0``.
        """
        dv = v1 - v0
        if dv <= 0.0:
            return 0.0
        a, tc = self.a, self.tc
        if tc == 0.0:
            return (v1 * v1 - v0 * v0) / (2.0 * a)
        if dv <= 0.5 * a * tc:  # still in the jerk phase: dv = j t^2 / 2
            t = math.sqrt(2.0 * dv / self.j)
            return v0 * t + self.j * t ** 3 / 6.0
        vj = v0 + 0.5 * a * tc  # end of the jerk phase, then constant acceleration a
        return v0 * tc + self.j * tc ** 3 / 6.0 + (v1 * v1 - vj * vj) / (2.0 * a)

    def reach(self, v: float, length: float) -> float:
        """Highest speed (m/s) reachable from (or that can stop down to) ``v`` within ``length`` (m)."""
        if length <= 0.0:
            return v
        a, tc = self.a, self.tc
        if tc == 0.0:
            return math.sqrt(v * v + 2.0 * a * length)
        if length >= (2.0 * v + self.dv_full) * tc:
            disc = (a * tc - 2.0 * v) ** 2 + 8.0 * a * length
            dv = 0.5 * (-(a * tc + 2.0 * v) + math.sqrt(disc))
            return v + max(dv, 0.0)
        # j u^3 + 2 v u - L = 0 with dv = j u^2 ; Newton from an upper bound converges monotonically
        j = self.j
        u = min(math.copysign(abs(length / j) ** (1.0 / 3.0), 1.0), length / (2.0 * v) if v > 0 else math.inf)
        for _ in range(_MAX_ITER):
            f = j * u ** 3 + 2.0 * v * u - length
            step = f / (3.0 * j * u * u + 2.0 * v)
            u -= step
            if abs(step) <= 1e-15 * max(u, 1e-300):
                return v + j * u * u
        raise ArithmeticError(f"reach(): Newton iteration did not converge (v={v}, L={length})")

    def peak(self, v0: float, v1: float, length: float, vmax: float) -> float:
        """Highest cruise speed ``vp <= vmax`` such that v0 → vp → v1 fits in ``length``.

        Parameters
        ----------
        v0, v1 : float
            Entry and exit speed (m/s); must be mutually reachable within ``length``.
        length : float
            Block length (m).
        vmax : float
            Speed limit of the block (m/s).

        Returns
        -------
        float
            Cruise speed (m/s); ``max(v0, v1)`` when there is no room to speed up.
        """
        lo = max(v0, v1)
        if vmax <= lo:
            return lo

        def g(vp: float) -> float:
            return self.distance(v0, vp) + self.distance(v1, vp) - length

        if g(vmax) <= 0.0:
            return vmax
        if self.tc == 0.0:
            return min(vmax, max(lo, math.sqrt(self.a * length + 0.5 * (v0 * v0 + v1 * v1))))
        g_lo = g(lo)
        if g_lo >= 0.0:
            return lo
        # Illinois (modified regula falsi) on a bracket [lo, hi]; g is increasing
        hi, g_hi = vmax, g(vmax)
        side = 0
        for _ in range(_MAX_ITER):
            x = (lo * g_hi - hi * g_lo) / (g_hi - g_lo)
            gx = g(x)
            if abs(gx) <= 1e-13 * length or hi - lo <= 1e-12 * hi:
                return x
            if gx > 0.0:
                hi, g_hi = x, gx
                if side == 1:
                    g_lo *= 0.5
                side = 1
            else:
                lo, g_lo = x, gx
                if side == -1:
                    g_hi *= 0.5
                side = -1
        raise ArithmeticError(f"peak(): root search did not converge (v0={v0}, v1={v1}, L={length}, vmax={vmax})")

    # ------------------------------------------------------------------ pieces
    def pieces(self, v_from: float, v_to: float) -> list[tuple[float, float, float]]:
        """Constant-jerk pieces ``(duration, accel_at_start, jerk)`` of a speed change.

        Parameters
        ----------
        v_from, v_to : float
            Speeds (m/s) at the start and end of the change.
        """
        dv = v_to - v_from
        if dv == 0.0:
            return []
        s = 1.0 if dv > 0 else -1.0
        dv = abs(dv)
        a = self.a
        if self.tc == 0.0:
            return [(dv / a, s * a, 0.0)]
        j = self.j
        if dv >= self.dv_full:
            return [(self.tc, 0.0, s * j), (dv / a - self.tc, s * a, 0.0), (self.tc, s * a, -s * j)]
        t1 = math.sqrt(dv / j)
        return [(t1, 0.0, s * j), (t1, s * j * t1, -s * j)]
