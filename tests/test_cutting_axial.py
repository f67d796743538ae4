"""The axial chip: a plunge, a G81 hole and G83 pecks load the tool through its end edges.

Facts derived here, not taken from the code (6 mm 2-flute flat end mill, A6061 Kt = 1230 N/mm2 of the
paper, end-edge thrust ratio ka = 0.28 of the machine file, Altintas' Kac/Ktc):

* axial chip per tooth ``h_a = F / (N S)``: F600 at S6000 gives 0.05 mm;
* each of the N end edges cuts from the axis to R: ``Ft = Kt h_a dr``, so the torque is
  ``N Kt h_a R^2 / 2`` = 2 x 1230 x 0.05 x 9 / 2 = 553.5 N.mm and the thrust ``N ka Kt h_a R`` =
  2 x 0.28 x 1230 x 0.05 x 3 = 103.32 N (on the workpiece along -Z: fz = -103.32 N);
* the removal rate is ``pi R^2 vz`` and a plunge d deep removes ``pi R^2 d`` (28.27 mm3 per mm);
* the end edges of a symmetric tool cancel sideways: fc = 0 in a plunge into solid;
* plunging with the centre on the stock's edge, half the end disc meets material: half of each.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting import CuttingError, CuttingLoad
from orchestrator import simulate

KT, KA, R, N = 1.23e9, 0.28, 3e-3, 2
S_RPM, F_MM_MIN = 6000.0, 600.0
H_A = F_MM_MIN / (N * S_RPM) * 1e-3  # m
THRUST = N * KA * KT * H_A * R  # N
TORQUE = N * KT * H_A * R * R / 2.0  # N.m
MRR = math.pi * R * R * F_MM_MIN / 60e3  # m3/s


def _plunge(compiled: bool, x: float = 5e-3, depth: float = 1e-3, rpm: float = S_RPM):
    """A plunge from 0.2 mm above the top face to ``depth`` below, at X ``x``; per-step outputs and the component."""
    saved = CuttingLoad.use_compiled
    CuttingLoad.use_compiled = compiled
    try:
        cut = CuttingLoad("cut", tool_diameter=2 * R, flutes=N, kt=KT, ke=0.5, ka=KA, stock_x_min=0.0,
                          stock_x_max=0.02, stock_y_min=-0.01, stock_y_max=0.01, stock_z_min=-0.01)
        h, vz, z0 = 1e-3, F_MM_MIN / 60e3, 0.2e-3
        cut.set("spindle_speed", rpm * 2 * math.pi / 60)
        cut.set("x_position", x)
        cut.set("z_position", z0)
        cut.setup(0.0)
        rows = []
        k = 0
        while True:
            k += 1
            z = max(z0 - vz * h * k, -depth)
            cut.set("z_position", z)
            cut.do_step((k - 1) * h, h)
            rows.append([float(cut.get(n)[0]) for n in ("fz", "spindle_torque", "spindle_power", "mrr", "fc",
                                                          "fc_peak", "fx_mean", "fy_mean")])
            if z <= -depth:
                return np.array(rows), cut
    finally:
        CuttingLoad.use_compiled = saved


@pytest.mark.parametrize("compiled", [False, True])
def test_plunge_into_solid_thrust_torque_and_volume_by_hand(compiled):
    out, _ = _plunge(compiled)
    fz, torque, power, mrr, fc, peak, fx, fy = out.T
    steady = slice(50, 100)  # well inside the material (it is entered after 20 steps)
    np.testing.assert_allclose(fz[steady], -THRUST, rtol=1e-9)  # -103.32 N
    np.testing.assert_allclose(torque[steady], TORQUE, rtol=1e-9)  # 0.5535 N.m
    np.testing.assert_allclose(power[steady], TORQUE * S_RPM * 2 * math.pi / 60, rtol=1e-9)  # Kt x MRR
    np.testing.assert_allclose(mrr[steady], MRR, rtol=1e-9)
    assert np.sum(mrr) * 1e-3 == pytest.approx(math.pi * R * R * 1e-3, rel=1e-9)  # pi 3^2 x 1 mm = 28.27 mm3
    assert np.all(fz <= 0.0) and np.all(fz[:19] == 0.0)  # in the air above the top face: nothing
    assert np.all(fc == 0.0) and np.all(peak == 0.0) and np.all(fx == 0.0) and np.all(fy == 0.0)


def test_numpy_and_compiled_steps_agree_bit_for_bit_on_a_plunge():
    a, _ = _plunge(False, x=1e-3)
    b, _ = _plunge(True, x=1e-3)
    assert np.array_equal(a, b)


def test_plunge_on_the_stock_edge_engages_half_the_end_disc():
    """Centre on x = 0, the stock's face: the end edges cut over half a revolution (the quadrature's sectors
    split evenly there), so thrust, torque and removal are half those of a full plunge."""
    out, _ = _plunge(True, x=0.0)
    fz, torque, _, mrr, fc, *_ = out.T
    full, _ = _plunge(True, x=5e-3)
    np.testing.assert_allclose(fz[50:100], -THRUST / 2, rtol=1e-9)
    np.testing.assert_allclose(torque[50:100], TORQUE / 2, rtol=1e-9)
    assert np.sum(mrr) == pytest.approx(np.sum(full[:, 3]) / 2, rel=1e-9)
    assert np.all(fc == 0.0)  # the end edges' lateral resultant is not modelled (see README limits)


def test_plunge_with_the_spindle_stopped_is_a_crash():
    with pytest.raises(CuttingError, match="spindle stopped"):
        _plunge(True, rpm=0.0)


CASE_TOML = """program = "g81.nc"

[stock]
min = [0.0, 0.0, -10.0]
max = [30.0, 20.0, 0.0]

[tool]
diameter_mm = 6.0
flutes = 2

[machine]
parameters = "default"
"""
G81 = "G21 G17 G90 G94 G54\nS6000 M3\nG0 X10. Y10. Z5.\nG98 G81 X10. Y10. Z-3. R1. F600\nG80\nG0 Z10.\nM30\n"
# 3 pecks of 1 mm (G83 returns to R 1 and comes back to 0.5 mm above the last bottom, No. 5115)
G83 = "G21 G17 G90 G94 G54\nS6000 M3\nG0 X10. Y10. Z5.\nG98 G83 X10. Y10. Z-3. R1. Q1. F600\nG80\nG0 Z10.\nM30\n"


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    path = tmp_path_factory.mktemp("axial")
    (path / "case.toml").write_text(CASE_TOML)
    (path / "g81.nc").write_text(G81)
    (path / "g83.nc").write_text(G83)
    return path


@pytest.mark.parametrize("name", ["g81.nc", "g83.nc"])
def test_drilling_cycle_removes_the_hole_once_with_thrust_and_no_lateral_load(folder, name):
    """A hole as deep as the tool actually went: the rapid retract waits for the in-position check, so the
    bottom is within the 20 um in-position width of Z-3 (without it the servo lag, following error = feed /
    position gain, left it about 0.1 mm short at F600); pi 3^2 x depth mm3 removed, whether drilled at once
    (G81) or in 3 pecks (G83) that re-enter their own hole (each layer once); the thrust at F600 S6000 is
    103.3 N; fc stays 0."""
    result = simulate(program=folder / name, case=folder, plot=False)
    assert result.success, result.message
    rec = result.recording
    t = np.asarray(rec.t)
    mrr = np.asarray(rec["mrr_mm3_per_min"]) / 60.0
    removed = float(np.sum(mrr[1:] * np.diff(t)))
    depth = -float(np.nanmin(rec["z_mm"]))
    assert 3.0 - 0.02 <= depth <= 3.0 + 0.02
    assert removed == pytest.approx(math.pi * 9.0 * depth, rel=1e-6)
    fz = np.asarray(rec["fz_N"])
    assert np.nanmin(fz) == pytest.approx(-THRUST, rel=0.02)  # the feed F600 reached in the hole
    assert np.nanmax(fz) <= 0.0
    assert np.nanmax(rec["fc_N"]) == 0.0 and np.nanmax(rec["fc_peak_N"]) == 0.0
    assert np.nanmax(rec["spindle_torque_Nm"]) == pytest.approx(TORQUE, rel=0.02)


def test_a_ramp_removes_the_swept_volume_with_its_z_share():
    """A ramp 1 mm down over 10 mm along +X, then 10 mm level (F600, S6000): the removed volume is that of the
    swept tool below the top face, integrated here on a 10 um grid (118.2 mm3). Without the end edges the
    Z share (about pi R^2 x 1 mm = 28.3 mm3) was missing; the periphery and the end disc (only where it was
    already under the disc a step before) count the rest once, to 0.5 %."""
    saved = CuttingLoad.use_compiled
    CuttingLoad.use_compiled = True
    try:
        cut = CuttingLoad("cut", tool_diameter=2 * R, flutes=N, kt=KT, ke=0.5, ka=KA, stock_x_min=0.0,
                          stock_x_max=0.04, stock_y_min=-0.01, stock_y_max=0.01, stock_z_min=-0.01)
        h, v = 1e-3, F_MM_MIN / 60e3
        cut.set("spindle_speed", S_RPM * 2 * math.pi / 60)
        cut.set("x_position", 5e-3)
        cut.setup(0.0)
        pts = [(5e-3, 0.0), (15e-3, -1e-3), (25e-3, -1e-3)]
        removed = 0.0
        t = 0.0
        for (xa, za), (xb, zb) in zip(pts[:-1], pts[1:]):
            n = int(round(math.hypot(xb - xa, zb - za) / (v * h)))
            for k in range(1, n + 1):
                cut.set("x_position", xa + (xb - xa) * k / n)
                cut.set("z_position", za + (zb - za) * k / n)
                cut.do_step(t, h)
                t += h
                removed += float(cut.get("mrr")[0]) * h
    finally:
        CuttingLoad.use_compiled = saved
    # swept volume: a point (x, y) is cut to the depth of the furthest tool centre c <= x + sqrt(R^2 - y^2)
    x, y = np.meshgrid(np.arange(0.0, 30.0, 0.01) + 0.005, np.arange(-3.0, 3.0, 0.01) + 0.005, indexing="ij")
    w = np.sqrt(9.0 - y * y)
    c_far, c_near = np.minimum(x + w, 25.0), np.maximum(x - w, 5.0)
    depth = np.where(c_far >= c_near, np.clip((c_far - 5.0) / 10.0, 0.0, 1.0), 0.0)  # mm
    exact = float(depth.sum()) * 1e-4  # mm3
    assert exact == pytest.approx(118.2, abs=0.1)
    assert removed * 1e9 == pytest.approx(exact, rel=5e-3)


def test_python_and_compiled_master_agree_on_the_pecks(folder):
    """The G83 program with two members (S6000 and S3000: twice the axial chip, twice the thrust at the same
    feed): the Python master and the compiled loop (one member per core) give the same recording bit for bit,
    fz_N included."""
    from orchestrator.case import load_case
    from orchestrator.master import Master, MasterSettings
    from orchestrator.twin import TwinOptions, build_twin

    from test_compiled_master import RPM, _assert_same

    def run(compiled):
        case = load_case(folder)
        twin = build_twin(case, batch=2, program_text=G83, options=TwinOptions(cutting_mode="zmap"))
        twin.nck.set_overrides(spindle={2: np.array([6000.0, 3000.0]) * RPM})
        settings = MasterSettings(step=twin.options.step, time_limit=6.0, stop_when=twin.stop_when,
                                  limits=twin.limits or {}, check_every=10)
        settings.compiled, settings.threads = compiled, 2
        return Master(twin.system, settings, twin.probes).run()

    a, b = run(False), run(True)
    _assert_same(a, b)
    fz = np.asarray(a.recording.data["fz_N"])
    assert np.nanmin(fz[:, 0]) == pytest.approx(-THRUST, rel=0.02)
    assert np.nanmin(fz[:, 1]) == pytest.approx(-2 * THRUST, rel=0.02)


def test_path_mode_reads_the_axial_chip_from_the_table(folder):
    """G81 in the path mode: the reference pass stores the end disc's engagement per station (pi R^2 and 2 pi R
    per unit of descent in solid), so thrust and torque equal the Z-map mode's and the removed volume agrees
    within the station spacing at the entry (20 um x pi R^2 = 0.57 mm3 at most). The thrust loads the Z drive, so
    the modes' different entries (the path mode's station spacing) leave slightly different Z speeds after it:
    peak thrust and torque agree to 1e-4 (measured 1.8e-5), no longer bit for bit."""
    from orchestrator.twin import TwinOptions

    runs = {}
    for mode in ("zmap", "path"):
        result = simulate(program=folder / "g81.nc", case=folder, options=TwinOptions(cutting_mode=mode), plot=False)
        assert result.success, result.message
        rec = result.recording
        t = np.asarray(rec.t)
        mrr = np.asarray(rec["mrr_mm3_per_min"]).ravel() / 60.0
        runs[mode] = (float(np.sum(mrr[1:] * np.diff(t))), float(np.nanmin(rec["fz_N"])),
                      float(np.nanmax(rec["spindle_torque_Nm"])), float(np.nanmax(rec["fc_N"])))
    (v_z, fz_z, tq_z, fc_z), (v_p, fz_p, tq_p, fc_p) = runs["zmap"], runs["path"]
    assert fz_p == pytest.approx(fz_z, rel=1e-4) and fz_p == pytest.approx(-THRUST, rel=0.02)
    assert tq_p == pytest.approx(tq_z, rel=1e-4)
    assert abs(v_p - v_z) <= math.pi * 9.0 * 0.02
    assert fc_p == fc_z == 0.0


def test_path_mode_python_and_compiled_master_agree_on_a_drilled_hole(folder):
    """G81 in the path mode, members S6000 and S3000: the Python master and the compiled loop (two threads)
    give the same recording bit for bit, fz_N included; S3000 doubles the thrust."""
    from orchestrator.case import load_case
    from orchestrator.master import Master, MasterSettings
    from orchestrator.twin import TwinOptions, build_twin, engagement_table

    from test_compiled_master import RPM, _assert_same

    case = load_case(folder)
    table = engagement_table(case, TwinOptions(), program_text=G81)

    def run(compiled):
        twin = build_twin(case, batch=2, program_text=G81, options=TwinOptions(cutting_mode="path", engagement=table))
        twin.nck.set_overrides(spindle={2: np.array([6000.0, 3000.0]) * RPM})
        settings = MasterSettings(step=twin.options.step, time_limit=6.0, stop_when=twin.stop_when,
                                  limits=twin.limits or {}, check_every=10)
        settings.compiled, settings.threads = compiled, 2
        return Master(twin.system, settings, twin.probes).run()

    a, b = run(False), run(True)
    _assert_same(a, b)
    fz = np.asarray(a.recording.data["fz_N"])
    assert np.nanmin(fz[:, 0]) == pytest.approx(-THRUST, rel=0.02)
    assert np.nanmin(fz[:, 1]) == pytest.approx(-2 * THRUST, rel=0.02)
