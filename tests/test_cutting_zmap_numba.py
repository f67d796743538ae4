"""Compiled Z-map cutting step (``fmus_src.cutting.zmap_numba``) against the numpy reference kernel.

The reference is the same component on the numpy path (``CuttingLoad.use_compiled = False``:
``kernel.cut_step``, ``SweptPath.advance/pop_ready``, ``ZMapStock.remove_sweep``), an independent
implementation of the same arithmetic (vectorised over members, teeth and instants). Required: per
step, forces and peak within 1e-9 N, means and MRR within 1e-12 relative; the compiled kernel does
the numpy operations in the same order, so on this platform (numpy and numba call the same libm
``sin``/``cos``/``atan2``/``hypot``) the outputs and the final Z-map are equal bit for bit, which is
asserted too. Each run is forced onto its kernel (the other one raises if called).

Also: a batch member's figures equal its solo run bit for bit on the compiled path, and the full-slot
mean force still matches the closed form (Altintas, ch. 2) derived in the test.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import fmus_src.cutting.component as component_module
from fmus_src.cutting import CuttingLoad
from fmus_src.jit import NUMBA_AVAILABLE

H = 1e-3
R = 3e-3
NAMES = ("fx", "fy", "fc", "fc_peak", "fx_mean", "fy_mean", "spindle_torque", "spindle_power", "mrr",
         "axial_depth", "chip_thickness", "engaged_teeth", "spindle_angle")
ABSOLUTE = ("fx", "fy", "fc", "fc_peak")  # N: within 1e-9 N
RELATIVE = ("fx_mean", "fy_mean", "spindle_torque", "spindle_power", "mrr")  # within 1e-12 relative
BLOCK = dict(tool_diameter=2 * R, flutes=2, kt=1.23e9, ke=0.5, stock_x_min=0.0, stock_x_max=0.03,
             stock_y_min=-0.01, stock_y_max=0.01, stock_z_min=-0.01, stock_z_max=0.0, stock_cell=2e-4)
RPM = 2 * math.pi / 60  # rad/s per rpm


def _refuse(*args, **kwargs):
    raise AssertionError("this run must not call this kernel")


def run(compiled, pos, omega, monkeypatch, **params):
    """Step a CuttingLoad (batch pos.shape[1]) through pos (K, B, 3) on one kernel; outputs (K-1, B) and heights."""
    comp = CuttingLoad("cut", batch=pos.shape[1], **{**BLOCK, **params})
    comp.use_compiled = compiled
    with monkeypatch.context() as mp:
        if compiled:
            mp.setattr(component_module, "cut_step", _refuse)
        else:
            mp.setattr(component_module, "cut_step_compiled", _refuse)
            mp.setattr(component_module, "commit", _refuse)
        for a, name in enumerate(("x_position", "y_position", "z_position")):
            comp.set(name, pos[0, :, a])
        comp.set("spindle_speed", omega)
        comp.setup(0.0)
        out = {n: [] for n in NAMES}
        for k in range(1, pos.shape[0]):
            for a, name in enumerate(("x_position", "y_position", "z_position")):
                comp.set(name, pos[k, :, a])
            comp.do_step((k - 1) * H, H)
            for n in NAMES:
                out[n].append(comp.get(n))
    return {n: np.array(v) for n, v in out.items()}, comp.stock.heights.copy()


def assert_same(compiled, reference):
    """The required bounds, then bit-identity (outputs and Z-map)."""
    (got, heights), (ref, ref_heights) = compiled, reference
    for n in ABSOLUTE:
        assert np.max(np.abs(got[n] - ref[n])) <= 1e-9, n
    for n in RELATIVE:
        assert np.all(np.abs(got[n] - ref[n]) <= 1e-12 * np.abs(ref[n])), n
    for n in NAMES:
        np.testing.assert_array_equal(got[n], ref[n], err_msg=n)
    np.testing.assert_array_equal(heights, ref_heights)


def both(pos, omega, monkeypatch, **params):
    compiled = run(True, pos, omega, monkeypatch, **params)
    reference = run(False, pos, omega, monkeypatch, **params)
    assert_same(compiled, reference)
    return compiled[0]


def line(start, end, steps):
    """Positions (steps + 1, 1, 3) linear from start to end."""
    s = np.linspace(0.0, 1.0, steps + 1)[:, None]
    return (np.asarray(start, float) + s * (np.asarray(end, float) - np.asarray(start, float)))[:, None, :]


def test_numba_is_available_for_the_compiled_path():
    assert NUMBA_AVAILABLE and CuttingLoad.use_compiled


def test_full_slot_equals_numpy_kernel(monkeypatch):
    # 100 mm/s at 20000 rpm, 2 teeth: fz = 0.15 mm; enters the block, cuts 20 mm of slot 2 mm deep
    pos = line([-0.004, 0.0, -2e-3], [0.02, 0.0, -2e-3], 240)
    out = both(pos, 20000 * RPM, monkeypatch)
    assert out["fc"].max() > 100.0 and out["mrr"][-1, 0] > 0.0  # it cuts


def test_arc_with_entry_exit_and_a_second_pass_equals_numpy_kernel(monkeypatch):
    # a 10 mm arc crossing the block's y edge (partial immersion, entry and exit), then a straight pass
    # 1.5 mm beside the first cut through committed (Z-map) material and back out
    ang = np.linspace(math.pi, -0.5 * math.pi, 300)
    arc = np.stack([0.012 + 0.01 * np.cos(ang), 0.008 + 0.01 * np.sin(ang), np.full(ang.size, -1.5e-3)], axis=1)
    back = line(arc[-1] + [0.0, 0.0015, -0.5e-3], [-0.005, -0.0005, -2e-3], 200)[:, 0]
    pos = np.concatenate([arc, back])[:, None, :]
    out = both(pos, 15000 * RPM, monkeypatch, stock_y_max=0.0)
    assert (out["engaged_teeth"] == 1).any() and (out["engaged_teeth"] == 0).any()


def test_batch_of_feeds_speeds_and_teeth_equals_numpy_and_solo_runs(monkeypatch):
    # three members, different feeds, spindle speeds and teeth: different substep counts per step
    feeds = np.array([0.06, 0.1, 0.14])  # m/s
    speeds = np.array([12000.0, 18000.0, 24000.0]) * RPM
    flutes = np.array([2, 3, 4])
    t = np.arange(151) * H
    x = np.minimum(-0.004 + feeds[None, :] * t[:, None], 0.012)
    pos = np.stack([x, np.full_like(x, 0.001), np.full_like(x, -1.5e-3)], axis=2)  # (K, 3, 3)
    batch = both(pos, speeds, monkeypatch, flutes=flutes)
    for m in range(3):
        solo, _ = run(True, pos[:, m:m + 1], speeds[m], monkeypatch, flutes=int(flutes[m]))
        for n in NAMES:
            np.testing.assert_array_equal(batch[n][:, m], solo[n][:, 0], err_msg=f"member {m} {n}")


def test_plunge_and_ramp_equal_numpy_kernel(monkeypatch):
    # member 0 plunges 1 mm at a fixed XY inside the block, then ramps along +x down to 2 mm;
    # member 1 ramps from above the block into it
    plunge = np.concatenate([line([0.01, 0.0, 0.0005], [0.01, 0.0, -1e-3], 40)[:, 0],
                             line([0.01, 0.0, -1e-3], [0.02, 0.0, -2e-3], 120)[1:, 0]])
    ramp = line([-0.004, 0.002, 0.0005], [0.016, 0.002, -2.5e-3], 160)[:, 0]
    pos = np.stack([plunge, ramp], axis=1)
    out = both(pos, 16000 * RPM, monkeypatch)
    assert out["fc"][:39, 0].max() == 0.0  # no XY feed while plunging: no chip
    assert out["fc"][60:, 0].min() > 0.0 and out["axial_depth"][-1, 1] > 2e-3


def test_full_slot_mean_force_matches_closed_form_on_compiled_path():
    # feed +x, fz = c, axial depth a, N teeth, Kr = Ke Kt, slot (phi from 0 to pi): the mean force on the
    # tool is N a c / (8 pi) [Kt cos 2phi - Kr (2phi - sin 2phi), Kt (2phi - sin 2phi) + Kr cos 2phi]_0^pi
    # = (-N a c Kr / 4, N a c Kt / 4); the component outputs the force on the workpiece (the negative)
    kt, ke, n_teeth, a, c = 1.23e9, 0.5, 2, 2e-3, 5e-5
    period = 3.8e-3  # tooth period, s: 190 steps = 50 periods
    omega = 2 * math.pi / (n_teeth * period)
    comp = CuttingLoad("cut", tool_diameter=2 * R, flutes=n_teeth, kt=kt, ke=ke, stock_x_min=0.0, stock_x_max=0.02,
                       stock_y_min=-0.01, stock_y_max=0.01, stock_z_min=-0.01, stock_z_max=0.0)
    assert comp.use_compiled
    v = c / period
    x0 = -R - 0.5e-3
    n_in = math.ceil((2 * R + 0.7e-3) / (v * H))
    comp.set("x_position", x0)
    comp.set("y_position", 0.0)
    comp.set("z_position", -a)
    comp.set("spindle_speed", omega)
    comp.setup(0.0)
    f = []
    for k in range(1, n_in + 191):
        comp.set("x_position", x0 + v * k * H)
        comp.do_step((k - 1) * H, H)
        if k > n_in:
            f.append([comp.get("fx_mean")[0], comp.get("fy_mean")[0]])
    expected = [n_teeth * a * c * ke * kt / 4, -n_teeth * a * c * kt / 4]  # [30.75, -61.5] N
    assert np.mean(f, axis=0) == pytest.approx(expected, rel=1e-6)


def test_subset_of_members_with_runout_and_a_lost_member_equals_numpy_kernel(monkeypatch):
    # member 1 has runout (its step stays on kernel_effects in both runs); member 2's position turns NaN
    # after 60 steps (held, outputs NaN): the compiled kernel gets the rows [0, 2] then [0] of the batch
    pos = np.repeat(line([-0.004, 0.0, -1.5e-3], [0.012, 0.0, -1.5e-3], 120), 3, axis=1)
    pos[61:, 2] = np.nan
    compiled = run(True, pos, 15000 * RPM, monkeypatch, runout_eccentricity=np.array([0.0, 10e-6, 0.0]))
    reference = run(False, pos, 15000 * RPM, monkeypatch, runout_eccentricity=np.array([0.0, 10e-6, 0.0]))
    got, ref = compiled[0], reference[0]
    for n in NAMES:
        np.testing.assert_array_equal(got[n], ref[n], err_msg=n)  # NaN where lost, in both
    np.testing.assert_array_equal(compiled[1], reference[1])
    assert np.isnan(got["fc"][-1, 2]) and got["fc"][-1, 0] > 0.0 and got["fc"][-1, 1] != got["fc"][-1, 0]
