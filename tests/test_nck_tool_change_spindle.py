"""M6 stops the spindle (machine setting ``tool_change_spindle``, "stop" by default; "keep": the old behaviour).

The truth, by hand on the default machine (spindle ramp 4000 rpm/s, speed arrival at 5 %, tool change 3 s,
Ts = 1 ms) and the two-tool program T1 M6 / S6000 M3 / slot / T2 M6 / S4000 M3 / slot:

* "stop": M6 stops the spindle (6000 -> 0 rpm in 6000 / 4000 = 1.5 s), then the 3 s tool change at rest;
  the spindle stays stopped until line 9's M3, then ramps 0 -> 4000 rpm and the cut waits 0.95 x 4000 / 4000
  = 0.95 s for speed arrival;
* "keep": the 3 s change at 6000 rpm, then 6000 -> 4000 rpm with the cut waiting (2000 - 200) / 4000 = 0.45 s;
* so "stop" takes 1.5 + 0.95 - 0.45 = 2.0 s longer, and T1 wears 3 s less at 6000 rpm but 1.5 s more on the
  ramp down: with Taylor's Tl = (C / V)^(1/n), the wear rate r ~ V^(1/n), and the linear ramp's wear is
  r(6000) x 1.5 s / (1/n + 1); T1's life used drops by r(6000) x (3 - 1.5 / (1/n + 1)).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.nck import GCodeError, InterpreterSettings, NCKernel, SpindleStop, ToolChange, interpret, plan_batch
from fmus_src.nck.errors import NCParameterError
from orchestrator.cost import CostModel, production_cost
from orchestrator.machine import MachineFileError, load_machine
from orchestrator.twin import nck_parameters
from tests.test_cutting_tool_table import PROGRAM as TWO_TOOL_PROGRAM

RPM = 2.0 * math.pi / 60.0
PROGRAM = TWO_TOOL_PROGRAM  # T1 slots at S6000, T2 M6, T2 slots at S4000
RAMP_DOWN_S = 6000.0 / 4000.0
CHANGE_S = 3.0
ARRIVAL_STOP_S = 0.95 * 4000.0 / 4000.0  # 0 -> 4000 rpm within 5 %
ARRIVAL_KEEP_S = (2000.0 - 0.05 * 4000.0) / 4000.0  # 6000 -> 4000 rpm within 5 %


@pytest.fixture(scope="module")
def kernels():
    params = nck_parameters(load_machine("default"))
    out = {}
    for mode in ("stop", "keep"):
        k = NCKernel(program_text=PROGRAM, **{**params, "tool_change_spindle": mode})
        k.setup(0.0)
        out[mode] = k
    return out


def _member(k: NCKernel):
    plan = k.plan_
    n = int(plan.done_index[0])
    ts = plan.period
    return (ts, plan.line[0][:n], plan.tool[0][:n], plan.spindle_ref[0][:n] / RPM, plan.spindle_speed[0][:n] / RPM)


def _first_cut(k: NCKernel, line: np.ndarray) -> int:
    """First sample of line 11's feed (after its wait for the spindle speed arrival): the path speed is 0 there
    and > 0 from the next sample on."""
    feed = k.plan_.feed[0][: len(line)]
    at11 = np.flatnonzero(line == 11)
    return int(at11[np.flatnonzero(feed[at11] > 0.0)[0]]) - 1


def test_default_machine_and_interpreter_stop_the_spindle():
    assert InterpreterSettings().tool_change_spindle == "stop"
    assert load_machine("default").values["nck"]["tool_change_spindle"] == "stop"
    assert NCKernel(program_text="M30\n").values["tool_change_spindle"] == "stop"


def test_m6_stops_first_then_changes_and_the_spindle_stays_stopped_until_m3(kernels):
    blocks = kernels["stop"].program_.blocks
    change = [i for i, b in enumerate(blocks) if isinstance(b, ToolChange)]
    # line 2: the spindle stands before the first M6, nothing to stop; line 8: stop, then the change at rest
    assert not isinstance(blocks[change[0] - 1], SpindleStop)
    stop = blocks[change[1] - 1]
    assert isinstance(stop, SpindleStop) and stop.line == 8 and blocks[change[1]].at_rest

    ts, line, tool, ref, speed = _member(kernels["stop"])
    at8 = np.flatnonzero(line == 8)
    # ramp down, then the change, one after the other; at rest: the first sample that is exactly 0 (the ramp's
    # 1.5 s in floating point leaves 1e-12 rpm at 1500 periods, so 1501)
    assert abs(len(at8) - (RAMP_DOWN_S + CHANGE_S) / ts) <= 1
    assert (ref[at8] == 0.0).all()
    ramp = len(at8) - round(CHANGE_S / ts)
    t = np.arange(ramp) * ts
    assert speed[at8[:ramp]] == pytest.approx(np.maximum(6000.0 - 4000.0 * t, 0.0), abs=1e-6)  # deceleration
    assert (speed[at8[ramp:]] == 0.0).all()  # the 3 s change at rest: no wear
    assert (tool[at8] == 1).all() and tool[at8[-1] + 1] == 2
    k9 = at8[-1] + 1  # line 9's M3 (the rapid of line 10 starts in the same sample)
    first_cut = _first_cut(kernels["stop"], line)  # line 10's rapid is shorter than the ramp: the cut waits
    assert ref[k9:first_cut + 1] == pytest.approx(4000.0) and ref[k9 - 1] == 0.0
    assert speed[k9] == 0.0  # M3 starts it from rest
    assert (first_cut - k9) * ts == pytest.approx(ARRIVAL_STOP_S, abs=ts / 2)
    assert speed[first_cut] == pytest.approx(0.95 * 4000.0, abs=1e-6)


def test_keep_turns_through_the_change_and_stop_costs_the_hand_time(kernels):
    ts, line, tool, ref, speed = _member(kernels["keep"])
    at8 = np.flatnonzero(line == 8)
    assert len(at8) == round(CHANGE_S / ts)
    assert ref[at8] == pytest.approx(6000.0) and speed[at8] == pytest.approx(6000.0)
    first_cut = _first_cut(kernels["keep"], line)
    assert (first_cut - (at8[-1] + 1)) * ts == pytest.approx(ARRIVAL_KEEP_S, abs=ts / 2)
    extra = kernels["stop"].duration_[0] - kernels["keep"].duration_[0]
    assert extra == pytest.approx(RAMP_DOWN_S + ARRIVAL_STOP_S - ARRIVAL_KEEP_S, abs=1.01 * ts)  # 2.0 s


def test_tool_wear_during_the_change_is_zero_and_t1_wears_the_hand_value_less(kernels):
    model = CostModel.from_machine(load_machine("default"))
    life = model.tool(6.0)  # T1 and T2 at [tool]'s 6 mm: T1's share is what the test checks
    used = {}
    for mode, k in kernels.items():
        ts, line, tool, ref, speed = _member(k)
        t = np.arange(len(line)) * ts
        used[mode] = production_cost(t, np.abs(speed), life, model, tool_in_spindle=tool).tools[1].life_used
        if mode == "stop":
            change = np.flatnonzero((line == 8) & (speed == 0.0))
            window = production_cost(t[change], speed[change], life, model, tool_in_spindle=tool[change])
            assert window.tool_life_used == 0.0 and len(change) == round(CHANGE_S / ts)
    n = life.taylor_n  # 0.15, the machine file's [cost]
    rate_6000 = float(life.wear_rate_per_s(np.array([6000.0]))[0])
    assert used["keep"] - used["stop"] == pytest.approx(rate_6000 * (CHANGE_S - RAMP_DOWN_S / (1.0 / n + 1.0)),
                                                       rel=1e-3)


def test_compiled_planner_equals_the_numpy_reference_bit_for_bit():
    from test_nck_plan_speed import assert_same

    rng = np.random.default_rng(11)
    k = NCKernel(program_text=PROGRAM, batch=4, **nck_parameters(load_machine("default")))
    k.set_overrides(spindle={3: rng.choice([3000.0, 6000.0, 8000.0], 4) * RPM,
                             9: rng.choice([2000.0, 4000.0, 6000.0], 4) * RPM})
    args = k.planning_inputs()
    assert {"stop", "tool"} <= {it.kind for it in args[0].items}
    assert_same(plan_batch(*args), plan_batch(*args, reference=True))


def test_m3_in_the_m6_block_restarts_and_s_alone_does_not():
    settings = InterpreterSettings()
    same_block = interpret("S6000 M3\nT2 M6 M3\nM30\n", "t.nc", settings).blocks
    assert [type(b).__name__ for b in same_block] == [
        "SpindleSpeed", "SpindleStop", "ToolChange", "SpindleSpeed", "ProgramEnd"]
    assert same_block[3].direction == 1 and same_block[3].speed == pytest.approx(6000.0 * RPM)  # S in effect
    s_alone = interpret("S6000 M3\nT2 M6\nS4000\nM30\n", "t.nc", settings).blocks
    assert s_alone[3].direction == 0  # an S word without M3/M4 leaves the spindle stopped
    kept = interpret("S6000 M3\nT2 M6\nS4000\nM30\n", "t.nc", InterpreterSettings(tool_change_spindle="keep"))
    assert [type(b).__name__ for b in kept.blocks] == ["SpindleSpeed", "ToolChange", "SpindleSpeed", "ProgramEnd"]
    assert kept.blocks[2].direction == 1


def test_the_stop_runs_with_the_z_retract_and_the_change_waits_for_both():
    # M6 with the retract from Z 10 to 300 mm (290 mm at 30 m/min: at least 0.58 s) while the spindle ramps down
    # from 6000 rpm (1.5 s): the change starts when both are done, max(retract, 1.5 s) after the M6 line starts
    params = {**nck_parameters(load_machine("default")), "tool_change_retract": "G28"}
    blocks = interpret("G0 Z10.\nS6000 M3\nT2 M6\nM30\n", "t.nc", InterpreterSettings(tool_change_retract="G28"))
    assert [type(b).__name__ for b in blocks.blocks] == [
        "Rapid", "SpindleSpeed", "SpindleStop", "Rapid", "ToolChange", "ProgramEnd"]
    text = "G0 Z10.\nS6000 M3\nG4 P2000\n{}T2 M6\nM30\n"  # the 2 s dwell brings the spindle to 6000 rpm
    runs = {}
    for name, program, mode in (("stop", text.format(""), "stop"), ("keep", text.format(""), "keep"),
                                ("M5 stop", text.format("M5\n"), "stop"), ("M5 keep", text.format("M5\n"), "keep")):
        k = NCKernel(program_text=program, **{**params, "tool_change_spindle": mode})
        k.setup(0.0)
        ts, line, _, _, speed = _member(k)
        m6 = np.flatnonzero(line == (5 if "M5" in name else 4))
        runs[name] = (k.duration_[0], len(m6) * ts, speed[m6[-1]])
    retract_s = runs["keep"][1] - CHANGE_S  # keep: the retract (and its in-position), then the change
    assert 290.0e-3 / 0.5 < retract_s < RAMP_DOWN_S
    assert runs["stop"][1] == pytest.approx(RAMP_DOWN_S + CHANGE_S, abs=1.01 * ts)
    assert runs["stop"][2] == 0.0 and runs["keep"][2] == pytest.approx(6000.0)
    # M5 written before M6: "stop" waits for its ramp the same way; "keep" changes during it, as before
    assert runs["M5 stop"][0] == runs["stop"][0] and runs["M5 keep"][0] == runs["keep"][0]
    assert runs["stop"][0] - runs["keep"][0] == pytest.approx(RAMP_DOWN_S - retract_s, abs=1.01 * ts)


def test_bad_settings_are_refused_naming_the_setting_and_the_machine_file_line(tmp_path):
    with pytest.raises(NCParameterError, match=r"tool_change_spindle must be one of \['stop', 'keep'\], got 'off'"):
        InterpreterSettings(tool_change_spindle="off")
    with pytest.raises(NCParameterError, match=r"NCKernel.tool_change_spindle must be one of \['stop', 'keep'\]"):
        NCKernel(program_text="M30\n", tool_change_spindle="halt").setup(0.0)
    text = load_machine("default").path.read_text()
    path = tmp_path / "bad.toml"
    path.write_text(text.replace('tool_change_spindle = { value = "stop"', 'tool_change_spindle = { value = "M5"'))
    line = 1 + text[: text.index("tool_change_spindle = {")].count("\n")
    with pytest.raises(MachineFileError, match=rf"bad.toml:{line}:.*tool_change_spindle.*\['stop', 'keep'\]"):
        load_machine(path)
    path.write_text("\n".join(s for s in text.splitlines() if not s.startswith("tool_change_spindle =")) + "\n")
    assert "tool_change_spindle" not in nck_parameters(load_machine(path))  # left out: the kernel's default, stop


def test_m6_error_without_a_tool_is_kept():
    with pytest.raises(GCodeError, match="M6 with no tool selected"):
        interpret("S6000 M3\nM6\nM30\n", "t.nc", InterpreterSettings())
