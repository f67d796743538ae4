"""``run_compiled``: :meth:`Master.run` with the step loop in :func:`.loop.run_chunk`.

The Python side does what the master does around its loop, in the same
order and with the master's own methods: set-up along the execution order,
stop / time-limit messages, divergence marking (:meth:`Master._check_divergence`,
called whenever the compiled loop sees a member that needs it), member
failures (:meth:`Master._collect_member_failures`), progress, recording and
termination. When a kernel reports failed members (an MCU alarm, a drive
integrator error) the loop returns right after that kernel call; the
component's own failure handling runs (it raises, with the Python master's
message, when no member is left), the rest of that step runs in Python (as
the master would) and the loop resumes at the next step. The path-mode
cutting kernel reports members off the path the same way, and the Z-map
cutting step members that need more substeps than the component allows.

The loop runs in chunks (at most :data:`CHUNK_STEPS` steps, and up to the
next progress report); recording buffers grow between chunks.
"""
from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from ..errors import CncTwinError
from ..recording import Recording
from .blocks import PASS_STEPS, MemberBlocks, block_count
from .layout import Layout, Unsupported
from .loop import (EV_CHECK, EV_CHUNK, EV_STOP, EV_TIME, KIND_CUT, KIND_DRIVE, KIND_ZMAP, NO_STOP_FLAGS,
                   recording_buffers, run_chunk, sample)

if TYPE_CHECKING:
    from ..master import Master, RunResult

log = logging.getLogger(__name__)

#: Longest chunk of the compiled loop between two returns to Python, steps.
CHUNK_STEPS = 20_000


def compiled_support(master: "Master") -> str | None:
    """None when :func:`run_compiled` covers ``master``'s system, else the reason it does not."""
    try:
        Layout(master)
    except Unsupported as exc:
        return str(exc)
    return None


def _after_kernel(layout: Layout, c: int, t_tick: float, h_i: float) -> None:
    """What component ``c``'s own ``do_step`` does after a kernel call that reported member failures.

    The loop returned right after the kernel (state advanced, outputs written, values
    unpacked into the component): fail the members with the component's own reasons
    (this raises when no member is left), then the rest of its step.
    """
    comp = layout.system.components[layout.order[c]]
    comp._t_step = t_tick  # noqa: SLF001 - set by Component.do_step
    if layout.kinds[c] == KIND_DRIVE:
        comp._status[...] = layout.drives[6][layout.comp_index[c]]  # noqa: SLF001
        comp._fail_stick_slip(h_i)  # noqa: SLF001
        comp._update_table(comp._state.position, (t_tick + h_i) - comp.t0)  # noqa: SLF001
    elif layout.kinds[c] == KIND_CUT:  # members off the path or with too many substeps
        comp.values["engaged_teeth"][...] = layout.cut[2]
        actual = comp._actual_speed()  # noqa: SLF001
        comp._finish_effects(h_i, np.maximum(actual, 0.0), actual)  # noqa: SLF001
        comp._fail_status(h_i)  # noqa: SLF001
    elif layout.kinds[c] == KIND_ZMAP:  # members needing too many substeps (held and blanked by the kernel)
        comp.fail_kernel_substeps(h_i)
    else:  # KIND_MCU: excess-error alarms
        comp._raise_alarms()  # noqa: SLF001
    if comp._failed_outputs:  # noqa: SLF001
        comp._blank_failed_outputs()  # noqa: SLF001


def _finish_step(master: "Master", layout: Layout, k: int, j: int, item: int) -> None:
    """Step the components after position ``item`` of fine tick ``j`` of step ``k`` in Python (as the master)."""
    s = master.settings
    comps = master.system.components
    n_fine = layout.n_fine
    for jj in range(j, n_fine):
        t_tick = s.t0 + (k * n_fine + jj) * (s.step / n_fine)
        first = item + 1 if jj == j else layout.tick_ptr[jj]
        for pos in range(first, layout.tick_ptr[jj + 1]):
            c = int(layout.tick_comp[pos])
            name = layout.order[c]
            master._transfer(master._wires[name])  # noqa: SLF001
            comps[name].do_step(t_tick, s.step / int(layout.comp_rate[c]))


def run_compiled(master: "Master") -> "RunResult | None":
    """Run ``master`` with the compiled loop; None (nothing done) when its system is not covered.

    Parameters
    ----------
    master : Master
        A master that has not run yet.

    Returns
    -------
    RunResult or None
        The same result :meth:`Master.run` returns (bit-identical recording), or None.
    """
    try:
        layout = Layout(master)
    except Unsupported as exc:
        log.debug("%s: compiled loop not used: %s", master.system.name, exc)
        return None
    s = master.settings
    system = master.system
    h = s.step
    max_steps = int(math.floor(s.time_limit / h + 1e-9))
    expected = master.expected_duration or s.time_limit
    capacity = max(min(max_steps, int(expected / h) + 16) // s.decimation + 3, 3)
    batch = system.batch
    t = s.t0
    k = 0
    success, message = True, ""
    stopped_at = np.full(batch, np.nan)
    master._start()  # noqa: SLF001 - failure bookkeeping and component set-up, as Master.run
    layout.bind()
    V = layout.pack()
    n_probe = layout.probe_rows.shape[0]
    rows, rec_t, rec = recording_buffers(capacity, n_probe, batch)
    n_rec = sample(t, V, layout.probe_rows, layout.probe_factor, rec_t, rec, 0)
    nck, mcu, drives, cut, zmap = layout.kernel_data()
    report_every = max(1, int(expected / h / 100))
    failed = master._failed  # noqa: SLF001
    v_current = True  # V (not the components' value arrays) holds the current values

    def grow(needed: int) -> None:
        nonlocal rows, rec_t, rec
        if needed > rows.shape[0]:
            old = rows
            rows, rec_t, rec = recording_buffers(max(needed, 2 * old.shape[0]), n_probe, batch)
            rows[:n_rec] = old[:n_rec]

    def progress(k: int) -> None:
        if master.progress is not None and k % report_every == 0:
            master.progress(s.t0 + k * h - s.t0, expected)

    # run_chunk's arguments before and after the recording buffers (the same arrays for the whole run)
    head = (max_steps, s.t0, h, layout.n_fine, s.check_every, s.decimation, V,
            layout.tick_ptr, layout.tick_comp, layout.comp_kind, layout.comp_index, layout.comp_rate,
            layout.comp_base, layout.wire_ptr, layout.wire_src, layout.wire_dst, layout.wire_factor,
            layout.check_rows, layout.check_lo, layout.check_hi, layout.stop_rows, stopped_at, failed,
            layout.probe_rows, layout.probe_factor)
    tail = (layout.real_ptr, layout.real_rows, layout.comp_failed, layout.comp_has_failed, nck, mcu, drives, cut,
            zmap)
    n_blocks = block_count(batch, s.threads)
    blocks = MemberBlocks(batch, n_blocks, head, tail) if n_blocks > 1 else None
    try:
        while True:
            k_limit = min(k + (CHUNK_STEPS if blocks is None else PASS_STEPS), max(max_steps, k))  # EV_TIME there
            if master.progress is not None:
                k_limit = min(k_limit, (k // report_every + 1) * report_every)
            grow(n_rec + (k_limit - k) // s.decimation + 2)
            if blocks is None:
                k, n_rec, event, c, code, j, item = run_chunk(k, k_limit, *head, rec_t, rec, n_rec, *tail,
                                                              False, NO_STOP_FLAGS)
            else:
                k, n_rec, event, c, code, j, item = blocks.run(k, k_limit, rec_t, rec, n_rec)
            t = s.t0 + k * h
            if event == EV_CHUNK:
                progress(k)
                continue
            if event == EV_STOP:
                message = master._stop_message(t)  # noqa: SLF001
                break
            if event == EV_TIME:
                success, message = master._time_limit_reached(stopped_at)  # noqa: SLF001
                break
            layout.unpack(V)
            if event == EV_CHECK:
                master._check_divergence(t)  # noqa: SLF001
                if k % s.decimation == 0:
                    n_rec = sample(t, V, layout.probe_rows, layout.probe_factor, rec_t, rec, n_rec)
                progress(k)
                continue
            t_tick = s.t0 + (k * layout.n_fine + j) * (h / layout.n_fine)
            # EV_FAIL: the component fails members, then the rest of step k runs in Python, as the master
            v_current = False  # the components hold the values now
            _after_kernel(layout, c, t_tick, h / int(layout.comp_rate[c]))
            _finish_step(master, layout, k, j, item)
            k += 1
            t = s.t0 + k * h
            master._collect_member_failures()  # noqa: SLF001
            if k % s.check_every == 0:
                master._check_divergence(t)  # noqa: SLF001
            layout.pack(V)
            v_current = True
            if k % s.decimation == 0:
                n_rec = sample(t, V, layout.probe_rows, layout.probe_factor, rec_t, rec, n_rec)
            progress(k)
        layout.unpack(V)
        master._check_divergence(t)  # noqa: SLF001
        if (k % s.decimation) != 0:
            n_rec = sample(t, V, layout.probe_rows, layout.probe_factor, rec_t, rec, n_rec)
    except CncTwinError as exc:
        success = False
        message = master._run_failed(exc, t)  # noqa: SLF001
    finally:
        if blocks is not None:
            blocks.close()
        if v_current:
            layout.unpack(V)
        ended = master._terminate_all()  # noqa: SLF001
    success, message = master._terminated(success, message, ended, t)  # noqa: SLF001
    if n_rec < rows.shape[0] // 2:  # do not keep a mostly unused buffer alive
        rows = rows[:n_rec].copy()
    units = {"t_s": "s", **dict(layout.channels)}
    recording = Recording.from_rows(rows[:n_rec], [channel for channel, _ in layout.channels], batch, units,
                                    success, message, system.name)
    return master._result(recording, success, message, k, t, stopped_at)  # noqa: SLF001
