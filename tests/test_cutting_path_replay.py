"""The compiled force replay (fmus_src.cutting.path_replay) against stepping the component force sample by sample.

Both run the same compiled kernels (path_kernel.path_step, path_effects.path_step_effects) with the same inputs;
the compiled loop only moves the effect clocks (droop, wear, cutting time, unwrapped angle) out of numpy into
scalar code with the same operations in the same order. So the reference is exact: the outputs of
run_force_replay must equal, bit for bit, those of the step-by-step loop it falls back to (forced here by making
the glue return None). Cases: a slot cut along x with a small y wobble, an uneven logger clock and a varying
spindle speed; three distinct members with every effect term the component has (runout, helix, edge force,
static deflection, chatter, wear, droop), and three on the baseline kernel (Kt, wear, droop). A member that
fails on the way sends the whole replay to the loop (same NaN member); a replay whose every member fails raises
the loop's DiagnosisError, word for word.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import orchestrator.diagnose.cutting_replay as cutting_replay
from fmus_src.cutting.path_replay import compiled_path_steps
from fmus_src.cutting.table import build_engagement_table
from orchestrator.case import load_case
from orchestrator.diagnose.cutting_case import CASE_TOML, SHORT_PROGRAM
from orchestrator.diagnose.cutting_replay import ForceInputs, run_force_replay
from orchestrator.diagnose.errors import DiagnosisError

OMEGA = 6000 * 2 * math.pi / 60
FEED = 7.5e-3  # 450 mm/min, m/s
N_SAMPLES = 250
THETA0 = np.array([0.1, 0.7, 2.0])


@pytest.fixture(scope="module")
def setting(tmp_path_factory):
    """Case, table of a 2 mm deep full slot along x at y = 10 mm, and the replay inputs (1 ms, jittered)."""
    folder = tmp_path_factory.mktemp("path_replay")
    (folder / "program.nc").write_text(SHORT_PROGRAM)
    (folder / "case.toml").write_text(CASE_TOML.replace('recording = "recording.csv"\n', ""))
    case = load_case(folder)
    path = np.array([[-0.004, 0.01, -0.002], [0.012, 0.01, -0.002]])
    table = build_engagement_table(path, 6e-3, [0.0, 0.0, -0.006], [0.016, 0.02, 0.0], 2e-5)
    k = np.arange(N_SAMPLES)
    t = 0.3 + 1e-3 * k + 2e-5 * np.sin(0.7 * k)  # a logger clock with jitter: uneven steps
    x = -0.0032 + FEED * (t - t[0])  # in the air for the first ~27 ms (the tool reaches x = 0 at -3 mm)
    y = 0.01 + 3e-6 * np.sin(2 * math.pi * 37.0 * t)
    z = np.full_like(t, -0.002)
    omega = OMEGA * (1.0 + 0.02 * np.sin(2 * math.pi * 3.0 * t))
    return case, table, ForceInputs(t, np.column_stack([x, y, z]), omega, "spindle_rpm")


def _spy(monkeypatch):
    """Count the compiled replays that ran (returned traces)."""
    used = []

    def spy(*args):
        r = compiled_path_steps(*args)
        used.append(r is not None)
        return r

    monkeypatch.setattr(cutting_replay, "compiled_path_steps", spy)
    return used


def _both(monkeypatch, case, table, inputs, members, theta):
    used = _spy(monkeypatch)
    fast = run_force_replay(case, table, inputs, members, theta)
    monkeypatch.setattr(cutting_replay, "compiled_path_steps", lambda *args: None)
    slow = run_force_replay(case, table, inputs, members, theta)
    return fast, slow, used


def _assert_identical(fast, slow):
    for name in ("fx", "fy", "torque", "omega", "engaged", "depth"):
        a, b = getattr(fast, name), getattr(slow, name)
        assert a.shape == b.shape and a.dtype == b.dtype, name
        np.testing.assert_array_equal(a, b, err_msg=name)  # bit for bit (NaN where the loop has NaN)


EFFECT_MEMBERS = [
    {"runout_eccentricity": 8e-6, "runout_phase": 0.3, "helix_angle": math.radians(30.0), "wear_rate": 0.5,
     "spindle_droop": 2.0, "edge_force_tangential": 1e4, "edge_force_radial": 5e3},
    {"edge_force_tangential": 2e4, "edge_force_radial": 1e4, "tool_stiffness": 2e7, "spindle_droop": 5.0,
     "kt": 1.3e9},
    {"chatter_frequency": 1150.0, "chatter_damping": 0.03, "chatter_stiffness": 3e7, "wear_rate": 1.0,
     "helix_angle": 0.2},
]


def test_effect_members_bit_identical_to_the_loop(monkeypatch, setting):
    case, table, inputs = setting
    fast, slow, used = _both(monkeypatch, case, table, inputs, EFFECT_MEMBERS, THETA0)
    assert used == [True]
    _assert_identical(fast, slow)
    # the comparison means something: no force in the air (the tool reaches the stock at x = -3 mm after
    # 0.2 mm / 7.5 mm/s = 27 ms), then every member cuts (2 mm deep, 25 um chip, Kt 1.23e9: tens of N), and
    # droop lowers the speed of the two members that have it below the input where a tooth is always in the
    # cut (the last 50 steps: over 1.3 mm into the stock, an engagement arc over the 120 deg pitch)
    fc = np.hypot(fast.fx, fast.fy)
    assert np.all(fc[:25] == 0.0) and np.all(fc[-20:].max(axis=0) > 30.0), fc.max(axis=0)
    om_in = 0.5 * (inputs.omega[:-1] + inputs.omega[1:])
    assert np.all(fast.omega[-50:, :2] < om_in[-50:, None])
    assert np.array_equal(fast.omega[1:, 2], om_in)
    assert len(set(fast.fx[-1])) == 3  # three distinct members


def test_baseline_kernel_members_bit_identical_to_the_loop(monkeypatch, setting):
    case, table, inputs = setting
    members = [{}, {"kt": 1.4e9}, {"wear_rate": 1.0, "spindle_droop": 3.0}]
    fast, slow, used = _both(monkeypatch, case, table, inputs, members, THETA0)
    assert used == [True]
    _assert_identical(fast, slow)
    assert len(set(fast.fx[-1])) == 3
    # with the same angle, Kt scales the force exactly: member 1 = 1.4/1.23 of member 0
    same = run_force_replay(case, table, inputs, members[:2], 0.5)
    ratio = same.fx[1:, 1] / np.where(same.fx[1:, 0] == 0, np.nan, same.fx[1:, 0])
    assert np.nanmax(np.abs(ratio - 1.4e9 / 1.23e9)) < 1e-12


def test_a_member_failing_on_the_way_sends_the_replay_to_the_loop(monkeypatch, setting):
    # member 1 asks for 400000 angle steps per tooth: its first step needs 0.63 rad / (2.09 rad / 4e5) = 1.2e5
    # substeps > MAX_SUBSTEPS = 1e5 and it fails there (NaN from then on); the others go on
    case, table, inputs = setting
    members = [{}, {"angle_steps_per_tooth": 400000}, {"helix_angle": 0.3}]
    fast, slow, used = _both(monkeypatch, case, table, inputs, members, THETA0)
    assert used == [False]
    _assert_identical(fast, slow)
    assert np.all(np.isnan(fast.fx[1:, 1])) and np.all(np.isfinite(fast.fx[:, [0, 2]]))


def test_every_member_off_the_path_raises_the_loops_error(monkeypatch, setting):
    # from sample 120 on the tool is 5 mm off the slot's line, beyond PATH_TOLERANCE = 2 mm, in the material
    case, table, inputs = setting
    pos = inputs.position.copy()
    pos[120:, 1] += 5e-3
    off = ForceInputs(inputs.t, pos, inputs.omega, inputs.omega_source)
    used = _spy(monkeypatch)
    with pytest.raises(DiagnosisError) as fast:
        run_force_replay(case, table, off, [{}, {"kt": 1.4e9}], 0.3)
    assert used == [False]
    monkeypatch.setattr(cutting_replay, "compiled_path_steps", lambda *args: None)
    with pytest.raises(DiagnosisError) as slow:
        run_force_replay(case, table, off, [{}, {"kt": 1.4e9}], 0.3)
    assert str(fast.value) == str(slow.value)
    text = str(fast.value)
    assert text.startswith(f"cutting replay at t = {inputs.t[120]:.4f} s (logger clock): cutting: member 0")
    assert "farther than path_tolerance = 0.002 m" in text and "(all 2 members have failed)" in text


def test_not_covered_returns_none(setting):
    # a component that is not set up, and a clock that does not increase, are left to the loop
    from fmus_src.cutting.path_component import PathCuttingLoad

    case, table, inputs = setting
    comp = PathCuttingLoad("cutting", batch=1)
    comp.attach_table(table)
    t = inputs.t
    om = np.full(t.size - 1, OMEGA)
    assert compiled_path_steps(comp, t, inputs.position, om) is None
    for i, a in enumerate("xyz"):
        comp.set(f"{a}_position", inputs.position[0, i])
    for name, value in (("tool_diameter", 6e-3), ("flutes", 3), ("stock_x_max", 0.016), ("stock_y_max", 0.02),
                        ("stock_z_min", -0.006), ("path_tolerance", 2e-3)):
        comp.set(name, value)
    comp.setup(float(t[0]))
    assert compiled_path_steps(comp, t[::-1].copy(), inputs.position, om) is None
    assert compiled_path_steps(comp, t, inputs.position, om) is not None


def test_member_blocks_in_threads_bit_identical_to_the_loop(monkeypatch, setting):
    """Nine members (every effect kind and the baseline, mixed) run as blocks in threads: the loop's numbers."""
    import fmus_src.cutting.path_replay as path_replay

    monkeypatch.setattr(path_replay, "member_blocks", lambda batch: [(0, 4), (4, 6), (6, batch)])
    case, table, inputs = setting
    members = EFFECT_MEMBERS + [{}, {"kt": 1.4e9}, {"wear_rate": 1.0, "spindle_droop": 3.0}] + EFFECT_MEMBERS[::-1]
    theta = np.linspace(0.1, 2.9, len(members))
    fast, slow, used = _both(monkeypatch, case, table, inputs, members, theta)
    assert used == [True]
    _assert_identical(fast, slow)
    fc = np.hypot(fast.fx, fast.fy)
    assert np.all(fc[-20:].max(axis=0) > 30.0)  # every member, in every block, cuts
