"""Z-map cutting load: a batch member's figures equal its solo run (per-member substeps).

The Z-map component cuts each communication step into ``n`` substeps, ``n``
from the spindle turn, the tool move and the tool mode of the member
(:meth:`CuttingLoad._substeps`). Every member uses the count it would use
alone, so a batch of members with different feeds and spindle speeds (hence
different ``n``) must reproduce, bit for bit, each member's separate run:
the reference is the same component with ``batch=1``, an independent run
with nothing shared. The same holds for the whole twin in Z-map mode (F and
S as NC-kernel overrides). Also checked: a member needing too many substeps
fails alone with a message naming it, and a single run still raises.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.cutting import CuttingError, CuttingLoad
from fmus_src.cutting.component import MAX_SUBSTEPS
from tests.test_cutting_path import drive, step_through

R = 3e-3
N_TEETH = 2
H = 1e-3
OMEGA = 2 * math.pi / (N_TEETH * 3.8e-3)  # rad/s, tooth period 3.8 ms
NAMES = ("fx", "fy", "fc", "fc_peak", "fx_mean", "fy_mean", "spindle_torque", "spindle_power", "mrr",
         "spindle_angle", "axial_depth", "chip_thickness", "engaged_teeth", "spindle_speed_actual",
         "tool_vibration_x", "tool_vibration_y", "cutting_time")
# 2/3 immersion: the block spans y in [0, 10] mm and x in [0, 3] mm; the tool centre runs at y = 1 mm
# through it, 1.5 mm deep (entry, steady cut, exit)
BLOCK = dict(tool_diameter=2 * R, flutes=N_TEETH, kt=1.23e9, ke=0.5, stock_x_min=0.0, stock_x_max=0.003,
             stock_y_min=0.0, stock_y_max=0.01, stock_z_min=-0.01, stock_z_max=0.0)
START = np.array([-R - 0.3e-3, 0.001, -1.5e-3])
END = np.array([0.003 + R + 0.3e-3, 0.001, -1.5e-3])
FEED_PER_TOOTH = np.array([8e-5, 1.2e-4, 1.6e-4])  # m
SPEEDS = np.array([OMEGA, 0.8 * OMEGA, 1.3 * OMEGA])  # rad/s


def substeps(omega):
    """Substep count of the component's rule for a 2-flute tool at 36 angle steps per tooth (the move is smaller)."""
    return math.ceil(omega * H / (math.pi / 36) - 1e-9)


def positions(feed_per_tooth, omega):
    """Tool-tip positions at t = k H (shape (K, B, 3)), linear from START to END, held at END once reached."""
    speed = feed_per_tooth * N_TEETH * omega / (2 * math.pi)  # m/s
    length = float(np.linalg.norm(END - START))
    k = int(math.ceil(length / (speed.min() * H)))
    s = np.minimum(np.arange(k + 1)[:, None] * speed[None, :] * H, length) / length  # (K, B)
    return START + s[..., None] * (END - START)


def run(pos, omega, **params):
    """Step a CuttingLoad of batch pos.shape[1] along pos; returns {name: (K-1, B)}."""
    return drive(CuttingLoad("cut", batch=pos.shape[1], **{**BLOCK, **params}), pos, omega, NAMES)


def member_params(params, m):
    """Parameters of member m alone (arrays sliced, scalars kept)."""
    return {k: (np.asarray(v)[m] if np.ndim(v) else v) for k, v in params.items()}


def assert_members_equal_solo(params):
    pos = positions(FEED_PER_TOOTH, SPEEDS)
    together = run(pos, SPEEDS, **params)
    assert together["fc_peak"].max() > 20.0  # it really cuts
    for m in range(3):
        alone = run(pos[:, m:m + 1], SPEEDS[m:m + 1], **member_params(params, m))
        assert alone["fc_peak"].max() > 20.0
        for n in NAMES:
            np.testing.assert_array_equal(together[n][:, m], alone[n][:, 0], err_msg=f"member {m}: {n}")


def test_members_use_different_substep_counts():
    # the premise: the three members need 10, 8 and 13 substeps per step (spindle turn), not one count
    assert [substeps(w) for w in SPEEDS] == [10, 8, 13]


def test_members_with_different_feeds_and_speeds_equal_their_solo_runs():
    assert_members_equal_solo({})


def test_members_with_runout_equal_their_solo_runs():
    # runout on (effects kernel), a different eccentricity per member
    assert_members_equal_solo(dict(runout_eccentricity=np.array([10e-6, 5e-6, 15e-6]), runout_phase=0.4))


def test_members_with_chatter_equal_their_solo_runs():
    # a tool mode per member (its own vibration and history); 32 substeps per mode period give 10, 8 and 11,
    # so with the spindle's 10, 8 and 13 the members still need 10, 8 and 13 substeps
    fn = np.array([300.0, 250.0, 320.0])
    assert_members_equal_solo(dict(chatter_frequency=fn, chatter_damping=0.05, chatter_stiffness=2e7))


def test_effects_on_for_one_member_only_leave_the_others_on_the_baseline():
    # member 1 with runout, members 0 and 2 without: each equals its solo run
    assert_members_equal_solo(dict(runout_eccentricity=np.array([0.0, 10e-6, 0.0]), runout_phase=0.4))


def test_a_member_needing_too_many_substeps_fails_alone():
    pos = positions(FEED_PER_TOOTH[:2], SPEEDS[:2])[:40]
    # member 1: a spindle speed needing MAX_SUBSTEPS + 1 substeps per step (pi/36 rad each)
    fast = (MAX_SUBSTEPS + 0.5) * math.pi / 36 / H
    speeds = np.array([SPEEDS[0], fast])
    comp = CuttingLoad("cut", batch=2, **BLOCK)
    for a, name in enumerate(("x_position", "y_position", "z_position")):
        comp.set(name, pos[0, :, a])
    comp.set("spindle_speed", speeds)
    comp.setup(0.0)
    comp.set("x_position", pos[1, :, 0])
    comp.do_step(0.0, H)
    failures = comp.take_failures()
    assert [f[0].tolist() for f in failures] == [[1]]
    assert "member 1" in failures[0][1] and f"more than {MAX_SUBSTEPS} substeps" in failures[0][1]
    assert np.isnan(comp.get("fc")[1]) and comp.get("engaged_teeth")[1] == 0
    # member 0 goes on as alone
    solo = run(pos[:, :1], SPEEDS[:1])
    first = {n: comp.get(n) for n in NAMES}
    rest = step_through(comp, pos, 2, NAMES)
    for n in NAMES:
        got = np.concatenate([first[n][None, :], rest[n]])
        np.testing.assert_array_equal(got[:, 0], solo[n][:, 0], err_msg=n)
    # alone, the same member raises (nothing left to compute)
    single = CuttingLoad("cut", batch=1, **BLOCK)
    single.set("spindle_speed", fast)
    single.setup(0.0)
    with pytest.raises(CuttingError, match=r"cut: step of 0.001 s of member 0 needs more than 100000 substeps"):
        single.do_step(0.0, H)


def test_twin_members_with_different_feeds_and_speeds_equal_their_solo_twin_runs():
    # the whole twin in Z-map mode: a 1 mm deep slot, 4 mm long, into the paper part; F and S of the slot per
    # member as NC-kernel overrides (line 2: S, line 5: F), each member against its solo twin run with its overrides
    from pathlib import Path

    from orchestrator.case import load_case
    from orchestrator.master import Master, MasterSettings
    from orchestrator.twin import TwinOptions, build_twin

    case = load_case(Path(__file__).resolve().parents[1] / "models" / "examples" / "paper_part")
    program = "G21 G90 G94\nS6000 M3\nG0 X-4. Y6. Z1.\nG1 Z-1. F200\nX4. F300\nG0 Z1.\nM30\n"
    rpm = np.array([6000.0, 4500.0])
    feed_mm_min = np.array([300.0, 450.0])

    def twin_run(members):
        twin = build_twin(case, batch=len(members), program_text=program,
                          options=TwinOptions(cutting_mode="zmap", start_mm=(-4.0, 6.0, 1.0)))
        twin.nck.set_overrides(feed={5: feed_mm_min[members] / 60e3}, spindle={2: rpm[members] * math.pi / 30})
        settings = MasterSettings(step=twin.options.step, time_limit=8.0, stop_when=twin.stop_when,
                                  limits=twin.limits or {})
        return Master(twin.system, settings, twin.probes).run()

    together = twin_run([0, 1])
    assert together.success
    for m in range(2):
        alone = twin_run([m])
        assert alone.success and np.nanmax(alone.recording["fc_N"]) > 10.0
        n = len(alone.recording)
        for name in alone.recording.channels:
            col = together.recording[name] if name == "t_s" else together.recording[name][:, m]
            np.testing.assert_array_equal(col[:n], alone.recording[name], err_msg=f"member {m}: {name}")
