"""Diagnosis of a servo logger's file: no ``line``, no commanded positions, no forces, a clock of its own.

A FANUC Servo Guide style log has the actual positions and the current commands only, starts when the
logger starts, and is quantised to the encoder's resolution. The twin's own run of a cutting program,
shifted by a known 2.5 s and reduced to such a log, must be aligned to the known shift, and the replayed
drives must carry the cutting load that the machine's drives carried (the twin's predicted forces). With
nothing but the logger's clock, quantisation and noise between the log and the twin, the diagnosis names no
effect.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from orchestrator.case import load_case
from orchestrator.diagnose import diagnose
from orchestrator.diagnose.align import recorded_quantum
from orchestrator.diagnose.prepare import prepare
from orchestrator.diagnose.refit import MIN_MASS_FRACTION, Parameter, _bounds
from orchestrator.machine import load_machine
from orchestrator.master import Master, MasterSettings, Probe
from orchestrator.recording import Recording
from orchestrator.simulate import simulate
from orchestrator.twin import build_twin

SHIFT_S = 2.5
PROGRAM = """G21 G17 G90 G94 G54
S6000 M3
G0 X-5. Y6. Z1.
G1 Z-1.5 F200
X14. F400
Y10.
X-5.
G0 Z5.
M30
"""
PAPER_PART = Path(__file__).resolve().parents[1] / "models" / "examples" / "paper_part"


@pytest.fixture(scope="module")
def logger_case(tmp_path_factory):
    folder = tmp_path_factory.mktemp("servo_log")
    (folder / "program.nc").write_text(PROGRAM)
    # the paper part's stock, tool and machine, with this program and a recording
    (folder / "case.toml").write_text('recording = "recording.csv"\n' + (PAPER_PART / "case.toml").read_text())
    twin = simulate(case=folder, plot=False).recording
    rng = np.random.default_rng(11)
    idx = np.arange(0, len(twin), 2)                       # a 2 ms logger
    channels = {"t_s": twin.t[idx] + SHIFT_S}
    for a in "xyz":
        channels[f"{a}_mm"] = np.round(twin[f"{a}_mm"][idx] * 1e3) / 1e3    # 1 µm encoder
        channels[f"{a}_tcmd_A"] = twin[f"{a}_tcmd_A"][idx] + rng.normal(0.0, 0.01, idx.size)
    Recording.from_channels(channels).write_csv(folder / "recording.csv")
    return folder, twin


def test_logger_clock_is_found_from_actual_positions(logger_case):
    # the actual positions lag the commands by the following error (about 1/Kp, ~17 ms here); correlating
    # them with the twin's commands gave that lag as a clock offset, so they are compared with the twin's
    # actual positions and refined: the known shift comes back to within a quarter of a servo tick
    folder, _ = logger_case
    case = load_case(folder)
    prep = prepare(case, Recording.read_csv(case.recording), case.machine)
    assert "with the twin's position" in prep.offset_method
    assert prep.offset == pytest.approx(SHIFT_S, abs=0.25e-3)


def test_drives_carry_the_predicted_cutting_load_when_no_force_is_recorded(logger_case):
    folder, twin = logger_case
    case = load_case(folder)
    prep = prepare(case, Recording.read_csv(case.recording), case.machine)
    assert prep.forces_source == "predicted"
    # on the logger clock, the load is what the twin's drives carried at program time t - offset: the input
    # disturbance_force of each drive, recorded at the end of the step over which it acted
    model = build_twin(case, batch=1)
    probes = [Probe(f"{a}_load", f"{a}_drive.disturbance_force", "N") for a in "xy"]
    settings = MasterSettings(step=model.options.step, time_limit=60.0, stop_when=model.stop_when)
    carried = Master(model.system, settings, probes).run().recording
    t_end = np.asarray(carried.t[1:], float)
    mid = t_end - 0.5 * model.options.step                     # inside the step that ends at t_end
    for a in "xy":
        np.testing.assert_array_equal(prep.disturbance[a](mid + prep.offset), np.asarray(carried[f"{a}_load"])[1:])
    assert np.max(np.abs(twin["fx_N"])) > 10.0             # the slot is cut: there is a load to carry


def test_the_twins_own_run_as_a_servo_log_has_no_effect(logger_case):
    # Y stands loaded by the X slots' cutting force, its held current winding up, and creeps by stick-slip
    # (slips of a few hundred nanometres) where the replay and the "machine" need not slip alike: those
    # holds are artefacts. Before, the difference after the replay's creep read as a 200 N Coulomb change.
    folder, _ = logger_case
    result = diagnose(folder)
    assert result.effects == []
    assert result.alignment["time_offset_s"] == pytest.approx(SHIFT_S, abs=0.25e-3)


def test_an_uneven_sparse_log_replays_the_twins_commands_at_the_servo_ticks(logger_case, tmp_path):
    # a random quarter of the 1 ms samples (4 ms on average, gaps of tens of ms): the twin's commands,
    # sampled at those instants and interpolated back to the servo ticks, were off by microns on every
    # move (157 µm at most on a rapid), which read as a feed-forward. Replayed from the twin's own 1 ms
    # interpolation, the residual of the twin's own run is the encoder's quantisation noise, q / sqrt(12).
    from orchestrator.diagnose.model import simulate as replay

    folder, twin = logger_case
    rng = np.random.default_rng(4)
    idx = np.sort(rng.choice(len(twin), len(twin) // 4, replace=False))
    channels = {"t_s": twin.t[idx] + SHIFT_S}
    for a in "xyz":
        channels[f"{a}_mm"] = np.round(twin[f"{a}_mm"][idx] * 1e3) / 1e3
        channels[f"{a}_tcmd_A"] = twin[f"{a}_tcmd_A"][idx]
    sparse = tmp_path / "sparse"
    sparse.mkdir()
    for name in ("program.nc", "case.toml"):
        (sparse / name).write_text((folder / name).read_text())
    Recording.from_channels(channels).write_csv(sparse / "recording.csv")
    case = load_case(sparse)
    prep = prepare(case, Recording.read_csv(case.recording), case.machine)
    assert not any(prep.ref_recorded.values())
    sim = replay(prep.machine, prep.t, prep.commands, [{}], prep.t_start, twin=prep.twin_commands(),
                 disturbance=prep.disturbance)
    for a in prep.axes:
        r = (prep.fe[a] - sim.fe[a][:, 0])[prep.valid]
        assert np.sqrt(np.mean((r - np.median(r)) ** 2)) < 0.4, a   # 1 µm / sqrt(12) = 0.29 µm


def _servo_log(tmp_path: Path, machine: Callable[[str], str]) -> Path:
    """A case whose recording is the servo log (2 ms, 1 µm, 10 mA, clock + 2.5 s) of the short part run on the
    default machine changed by ``machine(text) -> text``; the case itself names the default machine."""
    models = Path(__file__).resolve().parents[1] / "models" / "machines"
    (tmp_path / "truth.toml").write_text(machine((models / "default.toml").read_text()))
    case_text = (PAPER_PART / "case.toml").read_text()
    for name, parameters in (("machine", (tmp_path / "truth.toml").as_posix()), ("log", "default")):
        (tmp_path / name).mkdir()
        (tmp_path / name / "program.nc").write_text(PROGRAM)
        (tmp_path / name / "case.toml").write_text(
            'recording = "recording.csv"\n' + case_text.replace('parameters = "default"', f'parameters = "{parameters}"'))
    run = simulate(case=tmp_path / "machine", plot=False).recording
    rng = np.random.default_rng(7)
    idx = np.arange(0, len(run), 2)
    channels = {"t_s": run.t[idx] + SHIFT_S}
    for a in "xyz":
        channels[f"{a}_mm"] = np.round(run[f"{a}_mm"][idx] * 1e3) / 1e3
        channels[f"{a}_tcmd_A"] = run[f"{a}_tcmd_A"][idx] + rng.normal(0.0, 0.01, idx.size)
    Recording.from_channels(channels).write_csv(tmp_path / "log" / "recording.csv")
    return tmp_path / "log"


def _x_friction_plus_100_N(text: str) -> str:
    for old, new in (("coulomb_N = { value = 641.6,", "coulomb_N = { value = 741.6,"),
                     ("coulomb_N = { value = 661.9,", "coulomb_N = { value = 761.9,"),
                     ("static_N = { value = 775.2,", "static_N = { value = 875.2,"),
                     ("static_N = { value = 756.8,", "static_N = { value = 856.8,")):
        assert text.count(old) == 1
        text = text.replace(old, new)
    return text


def _x_feedforward_0_3(text: str) -> str:
    head, sep, rest = text.partition("[axis.x]")
    old = "velocity_feedforward = { value = 0.0,"
    assert sep and old in rest.split("[axis.y]")[0]
    return head + sep + rest.replace(old, "velocity_feedforward = { value = 0.3,", 1)


def _y_servo_delay_1_ms(text: str) -> str:
    assert "[axis.y.effects]" not in text
    return text + '\n[axis.y.effects]\nservo_delay_ms = { value = 1.0, source = "test" }\n'


@pytest.mark.parametrize("machine,effect,parameter,value", [
    # the X current steps by 100 N / (kt 2 pi / lead) = 0.19 A with the sign of the velocity
    (_x_friction_plus_100_N, "friction_mismatch", "coulomb_N", 100.0),
    # X lags 0.3/Kp = 6 ms less: no clock shift fits it, so it must not pull the clock of y and z (it did,
    # by 0.13 ms, and five false effects on all three axes followed)
    (_x_feedforward_0_3, "velocity_feedforward", "gain", 0.3),
])
def test_a_servo_log_of_a_machine_with_one_difference_names_exactly_it(tmp_path, machine, effect, parameter, value):
    # the "machine" differs from the parameter set in one X property; its servo log (2 ms, 1 µm, 10 mA, no
    # commands, no line, no forces, its own clock) must name exactly that, with its value
    result = diagnose(_servo_log(tmp_path, machine))
    assert [(e["effect"], e["axis"]) for e in result.effects] == [(effect, "x")]
    assert result.effects[0]["parameters"][parameter] == pytest.approx(value, rel=0.05)


def _same_machine(text: str) -> str:
    return text


def _scale_current(log: Path, axis: str, scale: float) -> None:
    """Rewrite the log's ``{axis}_tcmd_A`` as a logger with a scale error would have written it."""
    rec = Recording.read_csv(log / "recording.csv")
    channels = {n: np.asarray(rec[n], float) for n in rec.channels}
    channels[f"{axis}_tcmd_A"] = channels[f"{axis}_tcmd_A"] * scale
    Recording.from_channels(channels).write_csv(log / "recording.csv")


@pytest.mark.parametrize("machine,axis,scale,effects", [
    # recorded = 1.05 x true on X: as physics it read as a Coulomb change of 36 N, a servo delay and a
    # feed-forward; on Z (0.95) as four effects. A scale error of a channel is a recording artefact
    (_same_machine, "x", 1.05, []),
    (_same_machine, "z", 0.95, []),
    # with a real difference as well, both are found: the scale and the 100 N of friction
    (_x_friction_plus_100_N, "x", 1.05, [("friction_mismatch", "x", "coulomb_N", 100.0)]),
])
def test_a_current_logged_with_a_scale_error_is_corrected_in_the_alignment(tmp_path, machine, axis, scale, effects):
    log = _servo_log(tmp_path, machine)
    _scale_current(log, axis, scale)
    result = diagnose(log)
    assert [(e["effect"], e["axis"]) for e in result.effects] == [(e, a) for e, a, _, _ in effects], result.log
    for (_, _, parameter, value), found in zip(effects, result.effects):
        assert found["parameters"][parameter] == pytest.approx(value, rel=0.05)
    channels = result.alignment["channels"]
    assert channels[f"{axis}_tcmd_A"]["scale"] == pytest.approx(scale, abs=0.005)
    assert all(channels[f"{a}_tcmd_A"]["scale"] == 1.0 for a in "xyz" if a != axis)


def test_a_servo_delay_on_a_mostly_held_axis_is_named_alone(tmp_path):
    # y stands loaded through both X slots and moves once (4 mm): a 1 ms delay in its loop shows only in that
    # move's answer to the 200 Hz tooth load, far from linear in the delay. The held rows are left out and
    # a delay column linearised over 1 ms is a candidate. The replays carry the load as the twin's drives
    # do (a step mean): with the 1 ms samples of the instantaneous force instead, the delay came out as
    # 1.04 ms and a false y feed-forward of 0.067 followed
    result = diagnose(_servo_log(tmp_path, _y_servo_delay_1_ms))
    assert [(e["effect"], e["axis"]) for e in result.effects] == [("servo_delay", "y")], result.log
    assert result.effects[0]["parameters"]["delay_ms"] == pytest.approx(1.0, rel=0.01)


def test_recorded_quantum_is_the_encoder_step_and_zero_for_smooth_channels():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(0.0, 0.01, 500))
    np.testing.assert_allclose(recorded_quantum(np.round(x * 1e3) / 1e3), 1e-3, rtol=1e-9)
    np.testing.assert_allclose(recorded_quantum(np.round(x / 0.5e-3) * 0.5e-3), 0.5e-3, rtol=1e-9)
    assert recorded_quantum(x) == 0.0
    assert recorded_quantum(np.array([0.0, 1.0, 50.0])) == 0.0     # a few positions say nothing about a grid


def test_refit_keeps_the_moving_mass_positive():
    # a mass difference below -(1 - 0.1) x the parameter set's mass would make the replay's mass <= 0
    class _Prep:
        machine = load_machine("default")

    lo, hi = _bounds(_Prep(), Parameter("x", "inertia_mismatch", "mass_kg"))
    mass = float(_Prep.machine.values["axis"]["x"]["mass_kg"])
    assert lo == pytest.approx(-(1.0 - MIN_MASS_FRACTION) * mass) and mass + lo > 0.0
    assert hi > 0.0


def test_block_transitions_bracket_the_logger_offset():
    # the twin's NC changes line at 1 ms ticks; a 2.3 ms logger with jitter sees each change between two of
    # its samples. Every matched change brackets the offset, and 40 changes at varied phases pin it to far
    # below the logger's period (the midpoints' median is only good to about half a period).
    from orchestrator.diagnose.align import time_offset_from_lines

    rng = np.random.default_rng(5)
    t_nc = np.arange(0.0, 20.0, 1e-3)
    changes = np.sort(rng.choice(np.arange(100, t_nc.size - 100), 40, replace=False))
    line_nc = np.searchsorted(changes, np.arange(t_nc.size), side="right").astype(float) + 1.0
    offset = 1.2345
    t_rec = 0.5 + np.arange(0.0, 19.0, 2.3e-3) + rng.uniform(0.0, 0.2e-3, int(np.ceil(19.0 / 2.3e-3)))
    line_rec = line_nc[np.clip(np.searchsorted(t_nc, t_rec - offset, side="right") - 1, 0, t_nc.size - 1)]
    found, matched = time_offset_from_lines(t_rec, line_rec, t_nc, line_nc)
    assert matched >= 35
    assert found == pytest.approx(offset, abs=0.1e-3)


def test_a_few_block_changes_a_tick_off_the_twin_are_outvoted():
    # the same 2.3 ms logger, but the controller changes 5 of its 40 blocks one 1 ms tick later than the
    # twin (a block that waits for in-position, say). Their brackets lie 1 ms off the others', so the
    # brackets no longer share a point. The stretch most of them share is within 0.2 ms of the offset (a
    # late bracket can still tip the vote by a sliver), and on average it is far nearer than the median of
    # the midpoints (good only to about half the logger's period).
    from orchestrator.diagnose.align import consensus_bracket, offset_bracket_from_lines, time_offset_from_lines

    offset = 1.2345
    errors_consensus, errors_median, disjoint = [], [], 0
    for seed in range(5, 15):
        rng = np.random.default_rng(seed)
        t_nc = np.arange(0.0, 20.0, 1e-3)
        changes = np.sort(rng.choice(np.arange(100, t_nc.size - 100), 40, replace=False))
        line_nc = np.searchsorted(changes, np.arange(t_nc.size), side="right").astype(float) + 1.0
        late = changes.copy()
        late[rng.choice(40, 5, replace=False)] += 1                 # the controller's block changes
        line_ctrl = np.searchsorted(late, np.arange(t_nc.size), side="right").astype(float) + 1.0
        t_rec = 0.5 + np.arange(0.0, 19.0, 2.3e-3) + rng.uniform(0.0, 0.2e-3, int(np.ceil(19.0 / 2.3e-3)))
        line_rec = line_ctrl[np.clip(np.searchsorted(t_nc, t_rec - offset, side="right") - 1, 0, t_nc.size - 1)]
        lows, highs = offset_bracket_from_lines(t_rec, line_rec, t_nc, line_nc)
        disjoint += int(lows.max() > highs.min())                   # no offset inside every bracket
        lo, hi = consensus_bracket(lows, highs)
        found, matched = time_offset_from_lines(t_rec, line_rec, t_nc, line_nc)
        assert matched >= 30 and found == pytest.approx(0.5 * (lo + hi))
        assert found == pytest.approx(offset, abs=0.2e-3)
        errors_consensus.append(abs(found - offset))
        errors_median.append(abs(np.median(0.5 * (lows + highs)) - offset))
    assert disjoint >= 5
    assert np.mean(errors_consensus) < 0.5 * np.mean(errors_median)
    # without a 75 % majority there is no consensus: the brackets say nothing common
    assert consensus_bracket(np.array([0.0, 1.0, 2.0]), np.array([0.5, 1.5, 2.5])) is None


def test_an_axis_whose_lag_differs_does_not_pull_the_clock_of_the_others():
    # three axes moving at different times; the logger's clock is 2.5 s. The x of the "machine" lags its
    # twin 6 ms less (a feed-forward of 0.3 at Kp 50/s): no shift within +-5 ms fits it. Refined jointly it
    # pulls the clock off; refined per axis it is left out and the others give the clock.
    from orchestrator.diagnose.align import refine_offset, refine_offset_by_axes

    t_nc = np.arange(0.0, 6.0, 1e-3)

    def move(t, start):
        return 5.0 * np.clip((t - start) / 0.5, 0.0, 1.0) ** 2 * (3.0 - 2.0 * np.clip((t - start) / 0.5, 0.0, 1.0))

    starts = {"x": 1.0, "y": 2.5, "z": 4.0}
    nc = {a: move(t_nc, s) for a, s in starts.items()}
    t_rec = 2.5 + np.arange(0.2, 5.8, 2e-3)
    lag = {"x": -6e-3, "y": 0.0, "z": 0.0}
    rec = {a: np.round(move(t_rec - 2.5 - lag[a], s) * 1e3) / 1e3 for a, s in starts.items()}
    joint = refine_offset(t_rec, rec, t_nc, nc, 2.5)
    assert abs(joint - 2.5) > 0.1e-3                                   # pulled by x
    found, used = refine_offset_by_axes(t_rec, rec, t_nc, nc, 2.5)
    assert used == ["y", "z"]
    assert found == pytest.approx(2.5, abs=5e-6)
    # an x that a shift fits only roughly (0.8 ms more lag and 0.5 % more travel, as a compliance might
    # give): its own best shift is inside the span, but its residual is large and smooth, so its clock is
    # uncertain (it agrees with y and z within its standard error) and it gets little weight
    rec["x"] = np.round(1.005 * move(t_rec - 2.5 - 0.8e-3, starts["x"]) * 1e3) / 1e3
    assert abs(refine_offset(t_rec, rec, t_nc, nc, 2.5) - 2.5) > 20e-6                  # pulled by x
    found, used = refine_offset_by_axes(t_rec, rec, t_nc, nc, 2.5)
    assert used == ["x", "y", "z"]
    assert found == pytest.approx(2.5, abs=5e-6)
    # an x whose lag differs by 50 µs only, a shift fitting it exactly (a small feed-forward): inside the span
    # and with as small a residual as y and z, so weighting alone pulled the clock by about a third of that
    rec["x"] = np.round(move(t_rec - 2.5 + 50e-6, starts["x"]) * 1e3) / 1e3
    found, used = refine_offset_by_axes(t_rec, rec, t_nc, nc, 2.5)
    assert used == ["y", "z"]
    assert found == pytest.approx(2.5, abs=5e-6)


def test_axes_agree_on_a_clock_within_their_standard_errors():
    # the largest group agreeing pairwise within 4 standard errors, when it is the only one; else all axes
    from orchestrator.diagnose.align import agreeing_axes

    us = 1e-6
    assert agreeing_axes({"x": (0.0, us), "y": (3 * us, us), "z": (-2 * us, us)}) == ["x", "y", "z"]
    assert agreeing_axes({"x": (1000 * us, us), "y": (0.0, us), "z": (1 * us, us)}) == ["y", "z"]
    # two axes that disagree, or a chain (x~y, y~z, x!~z): which one is off cannot be told
    assert agreeing_axes({"x": (100 * us, us), "y": (0.0, us)}) == ["x", "y"]
    assert agreeing_axes({"x": (0.0, us), "y": (5 * us, us), "z": (10 * us, us)}) == ["x", "y", "z"]


def test_a_start_offset_beyond_the_span_is_re_centred():
    # the coarse clock handed to the refinement is 8 ms off (beyond its +-5 ms): every axis found its best shift
    # at the span's edge, and that edge was returned. The search is re-centred and the clock found.
    from orchestrator.diagnose.align import MAX_RECENTRES, refine_offset_by_axes

    def move(t):
        s = np.clip((t - 1.0) / 0.5, 0.0, 1.0)
        return 5.0 * s ** 2 * (3.0 - 2.0 * s)

    t_nc = np.arange(0.0, 3.0, 1e-3)
    nc = {"x": move(t_nc)}
    t_rec = 2.5 + np.arange(0.2, 2.8, 2e-3)
    rec = {"x": np.round(move(t_rec - 2.5) * 1e3) / 1e3}
    found, used = refine_offset_by_axes(t_rec, rec, t_nc, nc, 2.5 + 8e-3)
    assert used == ["x"] and found == pytest.approx(2.5, abs=5e-6)
    # a clock farther than the re-centred spans reach is not searched for: the last edge is returned
    reach = (1 + MAX_RECENTRES) * 5e-3
    found, _ = refine_offset_by_axes(t_rec, rec, t_nc, nc, 2.5 + reach + 4e-3)
    assert found == pytest.approx(2.5 + 4e-3, abs=0.1e-3)


def test_the_least_squares_lag_is_the_brute_force_one_and_unbiased_on_a_cut_window():
    # a window of a signal that does not vanish at the window's ends (a log cut into a move): the correlation
    # peak is pulled towards the lag that puts more of the signal's energy inside the window, the least-squares
    # lag is the true one; both against numpy's direct sums at every lag
    from orchestrator.diagnose.correlate import correlation_peak, least_squares_lag

    t = np.arange(0.0, 6.0, 1e-3)

    def ramp(t0: float) -> np.ndarray:
        return np.clip((t - t0) / 0.2, 0.0, 1.0)

    a = ramp(1.0) - ramp(2.0) + 2.0 * (ramp(3.0) - ramp(4.5))     # a velocity: plateaus of 1 and 2
    true = 3500                                                   # a window starting in the second plateau
    v = a[true:true + 1500] + np.random.default_rng(1).normal(0.0, 0.01, 1500)
    corr = np.correlate(a, v, mode="full")
    lags = np.arange(corr.size) - (v.size - 1)
    energy = np.array([np.sum(a[max(0, g):min(a.size, g + v.size)] ** 2) for g in lags])
    cost = energy - 2.0 * corr
    i, c_m, c_0, c_p = least_squares_lag(a, v)
    assert i == int(np.argmin(cost)) and lags[i] == true
    np.testing.assert_allclose([c_m, c_0, c_p], cost[i - 1:i + 2], rtol=1e-12)
    j, _, _, _ = correlation_peak(a, v)
    assert abs(lags[j] - true) > 100                               # the correlation peak is 0.27 s off here


def test_the_correlation_peak_is_numpys_full_correlation_peak_bit_for_bit():
    # the offset search's cross-correlation by FFT must give np.correlate's argmax and the three values
    # around it exactly (the reference implementation), for both length orders and a flat-topped peak
    from orchestrator.diagnose.correlate import correlation_peak

    rng = np.random.default_rng(9)
    for n, m in ((4000, 2500), (1500, 3100), (64, 64)):
        a = np.cumsum(rng.normal(size=n))
        v = np.cumsum(rng.normal(size=m))
        for x, y in ((a - a.mean(), v - v.mean()), (np.ones(n), np.ones(m))):
            c = np.correlate(x, y, mode="full")
            i = int(np.argmax(c))
            j, c_m, c_0, c_p = correlation_peak(x, y)
            assert j == i and c_0 == c[i]
            assert c_m == (c[i - 1] if i > 0 else c_m) and c_p == (c[i + 1] if i + 1 < c.size else c_p)


def test_residual_autocorrelation_is_the_lag_1_correlation_and_0_for_an_exact_fit():
    # an AR(1) residual r_k = 0.5 r_(k-1) + e_k has lag-1 correlation 0.5; an exact fit (r = 0) has none (the
    # confidence intervals of a refit with it were NaN); a trend is clipped at 0.98
    from orchestrator.diagnose.align import residual_autocorrelation

    rng = np.random.default_rng(2)
    e = rng.normal(size=200_000)
    r = np.zeros_like(e)
    for k in range(1, e.size):
        r[k] = 0.5 * r[k - 1] + e[k]
    assert residual_autocorrelation(r) == pytest.approx(0.5, abs=0.01)
    assert residual_autocorrelation(np.zeros(50)) == 0.0
    assert residual_autocorrelation(np.arange(50.0)) == 0.98
    assert residual_autocorrelation(-r) == pytest.approx(0.5, abs=0.01)
