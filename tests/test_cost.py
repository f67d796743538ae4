"""Production cost (paper Eq. 19-22, Table 3) against hand-derived values."""
from __future__ import annotations

import math

import numpy as np
import pytest

from orchestrator import load_machine
from orchestrator.cost import CostModel, production_cost


def test_cost_model_reads_table_3():
    model = CostModel.from_machine(load_machine("default"))
    assert model == CostModel(20000.0, 60.0, 2.778, 0.063, 0.15, 300.0)


def test_constant_speed_reduces_to_paper_equations():
    model = CostModel()
    rpm, d, tp = 6000.0, 6.0, 30.0
    v = math.pi * d * rpm / 1000.0                      # m/min
    tl = (300.0 / v) ** (1 / 0.15) * 60.0               # Eq. 22, min -> s
    ct = tp / tl * 20000.0 + tp / tl * 60.0 * (2.778 + 0.063)   # Eq. 20
    cm = tp * (2.778 + 0.063)                           # Eq. 21
    t = np.linspace(0.0, tp, 3001)
    cost = production_cost(t, np.full_like(t, rpm), d, model)
    assert cost.tool_life_used == pytest.approx(tp / tl, rel=1e-12)
    assert cost.tool_KRW == pytest.approx(ct, rel=1e-12)
    assert cost.machining_KRW == pytest.approx(cm, rel=1e-12)
    assert cost.total_KRW == pytest.approx(ct + cm, rel=1e-12)


def test_tool_life_is_only_used_while_the_spindle_turns():
    model = CostModel()
    t = np.linspace(0.0, 20.0, 2001)
    rpm = np.where(t < 10.0, 8000.0, 0.0)
    cost = production_cost(t, rpm, 6.0, model)
    tl = model.tool_life_s(8000.0, 6.0)
    assert cost.tool_life_used == pytest.approx(10.0 / tl, rel=2e-3)  # trapezoid over the step at t = 10 s
    assert cost.machining_KRW == pytest.approx(20.0 * 2.841)


def test_faster_spindle_wears_the_tool_faster():
    model = CostModel()
    lives = model.tool_life_s(np.array([1000.0, 4000.0, 8000.0]), 6.0)
    assert lives[0] > lives[1] > lives[2]
    # Taylor: T2/T1 = (V1/V2)^(1/n)
    assert lives[1] / lives[2] == pytest.approx(2.0 ** (1 / 0.15), rel=1e-12)


def _old_single_sum(t, rpm, d, model, tp):
    """The cost as computed before tools were told apart: one Miner's sum over the whole history."""
    v = math.pi * d * np.abs(rpm) / 1000.0
    rate = (v / model.taylor_C) ** (1.0 / model.taylor_n) / 60.0
    used = float(np.sum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t)))
    krw = model.labor_KRW_per_s + model.depreciation_KRW_per_s
    tool = used * model.tool_price_KRW + used * model.tool_change_time_s * krw
    return used, tool, tool + tp * krw


def test_one_tool_after_tool_0_costs_bit_for_bit_the_single_sum():
    """T1 M6 at t = 2 s with the spindle at rest (the bundled parts): tool 0 uses no life and is not listed;
    T1's Miner sum and the cost are the single sum over the whole history, bit for bit."""
    from orchestrator.cost import ToolUse

    model = CostModel.from_machine(load_machine("default"))
    t = np.arange(20001) * 1e-3
    rpm = np.clip((t - 3.0) * 4000.0, 0.0, 6000.0) * (t < 15.0)  # ramp to 6000 rpm, run, stop at 15 s
    tool = np.where(t < 2.0, 0.0, 1.0)
    used, tool_krw, total = _old_single_sum(t, rpm, 6.0, model, 20.0)
    for in_spindle in (None, tool, np.ones_like(t)):
        cost = production_cost(t, rpm, 6.0, model, 20.0, in_spindle)
        assert (cost.tool_life_used, cost.tool_KRW, cost.total_KRW) == (used, tool_krw, total)
    assert production_cost(t, rpm, 6.0, model, 20.0, tool).tools == {1: ToolUse(used, tool_krw)}
    assert production_cost(t, rpm, 6.0, model, 20.0).tools == {0: ToolUse(used, tool_krw)}  # no tool channel


def test_two_tools_each_wear_with_their_own_diameter_price_and_taylor_constants():
    """T1 (6 mm, the machine's Pt and Taylor C, n) 10 s at 6000 rpm; the spindle stops, T2 (10 mm, its own
    Pt = 50000 KRW, C = 400 m/min, n = 0.25) 15 s at 4000 rpm. Each step of the speed between two 1 ms
    samples adds half a sample to the trapezoid: 10.0005 s and 15.0005 s at speed."""
    model = CostModel.from_machine(load_machine("default"))
    t = np.arange(30001) * 1e-3
    tool = np.where(t < 12.0, 1.0, 2.0)
    rpm = np.where(t <= 10.0 + 1e-9, 6000.0, np.where(t >= 15.0 - 1e-9, 4000.0, 0.0))
    tools = {2: model.tool(10.0, price_KRW=50000.0, taylor_C=400.0, taylor_n=0.25)}
    cost = production_cost(t, rpm, 6.0, model, 30.0, tool, tools)
    tl1 = (300.0 / (math.pi * 6.0 * 6000.0 / 1000.0)) ** (1 / 0.15) * 60.0   # V = 113.1 m/min: 40 051 s
    tl2 = (400.0 / (math.pi * 10.0 * 4000.0 / 1000.0)) ** (1 / 0.25) * 60.0  # V = 125.7 m/min: 6160 s
    used1, used2 = 10.0005 / tl1, 15.0005 / tl2
    assert cost.tools[1].life_used == pytest.approx(used1, rel=1e-9)
    assert cost.tools[2].life_used == pytest.approx(used2, rel=1e-9)
    tc_krw = 60.0 * (2.778 + 0.063)
    assert cost.tools[1].KRW == pytest.approx(used1 * (20000.0 + tc_krw), rel=1e-9)
    assert cost.tools[2].KRW == pytest.approx(used2 * (50000.0 + tc_krw), rel=1e-9)
    assert cost.tool_life_used == pytest.approx(used1 + used2, rel=1e-12)
    assert cost.total_KRW == pytest.approx(30.0 * 2.841 + used1 * (20000.0 + tc_krw) + used2 * (50000.0 + tc_krw),
                                           rel=1e-9)
    # with [tool]'s 6 mm for both (before): T2's life would have been (10/6)^(1/0.15) = 30.1 times longer
    one = production_cost(t, rpm, 6.0, model, 30.0)
    assert one.tool_life_used == pytest.approx(used1 + 15.0005 / model.tool_life_s(4000.0, 6.0), rel=1e-9)
