"""Production cost with Taylor tool life (Sim & Lee 2023, Eq. 19–22, Table 3).

    Cp = Ct + Cm
    Ct = (Tp / Tl) · Pt + (Tp / Tl) · Tc · (Ep + Cd)       (tool cost)
    Cm = Tp · (Ep + Cd)                                    (machining cost)
    Tl = (C / V)^(1/n)   with V in m/min and Tl in min     (Taylor)

The paper runs one spindle speed per program. Here the spindle speed may
change from line to line, so the fraction of tool life a program uses is
Miner's sum ``∫ dt / Tl(V(t))`` over the time the spindle turns; at one
constant speed it is exactly the paper's ``Tp / Tl``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .machine import Machine


@dataclass(frozen=True)
class CostModel:
    """Cost parameters (Table 3 of the paper in the default machine file).

    Attributes
    ----------
    tool_price_KRW : float
        Pt, KRW per tool.
    tool_change_time_s : float
        Tc, s (printed as "Tp 60 sec" in the paper's Table 3).
    labor_KRW_per_s, depreciation_KRW_per_s : float
        Ep and Cd, KRW/s.
    taylor_n, taylor_C : float
        Taylor exponent and constant (V in m/min, T in min).
    """

    tool_price_KRW: float = 20000.0
    tool_change_time_s: float = 60.0
    labor_KRW_per_s: float = 2.778
    depreciation_KRW_per_s: float = 0.063
    taylor_n: float = 0.15
    taylor_C: float = 300.0

    @classmethod
    def from_machine(cls, machine: Machine) -> "CostModel":
        """Read the ``[cost]`` section of a machine file."""
        c = machine.si("cost")
        return cls(
            tool_price_KRW=float(c["tool_price"]),
            tool_change_time_s=float(c["tool_change_time"]),
            labor_KRW_per_s=float(c["labor"]),
            depreciation_KRW_per_s=float(c["depreciation"]),
            taylor_n=float(c["taylor_n"]),
            taylor_C=float(c["taylor_C"]),
        )

    def tool_wear_rate_per_s(self, spindle_rpm: np.ndarray | float, diameter_mm: float) -> np.ndarray:
        """Fraction of tool life used per second, ``1 / Tl``, 1/s (0 while the spindle stands).

        Parameters
        ----------
        spindle_rpm : array_like
            Spindle speed, rev/min (sign ignored).
        diameter_mm : float
            Cutter diameter, mm.
        """
        v_m_per_min = math.pi * diameter_mm * np.abs(np.asarray(spindle_rpm, dtype=float)) / 1000.0
        return (v_m_per_min / self.taylor_C) ** (1.0 / self.taylor_n) / 60.0

    def tool_life_s(self, spindle_rpm: np.ndarray | float, diameter_mm: float) -> np.ndarray:
        """Taylor tool life ``Tl = (C/V)^(1/n)``, s (inf while the spindle stands)."""
        with np.errstate(divide="ignore"):
            return 1.0 / self.tool_wear_rate_per_s(spindle_rpm, diameter_mm)


@dataclass(frozen=True)
class CostBreakdown:
    """Cost of one program run, KRW."""

    machining_time_s: float
    tool_life_used: float
    tool_KRW: float
    machining_KRW: float

    @property
    def total_KRW(self) -> float:
        """Cp = Ct + Cm."""
        return self.tool_KRW + self.machining_KRW


def production_cost(
    t_s: np.ndarray, spindle_rpm: np.ndarray, diameter_mm: float, model: CostModel, machining_time_s: float | None = None
) -> CostBreakdown:
    """Production cost of a run from its spindle-speed history.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Sample times, s.
    spindle_rpm : ndarray, shape (n,)
        Actual spindle speed, rev/min.
    diameter_mm : float
        Cutter diameter, mm.
    model : CostModel
        Cost parameters.
    machining_time_s : float, optional
        Tp, s; defaults to the span of ``t_s``.
    """
    t = np.asarray(t_s, dtype=float)
    tp = float(t[-1] - t[0]) if machining_time_s is None else float(machining_time_s)
    if len(t) > 1:
        inverse_life = model.tool_wear_rate_per_s(spindle_rpm, diameter_mm)
        used = float(np.sum(0.5 * (inverse_life[1:] + inverse_life[:-1]) * np.diff(t)))
    else:
        used = 0.0
    rate = model.labor_KRW_per_s + model.depreciation_KRW_per_s
    tool = used * model.tool_price_KRW + used * model.tool_change_time_s * rate
    return CostBreakdown(tp, used, tool, tp * rate)
