"""Cutting-effect terms wired into CuttingLoad / PathCuttingLoad (issue 8), against derived numbers.

Expected values are derived here independently of the components:

* closed forms for a full slot fed along +x with feed per tooth c, axial depth a, N teeth, tooth angle
  phi in (0, pi) engaged (Altintas ch. 2; force on the TOOL per tooth
  ``F = Ft (-cos, sin) + Fr (-sin, -cos)``, the components output the force on the workpiece);
* numeric quadrature (numpy) of the chip and force laws for runout (Kline & DeVor) and helix
  (axial slices of straight teeth);
* the zero-order (Altintas & Budak) stability limit of a full slot with an isotropic tool mode.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from test_cutting_path import along, assert_modes_agree, path_run, zmap_run

from fmus_src.cutting import CuttingError, CuttingLoad
from fmus_src.cutting.path_component import PathCuttingLoad
from fmus_src.cutting.table import EngagementTable

KT, KE = 1.23e9, 0.5
R = 3e-3
N = 2
H = 1e-3
TOOTH_PERIOD = 3.8e-3
OMEGA = 2 * math.pi / (N * TOOTH_PERIOD)
A, C = 2e-3, 5e-5  # axial depth, feed per tooth
V = C / TOOTH_PERIOD  # feed velocity at OMEGA, m/s
OUTPUTS = ("fx", "fy", "fc", "fc_peak", "fx_mean", "fy_mean", "spindle_torque", "spindle_power", "mrr",
           "spindle_angle", "axial_depth", "chip_thickness", "engaged_teeth", "spindle_speed_actual",
           "tool_vibration_x", "tool_vibration_y", "cutting_time")
EFFECTS_OFF = dict(runout_eccentricity=0.0, runout_phase=0.0, helix_angle=0.0, edge_force_tangential=0.0,
                   edge_force_radial=0.0, tool_stiffness=0.0, wear_rate=0.0, spindle_droop=0.0,
                   chatter_frequency=0.0, chatter_damping=0.0, chatter_stiffness=0.0)


def block(**kw):
    p = dict(tool_diameter=2 * R, flutes=N, kt=KT, ke=KE, stock_x_min=0.0, stock_x_max=0.03,
             stock_y_min=-0.01, stock_y_max=0.01, stock_z_min=-0.01, stock_z_max=0.0)
    p.update(kw)
    return p


def run(comp, xs, omega=OMEGA, h=H, depth=A, names=OUTPUTS):
    """Set up at xs[0] (y = 0, z = -depth) and step through xs[1:]; dict of (K, B) arrays."""
    comp.set("x_position", xs[0])
    comp.set("y_position", 0.0)
    comp.set("z_position", -depth)
    comp.set("spindle_speed", omega)
    comp.setup(0.0)
    out = {n: [] for n in names}
    for k in range(1, len(xs)):
        comp.set("x_position", xs[k])
        comp.do_step((k - 1) * h, h)
        for n in names:
            out[n].append(comp.get(n))
    return {n: np.array(v) for n, v in out.items()}


def slot_positions(steps, h=H, v=V, x0=-R - 0.5e-3):
    return x0 + v * h * np.arange(steps + 1)


def steady(h=H, v=V):
    """Index of the first step with the tool fully in the slot (x > R + 0.2 mm)."""
    return int(math.ceil((2 * R + 0.7e-3) / (v * h)))


def slot_mean_on_workpiece(kt, ke, a, c, n=N):
    """Mean force on the workpiece of a full slot (closed form): (N a c Kr / 4, -N a c Kt / 4)."""
    return np.array([n * a * c * ke * kt / 4, -n * a * c * kt / 4])


# ------------------------------------------------------------------------------------------ all off
def test_all_off_is_bit_identical_and_the_effects_kernel_reduces_to_the_baseline():
    xs = slot_positions(60)
    base = run(CuttingLoad("c", **block()), xs)
    off = run(CuttingLoad("c", **block(**EFFECTS_OFF)), xs)
    for n in OUTPUTS:
        np.testing.assert_array_equal(base[n], off[n], err_msg=n)
    assert np.all(base["spindle_speed_actual"] == OMEGA) and np.all(base["tool_vibration_x"] == 0.0)
    # a vanishing edge force switches the effects kernels on (Z-map and path): same numbers to rounding
    tiny = run(CuttingLoad("c", **block(edge_force_tangential=1e-300)), xs)
    peak = base["fc_peak"].max()
    assert peak > 50.0
    for n in ("fx", "fy", "fc", "fc_peak", "fx_mean", "fy_mean"):
        np.testing.assert_allclose(tiny[n], base[n], rtol=0, atol=1e-12 * peak, err_msg=n)
    np.testing.assert_array_equal(tiny["engaged_teeth"], base["engaged_teeth"])
    verts = [[xs[0], 0.0, -A], [xs[-1] + 1e-3, 0.0, -A]]
    pos = np.stack([xs, np.zeros_like(xs), np.full_like(xs, -A)], axis=1)[:, None, :]
    q0, _ = path_run(block(), verts, pos, OMEGA)
    q1, _ = path_run(block(edge_force_tangential=1e-300), verts, pos, OMEGA)
    for n in ("fx", "fy", "fc_peak", "fx_mean", "fy_mean", "spindle_torque", "mrr"):
        np.testing.assert_allclose(q1[n], q0[n], rtol=0, atol=1e-12 * max(peak, 1.0), err_msg=n)


# ------------------------------------------------------------------------------------------ edge force
@pytest.mark.parametrize("mode", ["zmap", "path"])
def test_edge_force_adds_its_closed_form_slot_mean(mode):
    # per tooth Fte = Kte a, Fre = Kre a while engaged (phi in (0, pi)); mean over a revolution, N teeth:
    # on the tool (N a / 2 pi) [int -Kte cos - Kre sin, int Kte sin - Kre cos] = (-N a Kre / pi, N a Kte / pi)
    kte, kre = 20e3, 12e3
    p = block(edge_force_tangential=kte, edge_force_radial=kre)
    k0 = steady()
    n_meas = 190  # 190 steps = 50 tooth periods
    xs = slot_positions(k0 + n_meas)
    if mode == "zmap":
        r = run(CuttingLoad("c", **p), xs)
    else:
        pos = np.stack([xs, np.zeros_like(xs), np.full_like(xs, -A)], axis=1)[:, None, :]
        r, _ = path_run(p, [[xs[0], 0.0, -A], [xs[-1] + 1e-3, 0.0, -A]], pos, OMEGA)
    sl = slice(k0, k0 + n_meas)
    got = np.array([r["fx_mean"][sl].mean(), r["fy_mean"][sl].mean()])
    expected = slot_mean_on_workpiece(KT, KE, A, C) + np.array([N * A * kre / math.pi, -N * A * kte / math.pi])
    assert got == pytest.approx(expected, rel=1e-5)
    # torque: N Kt a c R / pi (chip) + N Kte a R / 2 (edge, engaged half the time); MRR stays geometric
    torque = N * KT * A * C * R / math.pi + N * kte * A * R / 2
    assert r["spindle_torque"][sl].mean() == pytest.approx(torque, rel=1e-5)
    assert r["mrr"][sl].mean() == pytest.approx(2 * R * A * V, rel=1e-5)


# ------------------------------------------------------------------------------------------ deflection
def test_static_deflection_reduces_the_chip_by_the_closed_form_factor():
    # 2 teeth in a slot: one tooth in cut at a time; its radial force Ke Kt a h pushes the tool away by
    # Fr / k: h = h0 - Ke Kt a h / k  ->  every force scales by 1 / (1 + Ke Kt a / k)
    k = 2e6
    k0 = steady()
    xs = slot_positions(k0 + 190)
    base = run(CuttingLoad("c", **block()), xs)
    r = run(CuttingLoad("c", **block(tool_stiffness=k)), xs)
    factor = 1.0 / (1.0 + KE * KT * A / k)
    sl = slice(k0, k0 + 190)
    for n in ("fx_mean", "fy_mean", "spindle_torque", "fc"):
        np.testing.assert_allclose(r[n][sl], factor * base[n][sl], rtol=1e-9, atol=1e-9, err_msg=n)
    np.testing.assert_allclose(r["mrr"], base["mrr"], rtol=1e-12)  # material removed is geometric


# ------------------------------------------------------------------------------------------ wear
def test_wear_grows_the_force_linearly_with_cutting_time():
    rate = 2.0  # 1/s: +2 % per 10 ms of cutting
    xs = slot_positions(120)
    base = run(CuttingLoad("c", **block()), xs)
    r = run(CuttingLoad("c", **block(wear_rate=rate)), xs)
    cutting = base["mrr"][:, 0] > 0
    clock = np.cumsum(cutting) * H  # cutting time at the end of each step
    np.testing.assert_allclose(r["cutting_time"][:, 0], clock, rtol=0, atol=1e-15)
    before = np.concatenate([[0.0], clock[:-1]])  # the step uses the clock at its start
    for n in ("fx_mean", "fy_mean", "spindle_torque", "fx", "fy"):
        np.testing.assert_allclose(r[n][:, 0], base[n][:, 0] * (1 + rate * before), rtol=1e-12, atol=1e-12,
                                   err_msg=n)
    assert clock[-1] > 0.05


# ------------------------------------------------------------------------------------------ droop
@pytest.mark.parametrize("mode", ["zmap", "path"])
def test_spindle_droop_lowers_the_speed_by_droop_times_torque(mode):
    # slot at a fixed feed velocity v: the chip per tooth is 2 pi v / (N w), the mean torque
    # T = N Kt a R c / pi = 2 Kt a R v / w; with w = w0 - d T the steady speed solves
    # w^2 - w0 w + 2 d Kt a R v = 0
    d = 200.0  # (rad/s)/(N.m)
    k0 = steady()
    n_meas = 380
    xs = slot_positions(k0 + n_meas)
    p = block(spindle_droop=d)
    if mode == "zmap":
        r = run(CuttingLoad("c", **p), xs)
    else:
        pos = np.stack([xs, np.zeros_like(xs), np.full_like(xs, -A)], axis=1)[:, None, :]
        comp = PathCuttingLoad("c", **p)
        comp.attach_table(EngagementTable.from_parameters(np.array([[xs[0], 0.0, -A], [xs[-1] + 1e-3, 0.0, -A]]), p))
        r = run(comp, pos[:, 0, 0])
    w = r["spindle_speed_actual"][:, 0]
    torque = r["spindle_torque"][:, 0]
    # explicit: the speed of a step follows from the previous step's torque
    np.testing.assert_allclose(w[1:], OMEGA - d * torque[:-1], rtol=1e-14)
    assert w[0] == OMEGA
    steady_w = (OMEGA + math.sqrt(OMEGA ** 2 - 8 * d * KT * A * R * V)) / 2
    assert OMEGA - steady_w > 30.0  # a clear drop (about 6 %)
    assert w[k0 + 100:].mean() == pytest.approx(steady_w, rel=2e-3)
    # the spindle angle integrates the actual speed
    expected_angle = np.mod(np.cumsum(w) * H, 2 * math.pi)
    np.testing.assert_allclose(np.unwrap(r["spindle_angle"][:, 0]), np.unwrap(expected_angle), atol=1e-9)


# ------------------------------------------------------------------------------------------ runout
def kline_devor_step_means(n_teeth, rho, lam, a, c, theta0, span, samples=20001):
    """Mean (Fx, Fy) on the workpiece and torque over spindle angles [theta0, theta0 + span], slot fed along +x.

    Independent quadrature of the Kline-DeVor chip: tooth j (at theta + j 2pi/N, radius R + r_j,
    r_j = rho cos(lam - 2 pi j / N)) cuts the lowest surface left by the teeth that passed before it
    (tooth j + m passes a point m pitches earlier): h_j = min_m (m c sin phi + r_j - r_{j+m}), clipped at 0.
    """
    theta = theta0 + span * (np.arange(samples) + 0.5) / samples
    pitch = 2 * math.pi / n_teeth
    r = rho * np.cos(lam - pitch * np.arange(n_teeth))
    f = np.zeros((samples, 3))
    for j in range(n_teeth):
        phi = theta + j * pitch
        s, co = np.sin(phi), np.cos(phi)
        h = np.min([m * c * s + r[j] - r[(j + m) % n_teeth] for m in range(1, n_teeth + 1)], axis=0)
        h = np.where(s > 0, np.maximum(h, 0.0), 0.0)  # front half of the slot is material
        ft = KT * a * h
        fr = KE * ft
        f[:, 0] += ft * co + fr * s  # on the workpiece
        f[:, 1] += -ft * s + fr * co
        f[:, 2] += ft * R
    return f.mean(axis=0)


@pytest.mark.parametrize("flutes,lam_deg", [(2, 30.0), (3, 50.0)])
def test_runout_tooth_loads_follow_kline_devor(flutes, lam_deg):
    rho, lam = 12e-6, math.radians(lam_deg)
    period = 2 * math.pi / (flutes * OMEGA)
    h = period  # one tooth pass per communication step
    v = C / period
    k0 = steady(h=h, v=v) + 2
    xs = slot_positions(k0 + 20 * flutes, h=h, v=v)
    r = run(CuttingLoad("c", **block(flutes=flutes, runout_eccentricity=rho, runout_phase=lam)), xs, h=h)
    base = run(CuttingLoad("c", **block(flutes=flutes)), xs, h=h)
    pitch = 2 * math.pi / flutes
    for k in range(k0, k0 + 2 * flutes):
        theta0 = OMEGA * h * k
        exp = kline_devor_step_means(flutes, rho, lam, A, C, theta0, pitch)
        got = [r["fx_mean"][k, 0], r["fy_mean"][k, 0], r["spindle_torque"][k, 0]]
        assert got == pytest.approx(exp, rel=2e-4, abs=1e-3)
    # the tooth loads differ (a force at spindle frequency) but a revolution removes the nominal feed:
    # the mean over whole revolutions equals the run without runout
    per_tooth = r["spindle_torque"][k0:k0 + 2 * flutes, 0]
    assert per_tooth.max() / per_tooth.min() > 1.3
    sl = slice(k0, k0 + 20 * flutes)
    for n in ("fx_mean", "fy_mean", "spindle_torque", "mrr"):
        assert r[n][sl].mean() == pytest.approx(base[n][sl].mean(), rel=1e-6), n


# ------------------------------------------------------------------------------------------ helix
def helix_slice_force(theta, beta, a, c, slices=2000):
    """Force on the workpiece at spindle angle theta: axial-slice sum of straight-tooth forces (slot)."""
    z = (np.arange(slices) + 0.5) / slices * a
    f = np.zeros(2)
    for j in range(N):
        phi = theta + j * 2 * math.pi / N - z * math.tan(beta) / R
        s, co = np.sin(phi), np.cos(phi)
        h = np.where(s > 0, c * s, 0.0)
        ft = KT * (a / slices) * h
        fr = KE * ft
        f += [np.sum(ft * co + fr * s), np.sum(-ft * s + fr * co)]
    return f


@pytest.mark.parametrize("mode", ["zmap", "path"])
def test_helix_force_equals_the_axial_slice_average(mode):
    beta = math.radians(30.0)
    k0 = steady()
    xs = slot_positions(k0 + 40)
    p = block(helix_angle=beta, angle_steps_per_tooth=72)
    if mode == "zmap":
        r = run(CuttingLoad("c", **p), xs)
    else:
        comp = PathCuttingLoad("c", **p)
        comp.attach_table(EngagementTable.from_parameters(np.array([[xs[0], 0.0, -A], [xs[-1] + 1e-3, 0.0, -A]]), p))
        r = run(comp, xs)
    straight = run(CuttingLoad("c", **block()), xs)
    peak = straight["fc_peak"][k0:].max()
    for k in range(k0, k0 + 40):
        theta_end = OMEGA * H * (k + 1)
        exp = helix_slice_force(theta_end, beta, A, C)
        assert [r["fx"][k, 0], r["fy"][k, 0]] == pytest.approx(exp, abs=2e-3 * peak)
        ts = OMEGA * H * (k + (np.arange(64) + 0.5) / 64)
        exp_mean = np.mean([helix_slice_force(t, beta, A, C, 400) for t in ts], axis=0)
        assert [r["fx_mean"][k, 0], r["fy_mean"][k, 0]] == pytest.approx(exp_mean, abs=2e-3 * peak)
    # the helix smooths the load: the peak is that of the slice average, below the straight tooth's
    # Kt a c sqrt(1 + Ke^2); the mean over whole tooth periods (19 steps = 5 periods) is unchanged
    sl = slice(k0, k0 + 38)
    theta = np.linspace(0.0, 2 * math.pi / N, 721)
    helix_peak = max(np.hypot(*helix_slice_force(t, beta, A, C, 400)) for t in theta)
    assert peak == pytest.approx(KT * A * C * math.hypot(1, KE), rel=1e-4)
    assert helix_peak < 0.995 * peak
    assert r["fc_peak"][sl].max() == pytest.approx(helix_peak, rel=2e-3)
    assert r["fx_mean"][sl].mean() == pytest.approx(straight["fx_mean"][sl].mean(), rel=1e-3)
    assert r["fy_mean"][sl].mean() == pytest.approx(straight["fy_mean"][sl].mean(), rel=1e-3)


# ------------------------------------------------------------------------------------------ chatter
def zoa_limit(n_teeth, fn, zeta, k):
    """Zero-order stability limit of a full slot, isotropic x/y tool mode (Altintas & Budak 1995).

    Dynamic chip (q(t) - q(t - T)) . u; mean force on the tool per unit depth Kt A0 dq with
    A0 = N / (2 pi) int_0^pi w u^T dphi = N / 4 [[-Ke, -1], [1, -Ke]] (w = (-cos - Ke sin, sin - Ke cos),
    u = (sin, cos)). With eigenvalue lam of A0 and receptance G, 1 = Kt a (1 - e^{-i w T}) lam G has a
    real root a = 1 / (2 Kt Re(lam G)) and e^{-i w T} = -(conj(lam G) / |lam G|)^2.

    Returns
    -------
    a_lim : float
        Least stable axial depth over all chatter frequencies, m.
    f_c : float
        Chatter frequency there, Hz.
    tooth_period : float
        A tooth period T at that lobe bottom near 6000 rpm, s.
    """
    a0 = n_teeth / 4 * np.array([[-KE, -1.0], [1.0, -KE]])
    lams = np.linalg.eigvals(a0)
    wn = 2 * math.pi * fn
    w = np.linspace(0.9, 1.2, 300001) * wn
    g = 1 / (k * (1 - (w / wn) ** 2 + 2j * zeta * w / wn))
    best = None
    for lam in lams:
        z = lam * g
        i = int(np.argmax(z.real))
        if best is None or z.real[i] > best[0].real:
            best = (z[i], w[i])
    z, wc = best
    eps = (-2 * np.angle(np.conj(z)) + math.pi) % (2 * math.pi)  # w T = eps + 2 pi j
    j = np.arange(1, 60)
    tooth = (eps + 2 * math.pi * j) / wc
    rpm = 60 / (n_teeth * tooth)
    return 1 / (2 * KT * z.real), wc / (2 * math.pi), float(tooth[np.argmin(np.abs(rpm - 6000))])


def chatter_run(mode, n_teeth, depth, fn, zeta, k, tooth_period, duration):
    """Full slot along +x at C per tooth, sampled 20 times per tooth period; returns t, q (K, 2), fx."""
    h = tooth_period / 20
    omega = 2 * math.pi / (n_teeth * tooth_period)
    v = C / tooth_period
    p = block(flutes=n_teeth, stock_x_max=0.2, chatter_frequency=fn, chatter_damping=zeta, chatter_stiffness=k)
    xs = slot_positions(int(duration / h), h=h, v=v, x0=-R - 0.2e-3)
    if mode == "zmap":
        comp = CuttingLoad("c", **p)
    else:
        comp = PathCuttingLoad("c", **p)
        comp.attach_table(EngagementTable.from_parameters(np.array([[xs[0], 0, -depth], [xs[-1] + 1e-3, 0, -depth]]),
                                                          p))
    r = run(comp, xs, omega=omega, h=h, depth=depth, names=("tool_vibration_x", "tool_vibration_y", "fx", "fx_mean"))
    q = np.stack([r["tool_vibration_x"][:, 0], r["tool_vibration_y"][:, 0]], axis=1)
    return h * np.arange(1, len(xs)), q, r


def window_rms(e, windows=8):
    n = len(e) // windows
    return np.array([math.sqrt(np.mean(e[i * n:(i + 1) * n] ** 2)) for i in range(windows)])


def test_chatter_grows_beyond_and_decays_below_the_analytic_stability_limit():
    # 4 teeth (the zero-order solution is accurate for a full slot with 4 teeth; with 2 teeth the
    # strongly time-varying directional factor moves the limit), 1 kHz mode, 3 % damping, 10 N/um
    n_teeth, fn, zeta, k = 4, 1000.0, 0.03, 1e7
    a_lim, f_c, tooth = zoa_limit(n_teeth, fn, zeta, k)
    assert 0.2e-3 < a_lim < 0.3e-3
    results = {}
    for factor in (0.8, 1.25):
        t, q, _ = chatter_run("path", n_teeth, factor * a_lim, fn, zeta, k, tooth, 0.4)
        e = np.linalg.norm(q[20:] - q[:-20], axis=1)  # regenerative displacement q(t) - q(t - T)
        results[factor] = (t[20:], e)
        results["q"] = q
    below = window_rms(results[0.8][1])
    above = window_rms(results[1.25][1])
    assert below[-1] < 1e-3 * below[1]  # dies out: only the forced (tooth-periodic) response is left
    assert above[-1] > 20 * above[3] and above[-1] > 1e-6  # grows to micrometres
    # at the frequency of the analytic chatter mode (spectrum resolution 5 Hz)
    t, q = results[1.25][0], results["q"]
    ex = q[20:, 0] - q[:-20, 0]
    tail = ex[len(ex) // 2:] - ex[len(ex) // 2:].mean()
    spec = np.abs(np.fft.rfft(tail * np.hanning(tail.size)))
    freq = np.fft.rfftfreq(tail.size, t[1] - t[0])
    assert freq[np.argmax(spec)] == pytest.approx(f_c, abs=0.015 * f_c)


def test_chatter_saturates_when_teeth_leave_the_cut_and_zmap_agrees_with_path():
    n_teeth, fn, zeta, k = 4, 1000.0, 0.03, 1e7
    a_lim, _, tooth = zoa_limit(n_teeth, fn, zeta, k)
    t, q, _ = chatter_run("path", n_teeth, 3 * a_lim, fn, zeta, k, tooth, 0.3)
    e = np.linalg.norm(q[20:] - q[:-20], axis=1)
    rms = window_rms(e)
    assert rms[-1] == pytest.approx(rms[-2], rel=0.1)  # bounded: multiple regeneration, teeth jump out
    assert 10 * C > rms[-1] > C  # the vibration is of the order of the feed per tooth
    # Z-map and path mode agree on the tool vibration of a stable cut, once the response to the first
    # contact with the block face (an arc the two modes resolve differently) has died out
    _, qz, rz = chatter_run("zmap", n_teeth, 0.8 * a_lim, fn, zeta, k, tooth, 0.1)
    _, qp, rp = chatter_run("path", n_teeth, 0.8 * a_lim, fn, zeta, k, tooth, 0.1)
    late = slice(len(qp) // 2, None)
    scale = np.abs(qp[late]).max()
    assert scale > 1e-6  # forced vibration at the tooth frequency, about 1.5 um
    np.testing.assert_allclose(qz[late], qp[late], atol=0.005 * scale)
    np.testing.assert_allclose(rz["fx_mean"][late], rp["fx_mean"][late], atol=0.005 * np.abs(rp["fx_mean"]).max())


# ------------------------------------------------------------------------------------------ modes agree
@pytest.mark.parametrize("effect", [
    dict(runout_eccentricity=10e-6, runout_phase=0.4),
    dict(helix_angle=math.radians(30.0)),
    dict(edge_force_tangential=25e3, edge_force_radial=15e3),
    dict(tool_stiffness=3e6),
    dict(wear_rate=3.0),
    dict(chatter_frequency=1500.0, chatter_damping=0.05, chatter_stiffness=2e7),
], ids=["runout", "helix", "edge", "deflection", "wear", "chatter"])
def test_path_mode_agrees_with_zmap_mode_for_each_effect(effect):
    # 25 % radial immersion down-milling through a 7 mm block: entry, steady cut, exit.
    # (Spindle droop is compared in test_spindle_droop_...: both modes against the analytic speed. Here
    # it would turn the modes' different first-contact torque into a lasting spindle phase offset.)
    ae = 1.5e-3
    p = block(stock_x_max=0.007, stock_y_max=-(R - ae), **effect)
    verts = [[-R - 0.5e-3, 0.0, -A], [0.007 + R + 0.5e-3, 0.0, -A]]
    pos = along(verts, C / TOOTH_PERIOD * H)
    z = zmap_run(p, pos, OMEGA)
    q, _ = path_run(p, verts, pos, OMEGA)
    if "helix_angle" not in effect:
        assert_modes_agree(z, q, worst=5e-3)
        return
    # With a helix the path mode integrates the instantaneous force exactly over the axial depth
    # (checked against fine axial slices in test_diagnose_cutting_helix_chatter.py) while the Z-map
    # mode sums helix bands (5 deg of lag each here), so only the step means, which average a band's
    # lag spread over the substep, are compared: both modes use bands there. Where one band's arc at a
    # block corner is narrower than a substep (first and last contact) the Z-map mode misses it while
    # other bands still cut: 1 % of the steps may exceed 0.5 % of the peak, none 5 %.
    peak = z["fc_peak"].max()
    assert peak > 10.0
    for n, scale in (("fx_mean", peak), ("fy_mean", peak), ("spindle_torque", peak * R), ("mrr", z["mrr"].max())):
        err = np.abs(z[n] - q[n])
        assert err.max() <= 0.05 * scale, n
        assert np.mean(err > 5e-3 * scale) <= 0.01, n


# ------------------------------------------------------------------------------------------ errors
def test_effect_parameter_errors_name_the_field():
    with pytest.raises(CuttingError, match=r"c\.tool_stiffness: member 0 has -1.0"):
        CuttingLoad("c", **block(tool_stiffness=-1.0)).setup(0.0)
    with pytest.raises(CuttingError, match=r"c\.chatter_stiffness: .*chatter_frequency 900.0 Hz"):
        CuttingLoad("c", **block(chatter_frequency=900.0, chatter_damping=0.02)).setup(0.0)
    with pytest.raises(CuttingError, match=r"c\.chatter_damping: member 1 has 1.0"):
        CuttingLoad("c", batch=2, **block(chatter_damping=[0.1, 1.0])).setup(0.0)


# ------------------------------------------------------------------------------------------ machine file and twin
PROGRAM = """%
O0001 (C1 SHORT SLOT)
G21 G17 G40 G49 G90 G94
G54
S3000 M3
G0 X-5. Y5. Z1.
G1 Z-1. F600
X2. F600
G0 Z5.
M5
M30
%
"""


def test_machine_section_maps_to_the_component_and_the_twin_records_the_drooped_speed(tmp_path: Path):
    from orchestrator.case import Case, Stock, Tool
    from orchestrator.machine import load_machine, machine_to_toml
    from orchestrator.master import Master, MasterSettings
    from orchestrator.twin import TwinOptions, build_twin, cutting_parameters

    keys = dict(eccentricity_um=8.0, phase_deg=30.0, helix_deg=35.0, kte_N_per_mm=20.0, kre_N_per_mm=10.0,
                tool_stiffness_N_per_um=5.0, wear_rate_percent_per_min=3.0, spindle_droop_rpm_per_Nm=20.0,
                chatter_frequency_Hz=900.0, chatter_damping_ratio=0.03, chatter_stiffness_N_per_um=10.0)
    machine = load_machine("default").with_values("cutting.effects", **keys)
    path = tmp_path / "m.toml"
    path.write_text(machine_to_toml(machine, {"cutting.effects.helix_deg": "test"}))
    again = load_machine(path)
    assert again.values["cutting"]["effects"] == keys
    assert again.provenance["cutting.effects.helix_deg"] == "test"
    program = tmp_path / "slot.nc"
    program.write_text(PROGRAM)

    def case(m):
        return Case(folder=tmp_path, program=program, recording=None, stock=Stock((0.0, 0.0, -5.0), (10.0, 10.0, 0.0)),
                    tool=Tool(6.0, 2), machine=m, material=m.materials()[0])

    p = cutting_parameters(case(again))
    expected = dict(runout_eccentricity=8e-6, runout_phase=math.radians(30), helix_angle=math.radians(35),
                    edge_force_tangential=20e3, edge_force_radial=10e3, tool_stiffness=5e6,
                    wear_rate=0.03 / 60, spindle_droop=20 * 2 * math.pi / 60, chatter_frequency=900.0,
                    chatter_damping=0.03, chatter_stiffness=1e7)
    for name, value in expected.items():
        assert p[name] == pytest.approx(value, rel=1e-12), name

    def record(m):
        twin = build_twin(case(m))
        settings = MasterSettings(step=twin.options.step, time_limit=10.0, stop_when=twin.stop_when)
        return Master(twin.system, settings, twin.probes).run().recording

    base = load_machine("default")
    plain = record(base)
    zeros = record(base.with_values("cutting.effects", **{k: 0.0 for k in keys}))
    for channel in ("fx_N", "fy_N", "spindle_rpm", "spindle_torque_Nm", "x_mm"):
        np.testing.assert_array_equal(plain[channel], zeros[channel], err_msg=channel)
    # without droop the recorded speed is the NC kernel's (what the twin without cutting records)
    twin = build_twin(case(base), options=TwinOptions(cutting=False))
    air = Master(twin.system, MasterSettings(step=twin.options.step, time_limit=10.0, stop_when=twin.stop_when),
                 twin.probes).run().recording
    n = min(len(air), len(plain))
    np.testing.assert_array_equal(np.asarray(plain["spindle_rpm"])[:n], np.asarray(air["spindle_rpm"])[:n])
    droop = record(base.with_values("cutting.effects", spindle_droop_rpm_per_Nm=400.0))
    torque = np.asarray(droop["spindle_torque_Nm"]).ravel()
    rpm = np.asarray(droop["spindle_rpm"]).ravel()
    nominal = np.asarray(plain["spindle_rpm"]).ravel()
    cutting = np.flatnonzero(torque[:-1] > 0.05)
    assert cutting.size > 100
    # the recorded speed is the commanded ramped speed minus droop x previous step's torque
    np.testing.assert_allclose(rpm[cutting + 1], nominal[cutting + 1] - 400.0 * torque[cutting], rtol=1e-9)
