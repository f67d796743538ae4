"""The control's tool offset memory stated in case.toml (``[offsets] radius_mm`` / ``length_mm``) reaches the NC kernel."""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.case import CaseError, ToolOffsets, load_case
from orchestrator.twin import build_twin, reference_path

#: G41 D1 around the 20 x 20 mm square (0,0)-(20,20), clockwise (climb): with D1 = 3 mm the tool centre
#: runs on the square (-3,-3)-(23,23); G43 H1 adds H1 to Z.
PROGRAM = ("G21 G90 G17 G40 G49\nG0 X-10. Y-10. Z5.\nG43 H1 Z5.\nG1 Z-1. F300.\nG41 D1 X0. Y0. F600.\nY20.\nX20.\n"
           "Y0.\nX0.\nG40 X-10. Y-10.\nG0 Z5.\nM30\n")
CASE = 'program = "program.nc"\n\n[offsets]\nradius_mm = { 1 = 3.0 }\nlength_mm = { 1 = 0.5 }\n'


def _write(folder, body: str):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "case.toml").write_text(body)
    (folder / "program.nc").write_text(PROGRAM)
    return folder


def test_offsets_table_loads_and_defaults_to_zero(tmp_path):
    case = load_case(_write(tmp_path / "c", CASE))
    assert case.offsets == ToolOffsets({1: 3.0}, {1: 0.5})
    assert case.offsets.nck_parameters() == pytest.approx({"tool_radius_1": 3e-3, "tool_length_1": 0.5e-3})
    plain = load_case(_write(tmp_path / "p", 'program = "program.nc"\n'))
    assert plain.offsets == ToolOffsets() and plain.offsets.nck_parameters() == {}


def test_twin_runs_the_offset_path_of_the_case_registers(tmp_path):
    case = load_case(_write(tmp_path / "c", CASE))
    twin = build_twin(case, options=None)
    assert twin.nck.values["tool_radius_1"][0] == pytest.approx(3e-3)
    twin.nck.setup(0.0)
    ends = {(round(b.end[0] * 1e3, 9), round(b.end[1] * 1e3, 9)) for b in twin.nck.program_.blocks
            if hasattr(b, "end") and b.line in (6, 7, 8)}
    assert ends == {(-3.0, 23.0), (23.0, 23.0), (23.0, -3.0)}  # the square offset by 3 mm (intersections)
    z_cut = [b.end[2] for b in twin.nck.program_.blocks if getattr(b, "line", 0) == 4]
    assert z_cut == pytest.approx([-0.5e-3])  # Z-1 + H1 (0.5 mm)
    path = reference_path(case)  # the engagement table's path is the offset one too
    gap = np.linalg.norm(path[:, :2] - np.array([23e-3, 23e-3]), axis=1)
    assert gap.min() < 0.1e-3  # passes the offset corner (within the acc/dec corner blend) ...
    assert np.linalg.norm(path[:, :2] - np.array([20e-3, 20e-3]), axis=1).min() > 2.9e-3  # ... not the part's


@pytest.mark.parametrize("body, match", [
    (CASE + "wear_mm = { 1 = 0.1 }\n", r"case.toml:6: unknown field 'wear_mm' in \[offsets\]"),
    (CASE.replace("{ 1 = 3.0 }", "{ 201 = 3.0 }"), r"case.toml:4: \[offsets\] radius_mm: unknown register '201'; "
                                                    r"expected D numbers 1..200"),
    (CASE.replace("{ 1 = 0.5 }", "{ H1 = 0.5 }"), r"\[offsets\] length_mm: unknown register 'H1'; expected H"),
    (CASE.replace("{ 1 = 3.0 }", '{ 1 = "3" }'), r"case.toml:4: \[offsets\] radius_mm: D1 must be a number in mm"),
    (CASE.replace("{ 1 = 3.0 }", "{ 1 = nan }"), r"D1 must be a number in mm"),
    (CASE.replace("radius_mm = { 1 = 3.0 }", "radius_mm = 3.0"), r"radius_mm must be a table of register"),
])
def test_bad_offsets_name_case_toml_and_key(tmp_path, body, match):
    with pytest.raises(CaseError, match=match):
        load_case(_write(tmp_path / "c", body))
