"""Per-member reliability at component level: failure channel, per-member drive substeps, servo alarm.

* :meth:`Component.fail_members` / :meth:`Component.take_failures`: failed
  members' real outputs are NaN after every step, the reason is handed over
  once, and a component with no member left raises.
* ``DriveAxis``: each member integrates with its own substep, so a member of
  a mixed batch equals its solo run bit for bit (compiled kernel and numpy
  reference alike); a failing stick/slip step fails that member only.
* ``MCU``: the excess following-error alarm (FANUC SV0411 / SV0410) trips at
  the step derived by hand, identically in the compiled kernel and the numpy
  reference.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.component import Component, ComponentError, Variable
from fmus_src.servo import MCU, DriveAxis, ServoError
from fmus_src.servo.control import settle_ticks

KF = 2.0 * math.pi / 0.012  # N/A: kt = 1 N.m/A, Lb = 12 mm
TP = 1e-3


class Doubler(Component):
    """y = 2 u; fails the members whose input is negative."""

    variables = (Variable("u", "input", "1", 0.0), Variable("y", "output", "1", 0.0),
                 Variable("ok", "output", "1", True, type="Boolean"))

    def _setup(self, t0: float) -> None:
        self._do_step(t0, 1.0)

    def _do_step(self, t: float, h: float) -> None:
        self.values["y"][...] = 2.0 * self.values["u"]
        bad = self.values["u"] < 0.0
        if bad.any():
            self.fail_members(bad, f"{self.name}: negative input", ComponentError)


def test_failure_channel_blanks_outputs_reports_once_and_raises_when_no_member_is_left():
    c = Doubler("d", batch=3)
    c.setup(0.0)
    c.set("u", [1.0, -1.0, 2.0])
    c.do_step(0.0, 0.5)
    np.testing.assert_array_equal(c.failed_members, [False, True, False])
    np.testing.assert_array_equal(c.values["y"], [2.0, np.nan, 4.0])
    assert c.values["ok"].tolist() == [True, True, True]  # Boolean outputs are left alone
    (members, reason, t), = c.take_failures()
    assert members.tolist() == [1] and reason == "d: negative input" and t == 0.0
    assert c.take_failures() == []
    c.set("u", [1.0, 5.0, 2.0])  # a failed member stays failed: its outputs stay NaN
    c.do_step(0.5, 0.5)
    np.testing.assert_array_equal(c.values["y"], [2.0, np.nan, 4.0])
    assert c.take_failures() == []
    c.set("u", [-1.0, -1.0, -3.0])
    with pytest.raises(ComponentError, match=r"^d: negative input \(all 3 members have failed\)$"):
        c.do_step(1.0, 0.5)
    c.reset()
    assert not c.failed_members.any()


def test_single_member_failure_raises_the_reason_itself():
    c = Doubler("d")
    c.setup(0.0)
    c.set("u", -1.0)
    with pytest.raises(ComponentError, match=r"^d: negative input$"):
        c.do_step(0.0, 1.0)


# ------------------------------------------------------------------------------------------ drive
def drive_run(compiled: bool, batch: int, forces: np.ndarray, steps: int = 80, h: float = 250e-6,
              **params) -> tuple[np.ndarray, DriveAxis]:
    d = DriveAxis("x_drive", batch=batch, **params)
    d.use_compiled = compiled
    d.setup(0.0)
    d.set("current_cmd", forces / KF)
    out = []
    for k in range(steps):
        d.do_step(k * h, h)
        out.append(d.get("position"))
    return np.array(out), d


@pytest.mark.parametrize("compiled", [True, False])
def test_each_member_has_its_own_substep(compiled):
    """Member 1 (vs = 0.02 mm/s) has a Stribeck substep cap of 0.25 Ms vs / (Fs - Fc) = 22 us; member 0 keeps
    the Table 1 X values (cap 1.8 ms, so the 125 us integration step) and its solo trace."""
    force = np.array([900.0, 900.0])
    solo, _ = drive_run(compiled, 1, force[:1])
    mixed, d = drive_run(compiled, 2, force, stribeck_velocity_positive=[0.0016, 2e-5])
    rate = ((775.2 - 641.6) / 2e-5 - 7702.0) / 600.0  # 1/s
    np.testing.assert_allclose(d._step, [125e-6, 0.25 / rate], rtol=1e-12)  # noqa: SLF001
    np.testing.assert_array_equal(mixed[:, 0], solo[:, 0])


def test_compiled_and_reference_agree_with_mixed_substeps():
    force = np.array([900.0, -1200.0, 780.0])
    params = dict(stribeck_velocity_positive=[0.0016, 1e-4, 2e-5], integration_step=[125e-6, 50e-6, 125e-6])
    a, _ = drive_run(True, 3, force, **params)
    b, _ = drive_run(False, 3, force, **params)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("compiled", [True, False])
def test_a_failing_member_is_failed_and_frozen_the_other_goes_on(compiled):
    """Coulomb far above static friction: the break-away runs backwards within the first substep."""
    force = np.array([900.0, 900.0])
    solo, _ = drive_run(compiled, 1, force[:1])
    mixed, d = drive_run(compiled, 2, force, coulomb_positive=[641.6, 1e9])
    np.testing.assert_array_equal(mixed[:, 0], solo[:, 0])
    assert np.isnan(mixed[:, 1]).all()
    (members, reason, t), = d.take_failures()
    assert members.tolist() == [1] and t == 0.0
    assert reason == ("x_drive: stick/slip integrator: a table breaking away from rest moved backwards within "
                      "one substep of 0.000125 s; expected integration_step small against the Stribeck time scale")
    assert np.isnan(d._state.position[1]) and d._state.direction[1] == 0  # noqa: SLF001 - frozen


def test_a_failing_single_drive_raises_and_keeps_its_state():
    with pytest.raises(ServoError, match="x_drive: stick/slip integrator: .*moved backwards"):
        drive_run(True, 1, np.array([900.0]), coulomb_positive=1e9)


# ------------------------------------------------------------------------------------------ MCU alarm
def mcu_pair(batch: int, inputs: dict | None = None, **params) -> tuple[MCU, MCU]:
    """A compiled and a numpy-reference MCU, set up with ``inputs`` at t = 0."""
    pair = (MCU("mcu", batch=batch, **params), MCU("mcu", batch=batch, **params))
    pair[1].use_compiled = False
    for m in pair:
        for name, value in (inputs or {}).items():
            m.set(name, value)
        m.setup(0.0)
    return pair


def test_settle_ticks_is_eight_position_loop_time_constants():
    assert settle_ticks(np.array([50.0]), TP).tolist() == [160.0]        # 8 / (50 x 1 ms)
    assert settle_ticks(np.array([30.0]), TP).tolist() == [267.0]        # ceil(266.7)
    assert settle_ticks(np.array([-30.0, np.nan]), TP).tolist() == [math.inf, math.inf]


def test_in_motion_alarm_trips_when_the_error_passes_the_limit():
    """Reference ramps at 0.1 m/s, the table stays at 0: |e| = 0.1 t passes 18.05 mm at step 181."""
    pair = mcu_pair(2, x_excess_error_in_motion=[0.01805, 0.0], x_excess_error_at_stop=0.0005)
    tripped = []
    for m in pair:
        for k in range(1, 400):
            m.set("x_ref", 0.1 * k * TP)
            m.do_step((k - 1) * TP, TP)  # member 1 has the alarm off: the batch lives on, no exception
            if m.take_failures():
                tripped.append((k, m.failed_members.tolist()))
                break
    # the check uses the inputs of the step: error 0.1 k 1e-3 > 0.01805 first for k = 181
    assert tripped == [(181, [True, False]), (181, [True, False])]


def test_at_stop_alarm_trips_after_the_settling_time_identically_in_both_implementations():
    """Reference at rest 1 mm from the table: below 18 mm, so only the at-stop limit can trip, at tick 160."""
    pair = mcu_pair(1, {"x_ref": 1e-3}, x_excess_error_in_motion=0.018, x_excess_error_at_stop=0.0005)
    steps = []
    for m in pair:
        for k in range(400):
            try:
                m.do_step(k * TP, TP)
            except ServoError as err:
                steps.append((k, str(err)))
                break
    # position ticks k = 0, 1, ... each see an unchanged reference: still = k + 1 >= 160 first at k = 159
    message = ("mcu: SV0410 excess error at stop on X: following error 1 mm exceeds x_excess_error_at_stop = "
               "0.5 mm (FANUC No. 1829)")
    assert steps == [(159, message), (159, message)]


def test_alarm_off_by_default_in_the_bare_component():
    m = MCU("mcu")
    m.set("x_ref", 1.0)
    m.setup(0.0)
    for k in range(300):
        m.do_step(k * TP, TP)
    assert not m.failed_members.any()


@pytest.mark.parametrize("bad", [-1e-3, math.nan])
def test_alarm_limits_must_be_non_negative(bad):
    m = MCU("mcu", y_excess_error_at_stop=bad)
    with pytest.raises(ServoError, match=r"mcu: \{x,y,z\}_excess_error_at_stop must be finite and >= 0"):
        m.setup(0.0)
