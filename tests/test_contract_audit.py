"""Inputs the recording and diagnosis contracts allow (or forbid) that no other test tried (the contract audit).

Each test names the clause of ``shared/spec/recording.md`` or ``shared/spec/diagnosis.md`` it checks; expected
values are derived by hand from the program or the file, not pasted from a run.
"""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.recording import Recording, RecordingError
from orchestrator.validation import validate_recording
from tests.test_input_fuzz_regressions import diagnosis_case

# ----------------------------------------------------------------------------- "line: source line number (1-based,
#                                                                  in the program file) of the block being executed"
#: A main program calling a one-block subprogram twice (M98 ... L2): the blocks run on lines 2, 7, 7, 4, 5.
SUBPROGRAM = ("G90 G17 G21 G94\n"   # 1
              "G0 X0 Y0 Z5.\n"      # 2
              "M98 P1001 L2\n"      # 3: a call, no block of its own
              "G0 Y10.\n"           # 4
              "M30\n"               # 5
              "O1001\n"             # 6
              "G91 G1 X5. F600\n"   # 7: runs twice
              "G90\n"               # 8: modal only
              "M99\n")              # 9


def _lines(values: list[float]) -> Recording:
    return Recording.from_channels({"t_s": 0.1 * np.arange(len(values)), "line": np.array(values, float)})


@pytest.mark.parametrize("lines", [
    [2, 2, 7, 7, 4, 5],          # as the twin records it: back from 7 to 4 after the subprogram returns
    [2, 3, 7, 3, 7, 4, 5],       # a controller that reports the M98 line while it calls
    [2, 7, 5],                   # a sparse logger that misses line 4
])
def test_a_subprogram_program_may_go_back_to_the_line_after_its_call(lines):
    validate_recording(_lines(lines), "sub.nc", program_text=SUBPROGRAM)


@pytest.mark.parametrize("lines, row, value, before", [
    ([2, 4, 7, 5], 3, 7, 4),     # line 7 runs only before line 4
    ([2, 7, 4, 2], 4, 2, 4),     # line 2 runs once, first
])
def test_lines_out_of_the_subprograms_execution_order_name_the_row(lines, row, value, before):
    with pytest.raises(RecordingError, match=rf"^<memory>: column 'line', row {row} .*: line {value} after line "
                                             rf"{before} is not in the order sub\.nc executes its blocks in"):
        validate_recording(_lines(lines), "sub.nc", program_text=SUBPROGRAM)


def test_a_straight_program_still_refuses_a_line_going_back():
    text = "G90 G0 X0 Y0 Z5.\nG1 X5. F600\nG1 Y5.\nM30\n"
    with pytest.raises(RecordingError, match=r"row 3 .*the line goes back from 3 to 2; p\.nc has no loops or "
                                             r"subprograms"):
        validate_recording(_lines([1, 3, 2, 4]), "p.nc", program_text=text)


# ----------------------------------------------------------------------------- "Every column is optional except t_s"
def test_currents_and_lines_without_positions_say_the_drive_diagnosis_needs_an_actual_position(tmp_path):
    """``t_s, line, x_tcmd_A`` is a legal recording, but the following error needs ``x_mm``: the message used to
    be 'no axis moves (commanded stroke below 10 µm)' for a program that moves X by 20 mm."""
    from orchestrator.diagnose import DiagnosisError, diagnose

    # the short program's G1 X20. is its line 4; 40 samples 5 ms apart
    body = "".join(f"{0.005 * k:.3f},4,0.5\n" for k in range(40))
    folder = diagnosis_case(tmp_path / "c", "t_s,line,x_tcmd_A\n" + body)
    with pytest.raises(DiagnosisError, match=r"recording\.csv: no axis has its actual position \('x_mm', 'y_mm' "
                                             r"or 'z_mm'\) in more than half of the rows; .*"
                                             r"\['t_s', 'line', 'x_tcmd_A'\]"):
        diagnose(folder)


# ----------------------------------------------------------------------------- diagnosis.md: "Effects are listed
#                                                                                 most certain first"
def test_drive_and_cutting_effects_are_listed_most_certain_first():
    """The cutting effects were appended after the drives' (and chatter put first among them whatever its
    confidence): a 0.999 runout came after a 0.95 gravity, a 0.8 chatter before the runout."""
    from types import SimpleNamespace

    from orchestrator.diagnose.cutting_merge import merge_cutting

    def effect(name, confidence):
        return {"effect": name, "confidence": confidence}

    d = SimpleNamespace(effects=[effect("gravity", 0.95), effect("backlash", 0.95)], unexplained=[],
                        rms_before={}, rms_after={}, noise={}, alignment={"time_offset_s": 0.0, "channels": {}},
                        log=[], notes=[], provenance={}, machine=None)
    cres = SimpleNamespace(effects=[effect("chatter", 0.8), effect("runout", 0.999), effect("tool_wear", 0.95)],
                           unexplained=[], rms_before={}, rms_after={}, noise={},
                           alignment={"channels": {}, "spindle_angle_deg": 0.0}, log=[], notes=[], machine_values={})
    merge_cutting(d, cres, SimpleNamespace(folder="case"))
    # by confidence; equal confidences in the order each half gave them, drives first
    assert [e["effect"] for e in d.effects] == ["runout", "gravity", "backlash", "tool_wear", "chatter"]


# ----------------------------------------------------------------------------- recording.md: "Sampling may be uneven"
PAIRS_PROGRAM = "G21 G90 G17\nS3000 M3\nG0 X0 Y0 Z5.\nG1 X20. F600\nG1 Y10.\nM5\nM30\n"


@pytest.fixture(scope="module")
def pairs_case(tmp_path_factory):
    """The twin's own run of PAIRS_PROGRAM, logged from the program start in 1 ms pairs every 5 ms."""
    from orchestrator.simulate import simulate

    folder = tmp_path_factory.mktemp("pairs")
    (folder / "program.nc").write_text(PAIRS_PROGRAM)
    (folder / "case.toml").write_text('program = "program.nc"\nrecording = "recording.csv"\n')
    own = simulate(case=folder, plot=False).recording
    own.take(np.arange(len(own)) % 5 < 2).write_csv(folder / "recording.csv")
    return folder


def test_the_twins_own_run_logged_in_1_ms_pairs_every_5_ms_names_no_effect(pairs_case):
    """The start fit of Z (at rest, its rapid about to start) found a velocity of nm/s on this noise-free file
    (0.17 um/s on a longer run of it), which set the replayed Z sliding: a Z pitch error and feed-forward were
    named (baseline Z following-error residual 0.83 um rms there). With a 0.1 um encoder's noise at least in the
    fit, Z starts at rest and nothing is named."""
    from orchestrator.diagnose import diagnose

    result = diagnose(pairs_case)
    assert result.effects == [], result.log
    for a in "xyz":
        assert result.rms_before[f"{a}_fe_um"] < 0.01


def test_servo_identification_on_the_twins_own_run_in_1_ms_pairs_is_exact(pairs_case):
    """The same start fit gave Z Svp 0.86 and Svi 4.7 (the truth: 1 on every factor)."""
    from orchestrator.identify import identify_servo

    fit = identify_servo([pairs_case])
    for a in "xyz":
        for symbol in ("Spp", "Svp", "Svi"):
            assert fit.scales_[a][symbol] == pytest.approx(1.0, abs=2e-3), (a, symbol)


# ----------------------------------------------------------------------------- exit status of the command line
@pytest.mark.parametrize("argv, message", [
    (["identify", "cutting", "CASE", "--out", "OUT", "--axes", "x"], "--axes applies to friction and servo only"),
    (["identify", "friction", "CASE", "--out", "OUT", "--machine", "default"], "--machine applies to servo only"),
])
def test_an_option_the_identification_does_not_take_exits_2_like_every_user_error(argv, message, capsys):
    """Every user error exits with status 2 and one 'cnctwin: error:' line (README, What happens when); these
    two exited with status 1 (SystemExit with the message)."""
    from orchestrator.cli import main

    assert main(argv) == 2
    assert capsys.readouterr().err.strip() == f"cnctwin: error: {message}" + (
        " (friction and cutting use the case's)" if "machine" in message else "")
