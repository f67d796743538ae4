"""The optimiser on a slot cut out and back on one line (the SolidCAM post's O5002 form), and its fallback to the
Z-map model when members of the search lose the path mode's path while the original program follows it.

Hand numbers: a full slot 1 mm deep with a 6 mm two-flute end mill at F300, S6000 (fz = 0.025 mm) has the peak
Fc = Kt a fz sqrt(1 + Ke^2) = 1.23e9 x 1e-3 x 2.5e-5 x sqrt(1.25) = 34.38 N (one tooth at 90 deg).
"""
from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

from orchestrator.optimize import OptimizeSettings, backends, optimize
from orchestrator.optimize.checkpoint import latest_checkpoint
from orchestrator.optimize.reference import OFF_PATH

PROGRAM = """G21 G17 G90 G94 G54
S6000 M3
G0 X-5. Y10. Z2.
G1 Z-1. F300
X20.
X-5.
G0 Z5.
M30
"""
CASE = ('program = "program.nc"\n[stock]\nmin = [0.0, 0.0, -10.0]\nmax = [40.0, 20.0, 0.0]\n'
        '[tool]\ndiameter_mm = 6.0\nflutes = 2\n[machine]\nparameters = "default"\n')
HAND_N = 1.23e9 * 1e-3 * 300.0 / (6000.0 * 2) * 1e-3 * math.sqrt(1.25)  # 34.38 N


@pytest.fixture
def slot_case(tmp_path):
    folder = tmp_path / "slot"
    folder.mkdir()
    (folder / "case.toml").write_text(CASE)
    (folder / "program.nc").write_text(PROGRAM)
    return folder


def _settings(gens: int = 1):
    return OptimizeSettings(objective="time", pop=3, gens=gens, seed=1, progress=False, plot=False, check_front=False,
                            tidy=False)


def test_a_slot_out_and_back_optimises_in_path_mode(slot_case, tmp_path):
    out = tmp_path / "out"
    result = optimize(case=slot_case, settings=_settings(), out=out)
    report = json.loads((out / "report.json").read_text())
    assert report["search_cutting_model"] == "path" and report["notes"] == []
    assert report["before"]["max_cutting_load_N"] == pytest.approx(HAND_N, abs=0.05)
    # line 5 (X20.) cuts the slot; line 6 (X-5.) only its servo-lag tail (the tool still reaches for the end
    # after the command turns back); together 6 x 1 x 20 mm plus the half disc at the end (pi 3^2 / 2 x 1 mm),
    # less what the servo's shortfall at the turn leaves (within 0.5 %)
    removed = report["removed_mm3_by_line"]
    assert [row["line"] for row in report["lines"]] == [5, 6] and removed["6"] < 0.01 * removed["5"]
    assert removed["5"] + removed["6"] == pytest.approx(120.0 + 4.5 * math.pi, rel=5e-3)
    # the written program (re-simulated on the Z-map model): the slot's load is the hand number at its F and S
    row = report["lines"][0]
    fz = row["feed_after_mm_per_min"] / (row["spindle_after_rpm"] * 2) * 1e-3
    assert report["after"]["max_cutting_load_N"] == pytest.approx(1.23e9 * 1e-3 * fz * math.sqrt(1.25), abs=0.05)
    assert result.evaluations >= 2 and report["after"]["feasible"]
    assert report["after"]["cycle_time_s"] < report["before"]["cycle_time_s"]


def test_members_losing_the_path_move_the_search_to_the_zmap_model(slot_case, tmp_path, monkeypatch):
    """The path mode follows the original; from the second generation on, members whose feed differs from it
    are made to fail as a member losing the path does (the master's message, the line named by the figures):
    the search restarts on the Z-map model and the report's note names the line, instead of ending with every
    member failed."""
    real = backends.evaluate_population
    calls = []

    def losing(ctx, feeds, spindles):
        ev = real(ctx, feeds, spindles)
        calls.append(ctx.engagement is not None)
        if ctx.engagement is None or len(calls) < 2:  # the first generation follows the path; the second loses it
            return ev
        for b in np.flatnonzero(np.any(np.asarray(feeds) != ctx.original_feed, axis=1)):
            ev.success[b] = ev.feasible[b] = False
            ev.cycle_time_s[b] = ev.cost_KRW[b] = ev.max_load_N[b] = np.nan
            ev.reason[b] = (f"simulation failed: {ctx.case.program}:6: failed at t = 9.000000 s: cutting: member "
                            f"{b} at [0.0199, 0.01, -0.001] m is farther than path_tolerance = 0.0005 m from the "
                            "engagement table's path")
        return ev

    monkeypatch.setattr(backends, "evaluate_population", losing)
    out = tmp_path / "out"
    optimize(case=slot_case, settings=_settings(gens=2), out=out)
    report = json.loads((out / "report.json").read_text())
    assert calls[:2] == [True, True] and not any(calls[2:])  # restarted on the Z-map model after generation 2
    assert report["search_cutting_model"] == "zmap" and len(report["history"]) == 2
    # the checkpoints left are the Z-map search's (a resume does not mix in the path-mode generations)
    state = latest_checkpoint(out)
    assert state["generation"] == 2 and len(list((out / "checkpoints").glob("gen_*.pkl"))) == 2
    assert not any(OFF_PATH in r for ev in state["cache"].values() for r in ev.reason)
    assert len(report["notes"]) == 1
    assert re.search(r"a member of the search loses the path-mode cutting load's path although the original "
                     r"program follows it \(.*slot/program\.nc:6: .*farther than path_tolerance.*\): the search ran "
                     r"on the Z-map cutting model", report["notes"][0])
    # the search on the Z-map model found programs of its own: the written one is faster, within the limit
    assert report["after"]["feasible"] and report["after"]["max_cutting_load_N"] <= 60.0
    assert report["after"]["cycle_time_s"] < report["before"]["cycle_time_s"]
    assert report["lines"][0]["feed_after_mm_per_min"] != 300.0
