"""Decimal point input (FANUC No. 3401#0 DPI): ``"increment"`` (DPI = 0) reads numbers without a decimal point as
least input increments of IS-B (0.001 mm, 0.0001 in, 0.001 deg).

The truth of each case is the same program written with decimal points (what DPI = 0 must be equal to), read in
the default calculator mode: both must give the same blocks.
"""
from __future__ import annotations

import pytest

from fmus_src.nck import Dwell, GCodeError, InterpreterSettings, Linear, NCKernel, Rapid, interpret
from orchestrator.machine import MachineFileError, load_machine
from orchestrator.twin import nck_parameters

MM = 1e-3
INCREMENT = InterpreterSettings(decimal_input="increment", tool_lengths=[0.0])


def blocks(text: str, settings: InterpreterSettings = INCREMENT):
    return interpret(text, "t.nc", settings).blocks


def same_as_written_with_points(dpi0: str, with_points: str) -> None:
    assert blocks(dpi0) == blocks(with_points, InterpreterSettings(tool_lengths=[0.0]))


def test_x10_is_ten_micrometres_and_x10_point_is_ten_millimetres():
    ends = [b.end[0] for b in blocks("G21 G90 G0 X10\nX10.\nG20 X10\nM30\n") if isinstance(b, Rapid)]
    assert ends == pytest.approx([0.010 * MM, 10 * MM, 0.0010 * 25.4 * MM], rel=1e-12)


def test_calculator_type_is_the_default():
    assert InterpreterSettings().decimal_input == "calculator"
    ends = [b.end[0] for b in blocks("G90 G0 X10\nM30\n", InterpreterSettings()) if isinstance(b, Rapid)]
    assert ends == pytest.approx([10 * MM])


def test_arcs_by_r_and_by_ijk():
    same_as_written_with_points("G90 G0 X0 Y0\nG2 X20000 Y0 R10000 F300\nG3 X0 Y0 I-10000 J0\nM30\n",
                                "G90 G0 X0 Y0\nG2 X20. Y0 R10. F300\nG3 X0 Y0 I-10. J0\nM30\n")


def test_canned_cycle_levels_and_peck_scale_but_the_repeat_count_k_does_not():
    same_as_written_with_points("G90 G0 X0 Y0 Z10000\nG91 G99 G83 X5000 Z-5000 R-8000 Q2000 K3 F100\nG80\nM30\n",
                                "G90 G0 X0 Y0 Z10.\nG91 G99 G83 X5. Z-5. R-8. Q2. K3 F100\nG80\nM30\n")
    holes = {b.end[0] for b in blocks("G90 G0 X0 Y0 Z10.\nG91 G81 X5000 Z-5000 R-8000 K3 F100\nG80\nM30\n")
             if isinstance(b, Linear)}
    assert sorted(holes) == pytest.approx([5 * MM, 10 * MM, 15 * MM])  # three holes, 5 mm apart


def test_rotation_angle_and_polar_angle_are_in_thousandths_of_a_degree():
    same_as_written_with_points("G90 G0 X0 Y0\nG68 X0 Y0 R30000\nG1 X10000 F300\nG69\nM30\n",
                                "G90 G0 X0 Y0\nG68 X0 Y0 R30.\nG1 X10. F300\nG69\nM30\n")
    same_as_written_with_points("G90 G17 G0 X0 Y0\nG16\nG1 X10000 Y45000 F300\nG15\nM30\n",
                                "G90 G17 G0 X0 Y0\nG16\nG1 X10. Y45. F300\nG15\nM30\n")


def test_offsets_shifts_chamfers_and_the_scaling_centre_scale_but_magnifications_do_not():
    same_as_written_with_points("G10 L2 P1 X100000 Z-50000\nG10 L10 P1 R25000\nG90 G54 G43 H1 G0 X0 Y0 Z10000\n"
                                "G52 X1000\nG1 X20000 ,C2000 F300\nY20000\nG52 X0\n"
                                "G51 X10000 Y0 P2000\nG1 X15000\nG50\nM30\n",
                                "G10 L2 P1 X100. Z-50.\nG10 L10 P1 R25.\nG90 G54 G43 H1 G0 X0 Y0 Z10.\n"
                                "G52 X1.\nG1 X20. ,C2. F300\nY20.\nG52 X0\n"
                                "G51 X10. Y0 P2000\nG1 X15.\nG50\nM30\n")


def test_dwell_and_feed_without_a_point():
    # G4 P without a point is ms in both settings; G4 X is s under calculator input (DPI = 1) and counts the
    # 0.001 s increment under DPI = 0; F without a point under G21 G94 is mm/min in both settings
    text = "G90 G21 G94 G4 X2\nG4 P250\nG4 X1.5\nG1 X10. F600\nM30\n"
    assert [b.seconds for b in blocks(text) if isinstance(b, Dwell)] == pytest.approx([0.002, 0.25, 1.5])
    calculator = blocks(text, InterpreterSettings())
    assert [b.seconds for b in calculator if isinstance(b, Dwell)] == pytest.approx([2.0, 0.25, 1.5])
    assert [b for b in blocks(text) if not isinstance(b, Dwell)] == [b for b in calculator
                                                                     if not isinstance(b, Dwell)]


@pytest.mark.parametrize("text, word", [
    ("G20 G90 G1 X1. F20\nM30\n", "F20"),
    ("S1000 M3\nG95 G1 X1. F10\nM30\n", "F10"),
])
def test_f_without_a_point_under_inch_or_feed_per_revolution_is_refused(text, word):
    with pytest.raises(GCodeError, match="F with a decimal point") as info:
        blocks(text)
    assert info.value.word == word
    blocks(text.replace(word, word + "."))  # with the point it is read


def test_macro_values_are_real_values():
    # #17 = 3 is 3 mm of peck and #24 = 10 is X 10 mm: a variable is never a count of increments
    same_as_written_with_points("#24 = 10\n#17 = 3\nG90 G0 X0 Y0 Z10.\nG1 X#24 F300\n"
                                "G99 G83 X0 Z-6. R2. Q#17 F100\nG80\nM30\n",
                                "(#24)\n(#17)\nG90 G0 X0 Y0 Z10.\nG1 X10. F300\nG99 G83 X0 Z-6. R2. Q3. F100\nG80\nM30\n")


def test_g65_argument_without_a_point_is_refused():
    call = "G65 P9001 X10{}\nM30\nO9001\nG0 X#24\nM99\n"
    with pytest.raises(GCodeError, match="G65 argument X10 without a decimal point"):
        blocks(call.format(""))
    ends = [b.end[0] for b in blocks(call.format(".")) if isinstance(b, Rapid)]
    assert ends == pytest.approx([10 * MM])


def test_machine_file_setting_reaches_the_kernel(tmp_path):
    machine = load_machine("default")
    assert machine.values["nck"]["decimal_point_input"] == "calculator"
    params = nck_parameters(machine.with_values("nck", decimal_point_input="increment"))
    kernel = NCKernel(program_text="G90 G0 X0 Y0 Z10.\nG1 X10000 F600\nM30\n", **params)
    kernel.planning_inputs()
    assert [b.end[0] for b in kernel.blocks_ if isinstance(b, Linear)] == pytest.approx([10 * MM])
    path = tmp_path / "bad.toml"
    path.write_text(machine.path.read_text().replace('decimal_point_input = { value = "calculator"',
                                                     'decimal_point_input = { value = "DPI0"'))
    with pytest.raises(MachineFileError, match=r"decimal_point_input must be one of \['calculator', 'increment'\]"):
        load_machine(path)
