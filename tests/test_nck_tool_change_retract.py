"""M6 Z retract to the tool-change position (machine setting ``tool_change_retract``, off by default).

The truth: a VMC's tool-change macro sends Z up at rapid as ``G91 G28 Z0`` (or ``G91 G30 Z0``) does before the
swap, so M6 with the retract must plan exactly as the same program with that block written before a plain M6.
"""
from __future__ import annotations

import pytest

from fmus_src.nck import GCodeError, InterpreterSettings, NCKernel, Rapid, ToolChange, interpret
from orchestrator.machine import MachineFileError, load_machine
from orchestrator.twin import nck_parameters

MM = 1e-3
REF2 = (0.38, 0.225, 0.25)  # a 2nd reference position with Z below the 1st, m
PROGRAM = "G90 G54 G0 X10. Y10. G43 H1 Z20.\n{}T1 M6\nG0 Z5.\nM30\n"


def run(text: str, mode: str):
    settings = InterpreterSettings(tool_change_retract=mode, reference2=REF2, tool_lengths=[0.1])
    return interpret(text, "t.nc", settings).blocks


@pytest.mark.parametrize("mode, z", [("G28", 300.0), ("G30", 250.0)])
def test_m6_moves_z_straight_up_to_the_reference_z_then_the_tool_length_applies_again(mode, z):
    out = run(PROGRAM.format(""), mode)
    retract, change, down = out[1], out[2], out[3]
    assert isinstance(retract, Rapid) and retract.line == 2
    assert retract.start == pytest.approx((10 * MM, 10 * MM, 120 * MM))  # Z 20 + H1 100 mm
    assert retract.end == pytest.approx((10 * MM, 10 * MM, z * MM))
    assert isinstance(change, ToolChange)
    assert down.end[2] == pytest.approx(105 * MM)  # G43 H1 stays modal: Z 5 + 100 mm


def test_off_is_the_default_and_adds_no_move():
    assert InterpreterSettings().tool_change_retract == "off"
    out = run(PROGRAM.format(""), "off")
    assert [type(b).__name__ for b in out] == ["Rapid", "ToolChange", "Rapid", "ProgramEnd"]
    assert load_machine("default").values["nck"]["tool_change_retract"] == "off"


@pytest.mark.parametrize("mode, block", [("G28", "G91 G28 Z0.\nG90\n"), ("G30", "G91 G30 Z0.\nG90\n")])
def test_the_retract_plans_as_the_macro_block_written_out(mode, block):
    # the default machine's reference positions are machine coordinates, machine zero at axis (380, 225, 300) mm:
    # REF2 in the axis frame is machine (0, 0, -50) mm
    machine_ref2 = (0.0, 0.0, -0.05)
    params = {**nck_parameters(load_machine("default")), "tool_length_1": 0.1,
              **{f"reference2_{a}": v for a, v in zip("xyz", machine_ref2)}}
    with_retract = NCKernel(program_text=PROGRAM.format(""), **{**params, "tool_change_retract": mode})
    written = NCKernel(program_text=PROGRAM.format(block), **{**params, "tool_change_retract": "off"})
    with_retract.setup(0.0)
    written.setup(0.0)
    assert with_retract.duration_[0] == written.duration_[0]
    plain = NCKernel(program_text=PROGRAM.format(""), **params)
    plain.setup(0.0)
    # at least the extra Z travel (120 -> ref Z -> 105 instead of 120 -> 105) at the 30 m/min Z rapid rate
    extra = (2 * ({"G28": 300.0, "G30": 250.0}[mode] - 120.0)) * MM / (30.0 / 60.0)
    assert with_retract.duration_[0] - plain.duration_[0] >= extra
    a, b = with_retract.plan_.position[0], written.plan_.position[0]
    assert a.shape == b.shape and (a == b).all()


def test_no_move_when_z_is_already_there():
    out = run("G28 G91 Z0.\nG90\nT1 M6\nM30\n", "G28")
    assert sum(isinstance(b, Rapid) for b in out) == 1  # only the G28


@pytest.mark.parametrize("text, fragment", [
    ("G0 X0 Y0\nG68 X0 Y0 R30.\nT1 M6\nM30\n", "G68"),
    ("G0 X0 Y0 Z10.\nG81 X5. Z-5. R2. F100.\nT1 M6\nM30\n", "canned cycle G81"),
])
def test_retract_is_an_error_where_g28_is(text, fragment):
    with pytest.raises(GCodeError, match=fragment) as info:
        run(text, "G28")
    assert info.value.line == 3 and info.value.word == "M6"


def test_bad_machine_setting_names_the_line(tmp_path):
    text = load_machine("default").path.read_text()
    path = tmp_path / "bad.toml"
    path.write_text(text.replace('tool_change_retract = { value = "off"', 'tool_change_retract = { value = "Z"'))
    with pytest.raises(MachineFileError, match=r"tool_change_retract must be one of \['off', 'G28', 'G30'\]"):
        load_machine(path)
