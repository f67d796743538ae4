"""The in-position model before rapids divides by the smallest position loop gain Kv: a machine file with a
Kv the model cannot use fails when it is read, naming the file, the line, the key and what was expected; the
kernel refuses such a gain when it gets one directly (an FMU parameter), instead of counting forever."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck import NCKernel, NCParameterError
from fmus_src.nck.servo_settle import servo_in_position
from orchestrator.machine import MACHINES_DIR, MachineFileError, load_machine

DEFAULT_TOML = (MACHINES_DIR / "default.toml").read_text(encoding="utf-8")


def with_axis_values(values: dict[str, str | None], axis: str = "y") -> tuple[str, int]:
    """default.toml with ``[axis.<axis>] key = value`` for each item (None: the line removed); the text and the
    1-based line of the first key."""
    lines = DEFAULT_TOML.splitlines()
    header = lines.index(f"[axis.{axis}]")
    rows = {key: next(i for i in range(header + 1, len(lines)) if re.match(rf"{key}\s*=", lines[i])) for key in values}
    for key, value in values.items():
        lines[rows[key]] = "" if value is None else f'{key} = {{ value = {value}, source = "test" }}'
    return "\n".join(lines) + "\n", rows[next(iter(values))] + 1


def load_text(tmp_path: Path, text: str) -> None:
    path = tmp_path / "mach.toml"
    path.write_text(text, encoding="utf-8")
    load_machine(path)


@pytest.mark.parametrize("value", ["0.0", "-50.0"])
def test_a_zero_or_negative_position_gain_fails_at_read_naming_file_line_and_key(tmp_path, value):
    text, n = with_axis_values({"position_gain_per_s": value})
    with pytest.raises(MachineFileError) as info:
        load_text(tmp_path, text)
    assert str(info.value) == f"{tmp_path / 'mach.toml'}:{n}: [axis.y] position_gain_per_s must be a number > 0, " \
                              f"got {float(value)!r}"


def test_a_missing_position_gain_fails_at_read(tmp_path):
    text, _ = with_axis_values({"position_gain_per_s": None})
    header = DEFAULT_TOML.splitlines().index("[axis.y]") + 1
    with pytest.raises(MachineFileError, match=rf"mach\.toml:{header}: section \[axis\.y\] is missing "
                                               r"\['position_gain_per_s'\]"):
        load_text(tmp_path, text)


@pytest.mark.parametrize("gain, scale, kv", [
    ("0.5", "0.01", "0.005"),      # each key > 0, Kv = 0.005 1/s below FANUC No. 1825's smallest 0.01 1/s
    ("1e-200", "1e-200", "0"),     # the product underflows to 0
])
def test_a_position_loop_gain_too_small_for_the_in_position_model_fails_at_read(tmp_path, gain, scale, kv):
    text, n = with_axis_values({"position_gain_per_s": gain, "position_scale": scale})
    with pytest.raises(MachineFileError) as info:
        load_text(tmp_path, text)
    message = str(info.value)
    assert message.startswith(f"{tmp_path / 'mach.toml'}:{n}: [axis.y] position_gain_per_s x position_scale = "
                              f"{float(gain)!r} x {float(scale)!r} = {kv} 1/s ")
    assert message.endswith("expected a finite Kv of at least 0.01 1/s (FANUC No. 1825's smallest setting)")


def test_the_smallest_position_loop_gain_loads(tmp_path):
    text, _ = with_axis_values({"position_gain_per_s": "0.01"})  # x position_scale 1.0 = 0.01 1/s
    load_text(tmp_path, text)


def test_the_kernel_refuses_a_position_gain_below_the_smallest_setting():
    with pytest.raises(NCParameterError, match=r"y_position_gain must be at least 0\.01 1/s .* got 0\.005"):
        NCKernel(program_text="G1 X1. F600\nG0 X0\nM30\n", y_position_gain=0.005).setup(0.0)


def test_the_servo_model_refuses_a_gain_whose_decay_rounds_away_instead_of_counting_forever():
    # exp(-1e-300 x 1e-3) == 1.0: the deviation of Y would never decay (the count used to loop without end)
    path = np.zeros((3, 3))
    path[1:, 1] = 1e-3
    with pytest.raises(NCParameterError, match=r"axis Y gives no decay"):
        servo_in_position(path, path[-1], (50.0, 1e-300, 50.0), 0.02e-3, 1e-3)
