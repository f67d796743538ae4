"""G61 exact-stop mode, G9 one-block exact stop, G64, M0 and M1.

Times are derived from the acc/dec law (see tests/test_nck_planner.py): a rest-to-rest speed change of
dv = F = 600 mm/min = 0.01 m/s with a = 2 m/s2 and change time tc = 32 ms takes
t_ch = 2 sqrt(dv tc / a) (dv < a tc), and a block (or a chain) of length L from rest to rest takes
L/F + t_ch. The after-interpolation filter is switched off (time constant 0) so that the in-position
check adds nothing and the durations are exact up to the rounding to Ts = 1 ms of each rest-to-rest move.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.nck import Linear, NCKernel, interpret
from fmus_src.nck.blocks import ProgramStop

TS = 1e-3
F = 0.01  # m/s
L = 0.010  # m per block
T_CH = 2.0 * math.sqrt(F * 0.032 / 2.0)


def plan(text: str, **params) -> NCKernel:
    k = NCKernel(program_text=text, cutting_time_constant=0.0, **params)
    k.setup(0.0)
    return k


def n_ceil(seconds: float) -> int:
    return math.ceil(seconds / TS - 1e-9)


def boundary(k: NCKernel, line: int) -> int:
    """First sample at which ``line`` executes."""
    return int(np.argmax(k.plan_.line[0] == line))


def test_g61_stops_at_every_block_end_g64_does_not():
    g64 = plan("G64 G1 X10 F600\nX20\nX30\nM30\n")
    g61 = plan("G61 G1 X10 F600\nX20\nX30\nM30\n")
    # G64: one chain of 30 mm; G61: three rest-to-rest blocks of 10 mm
    assert g64.plan_.done_index[0] == n_ceil(3 * L / F + T_CH)
    assert g61.plan_.done_index[0] == pytest.approx(3 * n_ceil(L / F + T_CH), abs=1)
    diff = (g61.plan_.done_index[0] - g64.plan_.done_index[0]) * TS
    assert diff == pytest.approx(2 * T_CH, abs=3 * TS)  # two extra stops, each one more t_ch
    for line, x in ((2, 0.010), (3, 0.020)):
        k = boundary(g61, line)
        assert g61.plan_.feed[0, k] == 0.0  # at rest when the next block starts
        assert g61.plan_.position[0, k] == pytest.approx((x, 0.0, 0.0), abs=0.02e-3)
        k = boundary(g64, line)
        assert g64.plan_.feed[0, k] == pytest.approx(F, rel=1e-6)  # collinear: full feed through the junction


def test_g61_with_the_filter_waits_for_in_position():
    k = NCKernel(program_text="G61 G1 X10 F600\nX20\nM30\n")  # default 16 ms linear filter
    k.setup(0.0)
    b = boundary(k, 2)
    assert k.plan_.position[0, b] == pytest.approx((0.010, 0.0, 0.0), abs=0.02e-3)  # in-position width


def test_g9_stops_one_block_only():
    k = plan("G1 X10 F600\nG9 X20\nX30\nX40\nM30\n")
    # stop after line 2: a 20 mm chain and a 20 mm chain
    assert k.plan_.done_index[0] == pytest.approx(2 * n_ceil(2 * L / F + T_CH), abs=1)
    assert k.plan_.feed[0, boundary(k, 3)] == 0.0
    assert k.plan_.feed[0, boundary(k, 4)] == pytest.approx(F, rel=1e-6)
    blocks = [b for b in k.program_.blocks if isinstance(b, Linear)]
    assert [b.exact_stop for b in blocks] == [False, True, False, False]


def test_g64_cancels_g61():
    blocks = [b for b in interpret("G61 G1 X10 F600\nX20\nG64 X30\nX40\n").blocks if isinstance(b, Linear)]
    assert [b.exact_stop for b in blocks] == [True, True, False, False]


def test_g61_arc_ends_at_rest():
    blocks = [b for b in interpret("G61 G1 X10 F600\nG2 X20 Y0 R5\n").blocks]
    assert all(b.exact_stop for b in blocks[:2])


def test_m0_is_an_exact_stop_with_no_extra_time():
    m0 = plan("G1 X10 F600\nM0\nX20\nM30\n")
    g9 = plan("G9 G1 X10 F600\nX20\nM30\n")
    assert any(isinstance(b, ProgramStop) for b in m0.program_.blocks)
    assert m0.plan_.done_index[0] == g9.plan_.done_index[0] == pytest.approx(2 * n_ceil(L / F + T_CH), abs=1)
    assert m0.plan_.feed[0, boundary(m0, 3)] == 0.0


def test_m1_stops_the_path_like_m0_but_adds_no_time():
    # FANUC does not pre-read past M01 (buffering suppressed): two rest-to-rest blocks, no operator wait
    m1 = plan("G1 X10 F600\nM01\nX20\nM30\n")
    assert m1.plan_.done_index[0] == pytest.approx(2 * n_ceil(L / F + T_CH), abs=1)
    assert [b.code for b in m1.program_.blocks if isinstance(b, ProgramStop)] == ["M1"]
