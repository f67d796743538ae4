"""The members-innermost MCU and drive steps of the compiled loop give the scalar per-member results, bit for bit.

``mcu_rows`` against ``axis_member`` + ``axis_alarm`` (the loop's member-by-member MCU branch) and
``exponential_rows`` against ``exponential_member``, on seeded random states that reach every branch: the
position-loop tick, saturation and anti-windup, an excess-error alarm; sliding in both directions, stick, break-away,
reversal, a large correction, ``|J h| > 0.2``, a frozen (NaN) member and a step of two substeps.
"""
from __future__ import annotations

import numpy as np
import pytest

from fmus_src.servo.control_numba import axis_alarm, axis_member
from fmus_src.servo.control_rows import mcu_rows
from fmus_src.servo.exponential_numba import exponential_member
from fmus_src.servo.exponential_rows import ROWS_WORK, exponential_rows
from orchestrator.compiled.loop import DRIVE_ROWS, MCU_ROWS


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal bit for bit (NaN where NaN, signed zeros kept)."""
    return np.array_equal(np.asarray(a, dtype=np.float64).view(np.int64),
                          np.asarray(b, dtype=np.float64).view(np.int64))


def _drive_case(rng: np.random.Generator, batch: int) -> tuple:
    params = np.empty((12, batch))
    params[0] = rng.uniform(50.0, 150.0, batch)     # N/A
    params[1] = 1.0 / rng.uniform(50.0, 300.0, batch)  # 1/kg
    for off in (2, 7):
        params[off] = rng.uniform(20.0, 60.0, batch)            # Coulomb, N
        params[off + 1] = rng.uniform(5.0, 30.0, batch)         # Stribeck excess, N
        params[off + 2] = 1.0 / rng.uniform(1e-4, 2e-3, batch)  # 1 / Stribeck velocity, s/m
        params[off + 3] = rng.uniform(50.0, 500.0, batch)       # viscous, N s/m
        params[off + 4] = params[off] + params[off + 1]          # static, N
    velocity = rng.uniform(-0.05, 0.05, batch)
    direction = np.sign(velocity).astype(np.int8)
    kind = np.arange(batch) % 8
    velocity[kind == 1] = 0.0                      # at rest (stick or break-away with the force below)
    direction[kind == 1] = 0
    velocity[kind == 2] = -0.0
    direction[kind == 2] = rng.choice([-1, 0, 1], (kind == 2).sum()).astype(np.int8)
    velocity[kind == 3] = 1e-7 * np.sign(velocity[kind == 3] + 1e-30)  # a reversal within the step
    params[5, kind == 4] = 5e5                     # |J h| above 0.2 (expm1 branch)
    params[10, kind == 4] = 5e5
    position = rng.uniform(-0.1, 0.1, batch)
    position[kind == 5] = np.nan                   # a frozen member
    velocity[kind == 6] = np.nan                   # a NaN velocity on a live member
    current = rng.uniform(-3.0, 3.0, batch)
    current[kind == 7] = rng.uniform(-30.0, 30.0, (kind == 7).sum())  # large forces: large corrections
    disturbance = rng.uniform(-50.0, 50.0, batch)
    return params, position, velocity, direction, current, disturbance


@pytest.mark.parametrize("h", [250e-6, 500e-6, 125e-6])
def test_exponential_rows_is_exponential_member_bit_for_bit(h):
    rng = np.random.default_rng(7)
    batch = 203
    params, position, velocity, direction, current, disturbance = _drive_case(rng, batch)
    max_step = np.full(batch, 125e-6)
    base = 1
    V = np.full((base + len(DRIVE_ROWS) + 1, batch), -7.0)
    pos, vel, dirn = position.copy(), velocity.copy(), direction.copy()
    status = np.full(batch, 99, dtype=np.int8)
    work = np.full((ROWS_WORK, batch), np.nan)
    memo = np.full((2, batch), np.nan)
    x, v, d = position.copy(), velocity.copy(), direction.astype(float)
    for step in range(3):  # consecutive steps: the later ones take the friction exp kept in memo
        V[base] = current * (1.0 + 0.01 * step)
        V[base + 1] = disturbance
        first = exponential_rows(V, base, params, pos, vel, dirn, h, max_step, status, work, memo)
        expected = np.array([exponential_member(V[base, b], disturbance[b], *params[:, b], x[b], v[b], d[b], h,
                                                max_step[b]) for b in range(batch)])
        u, x_new, v_new, d_new, ff, code = expected.T
        for row, want in (("motor_force", u), ("position", x_new), ("velocity", v_new), ("friction_force", ff)):
            assert _same(V[base + DRIVE_ROWS.index(row)], want), (step, row)
        assert _same(pos, x_new) and _same(vel, v_new), step
        assert np.array_equal(dirn, d_new.astype(np.int8)) and np.array_equal(status, code.astype(np.int8))
        failed = np.flatnonzero(code != 0)
        assert first == (int(code[failed[0]]) if failed.size else 0)
        assert _same(V[0], np.full(batch, -7.0)) and _same(V[base + 6], np.full(batch, -7.0))  # rows untouched
        if step == 0:
            # every branch was reached: sliding both ways, stick, break-away, members for the scalar step
            assert (d_new > 0).any() and (d_new < 0).any() and ((d_new == 0) & (v_new == 0)).any()
            assert ((direction == 0) & (velocity == 0) & (d_new != 0)).any()
            if h == 250e-6:  # one substep: sliding (1) and stick (2) in the member loops, the rest (0) by
                assert set(np.unique(work[6])) == {0.0, 1.0, 2.0}  # exponential_member
        elif h == 250e-6:
            assert (memo[0] == memo[0]).sum() > batch // 10  # the friction exps kept for the next step
        x, v, d = x_new, v_new, d_new


@pytest.mark.parametrize("k0, n_ticks", [(0, 4), (3, 4), (5, 1), (8, 0)])
def test_mcu_rows_is_the_member_by_member_mcu_bit_for_bit(k0, n_ticks):
    rng = np.random.default_rng(11)
    batch = 37
    ratio, tp, tv = 4, 1e-3, 250e-6
    gains = np.empty((6, 3, batch))
    gains[0] = rng.uniform(20.0, 60.0, (3, batch))    # kp, 1/s
    gains[1] = rng.uniform(5.0, 50.0, (3, batch))     # kv, A s/m
    gains[2] = rng.uniform(50.0, 500.0, (3, batch))   # ki, 1/s
    gains[3] = rng.uniform(0.0, 1.0, (3, batch))      # velocity feed-forward
    gains[4] = rng.uniform(0.0, 0.1, (3, batch))      # acceleration feed-forward, A s^2/m
    gains[5] = rng.uniform(1.0, 5.0, (3, batch))      # current limit, A
    state = np.empty((7, 3, batch))
    state[0] = rng.uniform(-6.0, 6.0, (3, batch))     # integrators beyond the limit: anti-windup branches
    state[1:5] = rng.uniform(-0.01, 0.01, (4, 3, batch))
    state[5] = rng.uniform(-5.0, 5.0, (3, batch))
    state[6] = rng.integers(0, 500, (3, batch)).astype(float)
    base = 2
    V = np.full((base + len(MCU_ROWS), batch), -3.0)
    V[base:base + 3] = rng.uniform(-0.01, 0.01, (3, batch))
    V[base:base + 3, ::5] = state[3, :, ::5]          # reference unchanged: the still counter grows
    V[base + 3:base + 6] = V[base:base + 3] + rng.normal(0.0, 1e-4, (3, batch))
    V[base + 6:base + 9] = rng.uniform(-0.02, 0.02, (3, batch))
    width = rng.uniform(1e-5, 1e-4, batch)
    limits = np.empty((3, 3, batch))
    limits[0] = rng.uniform(5e-5, 5e-4, (3, batch))
    limits[1] = rng.uniform(5e-5, 5e-4, (3, batch))
    limits[2] = 100.0
    want_V, want_state = V.copy(), state.copy()
    want_alarm = np.zeros(batch, dtype=np.int8)
    for b in range(batch):  # the compiled loop's member-by-member MCU branch
        in_pos, code = True, 0
        for i in range(3):
            ref, pos, vel = want_V[base + i, b], want_V[base + 3 + i, b], want_V[base + 6 + i, b]
            cmd, v_cmd, still = axis_member(k0, n_ticks, ratio, tp, tv, tp * tp, gains, want_state, i, b, ref, pos,
                                            vel)
            want_V[base + 9 + i, b] = cmd
            want_V[base + 12 + i, b] = v_cmd
            err = abs(ref - pos)
            in_pos = in_pos and err <= width[b]
            if code == 0:
                code = axis_alarm(i, err, still, limits[0, i, b], limits[1, i, b], limits[2, i, b])
        want_V[base + 15, b] = 1.0 if in_pos else 0.0
        want_alarm[b] = code
    alarm = np.full(batch, 99, dtype=np.int8)
    n_alarm = mcu_rows(k0, n_ticks, ratio, tp, tv, tp * tp, gains, state, V, base, width, limits, alarm)
    assert _same(V, want_V) and _same(state, want_state)
    assert np.array_equal(alarm, want_alarm) and n_alarm == int((want_alarm != 0).sum())
    assert 0 < n_alarm < batch                       # alarms and quiet members both present
    if n_ticks:
        assert (np.abs(want_V[base + 9:base + 12]) == gains[5]).any()  # a saturated current command
