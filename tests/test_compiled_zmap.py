"""The compiled master loop steps the Z-map cutting load bit for bit as the Python master does.

The component's own step is the same compiled function when its effect terms are off, so every case is
also compared with the Python master running the component's numpy step (``CuttingLoad.use_compiled =
False``: the numpy kernel, independent of :mod:`fmus_src.cutting.zmap_numba`).

With every effect term off, :class:`fmus_src.cutting.component.CuttingLoad` runs in the compiled loop as
``KIND_ZMAP`` (:func:`fmus_src.cutting.zmap_numba.zmap_component_step`: the component's own step, with
the same floating-point operations in the same order). The reference is the Python master
(``MasterSettings(compiled=False)``) stepping the component itself; expected: identical recordings and
run results (see ``tests/test_compiled_master.py``), for single runs, batches in one and two threads,
members held on non-finite inputs (failed upstream) and members failed by the cutting load itself.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting.component import CuttingLoad
from orchestrator.bench.native import bench_case
from orchestrator.compiled import compiled_support
from orchestrator.master import Master, MasterSettings
from orchestrator.twin import TwinOptions, build_twin

from test_compiled_master import MM_PER_MIN, RPM, _assert_same, _runs, _twin


@pytest.fixture(scope="module")
def case():
    return bench_case()


def _zmap_twin(case, batch=1, seconds=2.5, **changes):
    return _twin(case, TwinOptions(cutting_mode="zmap"), batch, seconds, **changes)


def test_default_twin_is_covered(case):
    twin = build_twin(case)
    assert type(twin.cutting).__name__ == "CuttingLoad"
    assert compiled_support(Master(twin.system, MasterSettings(time_limit=0.01), twin.probes)) is None
    twin.cutting.set("wear_rate", 1e-3)  # an effect term on: left to the Python master, named
    assert "wear_rate" in compiled_support(Master(twin.system, MasterSettings(time_limit=0.01), twin.probes))


def _numpy_reference(make, monkeypatch):
    """The Python master's run with the component's numpy step (``use_compiled = False``): independent of
    :func:`~fmus_src.cutting.zmap_numba.zmap_component_step`, which the component itself uses otherwise."""
    with monkeypatch.context() as m:
        m.setattr(CuttingLoad, "use_compiled", False)
        twin, settings = make()
        settings.compiled = False
        with np.errstate(over="ignore", invalid="ignore"):
            return Master(twin.system, settings, twin.probes).run()


@pytest.fixture(scope="module")
def python_runs():
    """The Python-master runs of each case, shared by its thread counts: ``{key: (python, numpy kernel)}``.

    Neither depends on ``threads`` (only the compiled loop splits members into blocks), so each case's
    reference pair is run once and every thread count's compiled run is compared with both.
    """
    return {}


def _compared(make, threads, key, python_runs, monkeypatch):
    """The compiled run of ``make()`` in ``threads`` threads, checked bit for bit against the Python master
    (``_runs``' second run) and the numpy-kernel reference, both run once per ``key``."""
    if key not in python_runs:
        compiled, python = _runs(make, threads=threads)
        python_runs[key] = (python, _numpy_reference(make, monkeypatch))
    else:
        twin, settings = make()
        settings.compiled, settings.threads = True, threads
        master = Master(twin.system, settings, twin.probes)
        assert compiled_support(master) is None, compiled_support(master)
        with np.errstate(over="ignore", invalid="ignore"):
            compiled = master.run()
    python, numpy_kernel = python_runs[key]
    _assert_same(compiled, python)
    _assert_same(compiled, numpy_kernel)
    return compiled


def test_single_zmap_cutting_run_is_bit_identical(case, monkeypatch):
    a, b = _runs(lambda: _zmap_twin(case, seconds=3.0))
    _assert_same(a, b)
    _assert_same(a, _numpy_reference(lambda: _zmap_twin(case, seconds=3.0), monkeypatch))
    fc = a.recording["fc_N"]
    assert np.nanmax(fc) > 10.0  # the window includes cutting (from about 1.5 s)
    assert np.all(np.isfinite(fc))


@pytest.mark.parametrize("threads", [1, 2])
def test_batch_with_overrides_and_a_diverging_member(case, threads, python_runs, monkeypatch):
    """Two F/S variants and one unstable member (positive velocity feedback), caught by the limits."""
    # source lines of bench_part.nc: 7 = S6000 M3, 10 = first slot (F300), 14 = second slot (F400)
    feeds = {10: np.array([300.0, 450.0, 300.0]) * MM_PER_MIN, 14: np.array([400.0, 330.0, 400.0]) * MM_PER_MIN}
    spindles = {7: np.array([6000.0, 7000.0, 6000.0]) * RPM}

    def make():
        return _zmap_twin(case, batch=3, feeds=feeds, spindles=spindles, alarms=False,
                          members={2: {("mcu", "x_velocity_p_scale"): -1.0}})
    a = _compared(make, threads, "diverging", python_runs, monkeypatch)
    assert a.failures[2].startswith("diverged")
    assert all(f.startswith("did not reach") for f in a.failures[:2])
    fc = a.recording["fc_N"]
    assert np.nanmax(fc[:, 0]) > 10.0 and not np.array_equal(fc[:, 0], fc[:, 1])  # the overrides act
    assert np.all(np.isfinite(fc[:, :2]))


@pytest.mark.parametrize("threads", [1, 2])
def test_member_held_on_non_finite_inputs(case, threads, python_runs, monkeypatch):
    """A member failed by its x drive (break-away running backwards): NaN table position into the cutting load.

    The cutting load holds that member (spindle stopped, NaN outputs) without failing it; the others cut on.
    """
    def make():
        return _zmap_twin(case, batch=2, members={1: {("x_drive", "coulomb_positive"): 1e9}})
    a = _compared(make, threads, "held", python_runs, monkeypatch)
    assert a.failures[0].startswith("did not reach")  # 2.5 s of a 36 s program
    assert "x_drive: stick/slip integrator" in a.failures[1]
    assert np.nanmax(a.recording["fc_N"][:, 0]) > 10.0
    assert np.isnan(a.recording["fc_N"][-1, 1])


@pytest.mark.parametrize("threads", [1, 2])
def test_member_needing_too_many_substeps_fails_alone(case, threads, python_runs, monkeypatch):
    """10**9 angle steps per tooth: once the spindle turns, a 1 ms step needs far more than MAX_SUBSTEPS.

    Expected: that member fails with the cutting load's own message (the Python master's, bit for bit);
    the other member goes on cutting.
    """
    def make():
        return _zmap_twin(case, batch=2, members={1: {("cutting", "angle_steps_per_tooth"): 10**9}})
    a = _compared(make, threads, "substeps", python_runs, monkeypatch)
    assert a.failures[0].startswith("did not reach")  # 2.5 s of a 36 s program
    assert "cutting: step of 0.001 s of member 1 needs more than 100000 substeps" in a.failures[1]
    assert np.nanmax(a.recording["fc_N"][:, 0]) > 10.0


def test_single_run_failed_by_too_many_substeps(case, monkeypatch):
    def make():
        return _zmap_twin(case, seconds=1.0, members={0: {("cutting", "angle_steps_per_tooth"): 10**9}})
    a, b = _runs(make)
    _assert_same(a, b)
    _assert_same(a, _numpy_reference(make, monkeypatch))
    assert not a.success and "needs more than 100000 substeps" in a.message
    assert a.t_end < 1.0 and math.isfinite(a.t_end)
