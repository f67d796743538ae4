"""MCU: loop scheduling, gains, feed-forward, saturation and anti-windup (open loop, exact numbers)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.servo import MCU, ServoError

TV, TP = 250e-6, 1e-3
KP, KV, KI, IMAX = 50.0, 720.0, 90000.0, 40.0
KF = 2.0 * math.pi / 0.012


def mcu(batch: int = 1, **params: object) -> MCU:
    m = MCU("mcu", batch=batch, **params)
    m.setup(0.0)
    return m


def test_first_ticks_match_the_control_law_by_hand():
    m = mcu(x_position_scale=2.0, x_velocity_p_scale=0.5, x_velocity_i_scale=3.0)
    m.set("x_ref", 1e-4)
    m.do_step(0.0, TV)
    v_cmd = 2.0 * KP * 1e-4
    integ = 3.0 * KI * TV * v_cmd
    np.testing.assert_allclose(m.get("x_velocity_cmd"), v_cmd, rtol=1e-15)
    np.testing.assert_allclose(m.get("x_current_cmd"), 0.5 * KV * v_cmd + integ, rtol=1e-14)
    # next velocity tick (not a position tick): new ref is NOT read, v_cmd is held
    m.set("x_ref", 5e-4)
    m.set("x_velocity", 0.002)
    m.do_step(TV, TV)
    err = v_cmd - 0.002
    integ += 3.0 * KI * TV * err
    np.testing.assert_allclose(m.get("x_velocity_cmd"), v_cmd, rtol=1e-15)
    np.testing.assert_allclose(m.get("x_current_cmd"), 0.5 * KV * err + integ, rtol=1e-13)
    assert m.get("y_current_cmd")[0] == 0.0 and m.get("z_current_cmd")[0] == 0.0


def test_one_millisecond_steps_equal_four_quarter_steps():
    rng = np.random.default_rng(7)
    a, b = mcu(batch=2), mcu(batch=2)
    for j in range(50):
        inputs = {f"{ax}_{kind}": rng.normal(scale=1e-4, size=2) for ax in "xyz" for kind in ("ref", "position", "velocity")}
        for name, val in inputs.items():
            a.set(name, val)
            b.set(name, val)
        a.do_step(j * TP, TP)
        for q in range(4):
            b.do_step((4 * j + q) * TV, TV)
        for ax in "xyz":
            np.testing.assert_array_equal(a.get(f"{ax}_current_cmd"), b.get(f"{ax}_current_cmd"))
            np.testing.assert_array_equal(a.get(f"{ax}_velocity_cmd"), b.get(f"{ax}_velocity_cmd"))


@pytest.mark.parametrize("h", [3e-4, 1.1e-3, 1e-4])
def test_step_not_a_multiple_of_the_velocity_period_is_an_error(h):
    m = mcu()
    with pytest.raises(ServoError, match="velocity loop period"):
        m.do_step(0.0, h)


def test_non_contiguous_time_is_an_error():
    m = mcu()
    m.do_step(0.0, TP)
    with pytest.raises(ServoError, match="contiguous"):
        m.do_step(2 * TP, TP)


def test_position_period_must_be_a_multiple():
    with pytest.raises(ServoError, match="position_loop_period"):
        mcu(position_loop_period=0.6e-3)


def test_anti_windup_integrator_clamping_exact():
    """Constant velocity error e = Pp * 1 mm = 0.05 m/s: P part 36 A, integral +1.125 A per tick.

    Ticks 1-3 integrate (36 + 3.375 <= 40); tick 4 would give 40.5 A, so the integrator is clamped
    at 4 A (command exactly 40 A) and stays there however long the error persists. Reversing the
    error then gives -36 + 4 - 1.125 = -33.125 A at once; without anti-windup the integrator would
    hold 200 x 1.125 = 225 A and the command would stay at +40 A.
    """
    m = mcu()
    m.set("x_ref", 1e-3)
    currents = []
    for k in range(200):
        m.do_step(k * TV, TV)
        currents.append(m.get("x_current_cmd")[0])
    e = KP * 1e-3
    np.testing.assert_allclose(currents[:3], KV * e + KI * TV * e * np.arange(1, 4), rtol=1e-14)
    np.testing.assert_allclose(currents[3:], IMAX, rtol=1e-15)
    m.set("x_ref", 0.0)
    m.set("x_position", 1e-3)  # next position tick: v_cmd = -0.05 m/s
    m.do_step(200 * TV, TV)
    np.testing.assert_allclose(m.get("x_current_cmd"), -KV * e + (IMAX - KV * e) - KI * TV * e, rtol=1e-13)


def test_saturation_symmetric_and_per_member():
    m = mcu(batch=2, x_peak_current=[40.0, 10.0])
    m.set("x_ref", [-1.0, 1.0])
    m.do_step(0.0, TP)
    np.testing.assert_array_equal(m.get("x_current_cmd"), [-40.0, 10.0])


def test_feedforward_exact_on_a_parabolic_reference():
    """r = a t^2 / 2 sampled at 1 ms: backward differences give v_ref = a (t - Tp/2) and a_ref = a exactly.

    With Kvff = Kaff = 1, actual position = r and actual velocity = a (t - Tp/2), every velocity error
    is 0, so the command is the acceleration feed-forward a Ms Lb / (2 pi kt) alone (from the third
    position tick on, when the reference history is filled).
    """
    acc, mass = 2.0, 600.0
    m = mcu(x_velocity_feedforward=1.0, x_acceleration_feedforward=1.0, x_mass=mass)
    for j in range(1, 30):
        t = j * TP
        r = 0.5 * acc * t * t
        m.set("x_ref", r)
        m.set("x_position", r)
        m.set("x_velocity", acc * (t - TP / 2))
        m.do_step((j - 1) * TP, TP)
        if j >= 3:
            np.testing.assert_allclose(m.get("x_velocity_cmd"), acc * (t - TP / 2), rtol=1e-9)
            np.testing.assert_allclose(m.get("x_current_cmd"), acc * mass / KF, rtol=1e-6)


def test_batch_members_are_independent():
    gains = dict(x_position_gain=[30.0, 50.0, 70.0], x_velocity_p_scale=[0.8, 1.0, 1.3])
    b = mcu(batch=3, **gains)
    singles = [mcu(x_position_gain=g, x_velocity_p_scale=s) for g, s in zip(*gains.values())]
    rng = np.random.default_rng(3)
    for k in range(40):
        ref, vel = rng.normal(scale=1e-4, size=3), rng.normal(scale=1e-3, size=3)
        b.set("x_ref", ref)
        b.set("x_velocity", vel)
        b.do_step(k * TV, TV)
        for i, s in enumerate(singles):
            s.set("x_ref", ref[i])
            s.set("x_velocity", vel[i])
            s.do_step(k * TV, TV)
            np.testing.assert_allclose(b.get("x_current_cmd")[i], s.get("x_current_cmd")[0], rtol=1e-14, atol=1e-15)


def test_reset_restores_the_initial_state():
    m = mcu()
    m.set("x_ref", 1e-3)
    m.do_step(0.0, TP)
    first = m.get("x_current_cmd")
    m.reset()
    m.setup(0.0)
    assert m.get("x_current_cmd")[0] == 0.0
    m.set("x_ref", 1e-3)
    m.do_step(0.0, TP)
    np.testing.assert_array_equal(m.get("x_current_cmd"), first)
