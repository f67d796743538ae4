"""Reliability of batched (GA) runs: unstable candidates fail alone, with a reason; sane members are untouched.

A GA evaluates a population as one batch. A candidate whose gains or
friction drive the twin unstable must be marked failed with a reason
(``RunResult.failed`` / ``failures``) while the run carries on, and every
sane member must produce exactly the recording of its solo run.

The twin's runaway limits come from the machine file: position within
+-2 m, velocity within 3 x the axis's rapid traverse (X: 3 x 36 000 mm/min
= 1.8 m/s). The program is a short air cut (no spindle, no stock) so that
the unstable members leave the limits within 0.3 s.

The MCU's excess following-error alarm (FANUC SV0411 / SV0410, Nos. 1828 /
1829; machine file: 18 mm in motion on X, 0.5 mm at stop) usually catches a
runaway before the velocity limit does; the tests of the divergence detector
itself switch it off (``alarms=False``).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from orchestrator.case import case_for_program
from orchestrator.master import Master, MasterSettings
from orchestrator.twin import TwinOptions, build_twin

ROOT = Path(__file__).resolve().parents[1]
PROGRAM = "G90 G1 X5 Y2 F1200\nG0 X0 Y0\nM30\n"
CASE = case_for_program(ROOT / "models" / "examples" / "paper_part" / "program.nc")


def run(batch: int, members: dict[int, dict[tuple[str, str], float]], time_limit: float = 1.0,
        alarms: bool = True, program: str = PROGRAM, compiled: bool = True):
    """Run the twin with per-member parameter changes ``{member: {(component, parameter): value}}``.

    ``alarms=False`` switches the MCU's excess-error alarm off (all members, all axes);
    ``compiled=False`` runs the master's Python step loop instead of the compiled one.
    """
    twin = build_twin(CASE, batch=batch, program_text=program, options=TwinOptions(start_mm=(0.0, 0.0, 50.0)))
    if not alarms:
        for a in "xyz":
            for key in ("excess_error_in_motion", "excess_error_at_stop"):
                twin.mcu.set(f"{a}_{key}", 0.0)
    for b, changes in members.items():
        for (comp, name), value in changes.items():
            component = twin.system.components[comp]
            arr = component.get(name)
            arr[b] = value
            component.set(name, arr)
    settings = MasterSettings(step=twin.options.step, time_limit=time_limit, stop_when=twin.stop_when,
                              limits=twin.limits or {}, check_every=10, compiled=compiled)
    with np.errstate(over="ignore", invalid="ignore"):
        return Master(twin.system, settings, twin.probes).run(), twin


@pytest.fixture(scope="module")
def solo():
    result, _ = run(1, {})
    assert result.success and not result.failed.any()
    return result


def assert_member_equals_solo(result, b, solo):
    rec, ref = result.recording, solo.recording
    n = len(ref)
    assert len(rec) >= n
    for name in ref.channels:
        col = rec[name] if name == "t_s" else rec[name][:, b]
        np.testing.assert_array_equal(col[:n], ref[name], err_msg=f"member {b}, channel {name}")
    assert result.stopped_at[b] == solo.stopped_at[0]


def test_velocity_limit_is_three_times_rapid(solo):
    _, twin = run(1, {}, time_limit=1e-3)
    rapid_x = 36000.0 / 60.0 / 1000.0  # machine file: X rapid 36 000 mm/min
    assert twin.limits["x_drive.velocity"] == pytest.approx((-3 * rapid_x, 3 * rapid_x))
    assert twin.limits["x_drive.position"] == (-2.0, 2.0)


UNSTABLE = {
    1: {("mcu", "x_velocity_p_scale"): -1.0},       # positive velocity feedback: runaway
    2: {("mcu", "x_position_gain"): -30.0},         # positive position feedback: runaway
    3: {("mcu", "x_velocity_p_scale"): math.nan},   # a NaN gene
}


def test_unstable_members_fail_alone_with_a_reason_and_sane_members_equal_their_solo_run(solo):
    result, _ = run(5, UNSTABLE, alarms=False)
    # the run ends when the sane members are done; it is a success for them
    assert result.success
    assert "3 of 5 members diverged" in result.message
    assert result.failed.tolist() == [False, True, True, True, False]
    assert result.failures[0] is None and result.failures[4] is None
    assert "x_drive.velocity" in result.failures[1] and "is outside [-1.8, 1.8]" in result.failures[1]
    assert "x_drive.velocity" in result.failures[2] and "is outside [-1.8, 1.8]" in result.failures[2]
    assert "mcu.x_current_cmd is not finite" in result.failures[3]
    for b in (1, 2, 3):
        assert result.failures[b].startswith("diverged at t = ")
    for b in (0, 4):
        assert_member_equals_solo(result, b, solo)


def test_runaway_members_are_stopped_by_the_excess_error_alarm_first(solo):
    """With the alarm on, a runaway X axis trips SV0411 when its error passes 18 mm (well inside +-1.8 m/s)."""
    result, _ = run(5, UNSTABLE)
    assert result.success and "3 of 5 members failed" in result.message
    assert result.failed.tolist() == [False, True, True, True, False]
    for b in (1, 2):
        reason = result.failures[b]
        assert reason.startswith("failed at t = ") and "mcu: SV0411 excess error in motion on X" in reason
        assert "exceeds x_excess_error_in_motion = 18 mm (FANUC No. 1828)" in reason
        error_mm = float(reason.split("following error ")[1].split(" mm")[0])
        assert 18.0 < error_mm < 20.0  # caught within a step or two of crossing the limit
    assert "mcu.x_current_cmd is not finite" in result.failures[3]  # a NaN gene is caught as before
    for b in (0, 4):
        assert_member_equals_solo(result, b, solo)


def test_all_members_unstable_ends_the_run_with_the_first_reason():
    result, _ = run(2, {0: {("mcu", "x_velocity_p_scale"): -1.0}, 1: {("mcu", "x_position_gain"): -30.0}},
                    alarms=False)
    assert not result.success
    assert result.failed.all()
    assert "all 2 members" in result.message and "diverged at t = " in result.message
    assert len(result.recording) >= 2 and result.t_end < 1.0  # recording up to the failure kept


def test_a_tiny_mass_member_fails_alone(solo):
    # mass 1e-3 kg against gains tuned for 600 kg: the velocity loop is unstable at once
    result, _ = run(2, {1: {("x_drive", "mass"): 1e-3}}, time_limit=0.05)
    assert result.failed[1] and "x_drive.velocity" in result.failures[1]
    # the sane member is only cut short by the 0.05 s time limit, not by the unstable one
    assert "did not reach nck.done" in result.failures[0]


def test_a_tiny_mass_member_leaves_the_sane_member_bit_identical(solo):
    # the tiny mass caps its own Stribeck substep at ~1e-8 s; each member has its own substep
    result, _ = run(2, {1: {("x_drive", "mass"): 1e-3}}, time_limit=0.05)
    n = len(result.recording)
    np.testing.assert_array_equal(result.recording["x_mm"][:, 0], solo.recording["x_mm"][:n])


def test_inconsistent_friction_of_one_member_fails_that_member_only(solo):
    # Coulomb 1e9 N above the static friction: break-away runs backwards (the drive rejects it)
    result, _ = run(2, {1: {("x_drive", "coulomb_positive"): 1e9}})
    assert result.success and result.failed.tolist() == [False, True]
    assert result.failures[1].startswith("failed at t = ")
    assert "x_drive: stick/slip integrator: a table breaking away from rest moved backwards" in result.failures[1]
    assert "1 of 2 members failed" in result.message
    assert_member_equals_solo(result, 0, solo)
    # frozen: the failed member's outputs are NaN from its failure on, it never looks good
    t_fail = float(result.failures[1].split("t = ")[1].split(" s")[0])
    after = result.recording["t_s"] > t_fail + 1e-3
    assert np.isnan(result.recording["x_mm"][after, 1]).all()
    assert math.isnan(result.stopped_at[1])


def test_inconsistent_friction_of_a_single_run_is_a_clear_error():
    result, _ = run(1, {0: {("x_drive", "coulomb_positive"): 1e9}})
    assert not result.success and result.failed.tolist() == [True]
    assert result.message.startswith("simulation failed at t = ")
    assert "x_drive: stick/slip integrator: a table breaking away from rest moved backwards" in result.message
    # the member's own reason, in the per-member format; the run's message names the same failure
    assert result.failures[0] == result.message.replace("simulation failed at", "failed at", 1)


def test_a_member_that_never_settles_is_reported_with_a_reason(solo):
    # velocity P gain x 1e4: the loop chatters at the current limit and never comes in position
    result, _ = run(2, {1: {("mcu", "x_velocity_p_scale"): 1e4}}, time_limit=0.8)
    assert math.isnan(result.stopped_at[1]) and result.stopped_at[0] == solo.stopped_at[0]
    assert result.failures[1] is not None and "time limit" in result.failures[1]


def test_a_member_that_never_settles_is_not_reported_as_good(solo):
    result, _ = run(2, {1: {("mcu", "x_velocity_p_scale"): 1e4}}, time_limit=0.8)
    # the run as a whole completes (the sane member finished); the member that never settled is failed
    assert result.failed.tolist() == [False, True]
    assert "time limit of 0.8 s reached before nck.done" in result.message and "for 1 of 2 members" in result.message
    assert math.isnan(result.stopped_at[1])
    assert_member_equals_solo(result, 0, solo)  # the sane member is untouched


def test_a_bad_parameter_of_one_member_is_a_clear_error_naming_component_and_parameter():
    from orchestrator.errors import CncTwinError

    with pytest.raises(CncTwinError, match=r"x_drive\.mass must be finite and > 0"):
        run(2, {1: {("x_drive", "mass"): -1.0}})


STUCK = {("x_drive", "static_positive"): 1e9, ("x_drive", "coulomb_positive"): 1e9}


def test_an_axis_stuck_by_absurd_friction_is_not_reported_as_good():
    """Out 40 mm at rapid and back: without the alarm the stuck axis ends where it started and looks done.

    The error of the stuck axis is the reference itself; it passes the in-motion limit (18 mm) on the way
    out, before the reference reaches its end point (no 'at stop' state on the way).
    """
    program = "G90 G0 X40\nG0 X0\nM30\n"
    result, _ = run(2, {1: STUCK}, program=program)
    assert np.abs(result.recording["x_mm"][:, 1][~np.isnan(result.recording["x_mm"][:, 1])]).max() < 1e-9
    assert result.success and result.failed.tolist() == [False, True]
    reason = result.failures[1]
    assert "mcu: SV0411 excess error in motion on X" in reason and "(FANUC No. 1828)" in reason
    # it trips when the reference passes 18 mm: the recorded reference at the failure time is 18-19 mm
    t_fail = float(reason.split("t = ")[1].split(" s")[0])
    rec = result.recording
    x_ref = np.interp(t_fail, rec["t_s"], rec["x_ref_mm"][:, 1])
    assert 18.0 <= x_ref <= 19.5
    without, _ = run(2, {1: STUCK}, program=program, alarms=False)
    assert not without.failed[1] and without.stopped_at[1] > 0  # the gap the alarm closes


def test_an_axis_stuck_short_of_a_stop_trips_the_at_stop_alarm():
    """G1 X5 then a dwell: the NC waits for in-position, the reference rests at X5, the stuck axis at 0.

    5 mm is below the in-motion limit; once the reference has rested for 8 position-loop time constants
    (ceil(8 / (50 1/s x 1 ms)) = 160 position ticks) the at-stop limit (0.5 mm) applies: SV0410.
    """
    program = "G90 G1 X5 F1200\nG4 X0.5\nG0 X0\nM30\n"
    result, _ = run(2, {1: STUCK}, program=program, time_limit=2.0)
    assert result.success and result.failed.tolist() == [False, True]
    reason = result.failures[1]
    assert "mcu: SV0410 excess error at stop on X: following error 5 mm" in reason
    assert "exceeds x_excess_error_at_stop = 0.5 mm (FANUC No. 1829)" in reason
    rec = result.recording
    t_fail = float(reason.split("t = ")[1].split(" s")[0])
    resting = rec["t_s"][np.flatnonzero(np.abs(rec["x_ref_mm"][:, 1] - 5.0) < 1e-9)[0]]  # reference arrives at X5
    assert t_fail - resting == pytest.approx(0.160, abs=2e-3)


def test_a_single_run_with_a_stuck_axis_ends_with_the_alarm():
    result, _ = run(1, {0: STUCK}, program="G90 G0 X40\nG0 X0\nM30\n")
    assert not result.success and result.failed.tolist() == [True]
    assert "mcu: SV0411 excess error in motion on X" in result.message


def test_full_speed_rapids_stay_below_the_in_motion_limit():
    """The limits are 1.5 x the steady following error at rapid traverse, v / Kp (X, Y: 12 mm, Z: 10 mm).

    Long single-axis rapids (X 300, Y 200, Z 240 mm, inside the default machine's stroke limits X -382..380,
    Y -225..225, Z -210..300 mm from the start (0, 0, 50)) reach the rapid speed; the largest following error is
    then the steady lag within 1 %, and no alarm trips.
    """
    program = "G90 G0 X300\nG0 Y-200\nG0 Z290\nM30\n"
    result, twin = run(1, {}, program=program, time_limit=3.0)
    assert result.success and not result.failed.any(), result.message
    machine = CASE.machine
    for a in "xyz":
        axis = machine.table(f"axis.{a}")
        lag = axis["rapid_feed_mm_per_min"] / 60.0 / axis["position_gain_per_s"]  # mm
        assert axis["excess_error_in_motion_mm"] == pytest.approx(1.5 * lag)
        err = np.abs(result.recording[f"{a}_ref_mm"] - result.recording[f"{a}_mm"]).max()
        assert err == pytest.approx(lag, rel=0.01)


def test_python_and_compiled_master_loops_fail_the_same_members_for_the_same_reasons():
    """Divergence, an integrator failure and both alarms in one batch: the two step loops agree exactly."""
    members = {**UNSTABLE, 4: STUCK, 5: {("x_drive", "coulomb_positive"): 1e9}}
    program = "G90 G1 X5 F1200\nG4 X0.3\nG0 X40\nG0 X0\nM30\n"
    a, _ = run(6, members, program=program, time_limit=1.5)
    b, _ = run(6, members, program=program, time_limit=1.5, compiled=False)
    assert a.failed.tolist() == [False, True, True, True, True, True]
    assert a.failures == b.failures and a.message == b.message and a.success and b.success
    assert "SV0410 excess error at stop on X" in a.failures[4] and "x_drive: stick/slip" in a.failures[5]
    for name in a.recording.channels:
        np.testing.assert_array_equal(a.recording[name], b.recording[name], err_msg=name)
