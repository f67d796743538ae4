"""``cnctwin bench`` in a very short configuration: it runs end to end and returns every key (no timing asserts)."""
from __future__ import annotations

import argparse
import json
import math

import numpy as np
import pytest

from orchestrator.bench import BenchSettings, format_table, run_bench
from orchestrator.cli_bench import add_parsers
from orchestrator.fmu.fast_loop import compiler

pytestmark = pytest.mark.skipif(compiler() is None, reason="no C compiler")


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    settings = BenchSettings.quick()
    settings.twin_seconds = 0.3
    settings.batch_seconds = 0.05
    settings.compare_seconds = 0.05
    settings.length_seconds = (0.05, 0.1)
    settings.population_sizes = (1, 10)
    settings.population_seconds = 0.05
    settings.ring_steps = 200
    settings.servo_steps = 5
    settings.fused_seconds = 0.3
    settings.replay_seconds = 0.3
    settings.planning_batch = 10
    settings.fmu_dir = str(tmp_path_factory.mktemp("bench_fmus"))
    return run_bench(settings)


def test_keys(result):
    assert {"machine", "settings", "native_twin", "fused", "c_fmu", "native_ring", "pythonfmu", "scaling",
            "master_us_per_step", "ratios", "targets", "bench_wall_s", "servo_replay"} <= set(result)
    replay = result["servo_replay"]
    assert replay["compiled"]["compiled"] and not replay["tick_by_tick"]["compiled"]
    assert replay["compiled"]["batch"] == replay["tick_by_tick"]["batch"] == 10
    assert "servo_replay_tick_by_tick_over_compiled" in result["ratios"]
    assert result["machine"]["nproc"] >= 1 and result["machine"]["cpu"]
    twin = result["native_twin"]
    threaded = twin["batch_100"]["threads"] > 1  # members in blocks on several cores: also timed in one thread
    assert set(twin) == {"single", "single_air", "single_rk4", "single_python_master", "single_zmap",
                         "single_zmap_python_master", "batch_10", "batch_100",
                         "batch_100_variants"} | ({"batch_100_one_thread"} if threaded else set())
    assert twin["batch_100_variants"]["variants"] and not twin["batch_100"]["variants"]
    if threaded:
        assert twin["batch_100_one_thread"]["threads"] == 1 and twin["batch_100_one_thread"]["batch"] == 100
        assert "native_twin_batch_100_one_thread_over_threads" in result["ratios"]
    assert twin["single"]["threads"] == 1
    assert twin["single"]["compiled_loop"] and twin["batch_100"]["compiled_loop"]
    assert not twin["single_python_master"]["compiled_loop"] and not twin["single_zmap_python_master"]["compiled_loop"]
    assert twin["single_zmap"]["compiled_loop"]  # the Z-map cutting load is covered by the compiled loop
    assert twin["single_rk4"]["integrator"] == "rk4" and twin["single_zmap"]["cutting_mode"] == "zmap"
    assert set(result["fused"]) == {"single", "batch_10", "batch_100"}
    for path in ("master", "fast_loop", "plain_fmpy"):
        assert path in result["c_fmu"] and path in result["pythonfmu"]
    assert {"native_twin_single", "fused_single", "native_ring_master", "c_fmu_master", "c_fmu_fast_loop",
            "c_fmu_plain_fmpy", "pythonfmu_master", "pythonfmu_fast_loop", "pythonfmu_plain_fmpy",
            "native_twin_batch_100", "fused_batch_100", "native_twin_single_python_master",
            "native_twin_single_rk4", "native_twin_single_zmap"} <= set(result["master_us_per_step"])
    assert {"python_master_over_compiled_loop", "rk4_over_exponential_drives", "zmap_over_path_cutting",
            "zmap_python_master_over_compiled_loop"} <= set(
        result["ratios"])
    assert {"native_single_rt_factor", "native_population_100_rt_factor", "c_fmu_fast_loop_us_per_step"} <= set(
        result["targets"])
    plan = result["planning"]
    assert plan["identical"] and plan["batch"] == result["settings"]["planning_batch"]
    assert f"nc_planning_{plan['batch']}_reference_over_compiled" in result["ratios"]


def test_values_are_consistent(result):
    twin = result["native_twin"]
    assert twin["batch_100"]["batch"] == 100 and twin["single"]["steps"] == 300
    for group in (result["native_twin"], result["fused"]):
        for r in group.values():
            # real-time factor and cost per step describe the same run
            assert r["rt_factor"] == pytest.approx(r["batch"] * r["sim_s"] / r["wall_s"])
            assert r["us_per_step"] == pytest.approx(r["wall_s"] / r["steps"] * 1e6)
    for value in result["master_us_per_step"].values():
        assert math.isfinite(value) and value >= 0.0
    assert [p["batch"] for p in result["scaling"]["population"]] == [1, 10]
    json.dumps(result)  # plain JSON
    assert "native twin single" in format_table(result)


def test_cli_parser():
    parser = argparse.ArgumentParser(prog="cnctwin")
    add_parsers(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["bench", "--quick", "--json", "out.json"])
    assert args.quick and args.json == "out.json" and callable(args.func)


def test_bench_variants_change_the_program_s_own_f_and_s_words():
    """The lines the variants override carry the F and S words they name, and member 0 is the program as written."""
    from orchestrator.bench.native import BENCH_FEED_LINES, BENCH_PROGRAM, BENCH_SPINDLE_LINE, variant_overrides
    lines = BENCH_PROGRAM.read_text().splitlines()
    for line, f in BENCH_FEED_LINES.items():
        assert f"F{f:g}" in lines[line - 1].split("(")[0]
    s_line, s = BENCH_SPINDLE_LINE
    assert f"S{s:g}" in lines[s_line - 1]
    feed, spindle = variant_overrides(100, seed=0)
    mm_per_min = 1e-3 / 60.0
    for line, f in BENCH_FEED_LINES.items():
        values = feed[line] / mm_per_min
        assert values[0] == pytest.approx(f) and len(set(np.round(values).tolist())) > 10
        assert np.all((values >= 0.8 * f - 5.0) & (values <= 1.25 * f + 5.0))
    rpm = spindle[s_line] * 60.0 / (2.0 * math.pi)
    assert rpm[0] == pytest.approx(s) and np.all((rpm >= 5000.0 - 1e-6) & (rpm <= 7000.0 + 1e-6))
