"""Compiled force replay: a set-up path-mode cutting load stepped through a whole input series in one call.

The cutting diagnosis (:func:`orchestrator.diagnose.cutting_replay.run_force_replay`)
steps a :class:`.path_component.PathCuttingLoad` from force sample to force
sample, every batch member (parameter set) on the same recorded motion.
:func:`replay_path` runs those steps with the component's own state arrays,
per step ``k`` (``h = t[k + 1] - t[k]``), as ``PathCuttingLoad._do_step``:

1. the actual spindle speed (``CuttingLoad._actual_speed``): the step's speed
   input, minus ``droop x`` the previous step's torque where the member has a
   droop and the input is positive, floored at 0;
2. the wear factor ``1 + rate x t_cut`` (``CuttingLoad._wear``) on ``Kt``
   (when a member has wear) and on the edge coefficients (effect kernel);
3. one call of :func:`.path_kernel.path_step` or, with a geometric effect
   term on, :func:`.path_effects.path_step_effects`, with the new position
   and the actual speed as inputs;
4. the effect clocks (``CuttingLoad._finish_effects``): cutting time ``+ h``
   where the step removed material, the torque for the next step's droop,
   the unwrapped angle ``+ max(actual, 0) h``.

The scalar operations are those of the numpy expressions, in their order,
and the kernels are the same compiled functions, so the outputs equal a
step-by-step run bit for bit. A member failing in a step (kernel status not
0: too many substeps, off the table's path, a stalled spindle in material)
stops the call and is reported; the caller then steps the component itself,
which fails the member with the component's own message.
"""
from __future__ import annotations

import numpy as np

from ..jit import njit, njit_nogil
from ..jit_cache import guard_cache
from . import axial, chip, effect_model, kernel, path_effects, path_kernel
from . import path_axial as path_axial_module
from .path_axial import path_axial
from .path_effects import path_step_effects
from .path_kernel import OUT_DEPTH, OUT_FX, OUT_FY, OUT_MRR, OUT_TORQUE, PAR_KE, PAR_KT, ST_Z, path_step

#: Rows of the record of :func:`replay_path`, shape ``(N_RECORD_ROWS, n, B)`` (component output names).
RECORD_ROWS = ("fx", "fy", "spindle_torque", "spindle_speed_actual", "engaged_teeth", "axial_depth")
N_RECORD_ROWS = len(RECORD_ROWS)

#: Rows of the switch vector of :func:`replay_path` (1 on, 0 off).
SWITCH_ROWS = ("geometric", "droop", "wear")

#: Rows of the per-member effect coefficient block of :func:`replay_path`, shape ``(4, B)``.
EFFECT_ROWS = ("edge_force_tangential", "edge_force_radial", "wear_rate", "spindle_droop")

#: Status of :func:`replay_path`.
REPLAY_OK, REPLAY_MEMBER_FAILED = 0, 1


@njit_nogil
def replay_path(
    t: np.ndarray, positions: np.ndarray, step_omega: np.ndarray, switches: np.ndarray, effects: np.ndarray,
    par: np.ndarray, st: np.ndarray, out: np.ndarray, engaged: np.ndarray,
    verts: np.ndarray, vs: np.ndarray, ds: float, count: np.ndarray, alpha: np.ndarray, beta: np.ndarray,
    top: np.ndarray, z_floor: float, stock_top: float, reach_margin: float, tolerance: float, max_substeps: int,
    epar: np.ndarray, toff: np.ndarray, passes: np.ndarray, mode: np.ndarray, ht: np.ndarray, hx: np.ndarray,
    hy: np.ndarray, meta: np.ndarray, angle: np.ndarray, gap: np.ndarray, cutting_time: np.ndarray,
    torque: np.ndarray, status: np.ndarray, record: np.ndarray, m0: int, ka: np.ndarray, axial: np.ndarray,
    rcount: np.ndarray, ralpha: np.ndarray, rbeta: np.ndarray, rtop: np.ndarray, treach: np.ndarray,
) -> tuple[int, int]:
    """Steps ``t[k] -> t[k + 1]``, ``k = 0 .. n - 2``, of every member (see the module docstring).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Step boundaries [s], strictly increasing.
    positions : ndarray, shape (n, 3)
        Tool-tip position at each ``t`` [m] (row ``k + 1``: the input of step ``k``), every member.
    step_omega : ndarray, shape (n - 1,)
        Spindle speed input of each step [rad/s], every member.
    switches : ndarray of int64, shape (3,)
        :data:`SWITCH_ROWS`: a geometric term (the effect kernel), droop, wear on for some member.
    effects : ndarray, shape (4, B)
        :data:`EFFECT_ROWS`: ``Kte``, ``Kre`` [N/m], wear rate [1/s], droop [(rad/s)/(N.m)].
    par : ndarray, shape (5, B)
        The component's kernel parameters (rows ``PAR_*``; ``Kt`` before wear), not modified.
    st, out, engaged
        Kernel state (rows ``ST_*``), outputs (rows ``OUT_*``) and engaged teeth, updated in place.
    verts, vs, ds, count, alpha, beta, top, z_floor
        The :class:`.table.EngagementTable` arrays.
    stock_top, reach_margin, tolerance, max_substeps
        As the component passes them to the kernels [m, m, m, 1].
    epar, toff, passes, mode, ht, hx, hy, meta, angle, gap
        The effect kernel's arrays (:func:`.path_effects.path_step_effects`); ``mode``, the history and
        ``angle`` (unwrapped spindle angle [rad], shape (B,)) updated in place.
    cutting_time, torque : ndarray, shape (B,)
        Wear clock [s] and previous step's torque [N.m], updated in place.
    status : ndarray of int64, shape (B,)
        Kernel error kinds, all 0 on entry.
    record : ndarray, shape (N_RECORD_ROWS, n, B_all)
        Rows ``1 .. n - 1`` of columns ``m0 .. m0 + B - 1`` written: the outputs after each step
        (:data:`RECORD_ROWS`; row 0 is the caller's). Every other argument holds only the B members of this call,
        so calls for disjoint member blocks may run side by side in threads, writing disjoint columns.
    m0 : int
        Column of this call's first member in ``record``.
    ka : ndarray, shape (B,)
        End-edge thrust / tangential force ratio, 1.
    axial : ndarray, shape (2, S)
        The table's ``axial_area`` [m2] and ``axial_span`` [m] (:func:`.path_axial.path_axial`, after each step).
    rcount, ralpha, rbeta, rtop, treach
        The runout ring and each tooth's reach beyond the radius (:func:`.path_effects.path_step_effects`).

    Returns
    -------
    status, step : int
        :data:`REPLAY_OK` and -1, or :data:`REPLAY_MEMBER_FAILED` and the step in which a member failed
        (its kind in ``status``); the state is then partly advanced and must be discarded.
    """
    n = t.shape[0]
    batch = par.shape[1]
    geometric = switches[0] != 0
    droop_on = switches[1] != 0
    wear_on = switches[2] != 0
    inp = np.empty((4, batch))
    kpar = par.copy()
    coef = np.empty((4, batch))
    actual = np.empty(batch)
    z_old = np.empty(batch)
    fz = np.empty(batch)
    for k in range(n - 1):
        h = t[k + 1] - t[k]
        cmd = step_omega[k]
        for m in range(batch):
            a = cmd
            if droop_on:
                d = effects[3, m]
                if d != 0 and cmd > 0:
                    a = max(cmd - d * torque[m], 0.0)
            actual[m] = a
            inp[0, m] = positions[k + 1, 0]
            inp[1, m] = positions[k + 1, 1]
            inp[2, m] = positions[k + 1, 2]
            inp[3, m] = a
            wear = 1.0 + effects[2, m] * cutting_time[m]
            kt = par[PAR_KT, m] * wear if wear_on else par[PAR_KT, m]
            kpar[PAR_KT, m] = kt
            coef[0, m] = kt
            coef[1, m] = par[PAR_KE, m]
            coef[2, m] = effects[0, m] * wear
            coef[3, m] = effects[1, m] * wear
            z_old[m] = st[ST_Z, m]
        if geometric:
            code = path_step_effects(
                h, inp, kpar, st, out, engaged, verts, vs, ds, count, alpha, beta, top, z_floor, stock_top,
                reach_margin, tolerance, max_substeps, coef, epar, toff, passes, mode, ht, hx, hy, meta, angle, gap,
                status, rcount, ralpha, rbeta, rtop, treach)
        else:
            code = path_step(h, inp, kpar, st, out, engaged, verts, vs, ds, count, alpha, beta, top, z_floor,
                             reach_margin, tolerance, max_substeps, status)
        path_axial(out, fz, st, z_old, inp, kpar, ka, h, axial[0], axial[1], ds)  # the end edges
        if code != 0:
            return REPLAY_MEMBER_FAILED, k
        for m in range(batch):
            if out[OUT_MRR, m] > 0.0:
                cutting_time[m] = cutting_time[m] + h
            torque[m] = out[OUT_TORQUE, m]
            angle[m] = angle[m] + max(actual[m], 0.0) * h
            record[0, k + 1, m0 + m] = out[OUT_FX, m]
            record[1, k + 1, m0 + m] = out[OUT_FY, m]
            record[2, k + 1, m0 + m] = out[OUT_TORQUE, m]
            record[3, k + 1, m0 + m] = actual[m]
            record[4, k + 1, m0 + m] = engaged[m]
            record[5, k + 1, m0 + m] = out[OUT_DEPTH, m]
    return REPLAY_OK, -1


# the compiled loop links the kernels' code: recompile it when their modules change
guard_cache(replay_path, path_kernel, path_effects, kernel, chip, effect_model, path_axial_module, axial)
