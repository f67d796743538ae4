"""The twin's own run, written by `simulate` and read back by `diagnose`: nothing separates it from the twin.

The spec's answer is an empty `effects` list. A file written by `simulate` has no noise at all (12 significant
digits), so the noise floors come from the lowest resolutions a production log has (columns.POSITION_QUANTUM_UM,
columns.CURRENT_QUANTUM_A, cutting.FORCE_FLOOR_N), and its 1 ms force samples (5 per tooth period at 6000 rpm
with 2 flutes) are too coarse to load the replayed drives: they carry the twin's load, corrected by the forces
averaged over whole revolutions (prepare.corrected_forces), which on the twin's own run is its load exactly.
Before, the replay's own differences were named as friction, edge force and tool wear.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from orchestrator.diagnose import diagnose
from orchestrator.simulate import simulate

PROGRAM = """G21 G17 G40 G49 G90 G94
G54
T1 M6
S6000 M3
G0 X-5. Y6. Z1.
G1 Z-1.5 F200
X25. F400 (FULL SLOT)
G0 Z1.
X-2. Y-6.
G1 Z-2. F200
Y12. F400 (SIDE OF THE BLOCK, 1 MM RADIAL)
G1 X28.
G0 Z50.
M5
M30
"""
CASE = """program = "program.nc"
recording = "run/recording.csv"
[stock]
min = [0.0, 0.0, -10.0]
max = [25.0, 11.0, 0.0]
[tool]
diameter_mm = 6.0
flutes = 2
"""


@pytest.fixture(scope="module")
def own_run(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("own")
    (folder / "program.nc").write_text(PROGRAM)
    (folder / "case.toml").write_text(CASE)
    result = simulate(case=folder, out=folder / "run", plot=False)
    assert result.success and result.summary["max_cutting_load_N"] > 20.0  # it cuts
    return folder


def test_own_run_with_forces_names_no_effect(own_run):
    d = diagnose(own_run)
    assert d.effects == [], d.log
    assert any("sampled too coarsely" in line for line in d.log)
    drives = [u for u in d.unexplained if any(c.endswith(("_fe_um", "_tcmd_A")) for c in u["channels"])]
    assert drives == [], drives
    for a in "xy":  # the corrected load on the twin's own run is the twin's load: the replay is exact
        assert d.rms_before[f"{a}_tcmd_A"] < 1e-6, d.rms_before


def test_own_servo_log_without_forces_is_replayed_exactly(own_run, tmp_path):
    from orchestrator.recording import Recording

    rec = Recording.read_csv(own_run / "run" / "recording.csv")
    kept = {c: rec[c] for c in rec.channels if not c.startswith(("fx", "fy", "fz", "fc"))}
    (tmp_path / "run").mkdir()
    Recording.from_channels(kept).write_csv(tmp_path / "run" / "recording.csv")
    (tmp_path / "program.nc").write_text(PROGRAM)
    (tmp_path / "case.toml").write_text(CASE)
    d = diagnose(tmp_path)  # the replayed drives carry the twin's predicted load: the same as its own
    assert d.effects == [] and d.unexplained == [], d.log
    for a in "xy":
        assert d.rms_before[f"{a}_fe_um"] < 1e-4 and d.rms_before[f"{a}_tcmd_A"] < 1e-6


def test_identify_servo_on_own_run_gives_the_machine_files_factors(own_run):
    # the twin's own 1 ms log, forces recorded: with them interpolated onto the drives, X came back with
    # Svi 0.21 and Y with Svp 1.84 on the paper part; the corrected load is the twin's own
    from orchestrator.identify import identify_servo

    fit = identify_servo([own_run], axes=["x", "y"])
    for a in "xy":
        for name in ("Spp", "Svp", "Svi"):
            assert fit.scales_[a][name] == pytest.approx(1.0, abs=1e-6), (a, fit.scales_)
