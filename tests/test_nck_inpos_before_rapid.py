"""In-position check before a rapid that follows cutting feed (FANUC): the wait on the modelled servo.

Hand calculations for a P position loop of gain Kv: at feed v the axis lags by e0 = v/Kv; once the reference
stops, the deviation decays as e0 exp(-Kv t) and is within the width w after t = ln(e0/w)/Kv.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.nck import NCKernel
from fmus_src.nck.servo_settle import servo_in_position

TS = 1e-3
V = 600.0 / 60e3  # F600, m/s
W = 0.02e-3  # in-position width (default.toml), m
# a reference that stops at once: no acc/dec before interpolation (a huge acceleration, no jerk time) and
# no filter after it, so the wait is the servo's decay alone
ABRUPT = dict(accel_before_interp=1e6, accel_change_time_before_interp=0.0, cutting_time_constant=0.0)


def plan(text: str, **params) -> NCKernel:
    k = NCKernel(program_text=text, **params)
    k.setup(0.0)
    return k


@pytest.mark.parametrize("kv", [50.0, 100.0])
def test_wait_is_the_decay_of_the_following_error_into_the_width(kv):
    # Kv 50/s: e0 = 0.2 mm, t = ln(10)/50 = 46.05 ms; Kv 100/s: e0 = 0.1 mm, t = ln(5)/100 = 16.09 ms. The
    # sampled loop lags by about half a period more (e0 + v Ts/2), so allow 2 periods.
    text = "G90 G1 X10. F600\nG0 X0\nM30\n"
    gains = dict(x_position_gain=kv, y_position_gain=kv, z_position_gain=kv)
    on = plan(text, **ABRUPT, **gains)
    off = plan(text, in_position_before_rapid=False, **ABRUPT, **gains)
    added = float(on.plan_.duration[0] - off.plan_.duration[0])
    assert added == pytest.approx(math.log(V / kv / W) / kv, abs=2 * TS)


def test_servo_model_decay_against_the_closed_form():
    # a reference that steps 1 mm in one period and rests: the loop samples the held r[0] = 0, so at row 1 the
    # whole step is still to go (e = 1 mm), then e decays by exp(-Kv Ts) a period: in position after
    # 1 + ceil(ln(1 mm / 20 um) / (50/s x 1 ms)) = 1 + ceil(78.24) = 80 periods
    kv = 50.0
    path = np.zeros((2, 3))
    path[1, 0] = 1e-3
    expected = 1 + math.ceil(math.log(1e-3 / W) / (kv * TS))
    assert expected == 80
    assert servo_in_position(path, path[-1], (kv, kv, kv), W, TS) == expected


def test_cutting_to_cutting_in_g64_has_no_wait_and_only_the_rapid_waits():
    # two G1 blocks with a feed change: one chain in G64, the second block starts at the same sample with the
    # check on or off; the whole plan differs only by the wait before the rapid
    text = "G90 G1 X10. F600\nX20. F1200\nG0 X0\nM30\n"
    on, off = plan(text), plan(text, in_position_before_rapid=False)
    line_on, line_off = on.plan_.line[0], off.plan_.line[0]
    second_on, second_off = int(np.argmax(line_on == 2)), int(np.argmax(line_off == 2))
    assert second_on == second_off > 0
    rapid_on, rapid_off = int(np.argmax(line_on == 3)), int(np.argmax(line_off == 3))
    assert rapid_on > rapid_off
    assert float(on.plan_.duration[0] - off.plan_.duration[0]) == pytest.approx((rapid_on - rapid_off) * TS)


def test_g81_reference_retracts_only_once_the_modelled_servo_is_at_the_bottom():
    # G81 Z-3 at F600 on the default kernel: a P loop (Kv 50/s, exact for a held reference) run here on the
    # planned Z reference is within the width of Z-3 when the rapid retract starts; with the check off it is
    # about 0.1 mm short (the lag of a decelerating ramp)
    text = "G90 G0 X0 Y0 Z5.\nG99 G81 X0 Y0 Z-3. R2. F600\nG80\nM30\n"
    deepest = {}
    for check in (True, False):
        k = plan(text, in_position_before_rapid=check)
        z = k.plan_.position[0, : int(k.plan_.length[0]), 2]
        a = math.exp(-50.0 * TS)
        y = np.empty_like(z)
        y[0] = z[0]
        for i in range(1, len(z)):
            y[i] = a * y[i - 1] + (1 - a) * z[i - 1]
        deepest[check] = float(y.min())
    assert deepest[True] <= -3e-3 + W
    assert deepest[False] > -3e-3 + 0.05e-3


def test_g82_dwell_longer_than_the_decay_adds_no_wait_and_g86_waits_before_its_rapid_out():
    # G82 P100: the dwell starts once the reference is in position and lasts 0.1 s, longer than the servo's decay
    # (at most ln(v/Kv / w)/Kv = ln(0.2 / 0.02)/50 = 46 ms at F600), so the retract starts at the same sample.
    # G86 (feed in, spindle stop, rapid out): the spindle stop takes no time in the plan, so the rapid out waits
    # for the servo, a wait of at most that 46 ms (+ the 16 ms filter) per hole.
    g82 = "G90 S1000 M3\nG0 X0 Y0 Z5.\nG99 G82 X0 Y0 Z-3. R2. P100 F600\nG80\nM30\n"
    assert plan(g82).duration_[0] == plan(g82, in_position_before_rapid=False).duration_[0]
    g86 = "G90 S1000 M3\nG0 X0 Y0 Z5.\nG99 G86 X0 Y0 Z-3. R2. F600\nG80\nM30\n"
    added = float(plan(g86).duration_[0] - plan(g86, in_position_before_rapid=False).duration_[0])
    assert 0.0 < added <= math.log(V / 50.0 / W) / 50.0 + 0.016 + 2 * TS


def test_machine_file_key_switches_the_check_and_names_the_line_of_a_bad_value(tmp_path):
    from orchestrator import MachineFileError, load_machine
    from orchestrator.twin import nck_parameters

    text = load_machine("default").path.read_text()
    key = 'in_position_before_rapid = { value = "on"'
    assert key in text
    assert nck_parameters(load_machine("default"))["in_position_before_rapid"] is True
    off = tmp_path / "off.toml"
    off.write_text(text.replace(key, 'in_position_before_rapid = { value = "off"'))
    assert nck_parameters(load_machine(off))["in_position_before_rapid"] is False
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace(key, 'in_position_before_rapid = { value = "yes"'))
    line = next(i for i, l in enumerate(bad.read_text().splitlines(), 1) if l.startswith("in_position_before_rapid"))
    with pytest.raises(MachineFileError, match=rf"bad.toml:{line}:.*in_position_before_rapid"):
        load_machine(bad)


def test_the_compiled_position_loop_is_scipys_first_order_filter_bit_for_bit():
    """``position_loop_response`` is ``lfilter([0, 1 - a], [1, -a], r)`` (scipy's own operations, in order)."""
    from scipy.signal import lfilter

    from fmus_src.nck.servo_settle import position_loop_response

    rng = np.random.default_rng(25)
    for kv in (1.0, 33.3, 50.0, 300.0):
        a = math.exp(-kv * TS)
        ramp = np.minimum(np.arange(2000) * 1e-5, 0.0123)  # a move to rest, m
        noisy = np.cumsum(rng.normal(0.0, 1e-5, 3000))
        for r in (ramp, noisy, np.zeros(1), -ramp):
            assert np.array_equal(position_loop_response(r, a), lfilter([0.0, 1.0 - a], [1.0, -a], r))
    # the recurrence by hand: y[0] = 0, y[k + 1] = a y[k] + (1 - a) r[k]
    y = position_loop_response(np.array([1.0, 1.0, 1.0]), 0.5)
    assert y.tolist() == [0.0, 0.5, 0.75]
