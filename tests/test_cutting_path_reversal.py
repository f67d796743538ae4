"""Path mode across a reversal on one line that the servo turns back from short of its end (G83 pecks).

The forward-only projection of the path mode (:func:`fmus_src.cutting.path_kernel.locate`) cannot follow a tool
that turns back before the commanded motion does: a G83 peck returns to R and the servo turns back 0.14-0.50 mm
short of it. :func:`~fmus_src.cutting.path_kernel.across_reversal` re-finds the member after the reversal: across
stations where the reference pass met no material, or where the tool retraces its line within the servo's
shortfall of the reversal (a slot cut out and back). Checked here on the kernel's projection (analytic positions
on a polyline), on a slot cut out and back on one line (hand calculation, no load on the way back), on the
compiled replay against the component stepped step by step (bit for bit, baseline and effect kernels) and on the
whole twin with a G83 program and two slots after it, against the Z-map model (the independent reference) and
hand calculations: a full slot's peak Fc = Kt a fz sqrt(1 + Ke^2) and its removed volume width x depth x length.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from fmus_src.cutting import path_kernel as pk
from orchestrator.case import load_case
from orchestrator.simulate import simulate
from orchestrator.twin import TwinOptions
from tests.test_cutting_path import KE, KT, OMEGA, R, TOOTH_PERIOD, H, along, assert_modes_agree, params, path_run, \
    zmap_run

MM = 1e-3


def _state(x: float, y: float, z: float, s: float, seg: int, dist: float) -> np.ndarray:
    """One member's state (rows ST_*) at (x, y, z) [m], cursor (seg, s [m]), last distance [m]."""
    st = np.zeros((pk.ST_ROWS, 1))
    st[pk.ST_X, 0], st[pk.ST_Y, 0], st[pk.ST_Z, 0] = x, y, z
    st[pk.ST_S, 0], st[pk.ST_SEG, 0], st[pk.ST_DIST, 0] = s, seg, dist
    return st


# a G83 retract and return: up from Z-1 to R = Z1 (s 0..2 mm), back down to Z-0.5 (s 2..3.5 mm); stations 10 um
VERTS = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -0.5]]) * MM
VS = np.array([0.0, 2.0, 3.5]) * MM
DS = 0.01 * MM
MARGIN = 0.1 * MM


def _motion(z1: float, count: np.ndarray, z0: float = 0.86 * MM, s0: float = 1.86 * MM):
    """member_motion from the cursor at z0 on the way up (0.14 mm short of R) to z1 [m]: (seg, s, dist)."""
    st = _state(0.0, 0.0, z0, s0, 0, 0.0)
    out = pk.member_motion(st, 0, 0.0, 0.0, z1, MARGIN, VERTS, VS, DS, count)
    return out[6], out[7], out[8]


def test_a_member_turning_back_short_of_the_reversal_is_refound_after_it():
    air = np.zeros(351, dtype=np.int64)
    # turned back 0.14 mm short of R and moved down 0.01 mm: the return leg's point at z = 0.85 mm is at
    # s = 2 + (1 - 0.85) = 2.15 mm, 0.29 mm ahead: beyond the forward window (2 x 0.01 + 0.1 mm), found across
    seg, s, d = _motion(0.85 * MM, air)
    assert seg == 1 and s == pytest.approx(2.15 * MM, abs=1e-15) and d == pytest.approx(0.0, abs=1e-15)
    # standing still or moving on towards R: the forward projection, as before
    seg, s, d = _motion(0.86 * MM, air)
    assert seg == 0 and s == pytest.approx(1.86 * MM, abs=1e-15) and d == pytest.approx(0.0, abs=1e-15)
    seg, s, d = _motion(0.87 * MM, air)
    assert seg == 0 and s == pytest.approx(1.87 * MM, abs=1e-15) and d == pytest.approx(0.0, abs=1e-15)


def test_a_retracing_tool_is_refound_across_material_a_sideways_one_only_across_air():
    # the move down (-z) retraces the cursor's segment (+z), 0.14 mm short of the reversal (<= REVERSAL_LAG):
    # re-found after it even where the stretch holds material (the servo never reaches it)
    for station in (186, 200, 215):  # the cursor's, the reversal's, the landing point's station
        count = np.zeros(351, dtype=np.int64)
        count[station] = 1
        assert _motion(0.85 * MM, count)[:2] == (1, pytest.approx(2.15 * MM, abs=1e-15))
    # from 0.24 mm short of the reversal, a move 0.02 mm sideways and 0.01 mm down (cosine with the segment
    # -0.45 > -RETRACE_COS): not a retrace; the return leg's point at z = 0.75 mm (s = 2.25 mm, beyond the forward
    # window 2 x 0.022 + 0.1 mm) is 0.02 mm away, nearer than the cursor (sqrt(0.02^2 + 0.01^2) mm): taken
    # across air only
    def sideways(count):
        st = _state(0.0, 0.0, 0.76 * MM, 1.76 * MM, 0, 0.0)
        return pk.member_motion(st, 0, 0.02 * MM, 0.0, 0.75 * MM, MARGIN, VERTS, VS, DS, count)[6:]
    seg, s, d = sideways(np.zeros(351, dtype=np.int64))
    assert seg == 1 and s == pytest.approx(2.25 * MM, abs=1e-15) and d == pytest.approx(0.02 * MM, abs=1e-15)
    for station in (176, 200, 225):  # the cursor's, the reversal's, the landing point's station
        count = np.zeros(351, dtype=np.int64)
        count[station] = 1
        seg, s, d = sideways(count)
        assert seg == 0 and s == pytest.approx(1.76 * MM, abs=1e-15)
        assert d == pytest.approx(math.hypot(0.02, 0.01) * MM, abs=1e-15)
    # material beyond the landing point's neighbourhood (station 229 = floor(2.25 / 0.01) + 4) does not hold it
    count = np.zeros(351, dtype=np.int64)
    count[229:] = 1
    assert sideways(count)[:2] == (1, pytest.approx(2.25 * MM, abs=1e-15))


def test_a_retrace_farther_than_the_servo_lag_from_the_reversal_jumps_only_across_air():
    # up from Z-5 to Z1 (s 0..6 mm), back down to Z-3 (s 6..10 mm); the tool turns back 2.5 mm short of the
    # reversal (> REVERSAL_LAG = 2 mm: not a servo's shortfall) and moves down 0.01 mm to Z-1.51
    verts = np.array([[0.0, 0.0, -5.0], [0.0, 0.0, 1.0], [0.0, 0.0, -3.0]]) * MM
    vs = np.array([0.0, 6.0, 10.0]) * MM
    assert pk.REVERSAL_LAG == pytest.approx(2.0 * MM)

    def motion(count):
        st = _state(0.0, 0.0, -1.5 * MM, 3.5 * MM, 0, 0.0)
        return pk.member_motion(st, 0, 0.0, 0.0, -1.51 * MM, MARGIN, verts, vs, DS, count)[6:]
    seg, s, d = motion(np.zeros(1001, dtype=np.int64))  # across air: s = 6 + 2.51 mm
    assert seg == 1 and s == pytest.approx(8.51 * MM, abs=1e-15) and d == pytest.approx(0.0, abs=1e-15)
    count = np.zeros(1001, dtype=np.int64)
    count[500] = 1  # material at Z0, 1 mm short of the reversal
    seg, s, d = motion(count)
    assert seg == 0 and s == pytest.approx(3.5 * MM, abs=1e-15) and d == pytest.approx(0.01 * MM, abs=1e-15)


def test_no_reversal_ahead_no_jump():
    # a straight path: a tool moving back from its cursor stays projected on it (distance reported)
    verts = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 2.0]]) * MM
    st = _state(0.0, 0.0, 0.86 * MM, 1.86 * MM, 0, 0.0)
    out = pk.member_motion(st, 0, 0.0, 0.0, 0.85 * MM, MARGIN, verts, np.array([0.0, 2.0, 3.0]) * MM, DS,
                           np.zeros(301, dtype=np.int64))
    assert out[6] == 0 and out[7] == pytest.approx(1.86 * MM, abs=1e-15) and out[8] == pytest.approx(0.01 * MM)


@pytest.mark.parametrize("short", [0.3e-3, 0.6e-3])
def test_a_slot_cut_out_and_back_on_one_line_is_followed_the_way_back_has_no_load(short):
    """A slot cut out and back on one line (the SolidCAM post's O5002: X50., X-50.) whose tool turns back 0.3 or
    0.6 mm short of the end, in the material. Before: the stretch to skip held material, the cursor stayed and the
    member failed off the path. Now the member is re-found on the way back: the first pass cuts a full slot,
    peak Fc = Kt a fz sqrt(1 + Ke^2) (one tooth at 90 deg), the way back runs in the cut slot with no load, and
    the run agrees with the Z-map mode (the independent model, where the member removes its own material)."""
    a, c = 2e-3, 5e-5
    x0, x_end = -R - 0.5e-3, 0.006
    verts = [[x0, 0.0, -a], [x_end, 0.0, -a], [x0, 0.0, -a]]
    pos = along([[x0, 0.0, -a], [x_end - short, 0.0, -a], [x0, 0.0, -a]], c / TOOTH_PERIOD * H)
    q, _ = path_run(params(), verts, pos, OMEGA)
    x = pos[1:, 0, 0]
    turn = int(np.argmax(x))  # the step that reaches the turning point
    hand = KT * a * c * math.sqrt(1 + KE * KE)  # 276.7 N
    out = q["fc_peak"][:turn + 1, 0]
    assert out.max() == pytest.approx(hand, rel=1e-3)
    # the way back: the periphery grazes the slot's walls (interval ends at the tangency, chips of 1e-12 m)
    assert q["fc_peak"][turn + 2:, 0].max() <= 1e-6 * hand
    assert q["mrr"][turn + 2:, 0].max() <= 1e-6 * q["mrr"][:turn + 1, 0].max()
    z = zmap_run(params(), pos, OMEGA)
    # the two steps after the turn: the chip (the move over the last tooth period, 3.8 ms) still points forward,
    # so in the Z-map the teeth still touch the member's own slot end; the path mode reads the way back (cut to
    # the programmed end): no load. The net move over the tooth period one step after the turn is at most
    # (2.8 - 1) / 3.8 = 0.47 of a tooth's feed, so that load stays below half the slot's (the largest load holds)
    after = slice(turn + 1, turn + 3)
    assert z["fc_peak"][after, 0].max() < 0.5 * hand
    for name in z:
        z[name][after] = q[name][after]
    assert_modes_agree(z, q)


PROGRAM = """G21 G17 G90 G94 G54
S6000 M3
G0 X14. Y14. Z5.
G99 {cycle}
G80
G0 X-4. Y5. Z1.
G1 Z-1. F300
X24.
G0 Z1.
Y14.
G1 Z-1.
X-4.
G0 Z5.
M30
"""


#: The drilling cycle of PROGRAM: the G83 of the unseen part (F150, Q1; the servo turns back 0.14-0.40 mm short of
#: R, 0.03 mm short of each bottom), a deeper and faster one (Q3 to Z-9 at F300: 0.40-0.83 mm short of R, 0.06 mm of
#: each bottom) and G73 (F150; 0.2 mm retracts between pecks, in the hole).
CYCLES = ("G83 X14. Y14. Z-3. R1. Q1. F150", "G83 X14. Y14. Z-9. R1. Q3. F300", "G73 X14. Y14. Z-3. R1. Q1. F150")


@pytest.fixture(scope="module", params=CYCLES)
def peck_runs(request, tmp_path_factory):
    folder = tmp_path_factory.mktemp("peck")
    (folder / "case.toml").write_text('program = "program.nc"\n[stock]\nmin = [0.0, 0.0, -10.0]\n'
                                      'max = [20.0, 20.0, 0.0]\n[tool]\ndiameter_mm = 6.0\nflutes = 2\n'
                                      '[machine]\nparameters = "default"\n')
    (folder / "program.nc").write_text(PROGRAM.format(cycle=request.param))
    case = load_case(folder)
    return case, {mode: simulate(case=case, options=TwinOptions(cutting_mode=mode), plot=False)
                  for mode in ("path", "zmap")}


def _per_line(recording) -> tuple[dict[int, float], dict[int, float]]:
    """Largest Fc (N) and removed volume (mm3) per executing line."""
    t = np.asarray(recording.t, float)
    line = np.asarray(recording["line"], float).ravel()
    fc = np.asarray(recording["fc_peak_N"], float).ravel()
    mrr = np.asarray(recording["mrr_mm3_per_min"], float).ravel() / 60.0
    prev = np.concatenate([[line[0]], line[:-1]])  # a step's removal belongs to the line running at its start
    dt = np.concatenate([[0.0], np.diff(t)])
    lines = [int(v) for v in np.unique(line[np.isfinite(line)])]
    return ({n: float(fc[line == n].max()) for n in lines},
            {n: float(np.sum((mrr * dt)[prev == n])) for n in lines})


def test_g83_program_in_path_mode_agrees_with_the_zmap_model_and_hand_calculations(peck_runs):
    case, runs = peck_runs
    for mode, run in runs.items():
        assert run.success, (mode, run.message)  # before: "farther than path_tolerance" after the first peck
    path, zmap = runs["path"].recording, runs["zmap"].recording
    assert runs["path"].summary["cycle_time_s"] == runs["zmap"].summary["cycle_time_s"]
    peak_p, vol_p = _per_line(path)
    peak_z, vol_z = _per_line(zmap)
    # slot 1 (line 8, Y5) misses the hole; slot 2 (line 12, Y14) crosses it: both modes within 0.1 N, 0.1 %
    for n in (8, 12):
        assert peak_p[n] == pytest.approx(peak_z[n], abs=0.1)
    # the slots (every line but the pecks') remove the same volume in both modes, within 0.2 %: the slot
    # crossing the hole meets the hole's rim cells in the Z-map, the reference pass's table in path mode
    assert sum(vol_p.values()) - vol_p[4] == pytest.approx(sum(vol_z.values()) - vol_z[4], rel=2e-3)
    # the pecks remove their hole with the end edges (the axial chip): pi R^2 times the depth the tool reached,
    # a little less than programmed (the servo lag turns it back early), each layer once; the path mode takes
    # the material under the end disc from the reference pass (within 2 %)
    depth_mm = -float(re.search(r" Z(-[0-9.]+)", case.program.read_text()).group(1))  # the cycle's Z
    assert 0.97 * math.pi * 9.0 * depth_mm < vol_z[4] <= math.pi * 9.0 * depth_mm * (1 + 1e-9)
    assert vol_p[4] == pytest.approx(vol_z[4], rel=0.02)
    # hand calculation, full slot 1 mm deep at F300, S6000, 2 flutes: fz = 0.025 mm
    kt, ke = case.machine.si(f"material.{case.material}")["kt"], 0.5
    assert case.machine.si(f"material.{case.material}")["ke"] == ke
    fz = 300.0 / (6000.0 * 2) * MM
    assert peak_p[8] == pytest.approx(kt * 1 * MM * fz * math.sqrt(1 + ke * ke), abs=0.05)  # 34.38 N
    # removed volume of slot 1: 6 mm wide x 1 mm deep across the 20 mm block (lines 7-9: plunge, slot, lift)
    assert vol_p[7] + vol_p[8] + vol_p[9] == pytest.approx(6.0 * 1.0 * 20.0, rel=1e-3)


def _peck_then_slot(r_top: float) -> list[list[float]]:
    """Two pecks at (6, 5) mm from Z3 (to Z-1, back up to ``r_top`` [m], to Z-2, out), then a 1 mm deep slot along
    +x at y = -4 mm through the 12 mm block of :func:`tests.test_cutting_path.params`, m."""
    hx, hy, top, a = 6e-3, 5e-3, 3e-3, 1e-3
    x0, x1 = -R - 0.5e-3, 0.012 + R + 0.5e-3
    return [[hx, hy, top], [hx, hy, -1e-3], [hx, hy, r_top], [hx, hy, -2e-3], [hx, hy, top], [x0, -4e-3, top],
            [x0, -4e-3, -a], [x1, -4e-3, -a]]


@pytest.mark.parametrize("effects", [{}, {"runout_eccentricity": 5e-6, "runout_phase": 0.4, "helix_angle": 0.3}])
def test_compiled_replay_follows_the_pecks_bit_for_bit_and_the_slot_after_them_matches_zmap(effects):
    """The commanded path returns to R = Z1 between the pecks; the tool turns back 0.14 mm short of it. The
    compiled replay (path_replay) and the component stepped step by step (path_step, or path_step_effects with
    runout and helix) give the same outputs bit for bit; on the baseline kernel the slot after the pecks agrees
    with the Z-map mode (test_cutting_path's tolerances; the path-mode helix peak is exact where the Z-map mode
    keeps its bands, see README "Effect terms")."""
    from fmus_src.cutting.path_component import PathCuttingLoad
    from fmus_src.cutting.path_replay import compiled_path_steps
    from fmus_src.cutting.table import EngagementTable
    from tests.test_cutting_path import NAMES, assert_modes_agree, drive, zmap_run

    c = 5e-5
    p = params(**effects)
    pos = along(_peck_then_slot(0.86e-3), c / TOOTH_PERIOD * H)
    table = EngagementTable.from_parameters(np.asarray(_peck_then_slot(1e-3)), p)

    def component():
        comp = PathCuttingLoad("cut", batch=1, **p)
        comp.attach_table(table)
        return comp

    def set_up():
        comp = component()
        for a, name in enumerate(("x_position", "y_position", "z_position")):
            comp.set(name, pos[0, :, a])
        comp.set("spindle_speed", OMEGA)
        comp.setup(0.0)
        return comp

    t = H * np.arange(pos.shape[0])
    replay = compiled_path_steps(set_up(), t, pos[:, 0, :], np.full(pos.shape[0] - 1, OMEGA))
    comp = set_up()
    names = NAMES + ("axial_depth", "engaged_teeth")
    stepped = {n: [] for n in names}
    for k in range(1, pos.shape[0]):  # the replay's steps: t[k - 1] to t[k]
        for a, name in enumerate(("x_position", "y_position", "z_position")):
            comp.set(name, pos[k, :, a])
        comp.do_step(t[k - 1], t[k] - t[k - 1])
        for n in names:
            stepped[n].append(comp.get(n))
    stepped = {n: np.array(v) for n, v in stepped.items()}
    assert replay is not None
    for name, col in (("fx", "fx"), ("fy", "fy"), ("spindle_torque", "spindle_torque"), ("axial_depth", "axial_depth"),
                      ("engaged_teeth", "engaged_teeth")):
        np.testing.assert_array_equal(replay[name][1:, 0], stepped[col][:, 0], err_msg=name)
    assert stepped["fc_peak"].max() > 10.0  # the slot cuts (1 mm deep, 50 um per tooth: about 69 N)
    if not effects:  # the baseline against the Z-map mode (helix peaks differ by design: see the module docstring)
        assert_modes_agree(zmap_run(p, pos, OMEGA), drive(component(), pos, OMEGA), worst=0.04)
