"""Programs as CAM post-processors write them, end to end (``tests/fixtures/cam_posts``).

Nine case folders (``shared/spec/recording.md``: case.toml + program.nc; a 100 x 60 x 20 mm A6061 block, a 6 mm
2-flute end mill, machine "default"), each imitating one post's output as named at the top of its program:
Autodesk Fusion FANUC and Haas NGC, Mastercam Generic Fanuc 3X Mill (``A0.`` on every positioning line),
SolidCAM FANUC (G91 subprograms), Siemens NX Post Builder (``:0030`` tool change block), hyperMILL FANUC
(``G05.1 Q1``, ``G54.1 P1``), Mazak EIA (``G61.1 P1``, ``G5 P2``), HSMWorks in inch (R arcs, G73) and a
hand-written shop program (lower case, no blanks, ``m6t0012``, macro variables, ``/`` block delete).

Each program

* simulates, and its cycle time lies between bounds derived from the interpreted path and the machine file
  (``models/machines/default.toml``): at least the feed time sum(L / F), the rapid travel (slowest axis) and the
  tool changes and dwells; at most that plus, per block, one full acc/dec and an in-position wait, and the
  spindle ramps;
* through the optimiser's writer (``rewrite_program``) with seeded feeds on every feed line and speeds on every
  S word (but those of a tap, where F = pitch x S), changes only F and S words (every other character of every
  line is kept), and re-reads to the same blocks except feeds and spindle commands;
* and ``optimize`` runs on two of them (``time``, ``cost``) with small budgets: the written program changes
  only F and S words and simulates.

One simulation per case is shared by the module's tests.
"""
from __future__ import annotations

import math
import re
from dataclasses import fields, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
import pytest

from fmus_src.nck.blocks import Arc, Dwell, Linear, ProgramEnd, ProgramStop, Rapid, SpindleSpeed, SpindleStop, \
    ToolChange
from fmus_src.nck.writer import rewrite_program
from orchestrator.case import load_case
from orchestrator.optimize import OptimizeSettings, optimize
from orchestrator.simulate import simulate
from orchestrator.twin import build_twin

POSTS = Path(__file__).resolve().parent / "fixtures" / "cam_posts"
NAMES = sorted(p.name for p in POSTS.iterdir() if (p / "case.toml").is_file())

# models/machines/default.toml (SI)
ACCEL = 2.0  # accel_before_interp_mm_per_s2 = 2000
CHANGE_TIME = 0.032  # accel_change_time_before_interp_ms
T_CUT = 0.016  # cutting_time_constant_ms
T_RAPID = 0.060  # rapid_time_constant_ms
RAPID = (0.6, 0.6, 0.5)  # rapid_feed_mm_per_min X Y Z = 36000, 36000, 30000
TOOL_CHANGE = 3.0  # tool_change_time_s
RAMP = 4000.0 / 60.0  # spindle ramp_rpm_per_s, in rev/s per s
KP = 50.0  # position_gain_per_s
IN_POSITION = 2e-5  # in_position_width_mm
#: Longest settling of a position loop into the in-position width after a stop from rapid traverse:
#: following error v/Kp = 12 mm, decaying as exp(-Kp t) to 0.02 mm.
SETTLE = math.log(RAPID[0] / KP / IN_POSITION) / KP

#: An F or S word outside comments with the blanks before it: the letter, blanks, then a number, a variable or a
#: bracketed expression (a word the writer adds to a line comes with one blank).
_FS_WORD = re.compile(r"[ \t]*(?<![A-Za-z])[FfSs][ \t]*(?:#[0-9]+|\[[^\]]*\]|[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+))")
_COMMENT = re.compile(r"\([^()]*\)|;.*$")


def _without_f_and_s(text: str) -> list[str]:
    """Each line with its F and S words removed (comments and every other character kept)."""
    out = []
    for line in text.splitlines():
        pieces, pos = [], 0
        for m in _COMMENT.finditer(line):
            pieces.append(_FS_WORD.sub("", line[pos:m.start()]))
            pieces.append(m.group(0))
            pos = m.end()
        pieces.append(_FS_WORD.sub("", line[pos:]))
        out.append("".join(pieces))
    return out


@lru_cache(maxsize=None)
def _simulated(name: str):
    """One simulation of a case, shared by the tests of the module."""
    return simulate(program=POSTS / name / "program.nc", case=load_case(POSTS / name), plot=False)


def _read_as_the_twin(name: str, text: str):
    """The program as the twin's NC kernel interprets it (the case's registers and M codes)."""
    nck = build_twin(load_case(POSTS / name), batch=1, program_text=text).nck
    nck.setup(0.0)
    return nck.program_


@lru_cache(maxsize=None)
def _original(name: str):
    """The case's program as the twin reads it."""
    return _read_as_the_twin(name, (POSTS / name / "program.nc").read_text())


def _length(b: Linear | Arc) -> float:
    """Path length of a feed block, m."""
    if isinstance(b, Arc):
        return b.length
    return math.dist(b.start, b.end)


def _bounds(blocks) -> tuple[float, float]:
    """Cycle time bounds (s) of an interpreted program on the default machine (module docstring)."""
    low = high = 0.0
    speed = 0.0  # rev/s
    for b in blocks:
        if isinstance(b, (Linear, Arc)):
            t = _length(b) / b.feed
            low += t
            high += t + b.feed / ACCEL + CHANGE_TIME + T_CUT + SETTLE
            if isinstance(b, Linear) and b.rigid_tap:
                tap_speed = b.feed / b.tap_pitch  # rev/s, synchronised with Z from rest to rest
                high += 2.0 * tap_speed / RAMP
        elif isinstance(b, Rapid):
            t = max(abs(e - s) / v for s, e, v in zip(b.start, b.end, RAPID))
            low += t
            high += t + T_RAPID + SETTLE
        elif isinstance(b, ToolChange):
            low += TOOL_CHANGE
            high += TOOL_CHANGE
        elif isinstance(b, Dwell):
            low += b.seconds
            high += b.seconds + SETTLE
        elif isinstance(b, SpindleSpeed):
            new = b.speed / (2.0 * math.pi)
            high += abs(new - speed) / RAMP
            speed = new
        elif isinstance(b, SpindleStop):
            high += speed / RAMP
            speed = 0.0
        elif isinstance(b, (ProgramStop, ProgramEnd)):
            high += SETTLE
    return low, high


@pytest.mark.parametrize("name", NAMES)
def test_post_program_simulates_within_derived_bounds(name):
    result = _simulated(name)
    assert result.success, result
    cycle = result.summary["cycle_time_s"]
    low, high = _bounds(_original(name).blocks)
    assert low <= cycle <= high, (name, low, cycle, high)


_MASKED = {Linear: ("feed", "feed_line"), Arc: ("feed", "feed_line")}


def _without_feeds_and_speeds(blocks) -> list:
    """The blocks without spindle speed commands, feeds blanked (what F and S words may change)."""
    out = []
    for b in blocks:
        if isinstance(b, SpindleSpeed):
            continue
        masked = _MASKED.get(type(b))
        out.append(replace(b, **{f: 0 for f in masked}) if masked else b)
    return out


def _tapping_lines(blocks) -> tuple[set[int], set[int]]:
    """The lines of tapping strokes and the lines of the S words in effect at them."""
    strokes, speeds, speed_line = set(), set(), None
    for b in blocks:
        if isinstance(b, SpindleSpeed):
            speed_line = b.speed_line
        elif isinstance(b, Linear) and b.tap_pitch:
            strokes.add(b.line)
            speeds.add(speed_line)
    return strokes, speeds


@pytest.mark.parametrize("name", NAMES)
def test_writer_changes_only_f_and_s(name):
    """Seeded feeds on every feed line and speeds on every S line (but a tap's), written by the optimiser's
    writer (:func:`~fmus_src.nck.writer.rewrite_program`, which ``optimize`` calls for every individual)."""
    original = (POSTS / name / "program.nc").read_text()
    before = _original(name)
    rng = np.random.default_rng(7)
    tapping, tap_speeds = _tapping_lines(before.blocks)  # F = pitch x S there: F and S stay as written
    feed_lines = sorted({b.line for b in before.blocks if isinstance(b, (Linear, Arc))} - tapping)
    speed_lines = sorted({b.speed_line for b in before.blocks if isinstance(b, SpindleSpeed)} - tap_speeds)
    feeds = dict(zip(feed_lines, np.round(rng.uniform(100.0, 500.0, len(feed_lines)), -1).tolist()))
    speeds = dict(zip(speed_lines, (np.round(rng.uniform(1000.0, 8000.0, len(speed_lines)) / 50.0) * 50.0).tolist()))
    written = rewrite_program(original, feeds, speeds, file=name)
    assert written != original
    assert _without_f_and_s(written) == _without_f_and_s(original)
    after = _read_as_the_twin(name, written)
    assert _without_feeds_and_speeds(after.blocks) == _without_feeds_and_speeds(before.blocks)
    for line, feed in feeds.items():  # the written feeds are the ones the twin runs (in/min under G20)
        runs = [b for b in after.blocks if isinstance(b, (Linear, Arc)) and b.line == line]
        assert all(b.feed * 60000.0 == pytest.approx(feed, rel=1e-3) for b in runs), (name, line)


def test_masking_keeps_every_other_field():
    """The comparison above blanks only feeds: a changed end point or line number is seen."""
    a = Linear(3, (0.0, 0.0, 0.0), (1e-3, 0.0, 0.0), 0.005, 3)
    assert _without_feeds_and_speeds([a]) == _without_feeds_and_speeds([replace(a, feed=0.01, feed_line=2)])
    assert _without_feeds_and_speeds([a]) != _without_feeds_and_speeds([replace(a, end=(2e-3, 0.0, 0.0))])
    assert {f.name for f in fields(Linear)} >= set(_MASKED[Linear])
    assert _without_f_and_s("N10 G1 X5. F300. S5000 (F100 S2)\n#7=350.(FEED)\ng1x1.f#7;s") == \
        ["N10 G1 X5. (F100 S2)", "#7=350.(FEED)", "g1x1.;s"]


@pytest.mark.parametrize("name, objective", [("mazak_eia", "time"), ("nx_fanuc", "cost")])
def test_optimize_post_program(name, objective, tmp_path):
    settings = OptimizeSettings(objective=objective, pop=2, gens=1, seed=1, progress=False, plot=False)
    result = optimize(case=POSTS / name, settings=settings, out=tmp_path)
    original = (POSTS / name / "program.nc").read_text()
    written = (tmp_path / "optimized.nc").read_text()
    assert written == result.program_text
    assert _without_f_and_s(written) == _without_f_and_s(original)
    again = simulate(program=tmp_path / "optimized.nc", case=load_case(POSTS / name), plot=False)
    assert again.success
