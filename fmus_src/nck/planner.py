"""Offline planning of a whole program into sampled reference trajectories.

The program and the parameters fully determine the reference, so the NC
kernel plans everything at setup, sampled at the interpolation period Ts:

1. the block list is cut into *items*: chains of consecutive feed blocks
   (G1/G2/G3, coolant blocks do not interrupt them; a block with
   ``exact_stop`` — G61 mode, G9, canned-cycle feeds — ends its chain),
   single rapids, dwells, spindle commands, tool changes, M0 program stops
   and the program end;
2. each chain is planned with look-ahead (:mod:`.lookahead`; the window of
   ``lookahead_blocks`` blocks, shorter for the blocks read under Haas
   ``G103 P<n>``: :mod:`.block_buffering`) and interpolated with acc/dec
   before interpolation (:mod:`.interpolator`); each rapid is interpolated at
   its linear-positioning speed;
3. the interpolated increments of feed moves and of rapids are filtered by
   their own acc/dec after interpolation (:mod:`.filters`) and summed;
4. waits are inserted as a FANUC-like controller does: exact stop after a
   rapid (filtered reference within ``in_position_width`` of its end point,
   computed on the move's own filtered reference), in-position before dwell,
   tool change, M0 and program end and after a chain that ends in an exact
   stop (FANUC G61/G9: deceleration to rest, then the in-position check
   before the next block), spindle speed arrival before the next chain
   of feed blocks, ``tool_change_time`` for M6 (after the spindle has come
   to rest when the change waits for it, :attr:`ToolChange.at_rest`: the
   first sample at which the sampled speed is exactly 0); a rapid after
   cutting feed (also after a dwell or spindle command that follows it, as in G82 and
   G86) waits until the servo following the feed's filtered reference is
   within ``in_position_width`` on every axis (:mod:`.servo_settle`,
   ``in_position_before_rapid``), so a drilling cycle reaches its hole
   bottom before the rapid retract.

A rigid-tapping stroke (:attr:`Linear.rigid_tap`) is an item of its own: it
waits for the axes in position and the spindle at rest, then runs Z
synchronised with the spindle (:func:`.tapping.rigid_tap_stroke`), without
the after-interpolation filter; the spindle reference is that synchronised
speed. A spindle orientation of G76/G87 (:attr:`SpindleStop.orient`) makes
the next move wait until the spindle is at rest.

A spindle command that changes the commanded speed (or direction), M5 and a
tool change stop the path (the chain ends at rest). A spindle command that
leaves the command as it is (an S word repeating the speed in effect, as the
optimiser writes on every cutting line) is no command at all: no speed-arrival
wait and no stop; the feed blocks around it form one chain. Whether a command
changes anything depends on the member's spindle overrides, so each member
plans on its own variant of the schedule (:meth:`Schedule.without`).

The whole reference is held in memory, so a plan is limited to
:data:`MAX_PLAN_SAMPLES` interpolation periods. Before each item is sampled, a
lower bound of its duration (length / programmed feed, slowest-axis rapid
time, dwell, tool change time) is checked against the limit, and a program
that would exceed it (a tiny F, a huge dwell) raises :class:`GCodeError`
naming the block instead of exhausting memory.

Two paths give the same plans bit for bit: the numpy specification (``reference=True``) and, by default, compiled
kernels for the steps over all samples (:mod:`.chain_sampling`, :mod:`.plan_assembly`, :mod:`.plan_runs`) with
the segments that do not depend on a member's F and S shared across a batch (:mod:`.plan_reuse`).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from ..jit import NUMBA_AVAILABLE
from .blocks import (
    Arc, Block, Coolant, Dwell, Linear, ProgramEnd, ProgramStop, Rapid, SpindleSpeed, SpindleStop, ToolChange,
)
from .batch_plan import BatchPlan, BatchPlanBuilder
from .chain_sampling import sample_chain_compiled
from .errors import GCodeError, NCParameterError
from .filters import apply_fir, box_lengths, filter_extension
from .geometry import ChainGeometry, chain_geometry
from .interpolator import Segment, chain_pieces, interpolate_chain, interpolate_rapid
from .lookahead import block_windows, plan_chain_speeds
from .params import NCParams
from .plan_assembly import (
    assemble_positions, filtered_path_compiled, in_position_compiled, last_outside, sample_spindle_compiled,
    step_values,
)
from .plan_reuse import PlanReuse
from .profiles import SpeedChange
from .servo_settle import servo_in_position
from .spindle import arrival_time, sample_spindle, speed_after
from .tapping import rigid_tap_accel, rigid_tap_stroke

#: Feed blocks shorter than this are treated as zero-length (no motion, no time), m.
MIN_LENGTH = 1e-12
#: Most interpolation periods a plan may hold (the whole reference is kept in memory: 24 bytes of positions
#: per period and member in a batch plan, about 200 bytes while one member is planned; 1e7 periods are
#: 2.8 h of program at Ts = 1 ms).
MAX_PLAN_SAMPLES = 10_000_000
#: The servo check before a rapid (:mod:`.servo_settle`) models the last SERVO_MEMORY / (Kv Ts) periods of the feed
#: before it, starting there at rest on the reference: an earlier lag has decayed by exp(-40) < 1e-17 by the end.
SERVO_MEMORY = 40.0


@dataclass(frozen=True)
class Item:
    """One step of the schedule: ``kind`` in {"chain", "tap", "rapid", "dwell", "spindle", "stop", "tool",
    "coolant", "halt", "end"} ("tap": one rigid-tapping stroke); ``blocks`` are indices into the block list. ``exact_stop``: a chain whose
    last block is an exact stop (the next item waits for the in-position check)."""

    kind: str
    blocks: tuple[int, ...]
    geometry: ChainGeometry | None = None
    exact_stop: bool = False


@dataclass(frozen=True)
class Schedule:
    """The program cut into items (shared by all batch members).

    Attributes
    ----------
    blocks : tuple of Block
    items : tuple of Item
    initial : ndarray (3,)
        Machine position before the program (m).
    file : str
        Program name for error messages.
    skipped : frozenset of int
        Indices of spindle commands left out of the items (they change nothing).
    """

    blocks: tuple[Block, ...]
    items: tuple[Item, ...]
    initial: np.ndarray
    file: str = "<text>"
    skipped: frozenset[int] = frozenset()
    _variants: dict = field(default_factory=dict, repr=False, compare=False)

    def without(self, skipped: frozenset[int]) -> "Schedule":
        """This schedule with the spindle commands ``skipped`` left out (cached per set).

        Parameters
        ----------
        skipped : frozenset of int
            Block indices of :class:`SpindleSpeed` commands that do not change the command
            (:func:`unchanged_spindle_commands`).
        """
        if skipped == self.skipped:
            return self
        if skipped not in self._variants:
            self._variants[skipped] = build_schedule(self.blocks, self.initial, self.file, skipped)
        return self._variants[skipped]


def spindle_command(block: SpindleSpeed, speed: float, max_speed: float) -> float:
    """Signed spindle command (rad/s) of a spindle block at ``speed`` (rad/s), clamped to ``max_speed``."""
    return block.direction * min(float(speed), max_speed)


def unchanged_spindle_commands(blocks: Sequence[Block], speeds: np.ndarray, max_speed: float) -> frozenset[int]:
    """Indices of spindle commands that leave the commanded speed as it is.

    Parameters
    ----------
    blocks : sequence of Block
    speeds : ndarray (n_blocks,)
        Speed of each spindle command (rad/s) of one member, NaN elsewhere.
    max_speed : float
        Spindle speed clamp (rad/s).

    Returns
    -------
    frozenset of int
        Block indices of :class:`SpindleSpeed` commands whose signed, clamped command equals the one in
        effect (0 before the first command and after M5).
    """
    cmd = 0.0
    out = []
    for i, b in enumerate(blocks):
        if isinstance(b, SpindleSpeed):
            new = spindle_command(b, speeds[i], max_speed)
            if new == cmd:
                out.append(i)
            cmd = new
        elif isinstance(b, SpindleStop):
            cmd = 0.0
    return frozenset(out)


def build_schedule(blocks: Sequence[Block], initial: Sequence[float], file: str = "<text>",
                   skipped: frozenset[int] = frozenset()) -> Schedule:
    """Cut a block list into items.

    Parameters
    ----------
    blocks : sequence of Block
        Ending with :class:`ProgramEnd`.
    initial : (3,) machine position before the program (m).
    file : str
        Program name for error messages.
    skipped : frozenset of int, optional
        Indices of spindle commands that change nothing: left out, so they neither stop the path nor wait.

    Raises
    ------
    NCParameterError
        If ``skipped`` names a block that is not a :class:`SpindleSpeed`.
    """
    for i in skipped:
        if not isinstance(blocks[i], SpindleSpeed):
            raise NCParameterError(f"{file}: block {i} (line {blocks[i].line}) is not a spindle command; "
                                   "only spindle commands can be skipped")
    items: list[Item] = []
    chain: list[int] = []

    def flush() -> None:
        if chain:
            moving = tuple(i for i in chain if _length(blocks[i]) > MIN_LENGTH)
            if moving:
                exact = bool(blocks[chain[-1]].exact_stop)  # type: ignore[union-attr]
                items.append(Item("chain", moving, chain_geometry([blocks[i] for i in moving]), exact))
            chain.clear()

    for i, b in enumerate(blocks):
        if i in skipped:
            continue
        if isinstance(b, Linear) and b.rigid_tap:
            flush()
            items.append(Item("tap", (i,)))
            continue
        if isinstance(b, (Linear, Arc)):
            chain.append(i)
            if b.exact_stop:
                flush()
            continue
        if isinstance(b, Coolant):
            items.append(Item("coolant", (i,)))  # zero time, keeps the chain going
            continue
        flush()
        kind = {Rapid: "rapid", Dwell: "dwell", SpindleSpeed: "spindle", SpindleStop: "stop",
                ToolChange: "tool", ProgramStop: "halt", ProgramEnd: "end"}[type(b)]
        items.append(Item(kind, (i,)))
    flush()
    # coolant items inside a chain were appended before the chain: order by first block index
    items.sort(key=lambda it: it.blocks[0])
    return Schedule(tuple(blocks), tuple(items), np.asarray(initial, dtype=float), file, frozenset(skipped))


def _length(b: Block) -> float:
    if isinstance(b, Arc):
        return b.length
    return math.dist(b.start, b.end)  # type: ignore[union-attr]


@dataclass
class MemberPlan:
    """Sampled reference of one batch member (index k ↔ time t0 + k Ts).

    Attributes
    ----------
    position : ndarray (K, 3)
        Reference after acc/dec after interpolation (m).
    feed : ndarray (K,)
        Path speed before the after-interpolation filter (m/s).
    line, tool : ndarray (K,) of int
        Executing source line, tool in the spindle.
    spindle_ref, spindle_speed : ndarray (K,)
        Commanded (signed) and actual spindle speed (rad/s).
    done_index : int
        First sample at which the program is finished (in position after the end).
    """

    position: np.ndarray
    feed: np.ndarray
    line: np.ndarray
    tool: np.ndarray
    spindle_ref: np.ndarray
    spindle_speed: np.ndarray
    done_index: int


def _filtered_path(position: np.ndarray, boxes: list[int]) -> np.ndarray:
    """The reference after acc/dec after interpolation (m) of pre-filter samples ``position`` (n + 1, 3), n >= 1, as
    if the motion started at the first row: ``n + ext + 1`` rows."""
    n = position.shape[0] - 1
    ext = filter_extension(boxes)
    inc = np.zeros((n + ext + 1, 3))
    inc[1 : n + 1] = np.diff(position, axis=0)
    return position[0] + np.cumsum(apply_fir(inc, boxes), axis=0)


def _in_position(seg: Segment, boxes: list[int], width: float) -> int:
    """Samples after the segment start at which its own filtered reference is within ``width`` of its end."""
    n = seg.n
    if n == 0:
        return 0
    pos = _filtered_path(seg.position, boxes)
    dist = np.linalg.norm(pos - seg.position[-1], axis=1)
    out = np.nonzero(dist > width)[0]
    last_out = int(out[-1]) if len(out) else -1
    return max(n, last_out + 1)


def _ceil_periods(seconds: float, period: float) -> int:
    return max(int(math.ceil(seconds / period - 1e-9)), 0)


def _item_min_seconds(item: Item, blocks: Sequence[Block], params: NCParams, feeds: np.ndarray) -> float:
    """A lower bound of the time an item takes (s), computed before anything is allocated."""
    b = blocks[item.blocks[0]]
    if item.kind in ("chain", "tap"):
        total = 0.0
        for i in item.blocks:
            speed = min(float(feeds[i]), params.max_cutting_feed)
            total += _length(blocks[i]) / speed if speed > 0.0 else math.inf
        return total
    if item.kind == "rapid":
        d = np.abs(np.asarray(b.end) - np.asarray(b.start))  # type: ignore[union-attr]
        return float(max(d[a] / params.rapid_feed[a] for a in range(3)))
    if item.kind == "dwell":
        return float(b.seconds)  # type: ignore[union-attr]
    if item.kind == "tool":
        return params.tool_change_time
    return 0.0


def _check_length(schedule: Schedule, item: Item, k: int, params: NCParams, feeds: np.ndarray) -> None:
    """Raise GCodeError (naming the block) when the plan would exceed :data:`MAX_PLAN_SAMPLES`."""
    ts = params.interpolation_period
    seconds = _item_min_seconds(item, schedule.blocks, params, feeds)
    if k + seconds / ts <= MAX_PLAN_SAMPLES:
        return
    b = schedule.blocks[item.blocks[0]]
    limit = MAX_PLAN_SAMPLES * ts
    raise GCodeError(
        schedule.file, b.line, "", f"a program that runs at most {limit:.6g} s (the planning limit)",
        f"the program would run longer than {limit:.6g} s: this block alone takes at least {seconds:.6g} s "
        f"after {k * ts:.6g} s (a tiny feed rate or a huge dwell?)")


def _tap_item(schedule: Schedule, item: Item, feeds: np.ndarray, params: NCParams, accel: float, k: int,
              spindle_now, sp_last: tuple[int, float, float]) -> tuple[int, Segment, np.ndarray]:
    """A rigid-tapping stroke: its first sample (axes in position, spindle at rest), samples, spindle speed.

    Raises GCodeError naming the line when the spindle is commanded to turn (not stopped by M29) or the
    synchronised speed exceeds the spindle's maximum speed.
    """
    b = schedule.blocks[item.blocks[0]]
    assert isinstance(b, Linear)
    ts = params.interpolation_period
    if sp_last[2] != 0.0:
        raise GCodeError(schedule.file, b.line, "", "M29 S<rpm> (spindle stopped) before a rigid-tapping stroke",
                         "rigid-tapping stroke while the spindle is commanded to turn")
    k0 = k + _ceil_periods(abs(spindle_now(k)) / params.spindle_ramp, ts)  # the spindle comes to rest
    feed = min(float(feeds[item.blocks[0]]), params.max_cutting_feed)  # clamped like any cutting feed
    speed = feed / b.tap_pitch * 2.0 * math.pi
    if speed > params.spindle_max_speed * (1.0 + 1e-9):
        raise GCodeError(schedule.file, b.line, "S", f"S <= {params.spindle_max_speed * 60 / (2 * math.pi):.6g} "
                         "rpm (the maximum spindle speed, FANUC No. 5241)",
                         f"rigid tapping at {speed * 60 / (2 * math.pi):.6g} rpm exceeds the maximum spindle speed")
    seg, omega = rigid_tap_stroke(b.start, b.end, feed, b.tap_pitch, b.rigid_tap, accel, ts)
    return k0, seg, omega


def plan_member(schedule: Schedule, params: NCParams, feeds: np.ndarray, speeds: np.ndarray, *,
                reference: bool = False, reuse: PlanReuse | None = None) -> MemberPlan:
    """Plan one batch member.

    Parameters
    ----------
    schedule : Schedule
    params : NCParams
    feeds : ndarray (n_blocks,)
        Feed of each feed block (m/s), NaN elsewhere.
    speeds : ndarray (n_blocks,)
        Speed of each spindle command (rad/s), NaN elsewhere.
    reference : bool
        Plan with the numpy specification only (no compiled kernels, no ``reuse``): the plan the fast path
        must equal bit for bit (``tests/test_nck_plan_speed.py``).
    reuse : PlanReuse, optional
        Segments shared with the other members of a batch (ignored with ``reference``).

    Returns
    -------
    MemberPlan
    """
    compiled = NUMBA_AVAILABLE and not reference
    if reference:
        reuse = None
    schedule = schedule.without(unchanged_spindle_commands(schedule.blocks, speeds, params.spindle_max_speed))
    ts = params.interpolation_period
    sc = SpeedChange(params.accel_before_interp, params.accel_change_time_before_interp)
    cut_boxes = box_lengths(params.cutting_time_constant, params.cutting_filter, ts)
    rapid_boxes = box_lengths(params.rapid_time_constant, params.rapid_filter, ts)
    blocks = schedule.blocks
    k = 0
    segments: list[tuple[int, str, Segment]] = []
    line_cp: list[tuple[int, int]] = [(0, blocks[0].line if blocks else 0)]
    tool_cp: list[tuple[int, int]] = [(0, 0)]
    sp_events: list[tuple[int, float]] = []
    sp_last = (0, 0.0, 0.0)  # (sample, speed at that sample, command)
    ready = 0
    last: tuple[int, Segment, list[int]] | None = None
    last_cut = False  # the last motion was cutting feed (a chain): a rapid waits for the servo (servo_settled)
    gains = (params.x_position_gain, params.y_position_gain, params.z_position_gain)
    end_reason = "end of file"
    stop_spindle_at_end = False
    synced: list[tuple[int, np.ndarray]] = []  # (first sample, signed spindle speed) of rigid-tapping strokes
    tap_accel = rigid_tap_accel(params.spindle_ramp, params.spindle_max_speed, params.rigid_tapping_time_constant)

    def in_position(seg: Segment, boxes: list[int]) -> int:
        if compiled:
            count = functools.partial(in_position_compiled, seg.position, np.asarray(boxes, dtype=np.int64),
                                      params.in_position_width)
        else:
            count = functools.partial(_in_position, seg, boxes, params.in_position_width)
        return count() if reuse is None else reuse.in_position(seg, boxes, params.in_position_width, count)

    # the servo model runs on the last SERVO_MEMORY / (Kv Ts) periods of the feed (+ the filter's length) only:
    # what came before has decayed by exp(-SERVO_MEMORY) (below 1e-17 of any lag) by the end
    servo_tail = int(math.ceil(SERVO_MEMORY / (min(gains) * ts))) + filter_extension(cut_boxes)

    def servo_count(seg: Segment, boxes: list[int]) -> int:
        if seg.n == 0:
            return 0
        start = max(seg.n - servo_tail, 0)
        tail = np.ascontiguousarray(seg.position[start:])
        if compiled:
            path = filtered_path_compiled(tail, np.asarray(boxes, dtype=np.int64))
        else:
            path = _filtered_path(tail, boxes)
        return max(seg.n, start + servo_in_position(path, seg.position[-1], gains, params.in_position_width, ts))

    def servo_settled(k_now: int) -> int:
        """In-position check before a rapid that follows cutting feed (FANUC): on the modelled servo."""
        if not (params.in_position_before_rapid and last_cut and last is not None):
            return k_now
        k0, seg, boxes = last
        count = functools.partial(servo_count, seg, boxes)
        n = count() if reuse is None else reuse.in_position(seg, boxes, params.in_position_width, count,
                                                            servo=(gains, ts))
        return max(k_now, k0 + n)

    def shared(key: tuple, make: Callable[[], Segment]) -> Segment:
        return make() if reuse is None else reuse.segment(key, make)

    def settled(k_now: int) -> int:
        if last is None:
            return k_now
        k0, seg, boxes = last
        return max(k_now, k0 + in_position(seg, boxes))

    def chain_segment(item: Item, f: np.ndarray) -> Segment:
        geo = item.geometry
        assert geo is not None
        limits = [blocks[i].lookahead_limit for i in item.blocks]  # type: ignore[union-attr]
        window: int | list[int] = params.lookahead_blocks
        if any(limits):  # Haas G103 P<n> (see .block_buffering)
            window = block_windows(limits, params.lookahead_blocks)
        sp = plan_chain_speeds(geo, f, sc, max_cutting_feed=params.max_cutting_feed, arc_accel=params.arc_accel,
                               corner_velocity_difference=params.corner_velocity_difference,
                               lookahead_blocks=window)
        if not compiled:
            return interpolate_chain(geo, sp, sc, ts)
        return sample_chain_compiled(geo, chain_pieces(geo, sp, sc), ts)

    def spindle_now(k_now: int) -> float:
        k_e, w_e, cmd = sp_last
        return float(speed_after(w_e, cmd, params.spindle_ramp, (k_now - k_e) * ts))

    def spindle_at_rest() -> int:
        """First sample at which a spindle commanded to stop samples exactly 0 (the last sample otherwise)."""
        k_e, w_e, cmd = sp_last
        if cmd != 0.0 or w_e == 0.0:
            return k_e
        n = _ceil_periods(abs(w_e) / params.spindle_ramp, ts)
        while params.spindle_ramp * (n * ts) < abs(w_e):  # as sample_spindle rounds: w + (-w) = 0 exactly
            n += 1
        return k_e + n

    for item in schedule.items:
        b = blocks[item.blocks[0]]
        _check_length(schedule, item, max(k, ready), params, feeds)
        if item.kind == "chain":
            line_cp.append((k, b.line))
            k0 = max(k, ready)
            f = feeds[list(item.blocks)]
            seg = shared(("chain", params, item.blocks, f.tobytes()), functools.partial(chain_segment, item, f))
            for bi, tb in zip(item.blocks, seg.block_start.tolist()):
                line_cp.append((k0 + _ceil_periods(tb, ts), blocks[bi].line))
            segments.append((k0, "cut", seg))
            last = (k0, seg, cut_boxes)
            last_cut = True
            k = k0 + seg.n
            if item.exact_stop:
                k = settled(k)
        elif item.kind == "tap":
            k0, seg, omega = _tap_item(schedule, item, feeds, params, tap_accel, max(settled(k), ready),
                                       spindle_now, sp_last)
            line_cp.append((k, b.line))
            segments.append((k0, "sync", seg))
            synced.append((k0, omega))
            last = (k0, seg, [])
            last_cut = False
            k = k0 + seg.n
            sp_last = (k, 0.0, 0.0)
        elif item.kind == "rapid":
            k = servo_settled(k)
            line_cp.append((k, b.line))
            seg = shared(("rapid", params, item.blocks), functools.partial(
                interpolate_rapid, np.array(b.start), np.array(b.end), params.rapid_feed, ts))  # type: ignore[union-attr]
            segments.append((k, "rapid", seg))
            last = (k, seg, rapid_boxes)
            last_cut = False
            k = settled(k)
        elif item.kind == "dwell":
            k = settled(k)
            line_cp.append((k, b.line))
            k += _ceil_periods(b.seconds, ts)  # type: ignore[union-attr]
        elif item.kind == "tool":
            k = settled(k)
            line_cp.append((k, b.line))
            if b.at_rest:  # type: ignore[union-attr]
                k = max(k, spindle_at_rest())
            k += _ceil_periods(params.tool_change_time, ts)
            tool_cp.append((k, b.tool))  # type: ignore[union-attr]
        elif item.kind in ("spindle", "stop"):
            line_cp.append((k, b.line))
            if item.kind == "spindle":
                cmd = spindle_command(b, speeds[item.blocks[0]], params.spindle_max_speed)  # type: ignore[arg-type]
            else:
                cmd = 0.0
            w = spindle_now(k)
            sp_events.append((k, cmd))
            sp_last = (k, w, cmd)
            ready = k + _ceil_periods(arrival_time(w, cmd, params.spindle_ramp,
                                                   params.spindle_speed_arrival_tolerance), ts)
            if item.kind == "stop" and b.orient:  # G76/G87: the tool shift waits for the oriented spindle
                k += _ceil_periods(abs(w) / params.spindle_ramp, ts)
        elif item.kind == "coolant":
            line_cp.append((k, b.line))
        elif item.kind == "halt":
            k = settled(k)
            line_cp.append((k, b.line))
        elif item.kind == "end":
            k = settled(k)
            line_cp.append((k, b.line))
            end_reason = b.reason  # type: ignore[union-attr]
            stop_spindle_at_end = end_reason in ("M30", "M2")
    k_interp_end = k
    ext = filter_extension(cut_boxes) + filter_extension(rapid_boxes)
    K = max(k_interp_end, max((k0 + s.n for k0, _, s in segments), default=0)) + ext + 2
    final = segments[-1][2].position[-1] if segments else schedule.initial
    if compiled:
        position, feed = assemble_positions(segments, K, cut_boxes, rapid_boxes, schedule.initial, final)
        done = max(k_interp_end, last_outside(position, final, params.in_position_width) + 1)
    else:
        inc = {"cut": np.zeros((K, 3)), "rapid": np.zeros((K, 3)), "sync": np.zeros((K, 3))}
        feed = np.zeros(K)
        for k0, kind, seg in segments:
            if seg.n == 0:
                continue
            inc[kind][k0 + 1 : k0 + seg.n + 1] += np.diff(seg.position, axis=0)
            feed[k0 : k0 + seg.n + 1] = seg.speed
        y = apply_fir(inc["cut"], cut_boxes) + apply_fir(inc["rapid"], rapid_boxes) + inc["sync"]
        position = schedule.initial + np.cumsum(y, axis=0)
        moving = np.nonzero(np.any(y != 0.0, axis=1))[0]
        if len(moving):
            position[moving[-1]:] = final  # the last increment lands exactly on the end point
        dist = np.linalg.norm(position - final, axis=1)
        out = np.nonzero(dist > params.in_position_width)[0]
        done = max(k_interp_end, int(out[-1]) + 1 if len(out) else 0)
    # spindle: stopped by M30/M2 when the program is done; keep samples until it stands still
    k_total = K
    if stop_spindle_at_end:
        w_end = spindle_now(done)
        if sp_last[2] != 0.0 or w_end != 0.0:
            sp_events.append((done, 0.0))
            k_total = max(K, done + _ceil_periods(abs(w_end) / params.spindle_ramp, ts) + 2)
    if k_total > K:
        position = np.concatenate((position, np.repeat(position[-1:], k_total - K, axis=0)))
        feed = np.concatenate((feed, np.zeros(k_total - K)))
    if compiled:
        spindle_ref, spindle_speed = sample_spindle_compiled(
            np.array([e[0] for e in sp_events], dtype=np.int64), np.array([e[1] for e in sp_events], dtype=float),
            k_total, ts, params.spindle_ramp)
    else:
        spindle_ref, spindle_speed = sample_spindle(sp_events, k_total, ts, params.spindle_ramp)
    for k0, omega in synced:  # rigid tapping: the spindle runs synchronised with Z
        spindle_ref[k0 : k0 + len(omega)] = omega
        spindle_speed[k0 : k0 + len(omega)] = omega
    line = _step_function(line_cp, k_total, compiled)
    tool = _step_function(tool_cp, k_total, compiled)
    return MemberPlan(position, feed, line.astype(np.int64, copy=False), tool.astype(np.int64, copy=False),
                      spindle_ref, spindle_speed, done)


def _step_function(checkpoints: list[tuple[int, int]], n: int, compiled: bool) -> np.ndarray:
    """Value of the last checkpoint ``(sample, value)`` at or before each sample ``0 .. n-1`` (int64, shape (n,))."""
    keys = np.array([c[0] for c in checkpoints])
    values = np.array([c[1] for c in checkpoints])
    if (compiled and keys.dtype == np.int64 and values.dtype == np.int64 and keys[0] <= 0
            and bool(np.all(keys[1:] >= keys[:-1]))):
        return step_values(keys, values, n)
    return values[np.searchsorted(keys, np.arange(n), side="right") - 1]


def plan_batch(schedule: Schedule, params: Sequence[NCParams], feeds: np.ndarray, speeds: np.ndarray, *,
               reference: bool = False) -> BatchPlan:
    """Plan B members into a ragged :class:`~.batch_plan.BatchPlan` (identical members are planned and stored once).

    Each member is planned, copied into the batch storage and released before the next one, so memory
    grows with the sum of the distinct members' lengths (not B × the longest).

    Parameters
    ----------
    schedule : Schedule
    params : sequence of NCParams, length B
        All with the same interpolation period.
    feeds, speeds : ndarray (B, n_blocks)
        From :func:`fmus_src.nck.overrides.resolve_values`.
    reference : bool
        Plan every member with the numpy specification (:func:`plan_member` ``reference=True``); by default the
        compiled kernels run and the members share what does not depend on their F and S
        (:class:`.plan_reuse.PlanReuse`), with bit-identical plans.
    """
    builder = BatchPlanBuilder(reference=reference)
    stored: dict[tuple, int] = {}
    members: list[int] = []
    reuse = None if reference else PlanReuse()
    for b, p in enumerate(params):
        key = (p, feeds[b].tobytes(), speeds[b].tobytes())
        if key not in stored:
            stored[key] = builder.add(plan_member(schedule, p, feeds[b], speeds[b], reference=reference, reuse=reuse))
        members.append(stored[key])
    return builder.finish(members, params[0].interpolation_period)
