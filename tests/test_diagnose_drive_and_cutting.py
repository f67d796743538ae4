"""Feed drives and cutting process diagnosed together on one cutting recording (drives on).

Recordings: :func:`orchestrator.diagnose.cutting_case.write_cutting_case` with the short program (slots 1 and
2 mm deep in x, a side pass in y), a 2.5 kHz dynamometer with 1 N noise and the 1.7 ms CNC logger. Expected
values are the hidden truths; the held-current mechanism is checked against the independent truth servo.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.diagnose import diagnose
from orchestrator.diagnose.columns import AxisColumns
from orchestrator.diagnose.cutting_case import LOGGER_START_S, SHORT_PROGRAM, write_cutting_case
from orchestrator.diagnose.model import Simulated
from orchestrator.diagnose.prepare import twin_commands
from orchestrator.diagnose.replay import run_replay
from orchestrator.diagnose.rest import leave_out_held_current, stuck_stretches
from orchestrator.diagnose.truth import simulate_truth
from orchestrator.diagnose.truth_cutting import (Dynamometer, cutting_parameters_packed, fine_grid,
                                                 simulate_cutting, tick_mean)
from orchestrator.twin import engagement_table

DYN = Dynamometer(period_s=0.4e-3)


def test_the_held_current_of_a_loaded_hold_is_left_out_and_still_counted():
    # motor: moves, sticks from 0.2 to 0.6 s, moves again; the load is on only while it sticks
    t = np.linspace(0.0, 1.0, 1001)
    motor = np.where(t < 0.2, t, np.where(t < 0.6, 0.2, 0.2 + (t - 0.6)))
    assert stuck_stretches(t, motor) == [(200, 600)]
    rows = np.arange(t.size)
    sigma = 0.02
    held = np.where((t >= 0.2) & (t <= 0.6), 0.05 + 0.3 * (t - 0.4), 0.0)  # not predictable: left out
    y = np.concatenate([np.zeros(t.size), held / sigma])
    column = np.concatenate([np.zeros(t.size), np.ones(t.size)])
    cols = {"y": AxisColumns(rows, rows, 0.4, sigma, y, {"c": column}, {"o": column.copy()}, [])}
    sim = Simulated({}, {}, {"y": motor[:, None]}, {})
    counts = leave_out_held_current(t, cols, sim, {"y": lambda q: np.where((q > 0.3) & (q < 0.5), 30.0, 0.0)})
    assert counts == {"y": 1}
    c = cols["y"]
    kept = np.r_[0:200, 601:1001]
    np.testing.assert_array_equal(c.rows_tc, kept)                 # the 401 rows of the hold are gone
    assert c.rows_left_out == 401 and c.y.size == t.size + kept.size
    assert not np.any(c.y[t.size:])                                 # what is left is what was predictable
    assert c.columns["c"].size == c.artefacts["o"].size == c.y.size
    # an unloaded axis keeps its rows (its replay holds the recorded current exactly)
    cols = {"y": AxisColumns(rows, rows, 0.4, sigma, y, {}, {}, [])}
    assert leave_out_held_current(t, cols, sim, {"y": lambda q: np.zeros_like(q)}) == {}
    assert cols["y"].rows_tc.size == t.size


def test_a_hold_is_split_into_its_rests_and_the_creep_between_them():
    # 1 ms samples: moves at 10 mm/s, rests, creeps by 20 nm slips every 5 ms (stick-slip under a load: 1.2
    # mm/min within a slip step, below the 3 mm/min creep limit), rests again, moves on. The creep's 4 ms
    # pauses are not rests of their own (< 20 ms).
    k = np.arange(1001)
    t = k * 1e-3
    creep = np.clip((k - 500) // 5, 0, 20) * 20e-9
    motor = np.where(k < 200, (k - 200) * 1e-5, np.where(k <= 700, creep, creep[700] + (k - 700) * 1e-5))
    assert stuck_stretches(t, motor) == [(200, 504), (505, 599), (600, 700)]
    # a real move, however slow the programmed feed (100 mm/min = 1.7 mm/s), is no hold
    assert stuck_stretches(t, k * 1.7e-6) == []


@pytest.fixture(scope="module")
def clean_seed3(tmp_path_factory):
    """The clean truth recording of seed 3 (shared: the held-current check and a clean diagnosis read it)."""
    return write_cutting_case(tmp_path_factory.mktemp("clean3") / "c", {}, 3, program=SHORT_PROGRAM, dynamometer=DYN)


def test_truth_and_twin_hold_the_same_current_under_the_same_cutting_load(clean_seed3):
    """The independent truth (Karnopp, Euler substeps) and the twin's exact stick agree when loaded alike.

    The held current of y while x slots differs by far more than the logger's 0.01 A only when the replay
    is loaded by a noisy force: the baseline physics of both is the same.
    """
    case = load_case(clean_seed3)
    machine = case.machine
    nc = twin_commands(case, machine)
    first = simulate_truth(machine, nc, {}, axes=("x", "y", "z"))
    t_f = fine_grid(LOGGER_START_S, float(first.t[-1]))
    pos = np.column_stack([np.interp(t_f, first.t, first.table[a]) for a in "xyz"])
    omega = np.interp(t_f, np.asarray(nc.t, float), np.asarray(nc["spindle_rpm"], float)) * 2.0 * math.pi / 60.0
    packed = cutting_parameters_packed(machine, case.material, case.tool.diameter_mm * 1e-3, case.tool.flutes,
                                       {}, 0.0)
    run = simulate_cutting(engagement_table(case), t_f, pos, omega, packed)
    tv = float(machine.si("servo")["velocity_loop_period"])
    force = {"x": run.fx, "y": run.fy}
    truth = simulate_truth(machine, nc, {}, axes=("x", "y"),
                           disturbance={a: (lambda tk, f=force[a]: tick_mean(t_f, f, tk, tv)) for a in "xy"})
    same = {a: (lambda q, f=force[a]: tick_mean(t_f, f, q + 0.5 * tv, tv)) for a in "xy"}
    rep = run_replay(machine, truth.t_cmd, truth.ref, truth.t, t_start=float(truth.t_cmd[0]), disturbance=same)
    assert float(np.max(np.abs(run.fy))) > 20.0  # y is loaded while it stands still
    for a in "xy":  # 1/5 of the logger's current resolution, 1/50 of its encoder's
        assert np.max(np.abs(truth.current[a] - rep.current[a][:, 0])) < 0.002
        assert np.max(np.abs(truth.motor[a] - rep.motor[a][:, 0])) < 0.02e-6


@pytest.mark.parametrize("seed", [3, 5])
def test_clean_cutting_recording_with_drives_on_has_no_effects(seed, tmp_path, clean_seed3):
    folder = clean_seed3 if seed == 3 else write_cutting_case(tmp_path / f"clean{seed}", {}, seed,
                                                              program=SHORT_PROGRAM, dynamometer=DYN)
    d = diagnose(folder)
    assert d.effects == [], d.log
    spurious = [u for u in d.unexplained if any(ch.endswith(("_tcmd_A", "_fe_um")) for ch in u["channels"])]
    assert spurious == [], spurious
    for a in "xyz":
        assert d.rms_after[f"{a}_tcmd_A"] < 1.5 * d.noise[f"{a}_tcmd_A"]


def test_drive_and_cutting_effects_in_one_recording_are_both_found(tmp_path):
    edge = {"kte_N_per_mm": 8.0, "kre_N_per_mm": 5.0}
    folder = write_cutting_case(tmp_path / "both", {"edge_force": edge}, 3, program=SHORT_PROGRAM, dynamometer=DYN,
                                drive_effects={"x": {"friction_mismatch": {"coulomb_N": 50.0}}})
    d = diagnose(folder)
    found = {(e["effect"], e.get("axis")): e for e in d.effects}
    assert set(found) == {("friction_mismatch", "x"), ("edge_force", None)}, d.log
    assert found[("friction_mismatch", "x")]["parameters"]["coulomb_N"] == pytest.approx(50.0, rel=0.1)
    for key, value in edge.items():
        assert found[("edge_force", None)]["parameters"][key] == pytest.approx(value, rel=0.1)
    assert d.unexplained == []
