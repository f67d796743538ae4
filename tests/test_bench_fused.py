"""The fused reference (one numba loop) reproduces the native twin's servo traces.

* Air cut: the fused loop runs the same compiled MCU and drive kernels on the
  same parameter blocks, initial state, NC reference and tick schedule as the
  twin's components under the master, so positions and current commands are
  equal bit for bit.
* Cutting: the twin's Z-map cutting load is replaced by the engagement force
  along the NC reference, scaled with the actual feed per tooth. The servo
  stiffness keeps the position error of that approximation small. Stated tolerance: positions within
  0.5 um, current commands within 0.1 A (measured: 0.08 um and 0.025 A over 9 s of
  the paper part).
"""
from __future__ import annotations

import numpy as np
import pytest

from orchestrator.bench.fused import prepare_fused, reference_run
from orchestrator.bench.native import bench_case
from orchestrator.master import Master, MasterSettings, Probe
from orchestrator.twin import TwinOptions, build_twin

AXES = ("x", "y", "z")
N = 3500  # the bench program starts cutting at about 1.5 s


def _twin_traces(case, cutting: bool, n: int):
    twin = build_twin(case, options=TwinOptions(cutting=cutting))
    probes = [Probe(a, f"{a}_drive.position") for a in AXES] + [Probe(f"i{a}", f"mcu.{a}_current_cmd") for a in AXES]
    run = Master(twin.system, MasterSettings(step=1e-3, time_limit=n * 1e-3, limits=twin.limits), probes).run()
    assert run.steps == n
    rec = run.recording
    return np.stack([rec[a] for a in AXES], axis=1), np.stack([rec[f"i{a}"] for a in AXES], axis=1)


@pytest.fixture(scope="module")
def case():
    return bench_case()


def test_air_cut_bit_identical(case):
    n = 1500
    pos, cur = _twin_traces(case, False, n)
    fused_pos, fused_cur = prepare_fused(case, n, batch=2, cutting=False).run()
    for b in range(2):
        np.testing.assert_array_equal(fused_pos[:, :, b], pos)
        np.testing.assert_array_equal(fused_cur[:, :, b], cur)
    assert np.ptp(pos[:, 2]) > 0.04  # it moved (Z rapid from 50 mm down to 1 mm)


def test_cutting_within_tolerance(case):
    pos, cur = _twin_traces(case, True, N)
    ref, force = reference_run(case, N)
    assert np.abs(force).max() > 10.0  # the window includes cutting (not a vacuous comparison)
    fused_pos, fused_cur = prepare_fused(case, N, reference=(ref, force)).run()
    assert np.abs(fused_pos[:, :, 0] - pos).max() <= 0.5e-6
    assert np.abs(fused_cur[:, :, 0] - cur).max() <= 0.1
