"""A tool table per case: each tool of a program (T words, M6) cuts with its own cutter.

``[tools.T<n>]`` of case.toml (:func:`orchestrator.case.load_case`) lists cutters by tool number; the Z-map
cutting load takes the NC kernel's tool in the spindle and switches each member's radius and teeth at a tool
change (:mod:`fmus_src.cutting.tool_table`). Checked against hand calculations on a program that slots with
T1 (6 mm, 2 flutes), then with T2 (10 mm, 4 flutes) at its own F and S:

* removed volume of a full slot through the block = width (its own diameter) x depth x block length;
* peak cutting load of a full slot = Kt a fz sqrt(1 + Ke^2) with fz = F / (z S) of its own teeth (for two
  teeth, one tooth at 90 deg; for four teeth, the two engaged teeth 90 deg apart sum to that value at every
  angle: (Fx, Fy) = Kt a fz (-Ke, 1));
* the compiled master loop, the Python master and the numpy kernel give the same recording bit for bit;
* a case whose table lists T1 equal to [tool] runs bit for bit as the case without a table (paper part);
* the path mode (the optimiser's search): each engagement-table station carries the cutter that swept it, the
  slots meet the same hand values and the Z-map mode's results, and the optimiser searches such a case in
  path mode.
"""
from __future__ import annotations

import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from fmus_src.cutting.component import CuttingLoad
from orchestrator.case import CaseError, load_case
from orchestrator.compiled import compiled_support
from orchestrator.master import Master, MasterSettings
from orchestrator.simulate import simulate
from orchestrator.twin import TwinOptions, build_twin
from tests.test_cutting_path_reversal import _per_line
from test_compiled_master import _assert_same

MM = 1e-3
BLOCK_X_MM = 12.0  # the stock's length along the slots
PROGRAM = """G21 G90 G17
T1 M6
S6000 M3
G0 X-5. Y10. Z2.
G1 Z-1. F300
X17. F300
G0 Z5.
T2 M6
S4000 M3
G0 X-6. Y28. Z2.
G1 Z-1. F300
X18. F600
G0 Z5.
M30
"""
CASE = """program = "program.nc"
[stock]
min = [0.0, 0.0, -10.0]
max = [12.0, 40.0, 0.0]
{tool}
[tools.T2]
diameter_mm = 10.0
flutes = 4
[machine]
parameters = "default"
"""
TOOL_1 = "[tool]\ndiameter_mm = 6.0\nflutes = 2"


def _case_folder(folder, tool=TOOL_1, program=PROGRAM, case=CASE):
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "case.toml").write_text(case.format(tool=tool))
    (folder / "program.nc").write_text(program)
    return folder


@pytest.fixture(scope="module")
def two_tools(tmp_path_factory):
    case = load_case(_case_folder(tmp_path_factory.mktemp("two_tools")))
    return case, simulate(case=case, plot=False)


def test_each_slot_removes_its_own_width_and_peaks_at_its_own_hand_calculation(two_tools):
    case, result = two_tools
    assert result.success, result.message
    peak, removed = _per_line(result.recording)
    kt = case.machine.si(f"material.{case.material}")["kt"]
    ke = case.machine.si(f"material.{case.material}")["ke"]
    # slot 1 (lines 5-7: plunge in air, slot, lift): 6 mm wide, 1 mm deep through the 12 mm block
    assert removed[5] + removed[6] + removed[7] == pytest.approx(6.0 * 1.0 * BLOCK_X_MM, rel=1e-3)  # 72 mm3
    # slot 2 (lines 11-13) with T2: 10 mm wide (with the [tool] cutter it would be 72 mm3 again)
    assert removed[11] + removed[12] + removed[13] == pytest.approx(10.0 * 1.0 * BLOCK_X_MM, rel=1e-3)  # 120 mm3
    # slot 1: F300, S6000, 2 teeth: fz = 0.025 mm -> 34.38 N
    fz1 = 300.0 / (2 * 6000.0) * MM
    assert peak[6] == pytest.approx(kt * 1 * MM * fz1 * math.sqrt(1 + ke * ke), abs=0.05)
    # slot 2: F600, S4000, 4 teeth: fz = 0.0375 mm -> 51.57 N (with 2 teeth it would be 103 N)
    fz2 = 600.0 / (4 * 4000.0) * MM
    assert peak[12] == pytest.approx(kt * 1 * MM * fz2 * math.sqrt(1 + ke * ke), abs=0.1)
    assert result.summary["tool_changes"] == [{"line": 2, "tool": 1}, {"line": 8, "tool": 2}]
    # T1 is not listed: the note says it is cut with [tool] (T2 has its own cutter)
    assert len(result.summary["notes"]) == 1 and "T1 " in result.summary["notes"][0]
    assert "T2" in result.summary["notes"][0] and "6 mm, 2 flutes" in result.summary["notes"][0]


def _short_twin(case, batch=1):
    """The two-slot twin with a 0.2 s tool change, for 6.6 s: slot 1's end, both tool changes, slot 2's start
    (line 8's M6 stops the spindle: 1.5 s down from S6000, then 0.95 s up to S4000 instead of 0.45 s)."""
    twin = build_twin(case, batch=batch, options=TwinOptions(cutting_mode="zmap"))
    twin.nck.set("tool_change_time", 0.2)
    settings = MasterSettings(step=twin.options.step, time_limit=6.6, stop_when=twin.stop_when,
                              limits=twin.limits or {}, check_every=10)
    return twin, settings


def test_compiled_loop_python_master_and_numpy_kernel_agree_bit_for_bit(tmp_path, monkeypatch):
    program = PROGRAM.replace("X-5. Y10.", "X2. Y10.").replace("X17. F300", "X6. F600")  # a short slot 1
    case = load_case(_case_folder(tmp_path, program=program))
    runs = []
    for compiled, kernel in ((True, True), (False, True), (False, False)):
        with monkeypatch.context() as m:
            m.setattr(CuttingLoad, "use_compiled", kernel)
            twin, settings = _short_twin(case)
            settings.compiled = compiled
            master = Master(twin.system, settings, twin.probes)
            if compiled:
                assert compiled_support(master) is None, compiled_support(master)
            runs.append(master.run())
    _assert_same(runs[0], runs[1])
    _assert_same(runs[0], runs[2])
    rec = runs[0].recording
    line = np.asarray(rec["line"]).ravel()
    teeth = np.asarray(rec["fc_peak_N"]).ravel()
    assert np.nanmax(teeth[line == 6]) > 10.0 and np.nanmax(teeth[line == 12]) > 10.0  # both slots cut


def test_a_table_listing_t1_as_tool_runs_the_paper_part_bit_for_bit(tmp_path):
    folder = tmp_path / "paper"
    shutil.copytree(Path(__file__).resolve().parents[1] / "models" / "examples" / "paper_part", folder)
    plain = simulate(case=load_case(folder), plot=False)
    with open(folder / "case.toml", "a") as f:
        f.write("\n[tools.T1]\ndiameter_mm = 6.0\nflutes = 2\n")
    listed = load_case(folder)
    assert listed.tools and not listed.several_tools()
    table = simulate(case=listed, plot=False)
    assert plain.success and table.success
    assert plain.recording.channels == table.recording.channels
    for ch in plain.recording.channels:
        np.testing.assert_array_equal(plain.recording.data[ch], table.recording.data[ch], err_msg=ch)
    assert "notes" not in table.summary  # T1 listed: nothing assumed


def test_tool_table_parsing(tmp_path):
    case = load_case(_case_folder(tmp_path))
    assert case.tools == {2: type(case.tool)(10.0, 4)} and case.tool_stated and case.several_tools()
    assert case.tool_for(2).diameter_mm == 10.0 and case.tool_for(7) == case.tool
    bad = {
        "[tools.X2]\ndiameter_mm = 3.0\nflutes = 2\n": r"case.toml:11: unknown tool 'X2' in \[tools\]",
        "[tools.T3]\ndiameter_mm = 3.0\nflutes = 0\n": r"case.toml:13: \[tools.T3\] flutes must be a whole",
        "[tools.T3]\ndiameter_mm = -3.0\nflutes = 2\n": r"case.toml:12: \[tools.T3\] diameter_mm must be",
        "[tools.T3]\nflutes = 2\n": r"case.toml:11: \[tools.T3\] needs 'diameter_mm'",
        "[tools.T3]\ndiameter_mm = 3.0\nflutes = 2\nlength_mm = 50.0\n":
            r"case.toml:14: unknown field 'length_mm' in \[tools.T3\]",
        "[tools.T02]\ndiameter_mm = 3.0\nflutes = 2\n": r"case.toml:11: \[tools.T02\] lists T2 a second time",
    }
    base = CASE.format(tool=TOOL_1).replace('[machine]\nparameters = "default"\n', "")
    for extra, pattern in bad.items():  # each names case.toml and the line of the key
        (tmp_path / "case.toml").write_text(base + extra)
        with pytest.raises(CaseError, match=pattern):
            load_case(tmp_path)
    (tmp_path / "case.toml").write_text('program = "program.nc"\ntools = 3\n')
    with pytest.raises(CaseError, match=r"case.toml:2: 'tools' must be a table of tools"):
        load_case(tmp_path)


def test_without_tool_an_unlisted_tool_is_refused_naming_the_m6_and_the_case(tmp_path):
    folder = _case_folder(tmp_path, tool="[tools.T1]\ndiameter_mm = 6.0\nflutes = 2")
    case = load_case(folder)
    assert not case.tool_stated and set(case.tools) == {1, 2}
    build_twin(case)  # T1 and T2 listed: fine
    (folder / "program.nc").write_text(PROGRAM.replace("T2 M6", "T3 M6"))
    with pytest.raises(CaseError, match=rf"program.nc:8: M6 changes to T3, which {folder / 'case.toml'} does not "
                                        r"list \(its \[tools\] has T1, T2"):
        build_twin(case)


@pytest.fixture(scope="module")
def two_tools_path(two_tools):
    case, _ = two_tools
    return simulate(case=case, plot=False, options=TwinOptions(cutting_mode="path"))


def test_path_mode_cuts_each_slot_with_its_own_cutter(two_tools, two_tools_path):
    """The path mode (the optimiser's search model): the engagement table's stations carry the cutter that
    sweeps them; each slot removes its own width and peaks at its own hand value, as the Z-map mode."""
    case, zmap = two_tools
    from orchestrator.twin import engagement_table

    table = engagement_table(case)
    assert table.several_cutters and table.cutters() == [(3e-3, 2), (5e-3, 4)]  # T1 ([tool]), then T2
    assert table.radius == 3e-3  # the default cutter's, checked against tool_diameter
    result = two_tools_path
    assert result.success, result.message
    peak, removed = _per_line(result.recording)
    kt = case.machine.si(f"material.{case.material}")["kt"]
    ke = case.machine.si(f"material.{case.material}")["ke"]
    assert removed[5] + removed[6] + removed[7] == pytest.approx(6.0 * 1.0 * BLOCK_X_MM, rel=1e-3)  # 72 mm3
    assert removed[11] + removed[12] + removed[13] == pytest.approx(10.0 * 1.0 * BLOCK_X_MM, rel=1e-3)  # 120 mm3
    fz1 = 300.0 / (2 * 6000.0) * MM  # 34.38 N
    assert peak[6] == pytest.approx(kt * 1 * MM * fz1 * math.sqrt(1 + ke * ke), abs=0.05)
    fz2 = 600.0 / (4 * 4000.0) * MM  # 51.57 N (cut with T1's 2 teeth: 103 N)
    assert peak[12] == pytest.approx(kt * 1 * MM * fz2 * math.sqrt(1 + ke * ke), abs=0.1)
    # path and Z-map mode agree on the same run
    peak_z, removed_z = _per_line(zmap.recording)
    assert result.summary["cycle_time_s"] == zmap.summary["cycle_time_s"]
    for line in (6, 12):
        assert peak[line] == pytest.approx(peak_z[line], abs=0.05)
        assert removed[line] == pytest.approx(removed_z[line], rel=1e-3)


def test_path_mode_compiled_loop_and_python_master_agree_bit_for_bit(tmp_path):
    """One member, and 8 members in two blocks of threads (the table's station cutters shared by them)."""
    program = PROGRAM.replace("X-5. Y10.", "X2. Y10.").replace("X17. F300", "X6. F600")  # a short slot 1
    case = load_case(_case_folder(tmp_path, program=program))
    runs = []
    for compiled, batch, threads in ((True, 1, 1), (False, 1, 1), (True, 8, 2)):
        twin = build_twin(case, batch=batch, options=TwinOptions(cutting_mode="path"))
        twin.nck.set("tool_change_time", 0.2)
        settings = MasterSettings(step=twin.options.step, time_limit=6.6, stop_when=twin.stop_when,
                                  limits=twin.limits or {}, check_every=10, compiled=compiled, threads=threads)
        master = Master(twin.system, settings, twin.probes)
        if compiled:
            assert compiled_support(master) is None, compiled_support(master)
        runs.append(master.run())
    _assert_same(runs[0], runs[1])
    assert np.asarray(runs[2].recording.data["fc_peak_N"]).shape[1] == 8
    for ch in runs[0].recording.channels:  # every member of the blocks equals the single run
        one = np.asarray(runs[0].recording.data[ch]).reshape(-1)  # (n,): one member
        many = np.asarray(runs[2].recording.data[ch])
        for m in range(many.shape[1] if many.ndim == 2 else 1):  # the time axis is (n,) for both
            column = many[:, m] if many.ndim == 2 else many
            np.testing.assert_array_equal(column, one, err_msg=f"{ch}, member {m}")
    rec = runs[0].recording
    line = np.asarray(rec["line"]).ravel()
    peak = np.asarray(rec["fc_peak_N"]).ravel()
    assert np.nanmax(peak[line == 6]) > 10.0 and np.nanmax(peak[line == 12]) > 10.0  # both slots cut


def test_path_mode_refuses_what_it_cannot_carry_for_several_cutters(two_tools):
    from fmus_src.cutting.component import CuttingError
    from fmus_src.cutting.path_component import PathCuttingLoad
    from fmus_src.cutting.table import EngagementTable
    from orchestrator.diagnose.cutting_table import one_cutter_table
    from orchestrator.diagnose.errors import DiagnosisError
    from orchestrator.twin import cutting_parameters, engagement_table, reference_path

    case, _ = two_tools
    params = cutting_parameters(case)
    one = EngagementTable.from_parameters(reference_path(case), params)  # built without the cutters
    several = engagement_table(case)

    def setup(table, **extra):
        cut = PathCuttingLoad("cutting", **{**params, **extra})
        cut.attach_table(table)
        cut.setup(0.0)

    with pytest.raises(CuttingError, match=r"lists T2 \(10 mm, 4 flutes\).*built for one cutter"):
        setup(one)
    with pytest.raises(CuttingError, match=r"10 mm, 4-flute cutter that member 0's tool table .* does not list"):
        setup(several, tool_1_diameter=8e-3)
    with pytest.raises(CuttingError, match=r"several cutters and an effect term that depends on the teeth"):
        setup(several, runout_eccentricity=1e-5)
    setup(several)  # the case's own parameters
    with pytest.raises(DiagnosisError, match=r"case.toml: \[tools\] lists cutters other than \[tool\]"):
        one_cutter_table(case)


def test_station_cutters_follow_the_tool_that_reached_each_path_point():
    """A straight path: points 0-2 reached with a 6 mm 2-flute cutter, 3-4 with a 10 mm 4-flute one. A station
    takes the cutter of the point that ends its segment; a member takes its station's (ceil(s / ds))."""
    from fmus_src.cutting import path_kernel as pk
    from fmus_src.cutting.table import build_engagement_table

    path = np.column_stack([np.arange(5) * MM, np.zeros(5), np.full(5, 5 * MM)])  # in the air above the block
    cutters = (np.array([6, 6, 6, 10, 10]) * MM, np.array([2, 2, 2, 4, 4]))
    table = build_engagement_table(path, 6 * MM, [0, 0, -MM], [MM, MM, 0], 1e-4, spacing=0.25 * MM,
                                   cutters=cutters)
    s = np.arange(17) * 0.25 * MM  # stations; segment 2 (2-3 mm) ends at point 3, the 10 mm cutter's
    assert table.cutter_radius.tolist() == [3 * MM if x < 2 * MM else 5 * MM for x in s]
    assert table.cutter_flutes.tolist() == [2 if x < 2 * MM else 4 for x in s]
    par = np.zeros((5, 3))
    st = np.zeros((pk.ST_ROWS, 3))
    st[pk.ST_S] = [1.9 * MM, 2.0 * MM, 2.1 * MM]  # -> stations 8 (2 mm, on segment 2), 8, 9
    pk.station_cutters(par, st, table.cutter_radius, table.cutter_flutes, table.spacing)
    assert par[pk.PAR_RADIUS].tolist() == [5 * MM] * 3 and par[pk.PAR_FLUTES].tolist() == [4] * 3
    st[pk.ST_S] = [1.74 * MM, 0.0, 1.5 * MM]  # stations 7, 0, 6: the 6 mm cutter
    pk.station_cutters(par, st, table.cutter_radius, table.cutter_flutes, table.spacing)
    assert par[pk.PAR_RADIUS].tolist() == [3 * MM] * 3 and par[pk.PAR_FLUTES].tolist() == [2] * 3
    one = build_engagement_table(path, 6 * MM, [0, 0, -MM], [MM, MM, 0], 1e-4, spacing=0.25 * MM)
    assert not one.several_cutters and one.cutter_radius.size == 0
    pk.station_cutters(par, st, one.cutter_radius, one.cutter_flutes, one.spacing)  # one cutter: untouched
    assert par[pk.PAR_RADIUS].tolist() == [3 * MM] * 3


def test_members_with_their_own_tables_in_two_threads_match_the_python_master(tmp_path):
    """Member 1's T2 is an 8 mm 3-flute cutter: each member switches to its own; the compiled loop in two
    member blocks equals the Python master bit for bit."""
    program = PROGRAM.replace("X-5. Y10.", "X2. Y10.").replace("X17. F300", "X6. F600")
    case = load_case(_case_folder(tmp_path, program=program))
    runs = []
    for compiled in (True, False):
        twin, settings = _short_twin(case, batch=2)
        for name, value in (("tool_1_diameter", 8e-3), ("tool_1_flutes", 3)):
            arr = twin.cutting.get(name)
            arr[1] = value
            twin.cutting.set(name, arr)
        settings.compiled, settings.threads = compiled, 2
        runs.append(Master(twin.system, settings, twin.probes).run())
    _assert_same(runs[0], runs[1])
    rec = runs[0].recording
    line = np.asarray(rec["line"])[:, 0]
    peak = np.asarray(rec["fc_peak_N"])
    slot2 = line == 12
    # slot 2's start: the members' loads differ (10 mm 4 flutes vs 8 mm 3 flutes at the same F and S)
    assert np.nanmax(peak[slot2, 0]) > 10.0 and np.nanmax(peak[slot2, 1]) > 10.0
    assert not np.array_equal(peak[slot2, 0], peak[slot2, 1])


def test_the_optimiser_searches_several_cutters_in_path_mode(tmp_path):
    """A short two-tool case: T1 (6 mm, 2 flutes) slots 4 mm at F300 S6000 (34.38 N), T2 (10 mm, 4 flutes)
    4 mm at F600 S4000 (51.57 N). The search runs in path mode, and the written program, re-simulated on the
    Z-map model, stays within the 60 N limit."""
    import json

    from orchestrator.optimize import OptimizeSettings, optimize

    program = PROGRAM.replace("X-5. Y10.", "X4. Y10.").replace("X17. F300", "X12. F300")
    program = program.replace("X-6. Y28.", "X3. Y28.").replace("X18. F600", "X12. F600")
    folder = _case_folder(tmp_path / "case", program=program)
    settings = OptimizeSettings(objective="time", load_limit_N=60.0, feed_range=(100, 800), pop=4, gens=1,
                                seed=1)
    result = optimize(case=folder, settings=settings, out=tmp_path / "opt")
    report = json.loads((tmp_path / "opt" / "report.json").read_text())
    assert report["search_cutting_model"] == "path"
    assert not any("Z-map" in note for note in report["notes"])
    assert report["before"]["max_cutting_load_N"] == pytest.approx(51.57, abs=0.1)  # slot 2, the Z-map run
    assert result.after["max_cutting_load_N"] <= 60.0  # the written program, re-simulated on the Z-map model


def test_the_optimiser_keeps_the_zmap_model_for_tooth_effects_with_several_cutters(two_tools, monkeypatch):
    """Runout (or helix, edge force, deflection, chatter) with several cutters: the path mode refuses the pair,
    so the search runs on the Z-map model and the note says why."""
    from orchestrator.optimize import reference

    case, _ = two_tools
    monkeypatch.setattr(reference, "cutting_effect_parameters", lambda machine: {"runout_eccentricity": 1e-5})
    assert "turns on runout_eccentricity" in reference.path_mode_limit(case)
    monkeypatch.setattr(reference, "cutting_effect_parameters", lambda machine: {"wear_rate": 1e-3})
    assert reference.path_mode_limit(case) == ""  # wear scales Kt: any cutter
    monkeypatch.setattr(reference, "cutting_effect_parameters", lambda machine: {"helix_angle": 0.5})
    ref = reference.build_reference(case)
    assert ref.context.engagement is None
    assert re.search(r"turns on helix_angle, which the path-mode cutting load models for one cutter: the search "
                     r"ran on the Z-map cutting model", ref.context.search_model_note)


def test_tool_table_packing_lookup_and_errors():
    from fmus_src.cutting.component import CuttingError
    from fmus_src.cutting.tool_table import ToolTable, slot_of, slots, table_variables

    values = {v.name: np.full(2, v.start, dtype=np.int64 if v.type == "Integer" else np.float64)
              for v in table_variables()}
    values["tool_diameter"], values["flutes"] = np.array([6e-3, 6e-3]), np.array([2, 2])
    values["tool_3_number"] = np.array([2, 0])  # member 1: slot 3 empty (diameter 0 there)
    values["tool_3_diameter"] = np.array([10e-3, 0.0])
    values["tool_3_flutes"] = np.array([4, 0])
    values["tool_5_number"] = np.array([7, 2])
    values["tool_5_diameter"] = np.array([4e-3, 8e-3])
    values["tool_5_flutes"] = np.array([3, 3])
    table = ToolTable.from_values(values, 2, "cutting", CuttingError)
    assert table.number.tolist() == [[-1, 2, 7], [-1, 0, 2]]  # default column, then the used slots 3 and 5
    # T2 -> 5 mm radius for member 0 (slot 3), 4 mm for member 1 (slot 5); T9 and T0 -> the default
    for tool, expected in (([2, 2], [1, 2]), ([7, 7], [2, 0]), ([9, 0], [0, 0])):
        k = slots(table, np.array(tool))
        assert k.tolist() == expected
        assert [slot_of(table.number, m, float(tool[m])) for m in range(2)] == expected
    assert table.radius[[0, 1], slots(table, np.array([2, 2]))].tolist() == [5e-3, 4e-3]
    assert table.smallest_radius().tolist() == [2e-3, 3e-3]  # member 1's empty slot (radius 0) left out
    for name, value, message in (("tool_5_number", [7, 7], r"lists T7 in a second slot"),
                                 ("tool_5_number", [-1, 2], r"tool_5_number: member 0 has -1"),
                                 ("tool_5_flutes", [0, 3], r"tool_5_flutes: member 0 has 0 for T7")):
        bad = dict(values)
        bad[name] = np.array(value)
        if name == "tool_5_number" and value == [7, 7]:
            bad["tool_3_number"] = np.array([2, 7])
            bad["tool_3_diameter"] = np.array([10e-3, 5e-3])
            bad["tool_3_flutes"] = np.array([4, 2])
        with pytest.raises(CuttingError, match=message):
            ToolTable.from_values(bad, 2, "cutting", CuttingError)


def test_the_ssp_export_of_a_two_tool_case_runs_as_the_case(two_tools, tmp_path):
    from orchestrator.simulate import simulate_system_file
    from orchestrator.twin import write_twin_ssp

    case, result = two_tools
    ssd, _ = write_twin_ssp(case, tmp_path / "two_tools.ssd")
    text = ssd.read_text()
    assert 'startElement="nck" startConnector="tool" endElement="cutting" endConnector="tool"' in text
    system = simulate_system_file(ssd)
    assert system.success, system.message
    for ch in result.recording.channels:
        np.testing.assert_array_equal(system.recording.data[ch], result.recording.data[ch], err_msg=ch)
    # the cost per tool from the .ssv's tool table (the SSP file holds no cost keys: the machine's Table 3 values)
    assert system.summary["cost"]["tools"] == result.summary["cost"]["tools"]


def test_notes_name_only_the_tools_the_table_does_not_list():
    from orchestrator.summary import tool_notes

    changes = [(2, 1), (9, 2), (15, 3)]
    assert tool_notes(changes, True, 6.0, 2, listed=(1, 2, 3))[1] == []  # every tool listed: nothing assumed
    notes = tool_notes(changes, True, 6.0, 2, listed=(1, 2))[1]
    assert len(notes) == 1 and "uses T3 (the first change to one at line 15)" in notes[0]
    assert "(T1, T2)" in notes[0] and "6 mm, 2 flutes" in notes[0]
    # one tool, listed in no table: [tool] is that tool, as before; with a table that misses it: noted
    assert tool_notes([(2, 5)], True, 6.0, 2)[1] == []
    assert "uses T5" in tool_notes([(2, 5)], True, 6.0, 2, listed=(1,))[1][0]
    assert tool_notes(changes, False, 6.0, 2, listed=(1,))[1] == []  # no stock: no cutting load


def test_the_diagnosis_memo_key_tells_tool_tables_apart(tmp_path):
    from dataclasses import replace

    from orchestrator.diagnose.prepare import run_key

    case = load_case(_case_folder(tmp_path))
    plain = replace(case, tools={})
    assert run_key(case, case.machine) != run_key(plain, case.machine)
    assert run_key(plain, case.machine) == run_key(replace(plain), case.machine)


PRICED_T2 = "flutes = 4\nprice_KRW = 50000.0\ntaylor_C = 400.0\ntaylor_n = 0.25\n"


def test_each_tool_wears_with_its_own_cutter_and_price(two_tools, tmp_path):
    """The cost's Miner sum goes, sample by sample, to the tool in the spindle (the recording's ``tool``): T1
    (6 mm, the machine's Pt 20000 KRW, C 300, n 0.15) and T2 (10 mm; with its own Pt 50000 KRW, C 400, n 0.25
    in case.toml). Hand value: the sum over samples of dt / Tl, Tl = (C / V)^(1/n) min, V = pi D_k S (the
    rectangle rule over the 1 ms samples, against the cost's trapezoid: within 1e-4)."""
    from orchestrator.cost import CostModel, case_tool_lives
    from orchestrator.summary import summarize

    case, result = two_tools
    rec = result.recording
    t, rpm, tool = rec.t, np.abs(rec["spindle_rpm"]), rec["tool"]
    assert set(np.unique(tool).tolist()) == {0.0, 1.0, 2.0}  # T0 until line 2's M6, T1, T2 from line 8's
    tp = result.summary["cycle_time_s"]
    n = np.searchsorted(t, t[0] + tp + 1e-9)
    t, rpm, tool = t[:n], rpm[:n], tool[:n]
    dt = np.diff(t)
    tc_krw = 60.0 * (2.778 + 0.063)

    def hand(k, d_mm, c, exponent):
        at = (tool[:-1] == k) & (rpm[:-1] > 0.0)  # at rest the tool does not wear (Tl infinite)
        tl_s = (c / (np.pi * d_mm * rpm[:-1][at] / 1000.0)) ** (1.0 / exponent) * 60.0
        return float(np.sum(dt[at] / tl_s))

    plain = result.summary["cost"]["tools"]
    assert set(plain) == {"T1", "T2"}  # T0: the spindle stood before the first M6
    assert plain["T1"]["tool_life_used"] == pytest.approx(hand(1, 6.0, 300.0, 0.15), rel=1e-4)
    assert plain["T2"]["tool_life_used"] == pytest.approx(hand(2, 10.0, 300.0, 0.15), rel=1e-4)
    assert plain["T2"]["tool_KRW"] == pytest.approx(plain["T2"]["tool_life_used"] * (20000.0 + tc_krw), rel=1e-12)
    # at least the time T1 ran at S6000 / Tl(pi 6 mm 6000 rpm); at most all its turning time at that life
    at_speed = np.sum(dt[(tool[:-1] == 1) & (rpm[:-1] == 6000.0)])
    turning = np.sum(dt[(tool[:-1] == 1) & (rpm[:-1] > 0.0)])
    tl_1 = (300.0 / (np.pi * 6.0 * 6000.0 / 1000.0)) ** (1 / 0.15) * 60.0
    assert at_speed / tl_1 < plain["T1"]["tool_life_used"] < turning / tl_1
    assert result.summary["cost"]["tool_life_used"] == pytest.approx(
        plain["T1"]["tool_life_used"] + plain["T2"]["tool_life_used"], rel=1e-12)

    priced = load_case(_case_folder(tmp_path, case=CASE.replace("flutes = 4\n", PRICED_T2)))
    assert priced.tools[2].price_KRW == 50000.0 and priced.tool.price_KRW is None
    assert priced.several_tools() and priced.tools[2].same_cutter(case.tools[2])  # the cost keys cut nothing
    model = CostModel.from_machine(priced.machine)
    cost = summarize(rec, tp, model, *case_tool_lives(model, priced))["cost"]
    used2 = hand(2, 10.0, 400.0, 0.25)
    assert cost["tools"]["T1"] == plain["T1"]
    # T2 ramps up from rest after line 8's M6 (which stops the spindle), where its wear rate climbs as S^4: the
    # rectangle rule and the cost's trapezoid differ there by up to half a sample at S4000, 0.5 dt / Tl(4000 rpm)
    bound = 0.5 * float(dt.max()) / ((400.0 / (np.pi * 10.0 * 4000.0 / 1000.0)) ** (1.0 / 0.25) * 60.0)
    assert cost["tools"]["T2"]["tool_life_used"] == pytest.approx(used2, abs=bound)
    assert cost["tools"]["T2"]["tool_KRW"] == pytest.approx(used2 * (50000.0 + tc_krw),
                                                             abs=bound * (50000.0 + tc_krw))
    assert cost["tool_KRW"] == pytest.approx(cost["tools"]["T1"]["tool_KRW"] + cost["tools"]["T2"]["tool_KRW"],
                                             rel=1e-12)


def test_tool_cost_keys_are_checked_naming_case_toml_the_line_and_the_key(tmp_path):
    base = CASE.format(tool=TOOL_1).replace('[machine]\nparameters = "default"\n', "")
    bad = {  # line 11: [tools.T3], 12 diameter_mm, 13 flutes, 14 the cost key
        "price_KRW = -1.0": r"case.toml:14: \[tools.T3\] price_KRW must be a price in KRW per tool, >= 0, got -1.0",
        'price_KRW = "20000"': r"case.toml:14: \[tools.T3\] price_KRW must be .* got '20000'",
        "taylor_C = 0.0": r"case.toml:14: \[tools.T3\] taylor_C must be the Taylor constant C in m/min",
        "taylor_n = 1.5": r"case.toml:14: \[tools.T3\] taylor_n must be the Taylor exponent n, > 0 and <= 1, got 1.5",
        "taylor_n = true": r"case.toml:14: \[tools.T3\] taylor_n must be .* got True",
        "taylor_n = nan": r"case.toml:14: \[tools.T3\] taylor_n must be .* got nan",
    }
    _case_folder(tmp_path)
    for key, pattern in bad.items():
        (tmp_path / "case.toml").write_text(base + f"[tools.T3]\ndiameter_mm = 3.0\nflutes = 2\n{key}\n")
        with pytest.raises(CaseError, match=pattern):
            load_case(tmp_path)
    (tmp_path / "case.toml").write_text(base.replace("flutes = 2\n", "flutes = 2\nprice_KRW = -5\n", 1))
    with pytest.raises(CaseError, match=r"case.toml:8: \[tool\] price_KRW must be a price"):
        load_case(tmp_path)
    (tmp_path / "case.toml").write_text(base + "[tools.T3]\ndiameter_mm = 3.0\nflutes = 2\ntaylor_k = 0.2\n")
    with pytest.raises(CaseError, match=r"case.toml:14: unknown field 'taylor_k' in \[tools.T3\]; expected "
                                        r"\['diameter_mm', 'flutes', 'price_KRW', 'taylor_C', 'taylor_n'\]"):
        load_case(tmp_path)
    (tmp_path / "case.toml").write_text(base + "[tools.T3]\ndiameter_mm = 3.0\nflutes = 2\nprice_KRW = 0\n"
                                               "taylor_C = 250\ntaylor_n = 1\n")
    tool = load_case(tmp_path).tools[3]
    assert (tool.price_KRW, tool.taylor_C, tool.taylor_n) == (0.0, 250.0, 1.0)


def test_the_optimisers_evaluation_records_the_cost_per_tool(two_tools):
    """The evaluation records the tool in the spindle: the reference run's ``before`` has the cost per tool of
    simulate's summary.json (its spindle and tool histories are the NC kernel's; the cutting model of the search
    may end the run a step or so apart: within 1e-3)."""
    from orchestrator.optimize.reference import build_reference

    case, result = two_tools
    member = build_reference(case).evaluation.member(0)
    assert set(member["tools"]) == {"T1", "T2"}
    for name, use in result.summary["cost"]["tools"].items():
        assert member["tools"][name] == pytest.approx(use, rel=1e-3)
    assert member["tool_life_used"] == pytest.approx(sum(u["tool_life_used"] for u in member["tools"].values()))
