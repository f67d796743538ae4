"""Compiled replay of a set-up MCU and its drives against given reference positions (identification, diagnosis).

:func:`compiled_samples` runs what a tick-by-tick loop of ``mcu.do_step`` and
``drive.do_step`` would (see :func:`orchestrator.identify.closed_loop.run_servo_samples`)
in :func:`fmus_src.servo.replay_numba.replay_axis` from the blocks the
components built at set-up: one call per axis and block of members, run in
threads side by side (the kernel releases the GIL; members and axes never
interact, so the numbers do not depend on the split). It returns ``None`` when the
components are not in a state it covers (numba missing, the numpy
reference selected, an RK4 drive, a member already failed, a tick grid other
than the caller's) or when a member fails on the way (a stick/slip failure
or an excess-error alarm): the caller then steps the components itself,
which fail the member with their own message.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Iterator, Mapping

import numpy as np

from ..jit import NUMBA_AVAILABLE
from ..threads import member_blocks, usable_cores
from .drive import DriveAxis
from .errors import ServoError
from .mcu import AXES, MCU
from .replay_numba import DRIVE_EXTRA_ROWS, N_OUTPUT_ROWS, REPLAY_OK, replay_axis

#: Outputs of :func:`compiled_samples` (besides the MCU's ``current_cmd``).
COMPILED_OUTPUTS = ("table_position", "position", "motor_force")

#: False: :func:`compiled_samples` declines and the callers step the components tick by tick
#: (set by :func:`stepped_tick_by_tick`, for comparisons and benchmarks).
ENABLED = True

#: Tolerance on the components' tick grid against the caller's ``t0``, ``tv`` (relative).
GRID_RTOL = 1e-12


@contextmanager
def stepped_tick_by_tick() -> Iterator[None]:
    """Within the block every replay steps the components tick by tick (the reference the compiled path equals)."""
    global ENABLED
    previous, ENABLED = ENABLED, False
    try:
        yield
    finally:
        ENABLED = previous


def _covered(mcu: MCU, drives: Mapping[str, DriveAxis], t0: float, tv: float) -> bool:
    """True when the compiled replay reproduces these set-up components exactly."""
    if not (ENABLED and NUMBA_AVAILABLE and mcu.use_compiled and mcu.state == "initialized"):
        return False
    if mcu._next_tick != 0 or mcu.t0 != t0 or abs(mcu._tv - tv) > GRID_RTOL * tv or mcu.failed_members.any():
        return False
    for d in drives.values():
        if not (d.use_compiled and d.state == "initialized" and str(d.values["integrator"]) == "exponential"):
            return False
        if d.t0 != t0 or d.failed_members.any() or not np.all(np.isfinite(d._state.position)):
            return False
    return True


def _columns(values: np.ndarray) -> np.ndarray:
    """A series of shape ``(n,)`` or ``(n, B)`` as a C-contiguous float array ``(n, 1)`` or ``(n, B)``.

    A member axis broadcast from one column (stride 0) is kept as that one column, not copied ``B`` times.
    """
    arr = np.asarray(values, dtype=float)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.shape[1] > 1 and arr.strides[1] == 0:
        arr = arr[:, :1]
    return np.ascontiguousarray(arr)


def _drive_block(drive: DriveAxis) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Packed parameters, switches and state block of a set-up drive (see :mod:`.replay_numba`)."""
    v = drive.values
    extra = [drive._step] + [v[name] for name in DRIVE_EXTRA_ROWS[1:]]
    block = np.ascontiguousarray(np.vstack([drive._params] + [np.broadcast_to(np.asarray(r, dtype=float), (drive.batch,))
                                                                for r in extra]))
    switches = np.array([drive._load_on, drive._reversal_on, drive._table_on], dtype=np.int64)
    s, table = drive._state, drive._table
    state = np.vstack([s.position, s.velocity, s.direction.astype(float), table.table, table.travel,
                       table.last_direction]).astype(float)
    return block, switches, np.ascontiguousarray(state)


def compiled_samples(
    mcu: MCU,
    drives: Mapping[str, DriveAxis],
    ref: Mapping[str, np.ndarray],
    t0: float,
    tv: float,
    n_ticks: int,
    sample_tick: np.ndarray,
    sample_weight: np.ndarray,
    disturbance: Mapping[str, np.ndarray] | None = None,
) -> dict[str, dict[str, np.ndarray]] | None:
    """Outputs of set-up components at given instants, or ``None`` when they must be stepped one tick at a time.

    Parameters
    ----------
    mcu, drives : MCU and DriveAxis (one per axis in ``ref``), set up at ``t0`` and not yet stepped.
        They are consumed: their state after the call is not defined.
    ref : mapping axis -> ndarray, shape (n_ticks + 1,) or (n_ticks + 1, B)
        Reference position at each velocity-loop tick [m].
    t0, tv : float
        Start time and velocity-loop period [s].
    n_ticks : int
        Ticks to run.
    sample_tick : ndarray of int, shape (n_out,)
        Output ``i`` lies between the outputs after ticks ``sample_tick[i] - 1`` and ``sample_tick[i]``
        (``1 <= sample_tick[i] <= n_ticks``; tick 0 is the set-up).
    sample_weight : ndarray, shape (n_out,)
        Its weight ``w``: ``y[j - 1] (1 - w) + y[j] w`` (``w = 1``: the output after tick ``j`` itself).
    disturbance : mapping axis -> ndarray, shape (n_ticks,), optional
        Disturbance force of the axis during each tick [N].

    Returns
    -------
    dict or None
        ``{output: {axis: ndarray (n_out, B)}}`` for the outputs ``table_position``, ``position``,
        ``motor_force`` and ``current_cmd``: only the samples are kept, never the ticks.

    Raises
    ------
    ServoError
        A sample tick outside ``1 .. n_ticks``.
    """
    if not _covered(mcu, drives, t0, tv):
        return None
    tick = np.asarray(sample_tick, dtype=np.int64)
    weight = np.asarray(sample_weight, dtype=float)
    if tick.size and (tick.min() < 1 or tick.max() > n_ticks):
        raise ServoError(f"servo replay: sample ticks must lie in 1..{n_ticks}, got {tick.min()}..{tick.max()}")
    order = np.argsort(tick, kind="stable")  # the kernel walks the samples with the ticks
    tick, weight = np.ascontiguousarray(tick[order]), np.ascontiguousarray(weight[order])
    batch = mcu.batch
    names = (*COMPILED_OUTPUTS, "current_cmd")
    line = mcu._delay_line
    capacity = line.capacity if line is not None else 2
    calls: dict[str, tuple] = {}
    outs: dict[str, np.ndarray] = {}
    for a, drive in drives.items():
        i = AXES.index(a)
        out = np.empty((N_OUTPUT_ROWS, max(tick.size, 1), batch))
        out[0, 0], out[1, 0] = drive.values["table_position"], drive.values["position"]
        out[2, 0], out[3, 0] = drive.values["motor_force"], mcu.values[f"{a}_current_cmd"]
        block, switches, state = _drive_block(drive)
        held = np.asarray(drive.values["disturbance_force"], dtype=float).reshape(1, -1)
        dist = _columns(disturbance[a]) if disturbance is not None and a in disturbance else held
        calls[a] = (int(n_ticks), int(mcu._ratio), float(mcu._tp), float(mcu._tv), float(t0), i,
                    np.ascontiguousarray(mcu._gain_block[:, i, :]), mcu._state.block[:, i, :].copy(),
                    np.ascontiguousarray(mcu._limit_block[:, i, :]), np.ascontiguousarray(mcu._delay[i]),
                    int(capacity), _columns(ref[a]), dist, block, switches, state, tick, weight, out)
        outs[a] = out
    items = [(a, b0, b1) for a in calls for b0, b1 in member_blocks(batch, len(calls))]
    if len(items) == 1:
        statuses = [replay_axis(items[0][1], items[0][2], *calls[items[0][0]])]
    else:
        with ThreadPoolExecutor(max_workers=min(len(items), usable_cores())) as pool:
            statuses = list(pool.map(lambda item: replay_axis(item[1], item[2], *calls[item[0]]), items))
    if any(status != REPLAY_OK for status, _, _ in statuses):
        return None
    result: dict[str, dict[str, np.ndarray]] = {name: {} for name in names}
    for a, out in outs.items():
        for r, name in enumerate(names):
            column = np.empty((tick.size, batch))
            column[order] = out[r, : tick.size]
            result[name][a] = column
    return result
