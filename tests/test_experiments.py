"""Identification experiments: programs that the NC kernel accepts, case folders that load, sound plans."""
from __future__ import annotations

import math

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.experiments import (
    FRICTION_SPEEDS_MM_MIN, ExperimentError, plan_runs, write_experiment,
)
from orchestrator.machine import load_machine


def test_default_friction_speeds_span_the_stribeck_region():
    s = np.array(FRICTION_SPEEDS_MM_MIN)
    assert s[0] == 10.0 and s[-1] == 10000.0 and s.size == 16
    ratios = s[1:] / s[:-1]
    assert np.allclose(ratios, 10 ** 0.2, rtol=0.01)  # log-spaced, 5 per decade
    # paper Table 1: vs from 0.6 to 2 mm/s = 36 to 120 mm/min, inside the range with points on both sides
    assert (s < 36).sum() >= 3 and (s > 120).sum() >= 3


def test_plan_respects_stroke_and_plateau():
    m = load_machine("default")
    runs = plan_runs("z", (10.0, 1000.0, 10000.0), 1.0, m, 100.0, 0.3)
    for r in runs:
        assert r.stroke_mm <= 100.0 + 1e-9
        assert r.plateau_s >= 0.3
    # 10 mm/min with a 1 s plateau: travel = v T + v^2 / a + 2 v (jerk time 32 ms + filter 16 ms)
    v = 10.0 / 60.0
    assert runs[0].plateau_s == 1.0
    assert runs[0].stroke_mm == pytest.approx(v * 1.0 + v * v / 2000.0 + 2.0 * v * 0.048, abs=1e-3)
    # 10000 mm/min does not fit 1 s in 100 mm: shortened
    assert runs[2].plateau_s < 1.0
    with pytest.raises(ExperimentError, match="stroke limit"):
        plan_runs("z", (10000.0,), 1.0, m, 30.0, 0.3)
    with pytest.raises(ExperimentError, match="outside"):
        plan_runs("x", (20000.0,), 1.0, m, 200.0, 0.3)


@pytest.mark.parametrize("kind", ["friction", "servo", "cutting"])
def test_written_case_loads_and_program_parses(kind, tmp_path):
    from fmus_src.nck.component import NCKernel

    files = write_experiment(kind, tmp_path / kind)
    case = load_case(files["case"])
    assert case.program == files["program"]
    assert case.recording == tmp_path / kind / "recording.csv"
    assert (case.stock is not None) == (kind == "cutting")
    nck = NCKernel("nck", program_file=str(files["program"]))
    nck.setup(0.0)  # parses the whole program; raises on any unsupported word


def test_friction_program_moves_each_axis_out_and_back(tmp_path):
    files = write_experiment("friction", tmp_path, axes=("x", "y"), speeds_mm_min=(10.0, 100.0))
    text = files["program"].read_text()
    assert "G91" in text
    for axis in ("X", "Y"):
        moves = [float(line.split()[-2 if "F" in line.split()[-1] else -1][1:])
                 for line in text.splitlines() if line.startswith(("N", "G1")) and f" {axis}" in line]
        assert len(moves) == 4
        assert math.isclose(sum(moves), 0.0, abs_tol=1e-9)  # incremental moves return to the start


def test_unknown_kind_and_axis(tmp_path):
    with pytest.raises(ExperimentError, match="unknown experiment"):
        write_experiment("thermal", tmp_path)
    with pytest.raises(ExperimentError, match="unknown axis"):
        write_experiment("friction", tmp_path, axes=("a",))
