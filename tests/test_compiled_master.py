"""The compiled master loop gives the Python master's results bit for bit.

:func:`orchestrator.compiled.run_compiled` runs the communication-step loop of
an all-native twin in one numba function; it calls the same kernels (or their
scalar member functions) in the same order with the same floating-point
operations, and hands back to the master's own Python code for everything
around the loop (stop / time-limit messages, divergence marking, component
failures, progress). The reference is the Python master
(``MasterSettings(compiled=False)``); expected: identical recordings (every
channel, every sample, NaN where NaN) and identical run results (steps,
end time, success, message, stop times, failed members and their reasons).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from orchestrator.bench.native import bench_case
from orchestrator.case import case_for_program
from orchestrator.compiled import compiled_support, run_compiled
from orchestrator.master import Master, MasterSettings
from orchestrator.twin import TwinOptions, build_twin, engagement_table

ROOT = Path(__file__).resolve().parents[1]
AIR_PROGRAM = "G90 G1 X5 Y2 F1200\nG0 X0 Y0\nM30\n"
AIR_CASE = case_for_program(ROOT / "models" / "examples" / "paper_part" / "program.nc")
MM_PER_MIN = 1e-3 / 60.0
RPM = 2.0 * math.pi / 60.0


@pytest.fixture(scope="module")
def cut_case():
    case = bench_case()
    return case, engagement_table(case, TwinOptions())


def _runs(make, threads=1, **settings):
    """(compiled, python) results of two identical masters made by ``make()``; ``threads`` of the compiled one."""
    results = []
    for compiled in (True, False):
        twin, master_settings = make(**settings)
        master_settings.compiled = compiled
        master_settings.threads = threads
        master = Master(twin.system, master_settings, twin.probes)
        if compiled:
            assert compiled_support(master) is None, compiled_support(master)
        with np.errstate(over="ignore", invalid="ignore"):
            results.append(master.run())
    return results


def _assert_same(a, b) -> None:
    assert a.recording.channels == b.recording.channels
    assert a.recording.data.shape == b.recording.data.shape
    for ch in a.recording.channels:
        np.testing.assert_array_equal(a.recording.data[ch], b.recording.data[ch], err_msg=ch)
    assert (a.steps, a.t_end, a.success, a.message) == (b.steps, b.t_end, b.success, b.message)
    np.testing.assert_array_equal(a.stopped_at, b.stopped_at)
    np.testing.assert_array_equal(a.failed, b.failed)
    assert a.failures == b.failures
    assert a.recording.message == b.recording.message


def _cut_twin(case, table, batch=1, seconds=2.5, integrator="exponential", **changes):
    """A path-mode cutting twin of ``case`` (see :func:`_twin`)."""
    return _twin(case, TwinOptions(cutting_mode="path", engagement=table, drive_integrator=integrator), batch,
                 seconds, **changes)


def _twin(case, options, batch=1, seconds=2.5, feeds=None, spindles=None, alarms=True, members=None):
    """Twin and settings: ``feeds``/``spindles`` overrides, excess-error ``alarms`` off on request, and
    ``members = {b: {(component, parameter): value}}`` changed per member."""
    twin = build_twin(case, batch=batch, options=options)
    if feeds or spindles:
        twin.nck.set_overrides(feed=feeds, spindle=spindles)
    if not alarms:
        for a in "xyz":
            for key in ("excess_error_in_motion", "excess_error_at_stop"):
                twin.mcu.set(f"{a}_{key}", 0.0)
    for b, changes in (members or {}).items():
        for (comp, name), value in changes.items():
            component = twin.system.components[comp]
            arr = component.get(name)
            arr[b] = value
            component.set(name, arr)
    settings = MasterSettings(step=twin.options.step, time_limit=seconds, stop_when=twin.stop_when,
                              limits=twin.limits or {}, check_every=10)
    return twin, settings


@pytest.mark.parametrize("integrator", ["exponential", "rk4"])
def test_single_cutting_run_is_bit_identical(cut_case, integrator):
    case, table = cut_case
    a, b = _runs(lambda: _cut_twin(case, table, integrator=integrator))
    _assert_same(a, b)
    assert np.nanmax(a.recording["fc_N"]) > 10.0  # the window includes cutting (from about 1.5 s)


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_batch_with_feed_and_speed_overrides_and_a_diverging_member(cut_case, threads):
    """Three members: two F/S variants and one unstable (positive velocity feedback) caught by the limits.

    With 2 and 3 threads the members run in blocks side by side (the diverging one alone in its block with 3).
    """
    case, table = cut_case
    # source lines of bench_part.nc: 7 = S6000 M3, 10 = first slot (F300), 14 = second slot (F400)
    feeds = {10: np.array([300.0, 450.0, 300.0]) * MM_PER_MIN, 14: np.array([400.0, 330.0, 400.0]) * MM_PER_MIN}
    spindles = {7: np.array([6000.0, 7000.0, 6000.0]) * RPM}
    a, b = _runs(lambda: _cut_twin(case, table, batch=3, feeds=feeds, spindles=spindles, alarms=False,
                                   members={2: {("mcu", "x_velocity_p_scale"): -1.0}}), threads=threads)
    _assert_same(a, b)
    assert a.failures[2].startswith("diverged")
    assert all(f.startswith("did not reach") for f in a.failures[:2])  # 2.5 s of a 36 s program
    assert not np.array_equal(a.recording["fc_N"][:, 0], a.recording["fc_N"][:, 1])  # the overrides act


def _air_twin(batch=1, seconds=0.6, members=None, integrator="exponential"):
    twin = build_twin(AIR_CASE, batch=batch, program_text=AIR_PROGRAM)
    for d in twin.drives.values():
        d.set("integrator", integrator)
    for b, changes in (members or {}).items():
        for (comp, name), value in changes.items():
            component = twin.system.components[comp]
            arr = component.get(name)
            arr[b] = value
            component.set(name, arr)
    return twin, MasterSettings(step=1e-3, time_limit=seconds, stop_when=twin.stop_when,
                                limits=twin.limits or {}, check_every=10)


@pytest.mark.parametrize("threads", [1, 2])
def test_batch_member_failed_by_a_component_alarm(threads):
    """The MCU's excess-error alarm fails a member inside the loop (a component failure, not the limits)."""
    a, b = _runs(lambda: _air_twin(batch=2, members={1: {("mcu", "x_velocity_p_scale"): -1.0}}), threads=threads)
    _assert_same(a, b)
    assert a.success and a.failed.tolist() == [False, True]
    assert "SV0411" in a.failures[1]


@pytest.mark.parametrize("integrator, threads", [("exponential", 1), ("rk4", 1), ("rk4", 2)])
def test_batch_member_failed_by_its_drive(integrator, threads):
    """Coulomb friction far above the static friction: the break-away of one member runs backwards."""
    a, b = _runs(lambda: _air_twin(batch=2, integrator=integrator,
                                   members={1: {("x_drive", "coulomb_positive"): 1e9}}), threads=threads)
    _assert_same(a, b)
    assert a.success and a.failed.tolist() == [False, True]
    assert "x_drive: stick/slip integrator" in a.failures[1]


def test_single_run_ended_by_a_component_error_and_the_time_limit():
    a, b = _runs(lambda: _air_twin(members={0: {("mcu", "x_velocity_p_scale"): -1.0}}))
    _assert_same(a, b)
    assert not a.success and "SV0411" in a.message
    a, b = _runs(lambda: _air_twin(seconds=0.2))  # stops short of the program end: time limit
    _assert_same(a, b)
    assert not a.success and "time limit" in a.message


@pytest.mark.parametrize("threads", [1, 2])
def test_decimation_progress_and_no_stop_signal(threads):
    def make():
        twin = build_twin(AIR_CASE, batch=2, program_text=AIR_PROGRAM)
        return twin, MasterSettings(step=1e-3, time_limit=0.35, decimation=7, check_every=3, threads=threads)
    calls = []
    for compiled in (True, False):
        twin, settings = make()
        settings.compiled = compiled
        seen = []
        master = Master(twin.system, settings, twin.probes, progress=lambda t, T: seen.append((t, T)))
        calls.append((master.run(), seen))
    _assert_same(calls[0][0], calls[1][0])
    assert calls[0][1] == calls[1][1] and len(calls[0][1]) >= 50


def test_unsupported_systems_are_named_and_left_to_the_python_master():
    twin = build_twin(AIR_CASE, batch=1, program_text=AIR_PROGRAM)
    twin.drives["x"].set("gravity_force", 100.0)
    master = Master(twin.system, MasterSettings(time_limit=0.01), twin.probes)
    assert "gravity_force" in compiled_support(master)
    assert run_compiled(master) is None
    twin = build_twin(AIR_CASE, batch=1, program_text=AIR_PROGRAM)
    master = Master(twin.system, MasterSettings(time_limit=0.01, method="jacobi"), twin.probes)
    assert "jacobi" in compiled_support(master)


@pytest.mark.parametrize("threads", [2, 4])
def test_members_ending_at_different_steps_in_blocks(threads):
    """Four members at 1200, 300, 900 and 600 mm/min end the air move at different steps.

    The run stops when all members are done and in position: with the members split into blocks that
    run side by side, the blocks that finish first keep stepping until the last member is done, exactly
    as in one thread. Expected: the Python master's recording, stop times (the 5.385 mm move takes
    0.27-1.08 s plus acc/dec) and end step.
    """
    feeds = {1: np.array([1200.0, 300.0, 900.0, 600.0]) * MM_PER_MIN}

    def make():
        twin = build_twin(AIR_CASE, batch=4, program_text=AIR_PROGRAM)
        twin.nck.set_overrides(feed=feeds)
        return twin, MasterSettings(step=1e-3, time_limit=3.0, stop_when=twin.stop_when, limits=twin.limits or {},
                                    check_every=10)
    a, b = _runs(make, threads=threads)
    _assert_same(a, b)
    assert a.success and np.all(np.isfinite(a.stopped_at))
    length = math.hypot(5.0, 2.0)  # mm, then the rapid back
    move = length / np.array([1200.0, 300.0, 900.0, 600.0]) * 60.0
    assert np.all(np.diff(a.stopped_at[[0, 2, 3, 1]]) > 0)  # slower feed, later end
    assert np.all(a.stopped_at > move)
    assert a.t_end == pytest.approx(np.max(a.stopped_at))


def test_thread_count_of_a_batch():
    from orchestrator.compiled.blocks import MIN_MEMBERS_PER_BLOCK, block_count
    assert block_count(1, None) == 1 and block_count(3, 8) == 3 and block_count(100, 1) == 1
    assert block_count(100, None) in range(1, 100 // MIN_MEMBERS_PER_BLOCK + 1)
    assert block_count(MIN_MEMBERS_PER_BLOCK - 1, None) == 1
    for bad in (0, -1, 1.5, True):
        with pytest.raises(Exception, match="threads"):
            MasterSettings(threads=bad)
