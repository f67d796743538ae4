"""Compiled replay of a set-up path-mode cutting load along a given motion (cutting diagnosis).

:func:`compiled_path_steps` runs what a step-by-step loop of
``comp.do_step`` would (see
:func:`orchestrator.diagnose.cutting_replay.run_force_replay`) in
:func:`fmus_src.cutting.path_replay_numba.replay_path`, one call for all
steps and members, on copies of the state the component built at set-up
(the component itself is left as set up). It returns ``None`` when the
component is not in a state it covers (numba missing, not set up or already
stepped, a member already failed, no table or a table of several cutters,
inputs that are not finite or a time vector that does not increase) or when a member fails on the way (the
kernel's status): the caller then steps the component itself, which fails
the member with its own message.

Members are independent (each has its own state columns), so blocks of members run in threads
(:func:`fmus_src.threads.member_blocks`: one per core, at least 4 members each), on copies of their
columns, with the numbers of one call over all members.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..jit import NUMBA_AVAILABLE
from ..threads import member_blocks
from .component import MAX_SUBSTEPS
from .path_component import PathCuttingLoad
from .path_replay_numba import N_RECORD_ROWS, RECORD_ROWS, REPLAY_OK, replay_path

#: Outputs of :func:`compiled_path_steps` (component output names).
COMPILED_OUTPUTS = RECORD_ROWS


def _covered(comp: PathCuttingLoad, t: np.ndarray, positions: np.ndarray, step_omega: np.ndarray) -> bool:
    """True when the compiled replay reproduces these inputs on this set-up component exactly."""
    if not (NUMBA_AVAILABLE and isinstance(comp, PathCuttingLoad) and comp.state == "initialized"):
        return False
    if comp._table is None or "_st" not in comp.__dict__ or comp.failed_members.any() or comp._status.any():
        return False
    if comp._table.several_cutters:  # replay_path steps one cutter per member: the component switches them
        return False
    n = t.shape[0]
    if t.ndim != 1 or n < 2 or positions.shape != (n, 3) or step_omega.shape != (n - 1,):
        return False
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(positions)) and np.all(np.isfinite(step_omega))):
        return False
    return bool(np.all(np.diff(t) > 0.0))


def compiled_path_steps(
    comp: PathCuttingLoad, t: np.ndarray, positions: np.ndarray, step_omega: np.ndarray,
) -> dict[str, np.ndarray] | None:
    """Outputs of a set-up path-mode cutting load stepped from ``t[k]`` to ``t[k + 1]``, or ``None``.

    Step ``k`` takes the position ``positions[k + 1]`` and the spindle speed
    input ``step_omega[k]`` for every member, exactly as
    ``comp.set(...); comp.do_step(t[k], t[k + 1] - t[k])`` would.

    Parameters
    ----------
    comp : PathCuttingLoad
        Set up (at ``positions[0]``, time ``t[0]``) and not yet stepped; left unchanged.
    t : ndarray, shape (n,)
        Step boundaries [s].
    positions : ndarray, shape (n, 3)
        Tool-tip position at each ``t`` [m], work coordinates.
    step_omega : ndarray, shape (n - 1,)
        Spindle speed input of each step [rad/s].

    Returns
    -------
    dict or None
        ``{output: ndarray (n, B)}`` for :data:`COMPILED_OUTPUTS` (``engaged_teeth`` as int64), row
        ``k + 1`` after step ``k`` and row 0 the component's values after set-up; ``None`` when the
        component must be stepped one step at a time (not covered, or a member fails).
    """
    t = np.ascontiguousarray(t, dtype=np.float64)
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    step_omega = np.ascontiguousarray(step_omega, dtype=np.float64)
    if not _covered(comp, t, positions, step_omega):
        return None
    v = comp.values
    eff = comp._eff
    es = comp._effect_state
    tb = comp.table
    batch = comp.batch
    switches = np.array([eff.geometric, bool(np.any(eff.droop != 0)), bool(np.any(eff.wear_rate != 0))],
                        dtype=np.int64)
    effects = np.ascontiguousarray(np.stack([eff.kte, eff.kre, eff.wear_rate, eff.droop]), dtype=np.float64)
    engaged = np.array(v["engaged_teeth"], dtype=np.int64)
    record = np.empty((N_RECORD_ROWS, t.size, batch))
    for r, name in enumerate(RECORD_ROWS):
        record[r, 0] = v[name]
    # replay_path's member arrays with the axis of their members; everything else is shared and read only
    members = (
        (effects, 1), (comp._par, 1), (comp._st, 1), (comp._out, 1), (engaged, 0), (comp._epar, 1),
        (comp._runout, 0), (comp._passes, 0), (es.mode, 0), (es.ht, 0), (es.hx, 0), (es.hy, 0), (es.meta, 0),
        (es.angle, 0), (comp._gap, 0), (es.cutting_time, 0), (es.torque, 0),
        (np.zeros(batch, dtype=np.int64), 0), (comp._ka, 0), (comp._reach, 0),
    )
    shared = (tb.vertices, tb.vertex_s, tb.spacing, tb.count, tb.alpha, tb.beta, tb.top, tb.z_floor,
              float(tb.stock_upper[2]), comp._margin, comp._tolerance, MAX_SUBSTEPS)
    axial = np.ascontiguousarray(np.stack([tb.axial_area, tb.axial_span]), dtype=np.float64)
    ring = comp._ring  # the runout ring's table (the table itself when no tooth stands out)

    def block(b0: int, b1: int) -> int:
        """Members ``b0 .. b1 - 1`` on copies of their columns, writing their columns of ``record``."""
        cols = [np.array(a[(slice(None),) * axis + (slice(b0, b1),)], order="C") for a, axis in members]
        (eff_b, par_b, st_b, out_b, eng_b, epar_b, toff_b, passes_b, mode_b, ht_b, hx_b, hy_b, meta_b, angle_b,
         gap_b, ct_b, tq_b, status_b, ka_b, reach_b) = cols
        status, _ = replay_path(t, positions, step_omega, switches, eff_b, par_b, st_b, out_b, eng_b, *shared,
                                epar_b, toff_b, passes_b, mode_b, ht_b, hx_b, hy_b, meta_b, angle_b, gap_b, ct_b,
                                tq_b, status_b, record, b0, ka_b, axial, ring.count, ring.alpha, ring.beta,
                                ring.top, reach_b)
        return int(status)

    ranges = member_blocks(batch)
    if len(ranges) == 1:
        statuses = [block(0, batch)]
    else:  # members are independent: blocks of them in threads give the same numbers (replay_path is nogil)
        with ThreadPoolExecutor(max_workers=len(ranges)) as pool:
            statuses = list(pool.map(lambda r: block(*r), ranges))
    if any(status != REPLAY_OK for status in statuses):
        return None
    traces = {name: record[r] for r, name in enumerate(RECORD_ROWS)}
    traces["engaged_teeth"] = traces["engaged_teeth"].astype(np.int64)
    return traces

