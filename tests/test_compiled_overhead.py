"""The compiled loop's per-step savings change no number.

:func:`orchestrator.compiled.loop.run_chunk` keeps work space for a whole chunk (the path-cutting
kernel's interval buffers, sums and tooth rotations: :func:`fmus_src.cutting.path_kernel.path_work`),
reads the NC plan with a per-member run cursor (:func:`fmus_src.nck.sampling.find_run_from`) and runs
its step loop and the path-cutting kernel without numba's reference counting
(:func:`fmus_src.jit.njit_borrowed`). Expected: the same run index as the binary search for any guess;
the same outputs and states as a fresh :func:`~fmus_src.cutting.path_kernel.path_step` per step when
the work space is reused (members with different flute counts); and recordings and run results equal
to the Python master's bit for bit when chunks, passes of member blocks and divergence checks cut the
run at odd steps (the cursor and work space start afresh in every chunk and every block).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import orchestrator.compiled.runner as runner
from fmus_src.cutting import path_kernel as pk
from fmus_src.cutting.table import EngagementTable
from fmus_src.nck.sampling import find_run, find_run_from
from orchestrator.bench.native import bench_case, variant_overrides
from orchestrator.compiled import compiled_support
from orchestrator.compiled import loop
from orchestrator.master import Master, MasterSettings
from orchestrator.twin import TwinOptions, build_twin, engagement_table


def test_run_cursor_finds_the_binary_search_run_from_any_guess():
    rng = np.random.default_rng(3)
    for n_runs in (1, 2, 5, 40):
        run_key = np.concatenate([[0], np.cumsum(rng.integers(1, 6, n_runs - 1))]).astype(np.int64)
        for g in range(0, int(run_key[-1]) + 4):
            expected = find_run(run_key, g)
            for guess in (-5, -1, 0, 1, expected - 9, expected - 3, expected - 1, expected, expected + 1,
                          n_runs - 1, n_runs, n_runs + 7):
                assert find_run_from(run_key, g, guess) == expected, (n_runs, g, guess)


def test_kernels_are_declared_with_and_without_reference_counting():
    for fn in (loop._run_chunk, loop._nck_step, pk.path_step_into, pk.table_at, pk.locate):
        assert fn.targetoptions.get("_nrt") is False, fn
    for fn in (loop.run_chunk, pk.path_step, pk.path_work):
        assert fn.targetoptions.get("_nrt") is True, fn


def _line_table(p: dict) -> tuple[EngagementTable, np.ndarray]:
    vertices = np.array([[-0.004, 0.0, -0.001], [0.016, 0.0, -0.001]])
    return EngagementTable.from_parameters(vertices, p), vertices


def _path_inputs(batch: int, flutes: list[int]):
    p = dict(tool_diameter=6e-3, flutes=2, kt=1.23e9, ke=0.5, stock_x_min=0.0, stock_x_max=0.012,
             stock_y_min=-0.002, stock_y_max=0.01, stock_z_min=-0.01, stock_z_max=0.0)
    table, vertices = _line_table(p)
    par = np.zeros((5, batch))
    par[pk.PAR_RADIUS] = 3e-3
    par[pk.PAR_FLUTES] = flutes
    par[pk.PAR_KT] = 1.23e9
    par[pk.PAR_KE] = 0.5
    par[pk.PAR_STEPS] = 36.0
    st = np.zeros((pk.ST_ROWS, batch))
    st[pk.ST_X] = vertices[0, 0]
    st[pk.ST_Z] = vertices[0, 2]
    return table, par, st


@pytest.mark.parametrize("flutes", [[2, 4, 3, 4, 2], [3]])
def test_path_work_space_reused_across_steps_equals_a_fresh_step(flutes):
    batch = len(flutes)
    table, par, st_fresh = _path_inputs(batch, flutes)
    st_work = st_fresh.copy()
    args = (table.vertices, table.vertex_s, float(table.spacing), table.count, table.alpha, table.beta, table.top,
            float(table.z_floor), 1e-4, 1e-4, 1000)
    work = pk.path_work(table.alpha.shape[1], pk.max_flutes(par))
    cut = False
    omega = 2.0 * math.pi * np.array([100.0, 90.0, 110.0, 95.0, 105.0])[:batch]
    for k in range(1, 120):
        inp = np.zeros((4, batch))
        inp[0] = -0.004 + k * np.array([1.6e-4, 1.2e-4, 1.4e-4, 1.0e-4, 1.5e-4])[:batch]
        inp[2] = -0.001
        inp[3] = omega
        outs = []
        for st, fresh in ((st_fresh, True), (st_work, False)):
            out = np.zeros((12, batch))
            engaged = np.zeros(batch, dtype=np.int64)
            status = np.zeros(batch, dtype=np.int64)
            if fresh:
                n = pk.path_step(1e-3, inp, par, st, out, engaged, *args, status)
            else:
                n = pk.path_step_into(1e-3, inp, par, st, out, engaged, *args, status, *work)
            outs.append((n, out, engaged, status))
        assert outs[0][0] == outs[1][0] == 0
        for a, b in zip(outs[0][1:], outs[1][1:]):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(st_fresh, st_work)
        cut = cut or bool(np.any(outs[0][1][pk.OUT_FC] > 0.0))
    assert cut  # the members went through the material


def test_a_rotation_cache_too_small_is_refused_before_any_change():
    table, par, st = _path_inputs(2, [2, 4])
    st0 = st.copy()
    out = np.full((12, 2), 7.0)
    inp = np.zeros((4, 2))
    work = pk.path_work(table.alpha.shape[1], 3)
    n = pk.path_step_into(1e-3, inp, par, st, out, np.zeros(2, dtype=np.int64), table.vertices, table.vertex_s,
                          float(table.spacing), table.count, table.alpha, table.beta, table.top,
                          float(table.z_floor), 1e-4, 1e-4, 1000, np.zeros(2, dtype=np.int64), *work)
    assert n == -1
    np.testing.assert_array_equal(st, st0)
    assert np.all(out == 7.0)


@pytest.fixture(scope="module")
def cut_case():
    case = bench_case()
    return case, engagement_table(case, TwinOptions())


def _run(case, table, compiled: bool, batch: int, threads: int, seconds: float = 2.6, **settings):
    twin = build_twin(case, batch=batch, options=TwinOptions(cutting_mode="path", engagement=table))
    if batch > 1:
        feed, spindle = variant_overrides(batch, seed=5)
        twin.nck.set_overrides(feed=feed, spindle=spindle)
    s = MasterSettings(time_limit=seconds, stop_when=twin.stop_when, limits=twin.limits or {}, compiled=compiled,
                       threads=threads, **settings)
    master = Master(twin.system, s, twin.probes)
    if compiled:
        assert compiled_support(master) is None
    return master.run()


def _assert_same(a, b) -> None:
    assert a.recording.channels == b.recording.channels
    for ch in a.recording.channels:
        np.testing.assert_array_equal(a.recording.data[ch], b.recording.data[ch], err_msg=ch)
    assert (a.steps, a.t_end, a.success, a.message) == (b.steps, b.t_end, b.success, b.message)
    np.testing.assert_array_equal(a.stopped_at, b.stopped_at)
    np.testing.assert_array_equal(a.failed, b.failed)


@pytest.mark.parametrize("batch, threads", [(1, 1), (8, 2)])
def test_chunks_and_passes_at_odd_steps_with_checks_are_bit_identical(cut_case, monkeypatch, batch, threads):
    case, table = cut_case
    reference = _run(case, table, False, batch, 1, check_every=7, decimation=3)
    monkeypatch.setattr(runner, "CHUNK_STEPS", 173)  # chunk ends (new cursor, new work space) at odd steps
    monkeypatch.setattr(runner, "PASS_STEPS", 61)  # and the passes of the member blocks
    fast = _run(case, table, True, batch, threads, check_every=7, decimation=3)
    _assert_same(fast, reference)
    cut_channels = [ch for ch in fast.recording.channels if ch.startswith("fc")]
    assert cut_channels and np.nanmax(np.abs(fast.recording.data[cut_channels[0]])) > 0.0  # it cut
