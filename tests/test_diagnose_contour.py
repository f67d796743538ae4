"""Diagnosis of cases unlike the Z-stroke scorecard: effects on X and Y of an XY contour, loggers of 1 to 8 ms.

The recordings come from the independent truth simulation (:mod:`orchestrator.diagnose.truth`) of an air-cut
contour with arcs and reversals (:data:`orchestrator.diagnose.scorecard_contour.PROGRAM`), logged with a 1 µm
encoder, 0.3 µm / 0.02 A noise and a seeded clock offset, with or without ``line`` and the commands. Each test is
the worst finding of ``python -m orchestrator.diagnose.scorecard_contour`` before its fix.
"""
from __future__ import annotations

import pytest

from orchestrator.case import load_case
from orchestrator.diagnose import diagnose
from orchestrator.diagnose.prepare import twin_commands
from orchestrator.diagnose.scorecard_contour import CHANNELS, write_contour_case


@pytest.fixture(scope="module")
def contour(tmp_path_factory):
    """``make(axis, effects, period_s, channels) -> case folder``, sharing one twin run of the program."""
    root = tmp_path_factory.mktemp("contour")
    first = write_contour_case(root / "clean", "x", {}, 0, 8e-3, CHANNELS["servo guide"])
    case = load_case(first)
    nc = twin_commands(case, case.machine)

    def make(name: str, axis: str, effects: dict, period_s: float, channels: str, seed: int = 0):
        return write_contour_case(root / name, axis, effects, seed, period_s, CHANNELS[channels], nc=nc)

    return first, make


def _named(d) -> list[tuple[str, str]]:
    return [(e["effect"], e["axis"]) for e in d.effects]


def test_a_clean_servo_guide_log_at_8_ms_names_nothing(contour):
    first, _ = contour
    d = diagnose(first)
    assert d.effects == [], d.log


def test_a_feedforward_on_x_alone_does_not_pull_the_clock_of_y_and_z(contour):
    """X lags 1 ms less (0.05 / Kp): a shift fits it closely, inside the +-5 ms refinement, and weighted in,
    it moved the clock by 49 µs; inertia mismatches of 17-25 kg on all three axes followed, and the gain came
    out 0.040. The clock now rests on y and z, which agree on it."""
    _, make = contour
    d = diagnose(make("ff_x", "x", {"velocity_feedforward": {"gain": 0.05}}, 2e-3, "servo guide"))
    assert "refined on the positions of y, z" in d.log[0], d.log[0]
    assert _named(d) == [("velocity_feedforward", "x")], d.log
    assert d.effects[0]["parameters"]["gain"] == pytest.approx(0.05, rel=0.05)


def test_a_backlash_on_x_does_not_move_the_clock_within_the_line_bracket(contour):
    """With `line` but no commands, the clock was refined on all positions jointly within the transitions'
    bracket: a 3 µm X backlash moved it 11 µs, and inertia mismatches on X and Z followed."""
    _, make = contour
    d = diagnose(make("backlash_x", "x", {"backlash": {"width_um": 3.0}}, 4e-3, "line only"))
    assert _named(d) == [("backlash", "x")], d.log
    assert d.effects[0]["parameters"]["width_um"] == pytest.approx(3.0, rel=0.05)


@pytest.mark.parametrize("period_s, seed, was", [
    (1e-3, 0, "0.235 ms and a false z velocity_feedforward of 0.009"),
    (4e-3, 2, "0.221 ms and a false y inertia_mismatch of -32 kg"),
])
def test_a_servo_delay_between_whole_ticks_is_refitted_past_the_tick_kink(contour, period_s, seed, was):
    """A 0.3 ms delay on Y (1.2 velocity ticks), logged with commands: the selection's delay column is the
    response to one whole tick, the refit started below the kink at 0.25 ms and stopped in the local minimum
    there; another effect took up the rest (``was``). It now starts from a quarter-tick scan."""
    _, make = contour
    d = diagnose(make(f"delay_y_{seed}", "y", {"servo_delay": {"delay_ms": 0.3}}, period_s, "commands + line", seed))
    assert _named(d) == [("servo_delay", "y")], (was, d.log)
    assert d.effects[0]["parameters"]["delay_ms"] == pytest.approx(0.3, rel=0.02), was


def test_an_axis_held_at_its_breakaway_current_is_not_replayed_beyond_it(contour):
    """A Servo Guide log cut into the first X move: Z stands after its rapid down, its integrator wound to the
    static friction (-1418.9 N, -2.7099 A). The current estimated from the first noisy samples, -2.7156 A, lay
    beyond it: the replay broke away at once and slipped (0.69 A rms of Z current residual), and a Z reversal
    friction and a torque ripple were named next to the X feed-forward. The held current is now limited to what
    static friction holds."""
    import numpy as np

    from orchestrator.recording import Recording

    _, make = contour
    folder = make("ff_x_cut", "x", {"velocity_feedforward": {"gain": 0.05}}, 2e-3, "servo guide", seed=7)
    rec = Recording.read_csv(folder / "recording.csv")
    ch = {c: np.asarray(rec[c], float) for c in rec.channels}
    fast = np.flatnonzero(np.abs(np.gradient(ch["x_mm"], ch["t_s"])) * 60.0 > 1900.0)   # the F2000 X move
    start = int(fast[fast.size // 4])
    Recording.from_channels({c: v[start:] for c, v in ch.items()}).write_csv(folder / "recording.csv")
    d = diagnose(folder)
    assert _named(d) == [("velocity_feedforward", "x")], d.log
    assert d.rms_before["z_tcmd_A"] < 1.1 * d.noise["z_tcmd_A"]


def test_a_holding_current_is_limited_to_the_static_friction_band():
    # default Z: Fs 1418.8 N (+) / 1418.9 N (-), kf = kt 2 pi / lead = 2 pi / 0.012 m = 523.6 N/A; no load
    import math

    import numpy as np

    from orchestrator.identify.start_state import held_within_static_friction
    from orchestrator.machine import load_machine
    from orchestrator.twin import drive_parameters
    from fmus_src.servo import DriveAxis

    machine = load_machine("default")
    d = DriveAxis("z_drive", batch=2, **drive_parameters(machine, "z"))
    d.setup(0.0)
    kf = 2.0 * math.pi / 0.012
    np.testing.assert_allclose(held_within_static_friction(d, -2.7156), -1418.9 / kf, rtol=1e-8)
    np.testing.assert_allclose(held_within_static_friction(d, 3.0), 1418.8 / kf, rtol=1e-8)
    np.testing.assert_array_equal(held_within_static_friction(d, -1.0), [-1.0, -1.0])
    # a load resisting positive motion of 500 N shifts the band by 500 N / kf
    np.testing.assert_allclose(held_within_static_friction(d, 5.0, np.full(2, 500.0)), (500.0 + 1418.8) / kf,
                               rtol=1e-8)
