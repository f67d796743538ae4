"""Production cost with Taylor tool life (Sim & Lee 2023, Eq. 19–22, Table 3).

    Cp = Ct + Cm
    Ct = (Tp / Tl) · Pt + (Tp / Tl) · Tc · (Ep + Cd)       (tool cost)
    Cm = Tp · (Ep + Cd)                                    (machining cost)
    Tl = (C / V)^(1/n)   with V in m/min and Tl in min     (Taylor)

The paper runs one spindle speed per program. Here the spindle speed may
change from line to line, so the fraction of tool life a program uses is
Miner's sum ``∫ dt / Tl(V(t))`` over the time the spindle turns; at one
constant speed it is exactly the paper's ``Tp / Tl``.

A program that changes tools wears each tool on its own: at each sample the
wear goes to the tool in the spindle (the NC kernel's ``nck.tool``), with that
tool's diameter, price and Taylor constants (:class:`ToolLife`), and

    Ct = Σ_k used_k · (Pt_k + Tc · (Ep + Cd))
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

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

    def tool(self, diameter_mm: float, price_KRW: float | None = None, taylor_C: float | None = None,
             taylor_n: float | None = None) -> "ToolLife":
        """One tool's life parameters; a value not given is this model's (the machine file's ``[cost]``).

        Parameters
        ----------
        diameter_mm : float
            Cutter diameter, mm.
        price_KRW, taylor_C, taylor_n : float, optional
            Pt (KRW per tool), Taylor constant (m/min) and exponent of this tool.
        """
        return ToolLife(
            float(diameter_mm),
            self.tool_price_KRW if price_KRW is None else float(price_KRW),
            self.taylor_C if taylor_C is None else float(taylor_C),
            self.taylor_n if taylor_n is None else float(taylor_n),
        )

    def tool_of(self, cutter: Any) -> "ToolLife":
        """:meth:`tool` of a case's cutter (``orchestrator.case.Tool``: ``diameter_mm`` and the optional
        ``price_KRW``, ``taylor_C``, ``taylor_n``, None where case.toml does not state them)."""
        return self.tool(cutter.diameter_mm, getattr(cutter, "price_KRW", None), getattr(cutter, "taylor_C", None),
                         getattr(cutter, "taylor_n", None))

    def tool_wear_rate_per_s(self, spindle_rpm: np.ndarray | float, diameter_mm: float) -> np.ndarray:
        """Fraction of tool life used per second, ``1 / Tl``, 1/s (0 while the spindle stands).

        Parameters
        ----------
        spindle_rpm : array_like
            Spindle speed, rev/min (sign ignored).
        diameter_mm : float
            Cutter diameter, mm.
        """
        return self.tool(diameter_mm).wear_rate_per_s(spindle_rpm)

    def tool_life_s(self, spindle_rpm: np.ndarray | float, diameter_mm: float) -> np.ndarray:
        """Taylor tool life ``Tl = (C/V)^(1/n)``, s (inf while the spindle stands)."""
        with np.errstate(divide="ignore"):
            return 1.0 / self.tool_wear_rate_per_s(spindle_rpm, diameter_mm)


@dataclass(frozen=True)
class ToolLife:
    """Taylor tool life and price of one tool.

    Attributes
    ----------
    diameter_mm : float
        Cutter diameter, mm (cutting speed ``V = π D S``).
    price_KRW : float
        Pt, KRW per tool.
    taylor_C, taylor_n : float
        Taylor constant (m/min) and exponent: ``Tl = (C / V)^(1/n)`` min.
    """

    diameter_mm: float
    price_KRW: float
    taylor_C: float
    taylor_n: float

    def wear_rate_per_s(self, spindle_rpm: np.ndarray | float) -> np.ndarray:
        """Fraction of this tool's life used per second, ``1 / Tl``, 1/s (0 while the spindle stands).

        Parameters
        ----------
        spindle_rpm : array_like
            Spindle speed, rev/min (sign ignored).
        """
        v_m_per_min = math.pi * self.diameter_mm * np.abs(np.asarray(spindle_rpm, dtype=float)) / 1000.0
        return (v_m_per_min / self.taylor_C) ** (1.0 / self.taylor_n) / 60.0


@dataclass(frozen=True)
class ToolUse:
    """What one tool costs in a run.

    Attributes
    ----------
    life_used : float
        Fraction of the tool's life used (Miner's sum over the samples it was in the spindle).
    KRW : float
        ``life_used · (Pt + Tc · (Ep + Cd))``, KRW.
    """

    life_used: float
    KRW: float


@dataclass(frozen=True)
class CostBreakdown:
    """Cost of one program run, KRW.

    Attributes
    ----------
    machining_time_s : float
        Tp, s.
    tool_life_used : float
        Fraction of a tool life used, summed over the tools.
    tool_KRW, machining_KRW : float
        Ct and Cm, KRW.
    tools : dict int -> ToolUse
        Per tool number (the NC kernel's tool in the spindle; 0 before the first M6, listed only when it
        used some life): its life used and tool cost.
    """

    machining_time_s: float
    tool_life_used: float
    tool_KRW: float
    machining_KRW: float
    tools: Mapping[int, ToolUse] = field(default_factory=dict)

    @property
    def total_KRW(self) -> float:
        """Cp = Ct + Cm."""
        return self.tool_KRW + self.machining_KRW


def production_cost(
    t_s: np.ndarray,
    spindle_rpm: np.ndarray,
    diameter_mm: float | ToolLife,
    model: CostModel,
    machining_time_s: float | None = None,
    tool_in_spindle: np.ndarray | None = None,
    tools: Mapping[int, ToolLife] | None = None,
) -> CostBreakdown:
    """Production cost of a run from its spindle-speed history, tool by tool.

    Parameters
    ----------
    t_s : ndarray, shape (n,)
        Sample times, s.
    spindle_rpm : ndarray, shape (n,)
        Actual spindle speed, rev/min.
    diameter_mm : float or ToolLife
        The cutter of every tool ``tools`` does not list (the case's ``[tool]``): its diameter in mm (price and
        Taylor constants from ``model``) or its :class:`ToolLife`.
    model : CostModel
        Cost parameters (tool change time, labour and depreciation rates; the defaults of each tool's).
    machining_time_s : float, optional
        Tp, s; defaults to the span of ``t_s``.
    tool_in_spindle : ndarray, shape (n,), optional
        Tool number in the spindle at each sample (the recording's ``tool``; NaN counts as 0). None: one
        tool, number 0, throughout.
    tools : mapping int -> ToolLife, optional
        The tools with their own cutter and cost parameters (the case's ``[tools.T<n>]``).

    Returns
    -------
    CostBreakdown
        With one tool in the spindle throughout (or one after a tool 0 whose spindle stood), the same numbers
        bit for bit as a single Miner's sum over the whole history.
    """
    t = np.asarray(t_s, dtype=float)
    tp = float(t[-1] - t[0]) if machining_time_s is None else float(machining_time_s)
    default = diameter_mm if isinstance(diameter_mm, ToolLife) else model.tool(diameter_mm)
    tools = tools or {}
    if tool_in_spindle is None:
        number = np.zeros(len(t))
    else:
        number = np.nan_to_num(np.asarray(tool_in_spindle, dtype=float).reshape(len(t)), nan=0.0)
    rate = model.labor_KRW_per_s + model.depreciation_KRW_per_s
    present = [int(k) for k in np.unique(number)] if len(t) else [0]
    used_by: dict[int, ToolUse] = {}
    for k in present:
        life = tools.get(k, default)
        if len(t) > 1:
            inverse_life = life.wear_rate_per_s(spindle_rpm)
            if len(present) > 1:  # each sample's wear to the tool in the spindle then
                inverse_life = np.where(number == k, inverse_life, 0.0)
            used = float(np.sum(0.5 * (inverse_life[1:] + inverse_life[:-1]) * np.diff(t)))
        else:
            used = 0.0
        used_by[k] = ToolUse(used, used * life.price_KRW + used * model.tool_change_time_s * rate)
    total_used = sum(u.life_used for u in used_by.values())
    tool = sum(u.KRW for u in used_by.values())
    listed = {k: u for k, u in used_by.items() if k != 0 or u.life_used > 0.0}
    return CostBreakdown(tp, float(total_used), float(tool), tp * rate, listed)


def case_tool_lives(model: CostModel, case: Any) -> tuple[ToolLife, dict[int, ToolLife]]:
    """The tool lives of a case: its ``[tool]`` (every tool not listed) and its tool table ``[tools.T<n>]``.

    Parameters
    ----------
    model : CostModel
        The machine file's ``[cost]`` (each value a tool does not state).
    case : orchestrator.case.Case
        The case (``tool`` and ``tools``).
    """
    return model.tool_of(case.tool), {int(n): model.tool_of(c) for n, c in getattr(case, "tools", {}).items()}


def tool_use_json(breakdown: CostBreakdown) -> dict[str, dict[str, float]]:
    """``{"T1": {"tool_life_used": ..., "tool_KRW": ...}, ...}`` of a breakdown's tools, as JSON writes them."""
    return {f"T{k}": {"tool_life_used": u.life_used, "tool_KRW": u.KRW} for k, u in sorted(breakdown.tools.items())}
