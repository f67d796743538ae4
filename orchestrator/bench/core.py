"""``run_bench``: every figure of issue 9 measured in one process run, with the ratios between them.

All per-step costs of the FMU paths are *slopes*: each variant runs ``n`` and
``3 n`` communication steps from a fresh set-up and the cost per step is
``(T(3n) - T(n)) / 2n``, so instantiation, set-up and first-call costs drop
out; the intercept is reported as ``fixed_s``. Every variant runs once
untimed first (numba caches, pythonfmu's embedded imports). Real-time factors
of the twin are end to end (set-up included), as a user sees them.
"""
from __future__ import annotations

import math
import os
import platform
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import CncTwinError
from ..master import Master, MasterSettings
from .cfmu import build_lag_fmu, lag_ring
from .fused import prepare_fused, reference_run
from ..memo import forget
from ..twin import TwinOptions, engagement_table
from .native import bench_case, time_fused, time_twin
from .simd import time_simd
from .planning import time_planning
from .replays import time_servo_replay
from .systems import build_servo_fmus, native_lag_ring, plain_fmpy_loop, servo_fmu_system

#: Targets of issue 9.
TARGETS = {
    "native_single_rt_factor_min": 200.0,
    "native_population_100_rt_factor_min": 10_000.0,
    "c_fmu_master_us_per_step_max": 5.0,
}


@dataclass
class BenchSettings:
    """How long each measurement runs.

    Attributes
    ----------
    twin_seconds : float
        Simulated time of the single native twin run (the 30 s program), s.
    batch_seconds : float
        Simulated time of the batched runs (populations 10 and 100), s.
    compare_seconds : float
        Simulated time of the single runs that compare paths: Python master loop, RK4 drives,
        Z-map cutting (the last one runs on the Python master), s.
    batches : tuple of int
        Population sizes of the batched runs.
    length_seconds : tuple of float
        Program lengths of the growth-with-length series (single member), s.
    population_sizes : tuple of int
        Population sizes of the growth-with-population series.
    population_seconds : float
        Simulated time of each run of that series, s.
    ring_steps : int
        ``n`` of the slope measurements over the lag ring (C FMUs and native).
    servo_steps : int
        ``n`` of the slope measurements over the pythonfmu servo FMUs.
    fused_seconds : float
        Simulated time of the fused reference runs, s.
    replay_seconds : float
        Replayed time of the compiled servo replay (identification, diagnosis), s; the tick-by-tick
        replay it is compared with replays ``compare_seconds``.
    replay_batch : int
        Parameter sets of the servo replays.
    planning_batch : int
        Distinct variants of the NC planning row (compiled planner against the numpy reference).
    planning_repeats : int
        Runs of each planning path (interleaved; the best counts).
    fmu_dir : str or None
        Where the pythonfmu FMUs are built (a temp folder by default).
    """

    twin_seconds: float = 30.0
    batch_seconds: float = 30.0
    compare_seconds: float = 5.0
    batches: tuple[int, ...] = (10, 100)
    length_seconds: tuple[float, ...] = (2.5, 5.0, 10.0)
    population_sizes: tuple[int, ...] = (1, 3, 10, 30, 100)
    population_seconds: float = 1.0
    ring_steps: int = 20_000
    servo_steps: int = 300
    fused_seconds: float = 30.0
    replay_seconds: float = 30.0
    replay_batch: int = 10
    planning_batch: int = 100
    planning_repeats: int = 3
    fmu_dir: str | None = None

    @classmethod
    def quick(cls) -> BenchSettings:
        """A run of well under a minute (figures are then rough)."""
        return cls(twin_seconds=2.0, batch_seconds=2.0, compare_seconds=2.0, length_seconds=(0.5, 1.0),
                   population_sizes=(1, 10), population_seconds=0.5, ring_steps=1000, servo_steps=20,
                   fused_seconds=2.0, replay_seconds=2.0, planning_batch=20, planning_repeats=1)


def machine_info() -> dict:
    """``nproc``, the CPU model from ``/proc/cpuinfo`` and the versions that matter."""
    import fmpy
    import numba

    cpu = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "nproc": os.cpu_count(), "cpu": cpu, "python": platform.python_version(), "numpy": np.__version__,
        "numba": numba.__version__, "fmpy": fmpy.__version__, "platform": platform.platform(),
        "load_average": _load(),
    }


def _load() -> float:
    """1-minute load average (other jobs on the machine), NaN where unknown."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):
        return math.nan


#: A cost-per-step slope is measured over at least this much wall time between its two runs, s.
MIN_SLOPE_WALL_S = 0.02
#: ... growing ``n`` fourfold at a time up to this many steps.
MAX_SLOPE_STEPS = 2_000_000


def _two_runs(run: Callable[[int], None], n: int) -> tuple[int, list[float]]:
    """Wall times of ``run(n)`` and ``run(3 n)``, with ``n`` grown until they differ by MIN_SLOPE_WALL_S.

    A step of a compiled loop costs a fraction of a microsecond: over a few thousand steps the difference
    of the two runs would be lost in the set-up's jitter.
    """
    while True:
        t = []
        for steps in (n, 3 * n):
            t0 = time.perf_counter()
            run(steps)
            t.append(time.perf_counter() - t0)
        if t[1] - t[0] >= MIN_SLOPE_WALL_S or 12 * n > MAX_SLOPE_STEPS:
            return n, t
        n *= 4


def _slope(run: Callable[[int], None], n: int) -> dict:
    """Cost per step from runs of ``n`` and ``3 n`` steps (each from a fresh set-up; ``n`` grown as needed)."""
    n, t = _two_runs(run, n)
    per_step = max((t[1] - t[0]) / (2 * n), 0.0)
    return {"us_per_step": per_step * 1e6, "fixed_s": max(t[0] - n * per_step, 0.0), "steps": [n, 3 * n],
            "wall_s": t}


def _master_runner(make_system: Callable, probes: tuple[str, ...], h: float = 1e-3,
                   compiled: bool = True) -> Callable[[int], None]:
    """The master over a fresh system; ``compiled=False``: its Python loop (else the default: compiled paths)."""
    def run(steps: int) -> None:
        settings = MasterSettings(step=h, time_limit=steps * h, compiled=compiled)
        result = Master(make_system(), settings, list(probes)).run()
        if not result.success:
            raise CncTwinError(f"bench: master run failed: {result.message}")
    return run


def _fast_slope(make_system: Callable, probes: tuple[str, ...], n: int, h: float = 1e-3) -> dict:
    """FastFMULoop cost per step: one loop, set up and run briefly, then ``n`` and ``3 n`` more steps timed."""
    from ..fmu.fast_loop import FastFMULoop

    system = make_system()
    loop = FastFMULoop.from_system(system, probes)
    t0 = time.perf_counter()
    loop.run(max(2, n // 10), h)  # set-up (fmi2 initialisation) and first steps
    setup = time.perf_counter() - t0
    n, t = _two_runs(lambda steps: loop.run(steps, h), n)
    for comp in system.components.values():
        comp.terminate()
    per_step = max((t[1] - t[0]) / (2 * n), 0.0)
    return {"us_per_step": per_step * 1e6, "fixed_s": setup, "steps": [n, 3 * n], "wall_s": t}


def _plain_runner(make_system: Callable, probes: tuple[str, ...], h: float = 1e-3) -> Callable[[int], None]:
    def run(steps: int) -> None:
        plain_fmpy_loop(make_system(), steps, h, record=probes)
    return run


def _paths(make_system: Callable, probes: tuple[str, ...], n: int) -> dict:
    """Master (default: its compiled FMU loop), its Python loop, FastFMULoop and the plain fmpy loop (warmed up)."""
    out = {}
    python_master = lambda make, probes: _master_runner(make, probes, compiled=False)  # noqa: E731
    for key, factory in (("master", _master_runner), ("python_master", python_master),
                         ("plain_fmpy", _plain_runner)):
        runner = factory(make_system, probes)
        runner(max(2, n // 10))  # warm-up
        out[key] = _slope(runner, n)
    out["fast_loop"] = _fast_slope(make_system, probes, n)
    return out


def _fit_line(x: list[float], y: list[float]) -> dict:
    """Least-squares ``y = a x + b`` with the coefficient of determination."""
    xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if xa.size < 2:
        return {"slope": math.nan, "intercept": math.nan, "r2": math.nan}
    a, b = np.polyfit(xa, ya, 1)
    resid = ya - (a * xa + b)
    ss = float(np.sum((ya - ya.mean()) ** 2))
    return {"slope": float(a), "intercept": float(b), "r2": 1.0 - float(np.sum(resid ** 2)) / ss if ss > 0 else 1.0}


def run_bench(settings: BenchSettings | None = None, quick: bool = False,
              progress: Callable[[str], None] | None = None) -> dict:
    """Measure the twin's speed and the master's overhead; see the module docstring.

    Parameters
    ----------
    settings : BenchSettings, optional
        Lengths of the measurements (default: full; :meth:`BenchSettings.quick` with ``quick``).
    quick : bool
        Use :meth:`BenchSettings.quick` when ``settings`` is None.
    progress : callable, optional
        ``progress(text)`` before each measurement.

    Returns
    -------
    dict
        ``machine``, ``settings``, ``native_twin`` (single, single_air, batch_10, batch_100, ...),
        ``planning`` (NC planning of a population, :func:`.planning.time_planning`),
        ``fused`` (same keys), ``servo_replay`` (compiled, tick_by_tick), ``master_us_per_step`` (every path),
        ``c_fmu``, ``pythonfmu``,
        ``scaling`` (length, population), ``ratios`` and ``targets`` (value, target, met).
    """
    s = settings or (BenchSettings.quick() if quick else BenchSettings())
    say = progress or (lambda text: None)
    out: dict = {"machine": machine_info(), "settings": asdict(s), "quick": quick and settings is None}
    case = bench_case()
    t_start = time.perf_counter()

    # --- native twin: engagement table (once per program), warm-up (numba caches, imports), single, batched
    say("native twin: engagement table along the program path (once per program)")
    forget("engagement_table")   # timed as built, not as kept from an earlier call (orchestrator.memo)
    t_table = time.perf_counter()
    table = engagement_table(case, TwinOptions())
    out["engagement_table_s"] = time.perf_counter() - t_table
    say("native twin: warm-up (compiles or loads the numba caches)")
    for compiled in (True, False):
        for integrator in ("exponential", "rk4"):
            time_twin(case, 1, 0.05, engagement=table, compiled=compiled, integrator=integrator)
    for compiled in (True, False):
        time_twin(case, 1, 0.05, cutting_mode="zmap", compiled=compiled)
    if s.batches:  # first large batch of the process: memory from the OS, worker threads
        time_twin(case, max(s.batches), 0.05, engagement=table)
    say(f"native twin: single, {s.twin_seconds:g} s (compiled loop, exponential drives, path-mode cutting)")
    twin = {"single": time_twin(case, 1, s.twin_seconds, engagement=table)}
    say(f"native twin: single air cut (no cutting load), {s.twin_seconds:g} s")
    twin["single_air"] = time_twin(case, 1, s.twin_seconds, cutting=False)
    for key, what, kwargs in (("single_rk4", "RK4 drives", {"integrator": "rk4"}),
                              ("single_python_master", "Python master loop", {"compiled": False}),
                              ("single_zmap", "Z-map cutting", {"cutting_mode": "zmap"}),
                              ("single_zmap_python_master", "Z-map cutting, Python master loop",
                               {"cutting_mode": "zmap", "compiled": False})):
        say(f"native twin: single, {what}, {s.compare_seconds:g} s")
        twin[key] = time_twin(case, 1, s.compare_seconds, engagement=table, **kwargs)
    for b in s.batches:
        say(f"native twin: batch {b}, {s.batch_seconds:g} s")
        twin[f"batch_{b}"] = time_twin(case, b, s.batch_seconds, engagement=table)
    big = max(s.batches) if s.batches else 1
    if s.batches:  # an optimiser's population: distinct F and S per member (issue 9's "100 variants")
        say(f"native twin: batch {big} of distinct variants, {s.batch_seconds:g} s")
        twin[f"batch_{big}_variants"] = time_twin(case, big, s.batch_seconds, engagement=table, variants=True)
    if s.batches and twin[f"batch_{big}"]["threads"] > 1:
        say(f"native twin: batch {big} in one thread, {s.batch_seconds:g} s")
        twin[f"batch_{big}_one_thread"] = time_twin(case, big, s.batch_seconds, engagement=table, threads=1)
    out["native_twin"] = twin

    # --- fused reference (same case, same lengths, batch sizes)
    say("fused reference: open-loop NC reference and engagement")
    n_fused = int(round(max(s.fused_seconds, s.batch_seconds) / 1e-3))
    ref = reference_run(case, n_fused)
    fused = {}
    for key, b, seconds in [("single", 1, s.fused_seconds)] + [(f"batch_{b}", b, s.batch_seconds) for b in s.batches]:
        say(f"fused reference: {key}")
        problem = prepare_fused(case, int(round(seconds / 1e-3)), batch=b, reference=ref)
        problem.run()  # compile / load the cache
        fused[key] = time_fused(problem, repeats=2)
    out["fused"] = fused
    # the member-vectorised prototype of the same loop (largest batch; CPU times, interleaved with the fused one)
    say(f"fused reference, member-vectorised prototype: B = {max(s.batches)}")
    problem = prepare_fused(case, int(round(s.batch_seconds / 1e-3)), batch=max(s.batches), reference=ref)
    out["simd"] = time_simd(problem, repeats=2)

    # --- the servo replay of identification and diagnosis: compiled against the components tick by tick
    say(f"servo replay (identification, diagnosis): B = {s.replay_batch}, compiled {s.replay_seconds:g} s, "
        f"tick by tick {s.compare_seconds:g} s")
    time_servo_replay(case, min(0.2, s.replay_seconds), s.replay_batch)  # warm-up
    out["servo_replay"] = {"compiled": time_servo_replay(case, s.replay_seconds, s.replay_batch),
                           "tick_by_tick": time_servo_replay(case, s.compare_seconds, s.replay_batch,
                                                             compiled=False)}

    # --- NC planning of a population: the compiled planner against the numpy reference (same inputs, interleaved)
    say(f"NC planning: {s.planning_batch} distinct variants, compiled and numpy reference")
    out["planning"] = time_planning(s.planning_batch, s.planning_repeats, case)

    # --- C FMUs (four Lag instances in a ring) and the same ring of native components
    say("C-FMU ring: master, FastFMULoop, plain fmpy loop")
    fmu = build_lag_fmu()
    ring_probes = ("a.y", "d.y")
    out["c_fmu"] = _paths(lambda: lag_ring(fmu), ring_probes, s.ring_steps)
    say("native ring: master")
    runner = _master_runner(native_lag_ring, ring_probes)
    runner(max(2, s.ring_steps // 10))
    out["native_ring"] = {"master": _slope(runner, s.ring_steps)}

    # --- the project's pythonfmu FMUs (MCU + 3 drives, servo loop at 4 ticks per step)
    say("pythonfmu servo FMUs: build, master, FastFMULoop, plain fmpy loop")
    fmu_dir = Path(s.fmu_dir) if s.fmu_dir else Path(tempfile.gettempdir()) / f"cnctwin_bench_{os.getuid()}" / "fmus"
    mcu_fmu, drive_fmu = build_servo_fmus(fmu_dir)
    servo_probes = ("x_drive.position", "mcu.x_current_cmd")
    out["pythonfmu"] = _paths(lambda: servo_fmu_system(mcu_fmu, drive_fmu), servo_probes, s.servo_steps)

    # --- growth with program length and population size
    say("scaling with program length")
    lengths = [time_twin(case, 1, sec, engagement=table) for sec in s.length_seconds]
    say("scaling with population size")
    pops = [time_twin(case, b, s.population_seconds, engagement=table) for b in s.population_sizes]
    fit = _fit_line([r["sim_s"] for r in lengths], [r["wall_s"] for r in lengths])
    per_member = [r["wall_s"] / r["batch"] for r in pops]
    out["scaling"] = {
        "length": [{k: r[k] for k in ("sim_s", "wall_s", "us_per_step")} for r in lengths],
        "length_fit": {"wall_s_per_sim_s": fit["slope"], "fixed_s": fit["intercept"], "r2": fit["r2"]},
        "population": [{"batch": r["batch"], "sim_s": r["sim_s"], "wall_s": r["wall_s"],
                        "wall_s_per_member": r["wall_s"] / r["batch"]} for r in pops],
        "population_per_member_decreasing": bool(all(b < a for a, b in zip(per_member, per_member[1:]))),
        "population_exponent": (float(np.polyfit(np.log([r["batch"] for r in pops]),
                                                 np.log([r["wall_s"] for r in pops]), 1)[0])
                                if len(pops) >= 2 else math.nan),
    }

    # --- summary: µs per communication step of every path, ratios, targets
    c, p = out["c_fmu"], out["pythonfmu"]
    us = {
        "native_twin_single": twin["single"]["us_per_step"],
        "native_twin_single_air": twin["single_air"]["us_per_step"],
        "native_twin_single_rk4": twin["single_rk4"]["us_per_step"],
        "native_twin_single_python_master": twin["single_python_master"]["us_per_step"],
        "native_twin_single_zmap": twin["single_zmap"]["us_per_step"],
        "native_twin_single_zmap_python_master": twin["single_zmap_python_master"]["us_per_step"],
        "fused_single": fused["single"]["us_per_step"],
        "native_ring_master": out["native_ring"]["master"]["us_per_step"],
        "c_fmu_master": c["master"]["us_per_step"],
        "c_fmu_python_master": c["python_master"]["us_per_step"],
        "c_fmu_fast_loop": c["fast_loop"]["us_per_step"],
        "c_fmu_plain_fmpy": c["plain_fmpy"]["us_per_step"],
        "pythonfmu_master": p["master"]["us_per_step"],
        "pythonfmu_python_master": p["python_master"]["us_per_step"],
        "pythonfmu_fast_loop": p["fast_loop"]["us_per_step"],
        "pythonfmu_plain_fmpy": p["plain_fmpy"]["us_per_step"],
    }
    for b in s.batches:
        us[f"native_twin_batch_{b}"] = twin[f"batch_{b}"]["us_per_step"]
        us[f"fused_batch_{b}"] = fused[f"batch_{b}"]["us_per_step"]
    out["master_us_per_step"] = us

    def ratio(a: float, b: float) -> float:
        return a / b if b > 0 else math.inf

    ratios = {
        "native_twin_over_fused_single": ratio(us["native_twin_single"], us["fused_single"]),
        "native_twin_single_cutting_over_air": ratio(us["native_twin_single"], us["native_twin_single_air"]),
        "python_master_over_compiled_loop": ratio(us["native_twin_single_python_master"], us["native_twin_single"]),
        "rk4_over_exponential_drives": ratio(us["native_twin_single_rk4"], us["native_twin_single"]),
        "zmap_over_path_cutting": ratio(us["native_twin_single_zmap"], us["native_twin_single"]),
        "zmap_python_master_over_compiled_loop": ratio(us["native_twin_single_zmap_python_master"],
                                                       us["native_twin_single_zmap"]),
        "c_fmu_plain_fmpy_over_fast_loop": ratio(us["c_fmu_plain_fmpy"], us["c_fmu_fast_loop"]),
        "c_fmu_master_over_fast_loop": ratio(us["c_fmu_master"], us["c_fmu_fast_loop"]),
        "c_fmu_master_over_plain_fmpy": ratio(us["c_fmu_master"], us["c_fmu_plain_fmpy"]),
        "c_fmu_master_over_native_ring_master": ratio(us["c_fmu_master"], us["native_ring_master"]),
        "c_fmu_python_master_over_master": ratio(us["c_fmu_python_master"], us["c_fmu_master"]),
        "pythonfmu_python_master_over_master": ratio(us["pythonfmu_python_master"], us["pythonfmu_master"]),
        "pythonfmu_master_over_plain_fmpy": ratio(us["pythonfmu_master"], us["pythonfmu_plain_fmpy"]),
        "pythonfmu_fast_loop_over_plain_fmpy": ratio(us["pythonfmu_fast_loop"], us["pythonfmu_plain_fmpy"]),
    }
    replay = out["servo_replay"]
    ratios["servo_replay_tick_by_tick_over_compiled"] = ratio(replay["tick_by_tick"]["us_per_member_tick"],
                                                              replay["compiled"]["us_per_member_tick"])
    ratios[f"nc_planning_{s.planning_batch}_reference_over_compiled"] = ratio(out["planning"]["reference_s"],
                                                                          out["planning"]["compiled_s"])
    for b in s.batches:
        ratios[f"native_twin_over_fused_batch_{b}"] = ratio(us[f"native_twin_batch_{b}"], us[f"fused_batch_{b}"])
        ratios[f"native_twin_batch_{b}_per_member_over_single"] = ratio(
            twin[f"batch_{b}"]["us_per_member_step"], twin["single"]["us_per_member_step"])
    if f"batch_{big}_one_thread" in twin:
        ratios[f"native_twin_batch_{big}_one_thread_over_threads"] = ratio(
            twin[f"batch_{big}_one_thread"]["us_per_step"], us[f"native_twin_batch_{big}"])
    out["ratios"] = ratios

    targets = {
        "native_single_rt_factor": (twin["single"]["rt_factor"], TARGETS["native_single_rt_factor_min"], ">="),
        f"native_population_{big}_rt_factor": (twin.get(f"batch_{big}_variants", twin["single"])["rt_factor"],
                                               TARGETS["native_population_100_rt_factor_min"], ">="),
        "c_fmu_fast_loop_us_per_step": (us["c_fmu_fast_loop"], TARGETS["c_fmu_master_us_per_step_max"], "<="),
        "c_fmu_master_us_per_step": (us["c_fmu_master"], TARGETS["c_fmu_master_us_per_step_max"], "<="),
        "pythonfmu_fast_loop_vs_plain_fmpy": (us["pythonfmu_fast_loop"], us["pythonfmu_plain_fmpy"], "<="),
        "pythonfmu_master_vs_plain_fmpy": (us["pythonfmu_master"], us["pythonfmu_plain_fmpy"], "<="),
    }
    out["targets"] = {
        k: {"value": v, "target": t, "op": op, "met": bool(v >= t if op == ">=" else v <= t)}
        for k, (v, t, op) in targets.items()
    }
    out["bench_wall_s"] = time.perf_counter() - t_start
    out["load_average_end"] = _load()
    return out


def format_table(result: dict) -> str:
    """A plain-text table of :func:`run_bench`'s main figures."""
    m = result["machine"]
    lines = [f"cnctwin bench — {m['cpu']}, nproc {m['nproc']}, Python {m['python']}, numba {m['numba']}, "
             f"fmpy {m['fmpy']}{' (quick: rough figures)' if result.get('quick') else ''}",
             f"load average {m.get('load_average', math.nan):.2f} at start, "
             f"{result.get('load_average_end', math.nan):.2f} at end; engagement table built once in "
             f"{result.get('engagement_table_s', math.nan):.2f} s", ""]
    lines.append(f"{'run':<40}{'B':>5}{'thr':>4}{'sim s':>8}{'wall s':>9}{'x real time':>13}{'us/step':>11}")
    for label, group in (("native twin", result["native_twin"]), ("fused reference", result["fused"])):
        for key, r in group.items():
            lines.append(f"{label + ' ' + key:<40}{r['batch']:>5}{r.get('threads', 1):>4}{r['sim_s']:>8.2f}"
                         f"{r['wall_s']:>9.3f}{r['rt_factor']:>13.1f}{r['us_per_step']:>11.1f}")
    lines += ["", f"{'servo replay (identification, diagnosis)':<40}{'B':>5}{'sim s':>8}{'wall s':>9}"
                  f"{'x real time':>13}{'us/member tick':>16}"]
    for key, r in result.get("servo_replay", {}).items():
        lines.append(f"{key:<40}{r['batch']:>5}{r['sim_s']:>8.2f}{r['wall_s']:>9.3f}{r['rt_factor']:>13.1f}"
                     f"{r['us_per_member_tick']:>16.3f}")
    plan = result.get("planning")
    if plan:
        lines += ["", f"{'NC planning of distinct variants':<40}{'B':>5}{'wall s':>9}{'ms/member':>11}",
                  f"{'numpy reference':<40}{plan['batch']:>5}{plan['reference_s']:>9.3f}"
                  f"{plan['ms_per_member_reference']:>11.2f}",
                  f"{'compiled':<40}{plan['batch']:>5}{plan['compiled_s']:>9.3f}{plan['ms_per_member_compiled']:>11.2f}"
                  f"   ratio {plan['ratio']:.2f}, bit-identical: {'yes' if plan['identical'] else 'NO'}"]
    simd = result.get("simd")
    if simd:
        lines += ["", f"fused reference, member-vectorised prototype (B = {simd['batch']}, {simd['steps']} steps, CPU "
                      f"time): {simd['simd_s']:.3f} s against {simd['fused_s']:.3f} s scalar, "
                      f"{simd['simd_speedup']:.2f}x; scalar fallback on {100 * simd['scalar_fraction']:.3f} % of "
                      f"drive ticks; largest difference {simd['max_position_diff_m']:.2e} m, "
                      f"{simd['max_current_diff_a']:.2e} A"]
    lines += ["", f"{'communication step of':<44}{'us/step':>10}"]
    for key, value in result["master_us_per_step"].items():
        lines.append(f"{key:<44}{value:>10.2f}")
    lines += ["", f"{'ratio':<54}{'value':>10}"]
    for key, value in result["ratios"].items():
        lines.append(f"{key:<54}{value:>10.2f}")
    sc = result["scaling"]
    lines += ["", f"growth with length: {sc['length_fit']['wall_s_per_sim_s']:.3f} s wall per simulated s "
              f"+ {sc['length_fit']['fixed_s']:.3f} s (r2 {sc['length_fit']['r2']:.4f})",
              "growth with population: wall ~ B^{:.2f}; per member: {}".format(
                  sc["population_exponent"],
                  ", ".join(f"B={p['batch']}: {p['wall_s_per_member']:.3f} s" for p in sc["population"])), ""]
    lines.append(f"{'target':<40}{'value':>12}{'':>4}{'target':>12}  met")
    for key, t in result["targets"].items():
        lines.append(f"{key:<40}{t['value']:>12.2f}{t['op']:>4}{t['target']:>12.2f}  {'yes' if t['met'] else 'NO'}")
    lines.append(f"\n(bench took {result['bench_wall_s']:.1f} s)")
    return "\n".join(lines)
