"""The chip against a surface left several teeth back is the tool-centre displacement since then.

With runout a tooth that stands back leaves the older surface in place, and the next tooth cuts the surface
left ``i + 1`` teeth back (with chatter, a tooth that jumped out of the cut does the same). Its chip is the
tool-centre displacement over those ``i + 1`` tooth periods, ``c(t + h) - c(t + h - (i + 1) T)``
(:func:`fmus_src.cutting.kernel.chords_back`; the independent truth's ``c(t) - c(t - i T)``), not ``i + 1``
times the last period's chord, which assumes a constant feed. Along ``x = v t - a t^2 / 2``::

    x(t) - x(t - n T) = v n T - a n T (2 t - n T) / 2 = v(t) n T + a (n T)^2 / 2

so in a deceleration the chip over two periods exceeds twice the chord by ``a T^2``. Checked:

* the displacements against that closed form, and the fallback to the chord rule (run start, ``n T <= h``,
  a stopped spindle); at a constant feed the chord rule to 1e-12;
* the Z-map component with a runout larger than the feed per tooth (only the big tooth cuts, always the
  surface it left a revolution back): at a constant feed the same forces as the chord rule (1e-12); in a
  deceleration the chip output and the force are those of ``x(t) - x(t - 2T)``, and the force rises over the
  chord rule's by the ratio ``(x(t) - x(t - 2T)) / (2 (x(t) - x(t - T)))`` derived from the kinematics;
* the path-mode replay with runout against the independent truth on a slot that stops in the material.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting import CuttingLoad
from fmus_src.cutting import component as zmap_component
from fmus_src.cutting.kernel import CHIP_HISTORY_WIDTH, chord_advance, chord_feed, chords_back

OMEGA = 6000 * 2 * math.pi / 60  # rad/s
PERIOD = 2 * math.pi / (2 * OMEGA)  # 2 flutes: 5 ms
H = 1e-3
KT, KE = 1.23e9, 0.5
DEPTH = 2e-3
V0 = 7.5e-3  # 450 mm/min: 37.5 um per tooth
T_DEC, T_STOP = 0.02, 0.04  # constant feed until T_DEC, then a uniform stop over T_STOP
ACC = V0 / T_STOP
RHO = 30e-6  # runout at phase 0: tooth 0 stands out 30 um, tooth 1 back 30 um; 60 um > 37.5 um per tooth


def slot_x(t):
    """Tool-centre x of the slot [m]: constant feed, then a uniform deceleration to a stop."""
    t = np.asarray(t, float)
    td = np.clip(t - T_DEC, 0.0, T_STOP)
    return 0.005 + V0 * np.minimum(t, T_DEC) + V0 * td - 0.5 * ACC * td ** 2


def test_displacements_over_several_periods_in_a_deceleration_and_the_fallbacks():
    hist = np.zeros(CHIP_HISTORY_WIDTH)
    back = np.full((5, 2), np.nan)
    a = 0.2
    t = np.arange(0, 40) * H
    x = V0 * t - 0.5 * a * t ** 2
    y = -0.4 * x  # a straight line at an angle: both components scale alike
    checked = 0
    for k in range(1, t.size):
        dpx, dpy = x[k] - x[k - 1], y[k] - y[k - 1]
        fx, fy = chord_feed(hist, dpx, dpy, H, OMEGA, 2)
        chords_back(hist, dpx, dpy, H, OMEGA, 2, fx, fy, 5, back)
        assert (back[0, 0], back[0, 1]) == (fx, fy)  # row 0 is the chord itself, bit for bit
        for i in range(1, 5):
            n = i + 1
            if t[k] > n * PERIOD + 1e-9:  # the record reaches back n T: x(t) - x(t - nT), exactly (T = 5 steps)
                exact = V0 * n * PERIOD - a * n * PERIOD * (2 * t[k] - n * PERIOD) / 2
                assert back[i, 0] == pytest.approx(exact, rel=1e-12)
                assert back[i, 1] == pytest.approx(-0.4 * exact, rel=1e-12)
                # the chord rule n x (x(t) - x(t - T)) is short by a T^2 n (n - 1) / 2
                assert back[i, 0] - n * fx == pytest.approx(a * PERIOD ** 2 * n * (n - 1) / 2, rel=1e-6)
                checked += 1
            elif t[k] < n * PERIOD - 1e-9:  # not yet: the chord rule, bit for bit
                assert (back[i, 0], back[i, 1]) == (n * fx, n * fy)
        chord_advance(hist, H, dpx, dpy, OMEGA)
    assert checked > 80
    # n T <= h: the span lies within the step, the chord rule bit for bit (2 flutes at 60000 rpm: T = 0.5 ms,
    # 2 T = h); 3 T, 4 T, 5 T reach back into the record
    fast = 60000 * 2 * math.pi / 60
    fx, fy = chord_feed(hist, 3e-6, 1e-6, H, fast, 2)
    chords_back(hist, 3e-6, 1e-6, H, fast, 2, fx, fy, 5, back)
    assert (back[1, 0], back[1, 1]) == (2 * fx, 2 * fy)
    t_fast = math.pi / fast
    assert back[2, 0] == pytest.approx(3e-6 + (x[-1] - x[-2]) * (3 * t_fast - H) / H, rel=1e-12)
    # a step with the spindle stopped clears the record: the chord rule again
    chord_advance(hist, H, 1e-6, 0.0, 0.0)
    fx, fy = chord_feed(hist, 7e-6, 0.0, H, OMEGA, 2)
    chords_back(hist, 7e-6, 0.0, H, OMEGA, 2, fx, fy, 5, back)
    np.testing.assert_array_equal(back, np.arange(1, 6)[:, None] * np.array([[fx, fy]]))


def test_displacements_at_a_constant_feed_are_the_chord_rule():
    hist = np.zeros(CHIP_HISTORY_WIDTH)
    back = np.zeros((5, 2))
    dpx, dpy = 0.1 * H, 0.05 * H  # 0.1 m/s along a line: T = 5 ms, a revolution of 3 flutes 15 ms
    for k in range(60):
        fx, fy = chord_feed(hist, dpx, dpy, H, OMEGA, 3)
        chords_back(hist, dpx, dpy, H, OMEGA, 3, fx, fy, 5, back)
        rule = np.arange(1, 6)[:, None] * np.array([[fx, fy]])
        np.testing.assert_allclose(back, rule, rtol=1e-12, atol=0)
        chord_advance(hist, H, dpx, dpy, OMEGA)


def _chord_rule(hist, dp, h, omega, flutes, feed, nf, back):
    """The former chips: ``i + 1`` times the chord for the surface ``i + 1`` teeth back."""
    back[...] = np.arange(1, back.shape[1] + 1)[None, :, None] * feed[:, None, :]


def _runout_slot(x_of, n, **kw):
    params = dict(tool_diameter=6e-3, flutes=2, kt=KT, ke=KE, stock_x_min=0.0, stock_x_max=0.03,
                  stock_y_min=0.0, stock_y_max=0.02, stock_z_min=-0.01, stock_z_max=0.0,
                  runout_eccentricity=RHO, runout_phase=0.0)
    params.update(kw)
    comp = CuttingLoad("cut", **params)
    comp.set("x_position", x_of(0.0))
    comp.set("y_position", 0.01)
    comp.set("z_position", -DEPTH)
    comp.set("spindle_speed", OMEGA)
    comp.setup(0.0)
    out = {k: [] for k in ("fx", "fy", "fc", "fc_peak", "fx_mean", "fy_mean", "spindle_torque", "chip_thickness",
                           "spindle_angle")}
    for k in range(n):
        comp.set("x_position", x_of((k + 1) * H))
        comp.do_step(k * H, H)
        for name, values in out.items():
            values.append(float(comp.get(name)[0]))
    return {k: np.array(v) for k, v in out.items()}


@pytest.mark.parametrize("extra", [{}, {"chatter_frequency": 1150.0, "chatter_damping": 0.03,
                                        "chatter_stiffness": 300e6}], ids=["runout", "runout+chatter"])
def test_zmap_runout_at_a_constant_feed_keeps_the_chord_rule(monkeypatch, extra):
    # with the tool mode every tooth looks 5 surfaces back (MAX_PASSES): rows 1..4 of the displacements
    def steady(t):
        return 0.005 + V0 * np.asarray(t, float)

    new = _runout_slot(steady, 40, **extra)
    monkeypatch.setattr(zmap_component, "chords_back_all", _chord_rule)
    old = _runout_slot(steady, 40, **extra)
    assert new["fc"].max() > 50.0  # it cut
    for name in new:
        scale = np.abs(old[name]).max()
        np.testing.assert_allclose(new[name], old[name], rtol=1e-12, atol=1e-12 * scale, err_msg=name)


def test_zmap_runout_in_a_deceleration_cuts_the_displacement_over_a_revolution(monkeypatch):
    n = int(round((T_DEC + T_STOP) / H)) - 1  # up to 1 ms before the stop
    new = _runout_slot(slot_x, n)
    monkeypatch.setattr(zmap_component, "chords_back_all", _chord_rule)
    old = _runout_slot(slot_x, n)
    t = np.arange(1, n + 1) * H
    # only tooth 0 cuts (tooth 1 stands 60 um back, more than the feed per tooth), always the surface it left
    # itself a revolution (2 T) back: chip (x(t) - x(t - 2T)) sin(phi), phi its angle from +y clockwise
    revolution = slot_x(t) - slot_x(t - 2 * PERIOD)
    chord = slot_x(t) - slot_x(t - PERIOD)
    phi = np.mod(new["spindle_angle"], 2 * math.pi)
    ok = (t >= 2 * PERIOD - 1e-9) & (np.sin(phi) > 0.3) & (phi < math.pi)
    assert ok.sum() > 15
    np.testing.assert_allclose(new["chip_thickness"][ok], (revolution * np.sin(phi))[ok], rtol=1e-6)
    np.testing.assert_allclose(new["fc"][ok], (KT * DEPTH * revolution * np.sin(phi) * math.hypot(1.0, KE))[ok],
                               rtol=1e-6)
    # the chord rule took 2 (x(t) - x(t - T)) there; the force rises by the ratio of the two, which in the
    # deceleration is (2 v T + 2 a T^2) / (2 v T + a T^2): 1.08 two periods into it, 1.29 at the last instant
    # checked (6 ms before the stop, v = 1.1 mm/s), towards 2 at the stop
    np.testing.assert_allclose(old["chip_thickness"][ok], (2 * chord * np.sin(phi))[ok], rtol=1e-6)
    ratio = revolution / (2 * chord)
    np.testing.assert_allclose(new["fc"][ok] / old["fc"][ok], ratio[ok], rtol=1e-6)
    dec = ok & (t > T_DEC + 2 * PERIOD)
    assert dec.sum() > 5 and ratio[dec].min() > 1.07 and ratio[dec].max() > 1.25
    # at the constant feed before it the two agree
    const = ok & (t <= T_DEC)
    np.testing.assert_allclose(new["fc"][const], old["fc"][const], rtol=1e-12)


def test_path_replay_with_runout_at_a_stop_in_the_material_is_the_truths(tmp_path):
    from fmus_src.cutting.table import build_engagement_table
    from orchestrator.case import load_case
    from orchestrator.diagnose.cutting_case import CASE_TOML, SHORT_PROGRAM
    from orchestrator.diagnose.cutting_replay import ForceInputs, run_force_replay
    from orchestrator.diagnose.truth_cutting import cutting_parameters_packed, simulate_cutting

    # the slot of tests/test_diagnose_cutting_two_flutes.py (2 mm deep, decelerating uniformly from 450 mm/min
    # to a stop inside the block) with a 30 um runout at phase 0: one tooth cuts, always its own surface of a
    # revolution back. The truth (20 us grid, chip c(t) - c(t - 2T)) against the replay at 1 ms.
    (tmp_path / "program.nc").write_text(SHORT_PROGRAM)
    (tmp_path / "case.toml").write_text(CASE_TOML.replace("flutes = 3", "flutes = 2")
                                        .replace('recording = "recording.csv"\n', ""))
    case = load_case(tmp_path)
    path = np.array([[-0.004, 0.01, -0.002], [0.012, 0.01, -0.002]])
    table = build_engagement_table(path, 6e-3, [0.0, 0.0, -0.006], [0.016, 0.02, 0.0], 2e-5)
    v, t_stop, x_stop, dt = 7.5e-3, 0.04, 0.006, 20e-6
    t_f = np.arange(0.0, 1.0, dt)
    t_dec = 1.0 - t_stop
    x0 = x_stop - v * t_dec - 0.5 * v * t_stop
    a = v / t_stop

    def x_of(t):
        return np.where(t < t_dec, x0 + v * t, x0 + v * t_dec + v * (t - t_dec) - 0.5 * a * (t - t_dec) ** 2)

    pos = np.column_stack([x_of(t_f), np.full_like(t_f, 0.01), np.full_like(t_f, -0.002)])
    packed = cutting_parameters_packed(case.machine, case.material, 6e-3, 2,
                                       {"runout": {"eccentricity_um": RHO * 1e6, "phase_deg": 0.0}}, 0.3)
    run = simulate_cutting(table, t_f, pos, np.full(t_f.size, OMEGA), packed)
    ts = np.arange(0.9, 1.0 + 1e-9, 1e-3)
    inputs = ForceInputs(ts, np.column_stack([x_of(ts), np.full_like(ts, 0.01), np.full_like(ts, -0.002)]),
                         np.full(ts.size, OMEGA), "spindle_rpm")
    theta = float(np.interp(ts[0], t_f, run.theta)) % (2 * math.pi)
    sim = run_force_replay(case, table, inputs, [{"runout_eccentricity": RHO, "runout_phase": 0.0}], theta)
    fx, fy = np.interp(ts, t_f, run.fx), np.interp(ts, t_f, run.fy)
    fc = np.hypot(fx, fy)
    assert fc.max() > 150.0  # one tooth, chip 2 x 37.5 um at the crest: ~200 N
    err = np.hypot(sim.fx[:, 0] - fx, sim.fy[:, 0] - fy)
    dec = (ts > t_dec + 2 * PERIOD) & (ts < 1.0 - 1e-9)
    # both take the displacement over a revolution (10 samples, 500 truth steps) of the quadratic path exactly
    assert np.abs(err[dec]).max() < 1e-6 * fc.max(), err[dec]
    # where the chord rule's chip 2 (x(t) - x(t - T)) would be short of it by a T^2 / (2 v T + 2 a T^2) >= 4 %
    short = 1.0 - 2 * (x_of(ts) - x_of(ts - PERIOD)) / (x_of(ts) - x_of(ts - 2 * PERIOD))
    assert short[dec].min() > 0.04
