"""The Z drive carries the end edges' thrust of a plunge (``cutting.fz`` -> ``z_drive.disturbance_force``).

Facts derived here, not taken from the code (6 mm 2-flute flat end mill, A6061 Kt = 1230 N/mm2 of the paper,
ka = 0.28 of the machine file, plunge F600 at S6000 into solid):

* thrust on the workpiece ``fz = -N ka Kt h_a R`` with ``h_a = F / (N S)`` = 0.05 mm: -103.32 N;
* the Z slide carries the tool and feels ``-fz`` = +103.32 N (upward); the drive's ``Fd`` resists positive
  motion, so ``Fd = fz`` and a plunge needs ``u = Ff + fz``: 103.32 N more *downward* motor force;
* force per amp of the Z drive (``models/machines/default.toml``: kt 1.0 N.m/A, lead 12 mm):
  ``kt 2 pi / Lb`` = 523.60 N/A, so the Z current steps by -103.32 / 523.60 = -0.1973 A while the feed is
  steady (the velocity loop's integral action carries the whole load; friction and gravity are the same as in
  the air run at the same speed);
* a plunge has no lateral load: the X and Y currents are those of the air run, bit for bit.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from orchestrator import simulate
from orchestrator.twin import TwinOptions

KT, KA, R, N = 1.23e9, 0.28, 3e-3, 2
S_RPM, F_MM_MIN = 6000.0, 600.0
THRUST = N * KA * KT * (F_MM_MIN / (N * S_RPM) * 1e-3) * R   # N, 103.32
FORCE_PER_AMP = 1.0 * 2.0 * math.pi / 12e-3                   # N/A, Z drive of default.toml

CASE_TOML = """program = "plunge.nc"

[stock]
min = [0.0, 0.0, -10.0]
max = [30.0, 20.0, 0.0]

[tool]
diameter_mm = 6.0
flutes = 2

[machine]
parameters = "default"
"""
PLUNGE = "G21 G17 G90 G94 G54\nS6000 M3\nG0 X10. Y10. Z5.\nG1 Z-4. F600\nG0 Z10.\nM30\n"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("thrust")
    (folder / "case.toml").write_text(CASE_TOML)
    (folder / "plunge.nc").write_text(PLUNGE)
    out = {"folder": folder}
    for cutting in (True, False):
        result = simulate(program=folder / "plunge.nc", case=folder, options=TwinOptions(cutting=cutting),
                          plot=False)
        assert result.success, result.message
        out[cutting] = result.recording
    return out


def test_force_per_amp_of_the_machine_file():
    assert FORCE_PER_AMP == pytest.approx(523.599, abs=1e-3)
    assert THRUST / FORCE_PER_AMP == pytest.approx(0.19733, abs=1e-5)


def test_a_plunge_needs_more_downward_motor_force_by_the_thrust(runs):
    cut, air = runs[True], runs[False]
    assert np.array_equal(np.asarray(cut.t), np.asarray(air.t))
    z = np.asarray(cut["z_mm"])
    steady = (z < -1.0) & (z > -3.0) & (np.asarray(cut["feed_mm_per_min"]) == F_MM_MIN)
    assert steady.sum() > 100   # 2 mm at 10 mm/s: 200 samples of 1 ms
    fz = np.asarray(cut["fz_N"])[steady]
    assert fz == pytest.approx(-THRUST, rel=1e-3)   # on the workpiece, downward
    step = np.asarray(cut["z_tcmd_A"])[steady] - np.asarray(air["z_tcmd_A"])[steady]
    assert np.all(step < 0.0)                       # more downward motor force
    assert float(np.mean(step)) == pytest.approx(-THRUST / FORCE_PER_AMP, rel=0.01)
    assert float(np.max(np.abs(step + THRUST / FORCE_PER_AMP))) < 0.02 * THRUST / FORCE_PER_AMP
    # the thrust pushes the tool up: while it builds, the Z following error grows (the tool lags higher)
    lag = np.asarray(cut["z_mm"]) - np.asarray(air["z_mm"])
    assert float(np.max(lag)) > 0.0


def test_a_plunge_leaves_the_x_and_y_currents_alone(runs):
    for a in "xy":
        assert np.array_equal(np.asarray(runs[True][f"{a}_tcmd_A"]), np.asarray(runs[False][f"{a}_tcmd_A"]),
                              equal_nan=True)


def test_the_diagnosis_replays_carry_the_twins_thrust_on_z(runs):
    """``prepare.twin_loads`` (the load the replayed drives carry) has the plunge's thrust on Z, the step mean
    the twin's Z drive carried: -103.32 N at the steady feed."""
    from orchestrator.case import load_case
    from orchestrator.diagnose.prepare import twin_loads

    case = load_case(runs["folder"])
    loads = twin_loads(case, case.machine)
    assert "z" in loads.mean and "x" not in loads.mean and "y" not in loads.mean   # a plunge: no lateral load
    z = np.asarray(runs[True]["z_mm"])
    steady = (z < -1.0) & (z > -3.0) & (np.asarray(runs[True]["feed_mm_per_min"]) == F_MM_MIN)
    assert loads.mean["z"][steady] == pytest.approx(-THRUST, rel=1e-3)
