"""NCKernel component: defaults, batch overrides vs rewritten programs, stepping, end of program."""
from __future__ import annotations

import math

import numpy as np
import pytest

from fmus_src.component import ComponentError
from fmus_src.nck import NCKernel, NCParameterError, rewrite_program
from orchestrator.machine import load_machine

PROG = """%
O2000 (pocket)
G90 G17 G21 G54
T1 M6
S3000 M3
G0 X0 Y0 Z5
G1 Z-1 F150
X30 F300
G2 X40 Y10 R10
G1 Y30
G3 X30 Y40 I-10 J0
G1 X0
S4000
Y0
G0 Z50
M30
%
"""
RPM = 2 * math.pi / 60


def run_to_end(k: NCKernel, h: float = 1e-3) -> None:
    n = int(math.ceil(k.duration_.max() / h)) + 2
    for i in range(n):
        k.do_step(i * h, h)


def test_defaults_are_the_machine_file_values():
    m = load_machine("default")
    k = NCKernel()
    nck = m.si("nck")
    for name, value in nck.items():
        got = k.get(name)
        if name.startswith(("reference", "machine_zero")):
            continue  # the frame: compared below
        if name == "in_position_before_rapid":  # the file's "on"/"off" is the kernel's Boolean
            assert bool(got[0]) is (value == "on")
            continue
        assert (got == value) if isinstance(got, str) else got[0] == pytest.approx(value), name
    # the kernel's default frame has machine zero at the axis origin, so its reference positions are the default
    # machine's axis-frame positions: machine zero + reference position
    for name in [n for n in nck if n.startswith("reference")]:
        a = name[-1]
        assert k.get(f"machine_zero_{a}")[0] == 0.0
        assert k.get(name)[0] == pytest.approx(nck[f"machine_zero_{a}"] + nck[name]), name
    for key, value in m.si("spindle").items():
        assert k.get(f"spindle_{key}")[0] == pytest.approx(value), key
    for a in "xyz":
        assert k.get(f"{a}_rapid_feed")[0] == pytest.approx(m.si(f"axis.{a}")["rapid_feed"])


def test_overrides_equal_rewritten_program_and_batch_members_are_independent():
    feeds = np.array([150.0, 400.0, 500.0])  # mm/min for line 8 (modal to line 12)
    speeds = np.array([3000.0, 8000.0, 1000.0])  # rpm for line 13
    k = NCKernel(batch=3, program_text=PROG)
    k.set_overrides(feed={8: feeds * 1e-3 / 60}, spindle={13: speeds * RPM})
    k.setup(0.0)
    assert len(set(k.duration_.tolist())) == 3
    for b in range(3):
        text = rewrite_program(PROG, {8: feeds[b]}, {13: speeds[b]})
        single = NCKernel(program_text=text)
        single.setup(0.0)
        assert single.duration_[0] == k.duration_[b]
        n = single.plan_.position.shape[1]
        np.testing.assert_array_equal(single.plan_.position[0], k.plan_.position[b, :n])
    # higher feed on the long cuts -> shorter program (member 0 has the original values)
    assert k.duration_[1] < k.duration_[0]


def test_spindle_override_on_a_line_without_s_inserts_a_command():
    k = NCKernel(program_text=PROG)
    k.set_overrides(spindle={10: 6000 * RPM})
    k.setup(0.0)
    text = rewrite_program(PROG, spindle_by_line={10: 6000})
    single = NCKernel(program_text=text)
    single.setup(0.0)
    assert k.duration_[0] == single.duration_[0]


def test_stepping_outputs_and_hold_after_done():
    k = NCKernel(batch=2, program_text=PROG)
    k.set_overrides(feed={7: np.array([150.0, 500.0]) * 1e-3 / 60})
    k.setup(0.0)
    assert k.get("line")[0] == 4 and not k.get("done").any()
    run_to_end(k)
    assert k.get("done").all()
    w = 0.02e-3  # done = in position; the filter may still be flushing inside the in-position width
    assert k.get("x_ref") == pytest.approx([0.0, 0.0], abs=w) and k.get("z_ref") == pytest.approx([0.05, 0.05], abs=w)
    assert (k.get("line") == 16).all() and (k.get("tool") == 1).all()
    assert (k.get("spindle_ref") == 0).all()


def test_off_grid_steps_interpolate():
    k = NCKernel(program_text="G1 X10 F600\nM30\n")
    k.setup(0.0)
    k.do_step(0.0, 0.5)
    x_a = k.get("x_ref")[0]
    k.do_step(0.5, 0.0005)
    x_b = k.get("x_ref")[0]
    pos = k.plan_.position[0, :, 0]
    assert x_a == pos[500] and x_b == pytest.approx(0.5 * (pos[500] + pos[501]))


def test_program_file_parameter(tmp_path):
    f = tmp_path / "p.nc"
    f.write_text("G1 X1 F100\nM30\n")
    k = NCKernel(program_file=str(f))
    k.setup(0.0)
    assert k.blocks_[0].line == 1
    with pytest.raises(ComponentError):
        NCKernel(program_file=str(tmp_path / "missing.nc")).setup(0.0)


def test_bad_parameters_are_reported():
    with pytest.raises(NCParameterError):
        NCKernel(program_text="G1 X1 F100\n", cutting_filter="cosine").setup(0.0)
    with pytest.raises(NCParameterError):
        NCKernel(batch=2, program_text="G1 X1 F100\n", g54_x=np.array([0.0, 0.1])).setup(0.0)
    k = NCKernel(batch=2, program_text="G1 X1 F100\n")
    k.set_overrides(feed={1: np.array([1.0, -1.0])})
    with pytest.raises(NCParameterError):
        k.setup(0.0)


def test_thirty_second_program_plans():
    # ~30 s of mixed feed moves and arcs (planning speed is reported, not asserted)
    rng = np.random.default_rng(3)
    lines = ["G90 G21 S5000 M3", "G0 X0 Y0 Z1", "G1 Z-1 F600"]
    for i in range(150):
        x, y = rng.uniform(0, 50, 2)
        lines.append(f"G1 X{x:.3f} Y{y:.3f} F{rng.integers(3000, 9000)}" if i % 3 else f"G2 X{x:.3f} Y{y:.3f} R60")
    lines.append("M30")
    k = NCKernel(program_text="\n".join(lines))
    k.setup(0.0)
    assert 15.0 < k.duration_[0] < 60.0
    assert k.get("done")[0] == False  # noqa: E712
