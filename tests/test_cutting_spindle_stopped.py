"""Feeding the tool into the stock with the spindle stopped is a crash, reported as one.

Case: stock 0..30 x 0..20 x -10..0 mm, a 6 mm 2-flute end mill. The program plunges 1 mm at X10 Y10
with the spindle on, stops the spindle (M5), dwells 2 s (the spindle ramp of 4000 rpm/s stops
6000 rpm in 1.5 s, so the spindle is at exactly 0 rpm afterwards) and feeds 2 mm in +X (line 7).

Facts derived here, not taken from the code:

* With the spindle on, the same cut has a feed per tooth ``fz = F / (N S) = 100 / (2 x 6000) mm``
  and an axial depth ``a = 1 mm``; only one of the two teeth (180 deg apart) has a positive chip
  ``fz sin(phi)`` at a time, and after the first 2 mm out of its own hole the tooth facing the feed
  (``phi = 90 deg``) is in material, so the largest cutting load is
  ``Fc = Kt a fz sqrt(1 + Ke^2)`` (11.5 N with the paper's A6061 Kt, Ke).
* With the spindle stopped the chip per tooth is unbounded: the run must fail at the start of
  line 7, where the tool sits at the bottom of its plunge (X10 Y10 Z-1: its own hole has its
  diameter, so the first micrometres of the move bring the front tooth into the wall), before any
  load above 10 x that Fc is recorded, with a message naming the line and 0 rpm.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from fmus_src.cutting import CuttingError, CuttingLoad
from orchestrator import simulate
from orchestrator.case import load_case
from orchestrator.master import Master, MasterSettings
from orchestrator.optimize import OptimizeError, Ranges, build_reference
from orchestrator.optimize.evaluate import figures, run_twin
from orchestrator.twin import TwinOptions, build_twin, cutting_parameters

from test_compiled_master import RPM, _assert_same

CASE_TOML = """program = "stopped.nc"

[stock]
min = [0.0, 0.0, -10.0]
max = [30.0, 20.0, 0.0]

[tool]
diameter_mm = 6.0
flutes = 2

[machine]
parameters = "default"
"""
STOPPED = "G21 G17 G90 G94 G54\nS6000 M3\nG0 X10. Y10. Z1.\nG1 Z-1. F100\nM5\nG4 P2.\nG1 X12. F100\nG0 Z5.\nM30\n"
SPINDLE_ON = STOPPED.replace("M5\n", "M3\n")  # the same lines, the spindle kept on
AIR = "G21 G17 G90 G94 G54\nG0 X10. Y10. Z1.\nG1 X12. F100\nG0 Z5.\nM30\n"  # never started, 1 mm above the stock
FEED_MM_PER_MIN, SPEED_RPM, FLUTES, DEPTH_MM = 100.0, 6000.0, 2, 1.0


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    path = tmp_path_factory.mktemp("spindle_stopped")
    (path / "case.toml").write_text(CASE_TOML)
    for name, text in (("stopped.nc", STOPPED), ("on.nc", SPINDLE_ON), ("air.nc", AIR)):
        (path / name).write_text(text)
    return path


@pytest.fixture(scope="module")
def fc_on(folder):
    """The largest cutting load of the cut with the spindle on, Kt a fz sqrt(1 + Ke^2), N."""
    p = cutting_parameters(load_case(folder))
    fz = FEED_MM_PER_MIN / (FLUTES * SPEED_RPM) * 1e-3
    return p["kt"] * DEPTH_MM * 1e-3 * fz * math.sqrt(1.0 + p["ke"] ** 2)


def test_feeding_with_the_spindle_stopped_fails_at_line_7(folder, fc_on, tmp_path):
    program = folder / "stopped.nc"
    with np.errstate(over="ignore", invalid="ignore"):
        result = simulate(program=program, case=folder, out=tmp_path, plot=False)
    assert not result.success
    assert result.message.startswith(f"{program}:7: simulation failed at t = ")
    assert "cutting: the tool feeds into the stock with the spindle stopped (0 rpm) at t = " in result.message
    assert result.message.endswith("tool at X10.000 Y10.000 Z-1.000 mm: a crash; start the spindle (M3) before the cut")
    assert result.summary["message"] == result.message
    rec = result.recording
    assert rec["line"][-1] == 7 and rec["spindle_rpm"][-1] == 0.0
    # the crash is reported before any load far above the cut's own (here: none at all, the plunge has no chip)
    assert np.nanmax(rec["fc_N"]) <= 10.0 * fc_on and np.nanmax(rec["fc_peak_N"]) <= 10.0 * fc_on
    # ... within the first 50 ms of line 7 (the servo lag is a few ms)
    t_fail = float(re.search(r"at t = ([0-9.]+) s, tool at", result.message).group(1))
    t7 = rec.t[np.flatnonzero(rec["line"] == 7)[0]]
    assert t7 <= t_fail <= t7 + 0.05


def test_the_same_cut_with_the_spindle_on_cuts_normally(folder, fc_on):
    result = simulate(program=folder / "on.nc", case=folder, plot=False)
    assert result.success, result.message
    fc = result.recording["fc_N"]
    assert np.nanmax(fc) == pytest.approx(fc_on, rel=0.03)  # 11.5 N
    assert np.nanmax(result.recording["fc_N"][result.recording["line"] == 7]) == pytest.approx(fc_on, rel=0.03)


def test_an_air_move_with_the_spindle_stopped_is_fine(folder):
    result = simulate(program=folder / "air.nc", case=folder, plot=False)
    assert result.success, result.message
    assert np.all(result.recording["fc_N"] == 0.0) and np.all(result.recording["spindle_rpm"] == 0.0)


def test_fine_boring_shift_into_the_wall_is_reported_as_this_crash(folder):
    """G76: at the bottom the spindle is oriented (stopped) and the tool shifts Q = 0.5 mm (+X, the
    default machine's boring_shift); the case's tool is an end mill, a full cylinder, so the shift moves
    it into the wall it has just bored: the same crash, at the cycle's line, at the bottom Z-2."""
    program = folder / "g76.nc"
    program.write_text("G21 G17 G90 G94 G54\nS6000 M3\nG0 X10. Y10. Z5.\nG98 G76 X10. Y10. Z-2. R1. Q0.5 F100\n"
                       "G80\nG0 Z10.\nM30\n")
    with np.errstate(over="ignore", invalid="ignore"):
        result = simulate(program=program, case=folder, plot=False)
    assert not result.success and result.message.startswith(f"{program}:4: ")
    x_mm = float(re.search(r"spindle stopped \(0 rpm\) at t = [0-9.]+ s, tool at X([0-9.]+) Y10\.000 Z-2\.000 mm: "
                           r"a crash", result.message).group(1))
    assert 10.0 <= x_mm <= 10.5


def _pair(folder, mode, speeds_rpm):
    """Twin of the spindle-on program with the S word of line 2 set per member, and its settings."""
    case = load_case(folder)
    twin = build_twin(case, batch=len(speeds_rpm), program_text=SPINDLE_ON, options=TwinOptions(cutting_mode=mode))
    twin.nck.set_overrides(spindle={2: np.asarray(speeds_rpm, dtype=float) * RPM})
    return twin, MasterSettings(step=twin.options.step, time_limit=8.0, stop_when=twin.stop_when,
                                limits=twin.limits or {}, check_every=10)


def _run(folder, mode, speeds_rpm, compiled, threads=1):
    twin, settings = _pair(folder, mode, speeds_rpm)
    settings.compiled, settings.threads = compiled, threads
    with np.errstate(over="ignore", invalid="ignore"):
        return Master(twin.system, settings, twin.probes).run()


@pytest.fixture(scope="module")
def python_runs():
    """Runs that do not depend on the compiled loop's thread count, made once per cutting mode and shared
    by its parametrisations: ``{mode: (Python master, numpy Z-map kernel or None, compiled solo run)}``."""
    return {}


def _shared_runs(folder, mode, python_runs, monkeypatch):
    """The Python master's run of the pair, (Z-map only) the numpy kernel's, and member 1's solo run."""
    if mode not in python_runs:
        python = _run(folder, mode, [SPEED_RPM, 0.0], False)
        numpy_kernel = None
        if mode == "zmap":
            with monkeypatch.context() as m:
                m.setattr(CuttingLoad, "use_compiled", False)
                numpy_kernel = _run(folder, mode, [SPEED_RPM, 0.0], False)
        python_runs[mode] = (python, numpy_kernel, _run(folder, mode, [0.0], True))
    return python_runs[mode]


@pytest.mark.parametrize("mode,threads", [("zmap", 1), ("zmap", 2), ("path", 1)])
def test_a_member_that_never_starts_its_spindle_fails_alone(folder, fc_on, mode, threads, python_runs, monkeypatch):
    """Member 1 runs S0 (the spindle never turns): it crashes in the plunge; member 0 cuts as alone.

    Plunging with a stopped spindle is a crash too; the model has no chip for a purely axial feed, so it
    is caught once the tool also moves sideways into the material it is entering (the X/Y servos still
    settle after the rapid to X10 Y10): the tip is then below the stock top (Z0), above the plunge depth.

    Compiled loop (1 or 2 threads) and Python master give the same run bit for bit, and the same
    reason as member 1's solo run; the numpy Z-map kernel gives it too.
    """
    both = _run(folder, mode, [SPEED_RPM, 0.0], True, threads)
    python, numpy_kernel, solo = _shared_runs(folder, mode, python_runs, monkeypatch)
    _assert_same(both, python)
    if mode == "zmap":
        _assert_same(both, numpy_kernel)
    assert both.success and both.failed.tolist() == [False, True]
    assert both.failures[1].startswith("failed at t = ")
    assert "cutting: the tool feeds into the stock with the spindle stopped (0 rpm)" in both.failures[1]
    z_mm = float(re.search(r"tool at X10\.000 Y10\.000 Z(-?[0-9.]+) mm: a crash; start the spindle \(M3\) before the "
                           r"cut$", both.failures[1]).group(1))
    assert -DEPTH_MM < z_mm <= 0.0  # printed to 1 um: "Z-0.000" on the first step below the top
    assert not solo.success
    assert solo.message.replace("simulation failed at", "failed at", 1) == both.failures[1]
    fc = both.recording["fc_N"]
    assert np.nanmax(fc[:, 0]) == pytest.approx(fc_on, rel=0.03)
    assert np.nanmax(fc[:, 1]) <= 10.0 * fc_on and np.isnan(fc[-1, 1])


def test_component_reversed_spindle_crashes_and_rest_in_material_does_not():
    """The case's end mill cuts clockwise (M3); M4 is as good as stopped. A stopped tool at rest in
    material, with no feed, has no chip: no force and no failure."""
    r = 3e-3
    params = dict(tool_diameter=2 * r, flutes=2, kt=1.23e9, ke=0.5, stock_x_min=0.0, stock_x_max=0.012,
                  stock_y_min=-0.01, stock_y_max=0.01, stock_z_min=-0.01, stock_z_max=0.0)
    comp = CuttingLoad("cut", **params)
    comp.set("x_position", 2e-3)  # inside the block, 1 mm deep
    comp.set("z_position", -1e-3)
    comp.set("spindle_speed", 0.0)
    comp.setup(0.0)
    for k in range(5):
        comp.do_step(k * 1e-3, 1e-3)
    assert comp.get("fc_peak")[0] == 0.0 and not comp.failed_members.any()
    comp.set("spindle_speed", -6000.0 * RPM)
    comp.set("x_position", 2.01e-3)
    with pytest.raises(CuttingError, match=r"cut: the tool feeds into the stock with the spindle turning backwards "
                                           r"\(-6000 rpm, M4; the case's end mill cuts clockwise\) at t = 0\.006000 s, "
                                           r"tool at X2\.010 Y0\.000 Z-1\.000 mm"):
        comp.do_step(5e-3, 1e-3)


def test_the_optimiser_treats_a_crashing_program_as_infeasible(folder):
    """The spindle-on program is the reference; run with the crashing text, every member is infeasible,
    with the crash as its reason; a crashing original program is refused with that reason."""
    ranges = Ranges((50.0, 600.0), (1000.0, 8000.0))
    ref = build_reference(load_case(folder), program_text=SPINDLE_ON, ranges=ranges)
    ctx = ref.context
    feeds = np.repeat(ctx.original_feed[None, :], 2, axis=0)
    spindles = np.repeat(ctx.original_spindle[None, :], 2, axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        run = run_twin(ctx, feeds, spindles, 2, program_text=STOPPED)
    ev = figures(ctx, run, 2)
    assert not ev.success.any() and not ev.feasible.any()
    assert all("the spindle stopped (0 rpm)" in reason for reason in ev.reason)
    with pytest.raises(OptimizeError, match=r"the spindle stopped \(0 rpm\)"):
        build_reference(load_case(folder), program_text=STOPPED, ranges=ranges)
