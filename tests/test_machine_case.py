"""Machine parameter files and case folders: values, units, provenance, errors."""
from __future__ import annotations

import pytest

from orchestrator import MachineFileError, load_machine
from orchestrator.case import CaseError, load_case


def test_default_machine_holds_the_paper_values_in_si():
    m = load_machine("default")
    xp = m.si("axis.x.friction.positive")
    assert xp == {"coulomb": 641.6, "static": 775.2, "stribeck_velocity": 0.0016, "viscous": 7702.0}
    assert m.si("axis.y.friction.negative")["static"] == 1052.7
    assert m.si("axis.z.friction.positive")["viscous"] == 10313.1
    assert m.si("material.A6061") == {"kt": 1.23e9, "ke": 0.5, "ka": 0.28}  # ka: Altintas, no paper value
    cost = m.si("cost")
    assert cost["tool_change_time"] == 60.0 and cost["labor"] == 2.778 and cost["taylor_n"] == 0.15
    assert m.si("axis.x")["screw_lead"] == pytest.approx(0.012)
    assert m.si("nck")["max_cutting_feed"] == pytest.approx(10000 / 60000)
    assert m.si("spindle")["max_speed"] == pytest.approx(8000 * 2 * 3.141592653589793 / 60)


def test_every_default_value_has_provenance():
    m = load_machine("default")
    def leaves(node, prefix=""):
        for k, v in node.items():
            key = f"{prefix}.{k}" if prefix else k
            if isinstance(v, dict):
                yield from leaves(v, key)
            else:
                yield key
    missing = [k for k in leaves(m.values) if not k.startswith("machine.") and k not in m.provenance]
    assert missing == []
    assert all(s.startswith(("paper:", "assumption:")) for s in m.provenance.values())


def test_unknown_key_names_file_line_and_expected(tmp_path):
    text = (load_machine("default").path.read_text()).replace(
        "mass_kg = { value = 600.0", "mas_kg = { value = 600.0"
    )
    path = tmp_path / "typo.toml"
    path.write_text(text)
    with pytest.raises(MachineFileError) as info:
        load_machine(path)
    msg = str(info.value)
    line = next(i for i, l in enumerate(text.splitlines(), 1) if l.startswith("mas_kg"))
    assert f"typo.toml:{line}:" in msg and "'mas_kg'" in msg and "mass_kg" in msg


def test_missing_key_and_missing_file(tmp_path):
    text = load_machine("default").path.read_text()
    text = "\n".join(l for l in text.splitlines() if not l.startswith("ramp_rpm_per_s"))
    path = tmp_path / "short.toml"
    path.write_text(text)
    with pytest.raises(MachineFileError, match=r"\[spindle\] is missing \['ramp_rpm_per_s'\]"):
        load_machine(path)
    with pytest.raises(MachineFileError, match="no machine parameter set named 'nonesuch'"):
        load_machine("nonesuch")



def test_machine_file_without_the_newer_nck_keys_loads_with_the_shipped_values(tmp_path):
    # a user's machine file written before G28 and the peck cycles existed: the NC kernel's own defaults apply,
    # and they are the shipped file's values (0.2 mm, 0.5 mm), the reference positions in effect: the kernel's
    # (380, 225, 300) mm with machine zero at the axis origin are the shipped machine zero (380, 225, 300) mm +
    # reference position (0, 0, 0)
    from fmus_src.nck import NCKernel
    from orchestrator.machine import OPTIONAL_KEYS
    from orchestrator.twin import nck_parameters

    newer = OPTIONAL_KEYS["nck"]
    text = load_machine("default").path.read_text()
    text = "\n".join(l for l in text.splitlines() if l.split(" = ")[0] not in newer)
    path = tmp_path / "older.toml"
    path.write_text(text)
    params = nck_parameters(load_machine(path))
    from fmus_src.units import split_unit_suffix, to_si
    assert not {split_unit_suffix(k)[0] for k in newer} & set(params)
    shipped = load_machine("default").values["nck"]
    defaults = {v.name: v.start for v in NCKernel.variables}
    for key in newer:  # numbers in the key's unit (mm, ms), strings (rigid_tapping_mode, boring_shift) as they are
        name, symbol = split_unit_suffix(key)
        if name.startswith("machine_zero"):
            assert defaults[name] == 0.0  # machine coordinates = axis frame, as before the key existed
        elif name.startswith("reference"):
            shipped_axis = shipped[f"machine_zero_{name[-1]}_mm"] + shipped[key]
            assert defaults[name] == pytest.approx(to_si(shipped_axis, symbol), rel=1e-12)
        elif name == "in_position_before_rapid":  # the file's "on"/"off", the kernel's Boolean
            assert defaults[name] is (shipped[key] == "on")
        elif isinstance(shipped[key], str):
            assert defaults[name] == shipped[key]
        else:
            assert defaults[name] == pytest.approx(to_si(shipped[key], symbol), rel=1e-12)

def write_case(folder, body):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "case.toml").write_text(body)
    (folder / "program.nc").write_text("G21 G90\nM30\n")
    return folder


SPEC_CASE = '''program = "program.nc"
recording = "recording.csv"

[stock]
min = [0.0, 0.0, -20.0]
max = [100.0, 60.0, 0.0]

[tool]
diameter_mm = 6.0
flutes = 2

[machine]
parameters = "default"
'''


def test_spec_example_case_loads(tmp_path):
    case = load_case(write_case(tmp_path / "c", SPEC_CASE))
    assert case.program == tmp_path / "c" / "program.nc"
    assert case.recording == tmp_path / "c" / "recording.csv"
    assert case.stock.min_mm == (0.0, 0.0, -20.0) and case.stock.max_mm == (100.0, 60.0, 0.0)
    assert case.tool.diameter_mm == 6.0 and case.tool.flutes == 2
    assert case.machine.name == "default" and case.material == "A6061"


@pytest.mark.parametrize(
    "change, match",
    [
        (("flutes = 2", "flutes = 2.5"), r"case.toml:10: \[tool\] flutes"),
        (("diameter_mm = 6.0", "diamter_mm = 6.0"), r"case.toml:9: unknown field 'diamter_mm' in \[tool\]"),
        (("max = [100.0, 60.0, 0.0]", "max = [100.0, 60.0]"), r"case.toml:6: \[stock\] max must be a list of 3"),
        (("max = [100.0, 60.0, 0.0]", "max = [100.0, 60.0, -30.0]"), "must exceed min"),
        (('parameters = "default"', 'parameters = "nope.toml"'), "nope.toml: machine parameter file not found"),
    ],
)
def test_bad_cases_name_file_line_field(tmp_path, change, match):
    with pytest.raises((CaseError, MachineFileError), match=match):
        load_case(write_case(tmp_path / "c", SPEC_CASE.replace(*change)))
