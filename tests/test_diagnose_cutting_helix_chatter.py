"""Issue 8 (b, c): the exact helix of the path mode and the refit of the chatter mode, against derived numbers.

* Helix: the instantaneous force of a helical flute is ``int dF(phi(z)) dz`` with
  ``phi(z) = phi_j - z tan(helix) / R`` (Altintas ch. 2). It is computed here independently by a
  midpoint sum over 0.1 um axial slices of straight-tooth forces (``Ft = Kt h dz``, ``Fr = Ke Ft``,
  ``h = c sin(phi)`` on the engaged arc, which is derived from the block geometry): the sum's own
  error is below one slice's force (~1e-3 N), far below the 0.05 N the twin must meet.
* Chatter: see the section below.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting.path_component import PathCuttingLoad
from fmus_src.cutting.table import EngagementTable

KT, KE = 1.23e9, 0.5          # A6061 (models/machines/default.toml)
R, N = 3e-3, 3                # 6 mm 3-flute end mill
OMEGA = 6000 * 2 * math.pi / 60
C = 0.05e-3                   # feed per tooth (F900 at S6000 with 3 flutes)
V = C * N * OMEGA / (2 * math.pi)
H = 0.2e-3                    # sample period (5 kHz dynamometer)
HELIX = math.radians(30.0)


def _block(**kw):
    p = dict(tool_diameter=2 * R, flutes=N, kt=KT, ke=KE, stock_x_min=0.0, stock_x_max=0.03,
             stock_y_min=-0.01, stock_y_max=0.01, stock_z_min=-0.01, stock_z_max=0.0, helix_angle=HELIX)
    p.update(kw)
    return p


def _twin(p, depth, steps):
    """Path mode along +x at depth, V, starting inside the block (behind the tool the chip is negative).

    Returns the spindle angle and the force on the workpiece at each step end.
    """
    x0 = 5e-3
    xs = x0 + V * H * np.arange(steps + 1)
    comp = PathCuttingLoad("c", **p)
    comp.attach_table(EngagementTable.from_parameters(np.array([[x0, 0.0, -depth], [xs[-1] + 1e-3, 0.0, -depth]]),
                                                      p))
    comp.set("x_position", xs[0])
    comp.set("y_position", 0.0)
    comp.set("z_position", -depth)
    comp.set("spindle_speed", OMEGA)
    comp.setup(0.0)
    theta, f = [], []
    for k in range(1, len(xs)):
        comp.set("x_position", xs[k])
        comp.do_step((k - 1) * H, H)
        theta.append(float(comp.get("spindle_angle")[0]))
        f.append([float(comp.get("fx")[0]), float(comp.get("fy")[0])])
    return np.array(theta), np.array(f)


def _slices(theta, depth, phi_start, slices=30000):
    """Force on the workpiece: midpoint sum over axial slices; the engaged arc is [phi_start, pi]."""
    z = (np.arange(slices) + 0.5) / slices * depth
    f = np.zeros(2)
    for j in range(N):
        phi = np.mod(theta + j * 2 * math.pi / N - z * math.tan(HELIX) / R, 2 * math.pi)
        s, co = np.sin(phi), np.cos(phi)
        h = np.where((phi >= phi_start) & (phi <= math.pi), C * s, 0.0)
        ft = KT * (depth / slices) * h
        fr = KE * ft
        f += [np.sum(ft * co + fr * s), np.sum(-ft * s + fr * co)]
    return f


@pytest.mark.parametrize("case", ["slot_2mm", "side_pass_3mm_1mm"])
def test_helix_instantaneous_force_equals_the_axial_integral(case):
    if case == "slot_2mm":
        depth, p, phi_start = 2e-3, _block(), 0.0
    else:  # 1 mm radial: material where R cos(phi) <= -(R - 1 mm), cut where the chip c sin(phi) > 0
        ae = 1e-3
        depth, p, phi_start = 3e-3, _block(stock_y_max=-(R - ae)), math.acos(-(R - ae) / R)
    theta, f = _twin(p, depth, 120)
    err = [np.hypot(*(f[k] - _slices(theta[k], depth, phi_start))) for k in range(len(f))]
    peak = np.abs(f).max()
    assert peak > 50.0       # a real load: about Kt a c sin(phi) per tooth
    assert max(err) < 0.05   # N


def test_truth_slices_agree_with_the_exact_helix_on_the_deep_side_pass():
    # the truth (50 um slices, each cutting with its fraction inside the engaged arc) against the twin's
    # exact integral on a 3 mm deep, 1 mm radial side pass; the slices' midpoint error is second order:
    # (50 um tan(30 deg) / R)^2 / 24 of the flute's force, about 1e-5 of it
    from fmus_src.cutting.table import build_engagement_table
    from orchestrator.diagnose.truth_cutting import _Q, simulate_cutting

    depth, ae, dt = 3e-3, 1e-3, 20e-6
    stock = ([0.0, -0.01, -0.006], [0.02, -(R - ae), 0.0])
    path = np.array([[0.004, 0.0, -depth], [0.02, 0.0, -depth]])
    table = build_engagement_table(path, 2 * R, *stock, 1e-4)
    t = np.arange(0.0, 0.2, dt)
    pos = np.column_stack([0.004 + V * t, np.zeros_like(t), np.full_like(t, -depth)])
    q = dict.fromkeys(_Q, 0.0)
    q.update(radius=R, flutes=N, kt=KT, kr=KE * KT, helix=HELIX, theta0=0.3)
    run = simulate_cutting(table, t, pos, np.full(t.size, OMEGA), np.array([q[k] for k in _Q]))
    comp = PathCuttingLoad("c", tool_diameter=2 * R, flutes=N, kt=KT, ke=KE, helix_angle=HELIX,
                           stock_x_min=stock[0][0], stock_y_min=stock[0][1], stock_z_min=stock[0][2],
                           stock_x_max=stock[1][0], stock_y_max=stock[1][1], stock_z_max=stock[1][2],
                           initial_spindle_angle=float(run.theta[0]))
    comp.attach_table(table)
    every = 10
    for i, a in enumerate("xyz"):
        comp.set(f"{a}_position", pos[0, i])
    comp.set("spindle_speed", OMEGA)
    comp.setup(0.0)
    err = []
    for k in range(every, t.size, every):
        for i, a in enumerate("xyz"):
            comp.values[f"{a}_position"][...] = pos[k, i]
        comp.do_step(t[k - every], t[k] - t[k - every])
        if t[k] > 0.02:  # the history of the chip (one tooth period) is the path's
            err.append(math.hypot(comp.values["fx"][0] - run.fx[k], comp.values["fy"][0] - run.fy[k]))
    peak = np.hypot(run.fx, run.fy).max()
    assert peak > 50.0
    assert max(err) < 0.1  # N


# ------------------------------------------------------------------------------------------ chatter
def test_stability_limit_equals_the_closed_form_of_a_full_slot():
    # full slot: A0 = N / 4 [[-Ke, -1], [1, -Ke]] in closed form (Altintas & Budak), eigenvalues
    # N / 4 (-Ke +- i); with G = 1 / (k (1 - r^2 + 2 i zeta r)) the limit is 1 / (2 Kt max Re(lam G))
    from orchestrator.diagnose.cutting_chatter import stability_limit

    fn, zeta, k = 1150.0, 0.03, 3e7
    lam = N / 4 * (-KE + 1j)
    r = np.linspace(0.8, 1.3, 200001)
    g = 1 / (k * (1 - r ** 2 + 2j * zeta * r))
    expected = 1 / (2 * KT * max((lam * g).real.max(), (np.conj(lam) * g).real.max()))
    a_lim, f_c = stability_limit(KT, KE, N, (0.0, math.pi), fn, zeta, k)
    assert a_lim == pytest.approx(expected, rel=1e-4)
    assert fn < f_c < 1.05 * fn   # regenerative chatter sits just above the natural frequency
    a2, _ = stability_limit(KT, KE, N, (0.0, math.pi), fn, zeta, 2 * k)
    assert a2 == pytest.approx(2 * a_lim, rel=1e-9)   # G ~ 1 / k


def test_envelope_growth_and_band_power_of_known_signals():
    from orchestrator.diagnose.cutting_chatter import band_power, envelope, growth_rate

    t = np.arange(0.0, 1.0, 0.2e-3)
    f0, sigma, top = 1143.0, 50.0, 40.0
    # grows as exp(sigma t) from 0.05 N until it saturates at 40 N (t = 0.53 s), then holds; fy a quarter
    # period behind fx: the envelope of the pair is the amplitude itself
    amp = np.minimum(0.05 * np.exp(sigma * t), top)
    fx = amp * np.cos(2 * np.pi * f0 * t)
    fy = amp * np.sin(2 * np.pi * f0 * t)
    tc, env = envelope(t, fx, fy, f0)
    late = (tc > 0.7) & (tc < 0.95)  # the FFT band-pass wraps around at the record ends
    assert env[late] == pytest.approx(top * math.sqrt(2), rel=0.02)  # fx and fy combined
    assert growth_rate(tc, env, floor=0.1) == pytest.approx(sigma, rel=0.05)
    # band power scales with the amplitude squared and ignores a spindle harmonic 43 Hz away
    hum = 30.0 * np.cos(2 * np.pi * 1100.0 * t)
    p1 = band_power(t, fx + hum, fy, f0)
    p2 = band_power(t, 2 * fx + hum, 2 * fy, f0)
    assert p2 / p1 == pytest.approx(4.0, rel=0.01)
