"""The member-vectorised servo prototype (orchestrator.bench.simd) agrees with the scalar fused reference.

* ``exp_poly`` (range reduction, Taylor polynomial to r^13, exponent bits) against ``math.exp``: a few ulp.
* ``simd_servo_loop`` against ``fused_servo_loop`` on the bench part with cutting (moves, reversals, axes
  at rest): the only differences are rounding (``exp_poly`` for libm's ``exp``, ``sqrt`` for ``hypot``), so
  positions and current commands agree far inside 1e-9 of their range. The members get distinct table
  masses, so a member mixed up with another would show.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from orchestrator.bench.fused import prepare_fused, reference_run
from orchestrator.bench.native import bench_case
from orchestrator.bench.simd import exp_poly, run_simd

N = 3500  # the bench program starts cutting at about 1.5 s
B = 9  # not a multiple of the vector width: the loops' remainders run too


def test_exp_poly_within_a_few_ulp():
    rng = np.random.default_rng(7)
    xs = np.concatenate([rng.uniform(-708.0, 709.0, 2000), rng.uniform(-1.0, 1.0, 2000),
                         [0.0, -0.0, 1.0, -1.0, math.log(2.0), -math.log(2.0) / 2, 700.0, -700.0]])
    for x in xs:
        exact = math.exp(x)
        assert abs(exp_poly(x) - exact) <= 4 * math.ulp(exact), x
    assert exp_poly(0.0) == 1.0


@pytest.fixture(scope="module")
def problem():
    case = bench_case()
    ref = reference_run(case, N)
    assert np.abs(ref[1]).max() > 10.0  # the window includes cutting
    base = prepare_fused(case, N, batch=B, reference=ref)
    state = list(base._state0)  # noqa: SLF001
    params = np.array(state[3], copy=True)
    params[:, 1, :] *= np.linspace(0.8, 1.2, B)  # 1 / table mass per member: distinct dynamics
    state[3] = params
    return dataclasses.replace(base, _state0=tuple(state))


def test_simd_matches_scalar_fused(problem):
    ref_pos, ref_cur = problem.run()
    pos, cur, scalar = run_simd(problem)
    n_ticks = problem._scalars[0]  # noqa: SLF001
    fraction = scalar / (N * n_ticks * 3 * B)
    assert 0.0 < fraction < 0.05  # transitions went to the scalar step, the bulk to the vector path
    assert np.abs(pos - ref_pos).max() <= 1e-9 * np.ptp(ref_pos)
    assert np.abs(cur - ref_cur).max() <= 1e-9 * np.ptp(ref_cur)
    assert np.abs(ref_pos[:, :, 0] - ref_pos[:, :, -1]).max() > 1e-7  # the members do differ
