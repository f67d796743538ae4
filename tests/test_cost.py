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
