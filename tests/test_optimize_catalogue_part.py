"""The bundled catalogue part: its original conditions are the stated catalogue values and stay within 60 N.

``models/examples/catalogue_part`` is the like-for-like optimisation example (README "Optimisation"). Its
program comments state the conditions; this test derives them from the program and the loads from Eq. 10-13.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck import Arc, Linear, SpindleSpeed, interpret
from orchestrator.case import load_case
from orchestrator.optimize import build_reference

PART = Path(__file__).resolve().parent.parent / "models" / "examples" / "catalogue_part"
SLOTS, SHOULDER, CONTOUR = (17, 21), 25, tuple(range(29, 36))


@pytest.fixture(scope="module")
def reference():
    return build_reference(load_case(PART))


def test_conditions_are_the_documented_catalogue_values():
    blocks = interpret((PART / "program.nc").read_text(encoding="utf-8"), "program.nc").blocks
    rpm = [b.speed * 60.0 / (2.0 * math.pi) for b in blocks if isinstance(b, SpindleSpeed)]
    assert rpm == pytest.approx([8000.0])  # the spindle maximum: Vc = pi 6 mm 8000 / 1000 = 150.8 m/min
    assert math.pi * 6.0 * rpm[0] / 1000.0 == pytest.approx(150.8, abs=0.05)
    fz = {b.line: b.feed * 60000.0 / (2 * rpm[0]) for b in blocks if isinstance(b, (Linear, Arc))}
    for line in (*SLOTS, SHOULDER):
        assert fz[line] == pytest.approx(0.025)  # lowest chip load of the slotting range: F400
    for line in CONTOUR:
        assert fz[line] == pytest.approx(0.03125)  # F500, the top of the feed range


def test_original_stays_within_the_load_limit_with_the_derived_slot_loads(reference):
    ctx = reference.context
    assert ctx.lines.tolist() == [*SLOTS, SHOULDER, *CONTOUR]
    assert bool(reference.evaluation.feasible[0]) and reference.evaluation.max_load_N[0] <= 60.0
    # Full slot, 2 flutes: one tooth engaged, h = fz sin(phi), Ft = Kt a h, Fr = Ke Ft (Eq. 10-13):
    # the resultant peaks at phi = 90 deg: Kt a fz sqrt(1 + Ke^2) = 34.4 N at a = 1 mm, 51.6 N at 1.5 mm
    material = ctx.case.machine.si("material.A6061")
    kt, ke = material["kt"], material["ke"]
    loads = dict(zip(ctx.lines.tolist(), reference.evaluation.line_max_load_N[0].tolist()))
    for line, depth in zip(SLOTS, (1e-3, 1.5e-3)):
        assert loads[line] == pytest.approx(kt * depth * 0.025e-3 * np.sqrt(1.0 + ke**2), rel=0.01)
