"""Fast NC planning (compiled kernels, segments shared across a batch) is bit-identical to the numpy reference.

``plan_batch(..., reference=True)`` / ``plan_member(..., reference=True)`` run the numpy specification only;
the default path must give the same bits in every array of every member: positions, feed, spindle reference
and speed, line, tool and done index. Programs: the bench part (40 of issue 9's variants), the paper part
with a GA-like population (F 100-500 mm/min, S 1000-8000 rpm per cutting line), and a program with arcs, a
helix, canned cycles, rigid tapping, a dwell, tool changes, G61, G9 and a G103 window, with random F/S per line.
"""
from __future__ import annotations

import numpy as np
import pytest

from fmus_src.nck import NCKernel
from fmus_src.nck.filters import apply_fir
from fmus_src.nck.numpy_ops import np_clip, np_maximum, np_minimum, np_sign
from fmus_src.nck.plan_assembly import fir, last_outside, sample_spindle_compiled
from fmus_src.nck.planner import plan_batch, plan_member
from fmus_src.nck.plan_reuse import PlanReuse
from fmus_src.nck.settings import MM, RPM
from fmus_src.nck.spindle import sample_spindle
from orchestrator.bench.native import BENCH_CASE, bench_case, variant_overrides
from orchestrator.bench.planning import PLAN_FIELDS, ga_population, planning_inputs, same_plan
from orchestrator.simulate import resolve_case

#: Source lines of the paper part's feed moves (N60-N210 without the rapids).
PAPER_LINES = [10, 11, 14, 15, 18, 19, 20, 21, 22, 23, 24, 25]

FEATURES = """%
O1003 (PLANNING FEATURES)
G21 G17 G90 G94 G40 G49
T1 M6
S3000 M3
G0 X0. Y0. Z5.
G1 Z-1. F200.
X10. F400.
G2 X20. Y10. R10.
G3 X10. Y20. I-10. J0.
G2 X10. Y20. Z-2. I0. J-5.
G61
G1 X0. Y20.
Y10.
G64
G9 G1 X5. Y5.
X8. Y2.
G103 P1
X10. Y0.
X12.
X14. Y1.
G103
G4 P500
G0 Z5.
G81 X30. Y30. Z-3. R2. F150.
X35.
G80
G83 X40. Y30. Z-5. R2. Q1. F120.
G80
T2 M6
M29 S500
G84 X50. Y30. Z-5. R2. F500.
G80
S2000 M3
G0 X20. Y20.
G1 Z-1. F300.
G2 X20. Y20. I5. J0. F350.
G0 Z50.
M5
M30
%
"""
#: FEATURES lines with an F word (not the tapping line) and the lines that get an S gene (5, 34: S words; the
#: others: inserted as the optimiser does, on cutting lines inside chains).
FEATURE_FEED_LINES = [7, 8, 25, 28, 36, 37]
FEATURE_SPINDLE_LINES = [5, 8, 13, 19, 34, 36]


def assert_same(a, b) -> None:
    """Every array of two batch plans holds the same bits."""
    for name in PLAN_FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert x.tobytes() == y.tobytes(), name
        assert np.array_equal(x, y), name
    assert same_plan(a, b)


def feature_inputs(batch: int, seed: int, **params) -> tuple:
    """FEATURES with seeded F per F line and S per spindle line (S from few values, so that some members repeat
    the speed in effect and their S commands drop out of the schedule)."""
    rng = np.random.default_rng(seed)
    k = NCKernel(program_text=FEATURES, batch=batch, **params)
    feed = {line: rng.choice([150.0, 200.0, 350.0, 600.0, 2000.0], batch) * MM / 60.0 for line in FEATURE_FEED_LINES}
    spindle = {line: rng.choice([2000.0, 3000.0, 9000.0], batch) * RPM for line in FEATURE_SPINDLE_LINES}
    k.set_overrides(feed=feed, spindle=spindle)
    return k.planning_inputs()


# ---------------------------------------------------------------------------- whole batches
def test_bench_program_variants_bit_identical():
    args = planning_inputs(bench_case(), 40, *variant_overrides(40))
    assert_same(plan_batch(*args), plan_batch(*args, reference=True))


def test_paper_part_ga_population_bit_identical():
    case = resolve_case(case=BENCH_CASE)
    args = planning_inputs(case, 24, *ga_population(PAPER_LINES, 24, seed=3))
    assert len({row.tobytes() for row in args[2]}) == 24  # distinct members
    assert_same(plan_batch(*args), plan_batch(*args, reference=True))


def test_acc_dec_spans_of_short_cam_segments_bit_identical():
    # 0.1 mm blocks along X then Y (a linearised CAM path: speed changes cross block ends inside acc/dec spans,
    # fmus_src.nck.spans), each member with its own F on the two runs of blocks
    text = ("G90 G0 X0 Y0\nG1 F3000\n" + "".join(f"X{0.1 * k:.1f}\n" for k in range(1, 121))
            + "Y0.1 F1500\n" + "".join(f"Y{0.1 * k:.1f}\n" for k in range(2, 121)) + "M30\n")
    rng = np.random.default_rng(5)
    k = NCKernel(program_text=text, batch=12)
    k.set_overrides(feed={2: rng.choice([600.0, 3000.0, 6000.0], 12) * MM / 60.0,
                          123: rng.choice([400.0, 1500.0, 5000.0], 12) * MM / 60.0})
    args = k.planning_inputs()
    assert_same(plan_batch(*args), plan_batch(*args, reference=True))


@pytest.mark.parametrize("seed", [0, 1])
def test_feature_program_random_population_bit_identical(seed):
    args = feature_inputs(16, seed)
    kinds = {it.kind for it in args[0].items}
    assert {"chain", "tap", "rapid", "dwell", "tool", "spindle", "stop", "end"} <= kinds
    assert_same(plan_batch(*args), plan_batch(*args, reference=True))


@pytest.mark.parametrize("params", [
    {"cutting_filter": "bell", "rapid_filter": "linear", "cutting_time_constant": 0.033},
    {"accel_change_time_before_interp": 0.0, "cutting_time_constant": 0.0, "rapid_time_constant": 0.0},
    {"in_position_width": 0.5e-3, "lookahead_blocks": 3, "spindle_ramp": 100.0},
])
def test_feature_program_other_parameters_bit_identical(params):
    args = feature_inputs(6, 7, **params)
    assert_same(plan_batch(*args), plan_batch(*args, reference=True))


def test_members_sharing_segments_equal_their_own_reference_plans():
    schedule, params, feeds, speeds = feature_inputs(8, 11)
    reuse = PlanReuse()
    for b in range(8):
        new = plan_member(schedule, params[b], feeds[b], speeds[b], reuse=reuse)
        ref = plan_member(schedule, params[b], feeds[b], speeds[b], reference=True)
        for name in ("position", "feed", "line", "tool", "spindle_ref", "spindle_speed"):
            x, y = getattr(new, name), getattr(ref, name)
            assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), (b, name)
        assert new.done_index == ref.done_index


# ---------------------------------------------------------------------------- kernels against numpy
SPECIAL = [-np.inf, -2.0, -1.0, -0.0, 0.0, 1e-300, 1.0, 2.0, np.inf, np.nan]


def _bits(x: float) -> bytes:
    return np.float64(x).tobytes()


def test_scalar_ops_follow_numpy_signed_zero_and_nan_rules():
    for a in SPECIAL:
        assert _bits(np_sign(a)) == _bits(np.sign(np.float64(a)))
        for b in SPECIAL:
            assert _bits(np_maximum(a, b)) == _bits(np.maximum(np.float64(a), np.float64(b))), (a, b)
            assert _bits(np_minimum(a, b)) == _bits(np.minimum(np.float64(a), np.float64(b))), (a, b)
        for lo, hi in ((0.0, 1.0), (-0.0, 0.0), (0.0, -0.0), (0.0, 0.0), (-1.0, 2.0)):
            want = np.clip(np.array([a]), lo, hi)[0]
            assert _bits(np_clip(a, lo, hi)) == _bits(want), (a, lo, hi)


@pytest.mark.parametrize("boxes", [[], [1], [16], [30, 30], [3, 4], [500]])
def test_fir_equals_apply_fir(boxes):
    rng = np.random.default_rng(len(boxes))
    x = np.zeros((400, 3))
    x[10:200] = rng.standard_normal((190, 3)) * 1e-5
    x[50:60, 1] = -0.0
    assert fir(x, np.asarray(boxes, dtype=np.int64)).tobytes() == apply_fir(x, boxes).tobytes()


def test_spindle_samples_equal_sample_spindle():
    rng = np.random.default_rng(5)
    for _ in range(20):
        k = np.sort(rng.integers(0, 300, 6))
        cmd = rng.choice([0.0, -0.0, 300.0, -300.0, 837.7, 50.0], 6)
        events = list(zip(k.tolist(), cmd.tolist()))
        ref = sample_spindle(events, 320, 1e-3, 418.9)
        new = sample_spindle_compiled(k.astype(np.int64), cmd.astype(float), 320, 1e-3, 418.9)
        assert ref[0].tobytes() == new[0].tobytes() and ref[1].tobytes() == new[1].tobytes()


def test_in_position_decision_at_the_width_is_numpy_s():
    # rows exactly at, one ulp inside and outside the width (and NaN): the band leaves these to numpy's norm
    width = 0.02e-3
    target = np.array([0.1, 0.2, -0.05])
    rng = np.random.default_rng(2)
    rows = []
    for _ in range(200):
        u = rng.standard_normal(3)
        u /= np.linalg.norm(u)
        r = width * rng.choice([1.0, 1.0 - 1e-16, 1.0 + 1e-16, 1.0 - 2e-10, 1.0 + 2e-10, 0.5, 2.0])
        rows.append(target + r * u)
    position = np.array(rows)
    for upto in range(0, len(rows), 7):
        p = position[: upto + 1]
        out = np.nonzero(np.linalg.norm(p - target, axis=1) > width)[0]
        assert last_outside(p, target, width) == (int(out[-1]) if len(out) else -1)
    p = np.vstack([position[:3], [[np.nan, 0.0, 0.0]], np.repeat(target[None], 3, axis=0)])
    out = np.nonzero(np.linalg.norm(p - target, axis=1) > width)[0]
    assert last_outside(p, target, width) == (int(out[-1]) if len(out) else -1)
    assert last_outside(p, target, 0.0) == int(np.nonzero(np.linalg.norm(p - target, axis=1) > 0.0)[0][-1])


def _numpy_assembly(segments, K, cut_boxes, rapid_boxes, initial, final):
    """The numpy steps of plan_member (reference path) from segments to positions and feed."""
    inc = {"cut": np.zeros((K, 3)), "rapid": np.zeros((K, 3)), "sync": np.zeros((K, 3))}
    feed = np.zeros(K)
    for k0, kind, seg in segments:
        if seg.n == 0:
            continue
        inc[kind][k0 + 1: k0 + seg.n + 1] += np.diff(seg.position, axis=0)
        feed[k0: k0 + seg.n + 1] = seg.speed
    y = apply_fir(inc["cut"], cut_boxes) + apply_fir(inc["rapid"], rapid_boxes) + inc["sync"]
    position = initial + np.cumsum(y, axis=0)
    moving = np.nonzero(np.any(y != 0.0, axis=1))[0]
    if len(moving):
        position[moving[-1]:] = final
    return position, feed


@pytest.mark.parametrize("overlap", [False, True])
def test_assembly_kernels_equal_numpy(overlap):
    # segments one after the other (streamed kernel, with rests between them) and overlapping ones (the
    # general kernel); zero-length segments and -0.0 increments included
    from fmus_src.nck.interpolator import Segment
    from fmus_src.nck.plan_assembly import assemble_positions

    rng = np.random.default_rng(4)
    segments, k = [], 0
    point = np.array([0.01, -0.02, 0.03])
    for i in range(12):
        n = int(rng.choice([0, 1, 5, 40, 300]))
        pos = point + np.cumsum(rng.standard_normal((n + 1, 3)) * 1e-5 * (i % 3 != 2), axis=0)
        pos[:, 2] = -0.0 if i == 4 else pos[:, 2]
        point = pos[-1]
        seg = Segment(pos, rng.uniform(0, 0.1, n + 1), np.zeros(1), 0.0)
        segments.append((k, ("cut", "rapid", "sync")[i % 3], seg))
        k += n + int(rng.integers(0, 90)) - (25 if overlap and n > 30 else 0)
    K = k + 400
    initial, final = np.array([0.0, 0.1, -0.0]), segments[-1][2].position[-1]
    for cut, rapid in (([16], [30, 30]), ([], [7]), ([8, 8], [])):
        want = _numpy_assembly(segments, K, cut, rapid, initial, final)
        got = assemble_positions(segments, K, cut, rapid, initial, final)
        assert got[0].tobytes() == want[0].tobytes() and got[1].tobytes() == want[1].tobytes()


def test_reuse_keeps_a_segment_from_its_second_request_on():
    from fmus_src.nck.interpolator import Segment

    reuse = PlanReuse()
    made = []

    def make():
        made.append(Segment(np.zeros((2, 3)), np.zeros(2), np.zeros(1), 0.0))
        return made[-1]

    first = reuse.segment("a", make)
    assert reuse.in_position(first, [4], 1e-5, lambda: 7) == 7 and not reuse._segments  # seen once: not kept
    second = reuse.segment("a", make)
    assert reuse.segment("a", make) is second and len(made) == 2
    assert reuse.in_position(second, [4], 1e-5, lambda: 9) == 9
    assert reuse.in_position(second, [4], 1e-5, lambda: -1) == 9  # counted once for a kept segment
