"""The diagnosis's drive loads include the thrust on Z (orchestrator.diagnose.prepare).

* ``DRIVE_LOADS`` maps z to the twin's ``cutting.fz`` (the step-mean thrust on the workpiece, which the
  twin connects to ``z_drive.disturbance_force``);
* a recorded ``fz_N`` becomes the Z load as it stands (the same sign convention as ``fx_N``: force on the
  workpiece = ``Fd``);
* recorded forces too coarse for the tooth load are corrected axis by axis; an axis the dynamometer did not
  measure (a log without ``fz_N``) carries the twin's own load, here a constant -51.66 N thrust
  (F300 S6000, 6 mm 2-flute, ka 0.28: 2 x 0.28 x 1230 x 0.025 x 3 N).
"""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.diagnose.prepare import DRIVE_LOADS, SampledForce, TwinLoads, corrected_forces, recorded_forces
from orchestrator.recording import Recording

THRUST = 2 * 0.28 * 1230.0 * 0.025 * 3.0   # N


def test_the_twin_loads_its_z_drive_with_the_thrust():
    assert THRUST == pytest.approx(51.66)
    assert DRIVE_LOADS["z"] == "cutting.fz"


def test_a_recorded_fz_loads_the_z_drive():
    t = 1e-3 * np.arange(50)
    rec = Recording.from_channels({"t_s": t, "fx_N": np.full(50, 3.0), "fy_N": np.full(50, -2.0),
                                   "fz_N": np.full(50, -THRUST)}, source="<test>")
    loads = recorded_forces(rec)
    assert sorted(loads) == ["x", "y", "z"]
    assert loads["z"](np.array([0.01, 0.02])) == pytest.approx([-THRUST, -THRUST])


def test_a_dynamometer_without_fz_leaves_z_on_the_twins_thrust():
    h, n = 1e-3, 200
    loads = TwinLoads(0.0, h, {"x": np.full(n, 10.0), "z": np.full(n, -THRUST)},
                      {"x": np.full(n, 10.0), "z": np.full(n, -THRUST)}, {"x": 4, "z": 4}, {"x": 1, "z": 1})
    t = 0.5 + np.arange(0.0, 0.2, 1e-3)            # logger clock = program clock + 0.5 s
    measured = {"x": SampledForce(t, np.full(t.size, 12.0)), "y": SampledForce(t, np.zeros(t.size))}
    out = corrected_forces(measured, loads, lambda: 0.5, revolution_s=0.01)
    assert sorted(out) == ["x", "z"]
    q = 0.5 + np.array([0.05, 0.1])
    assert out["z"](q) == pytest.approx([-THRUST, -THRUST])
    assert out["x"](q) == pytest.approx([12.0, 12.0])   # the twin's 10 N + the measured 2 N beyond it
