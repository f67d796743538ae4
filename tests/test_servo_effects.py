"""MCU effect terms: servo delay (pure delay of the current command), against the undelayed MCU."""
from __future__ import annotations

import numpy as np
import pytest

from fmus_src.servo import MCU, ServoError

TV = 250e-6


def drive_open_loop(m: MCU, n: int, seed: int = 3) -> np.ndarray:
    """Feed seeded random inputs tick by tick; return the published x current commands, shape (n + 1, B)."""
    rng = np.random.default_rng(seed)
    out = [m.get("x_current_cmd")]
    for k in range(n):
        m.set("x_ref", 1e-3 * np.sin(0.01 * k) + rng.normal(scale=1e-6))
        m.set("x_position", rng.normal(scale=1e-5))
        m.set("x_velocity", rng.normal(scale=1e-3))
        m.do_step(k * TV, TV)
        out.append(m.get("x_current_cmd"))
    return np.array(out)


@pytest.mark.parametrize("ticks", [1, 3])
def test_integer_delay_shifts_the_command(ticks):
    plain = MCU("a")
    plain.setup(0.0)
    delayed = MCU("b", x_servo_delay=ticks * TV)
    delayed.setup(0.0)
    a = drive_open_loop(plain, 200)
    b = drive_open_loop(delayed, 200)
    np.testing.assert_allclose(b[ticks:], a[:-ticks], rtol=0, atol=1e-12)
    assert np.all(b[:ticks] == a[0])


def test_fractional_delay_interpolates_linearly():
    plain = MCU("a")
    plain.setup(0.0)
    delayed = MCU("b", x_servo_delay=1.25 * TV)
    delayed.setup(0.0)
    a = drive_open_loop(plain, 100)
    b = drive_open_loop(delayed, 100)
    np.testing.assert_allclose(b[3:], 0.75 * a[2:-1] + 0.25 * a[1:-2], rtol=0, atol=1e-12)


def test_delay_per_member_and_compiled_equals_reference():
    delays = np.array([0.0, 2 * TV, 0.6e-3])
    outs = []
    for compiled in (True, False):
        m = MCU("m", batch=3, x_servo_delay=delays)
        m.use_compiled = compiled
        m.setup(0.0)
        outs.append(drive_open_loop(m, 120))
    np.testing.assert_array_equal(outs[0], outs[1])
    single = MCU("s", x_servo_delay=2 * TV)
    single.setup(0.0)
    np.testing.assert_array_equal(outs[0][:, 1], drive_open_loop(single, 120)[:, 0])


def test_negative_delay_is_refused():
    m = MCU("m", z_servo_delay=-1e-3)
    with pytest.raises(ServoError, match="servo_delay"):
        m.setup(0.0)
