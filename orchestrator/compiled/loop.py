"""The compiled communication-step loop: the master's schedule over kernel components, in one numba call.

:func:`run_chunk` advances an all-native system from step ``k`` exactly as
:meth:`orchestrator.master.Master.run` does (Gauss-Seidel, multi-rate), but
with every variable that crosses a component boundary held in one array
``V`` (rows = variables, columns = batch members) and every component step a
call of the compiled kernel the component itself would call:

* NC kernel: the planned samples (the ragged :class:`fmus_src.nck.batch_plan.BatchPlan`), read as
  ``NCKernel._write`` reads them (:func:`fmus_src.nck.sampling.read_member`);
* MCU: :func:`fmus_src.servo.control_numba.mcu_kernel`, member by member (its scalar
  :func:`~fmus_src.servo.control_numba.axis_member` / :func:`~fmus_src.servo.control_numba.axis_alarm`);
* drive axes: :func:`fmus_src.servo.stick_slip_numba.advance_kernel` or, member by member,
  :func:`fmus_src.servo.exponential_numba.exponential_member` (the drive's ``integrator``);
* path-mode cutting: :func:`fmus_src.cutting.path_kernel.station_cutters` (a table of several cutters: each
  member's radius and teeth), then :func:`fmus_src.cutting.path_kernel.path_step_into` (``path_step`` on work
  space allocated once per call of :func:`run_chunk`);
* Z-map cutting (effect terms off): :func:`fmus_src.cutting.zmap_numba.zmap_component_step`, the whole
  ``CuttingLoad._do_step`` (step kernel, outputs, clocks, path advance and Z-map removal).

Connections are index triples ``(source row, target row, factor)``; probes
are rows with factors. The floating-point operations are those of the
master and the components, in the same order, so recordings are equal bit for
bit (tested). The loop returns to Python on an *event*: end of the chunk,
stop condition, time limit, a member that needs the divergence check, or a
component error; Python then does what the master does at that point
(messages, failures, progress) — see :mod:`.runner`.
"""
from __future__ import annotations

import math

import numpy as np

from fmus_src.cutting import kernel as cutting_kernel
from fmus_src.cutting import engagement as cutting_engagement
from fmus_src.cutting import axial as cutting_axial
from fmus_src.cutting import path_axial as cutting_path_axial
from fmus_src.cutting import path_kernel, zmap_numba
from fmus_src.cutting import stock as cutting_stock
from fmus_src.jit import njit, njit_borrowed, njit_nogil
from fmus_src.jit_cache import guard_cache
from fmus_src.nck import sampling
from fmus_src.nck.sampling import find_run_from, read_run, sample_position
from fmus_src.servo import control_numba, exponential_numba, stick_slip, stick_slip_numba
from fmus_src.servo import control_rows, exponential_rows as exponential_rows_module
from fmus_src.servo.control_numba import axis_alarm, axis_member
from fmus_src.servo.control_rows import mcu_rows
from fmus_src.servo.exponential_rows import ROWS_WORK, exponential_rows
from fmus_src.servo.exponential_numba import exponential_member
from fmus_src.servo.stick_slip_numba import OK, advance_kernel
from fmus_src.cutting.path_axial import path_axial
from fmus_src.cutting.path_kernel import ST_Z, max_flutes, path_step_into, path_work, station_cutters
from fmus_src.cutting.zmap_numba import IO_ROWS, zmap_component_step

#: Component kinds of the compiled loop.
KIND_NCK, KIND_MCU, KIND_DRIVE, KIND_CUT, KIND_ZMAP = 0, 1, 2, 3, 4
#: Drive integrators (``DriveAxis.integrator``).
INTEGRATOR_RK4, INTEGRATOR_EXPONENTIAL = 0, 1
#: Events returned by :func:`run_chunk`: chunk end, stop condition, time limit, divergence check needed,
#: component error (the whole batch), member failures reported by a kernel (after its call).
EV_CHUNK, EV_STOP, EV_TIME, EV_CHECK, EV_FAIL = 0, 1, 2, 3, 5
#: Smallest batch whose MCU and exponential drive steps run with the members innermost
#: (:func:`fmus_src.servo.control_rows.mcu_rows`, :func:`fmus_src.servo.exponential_rows.exponential_rows`;
#: same results, member by member, as the scalar per-member calls used below it).
ROWS_MIN_BATCH = 2
#: :func:`run_chunk`'s ``all_done_at`` when it returns at the stop condition itself (not written).
NO_STOP_FLAGS = np.zeros(1, dtype=np.bool_)

# rows of each kind's block in V (offsets from the component's base row)
NCK_ROWS = ("x_ref", "y_ref", "z_ref", "feed_ref", "spindle_ref", "spindle_speed", "line", "tool", "done")
MCU_ROWS = ("x_ref", "y_ref", "z_ref", "x_position", "y_position", "z_position", "x_velocity", "y_velocity",
            "z_velocity", "x_current_cmd", "y_current_cmd", "z_current_cmd", "x_velocity_cmd", "y_velocity_cmd",
            "z_velocity_cmd", "in_position")
DRIVE_ROWS = ("current_cmd", "disturbance_force", "position", "velocity", "motor_force", "friction_force",
              "table_position")
CUT_INPUTS = ("x_position", "y_position", "z_position", "spindle_speed")
CUT_OUTPUTS = ("fx", "fy", "fc", "fc_peak", "fx_mean", "fy_mean", "spindle_torque", "spindle_power", "mrr",
               "spindle_angle", "axial_depth", "chip_thickness")
#: Outputs of the effect terms (issue 8); with the effects off: the input speed, 0, 0 and the cutting clock.
CUT_EFFECT_OUTPUTS = ("spindle_speed_actual", "tool_vibration_x", "tool_vibration_y", "cutting_time")
#: ``fz``: the end edges' thrust (axial chip; path mode: :func:`fmus_src.cutting.path_axial.path_axial`).
CUT_ROWS = CUT_INPUTS + CUT_OUTPUTS + ("engaged_teeth",) + CUT_EFFECT_OUTPUTS + ("fz",)
#: ``tool``: the tool in the spindle (not read: PathCuttingLoad takes each station's cutter from its table).
CUT_ROWS = CUT_ROWS + ("tool",)
#: Rows of the Z-map cutting load (``CuttingLoad``), in the order of ``zmap_component_step``'s ``io``.
ZMAP_ROWS = IO_ROWS
_OUT_TORQUE = 4 + CUT_OUTPUTS.index("spindle_torque")
_OUT_MRR = 4 + CUT_OUTPUTS.index("mrr")
_ROW_FZ = CUT_ROWS.index("fz")


@njit_borrowed
def _nck_step(kf: float, base: int, V: np.ndarray, n_samples: int, position: np.ndarray, offset: np.ndarray,
              length: np.ndarray, run_key: np.ndarray, run_feed: np.ndarray, run_sref: np.ndarray,
              run_sact: np.ndarray, run_line: np.ndarray, run_tool: np.ndarray, done_index: np.ndarray,
              cursor: np.ndarray) -> None:
    """``NCKernel._write(kf)`` for every member: :func:`fmus_src.nck.sampling.read_plan`'s reading, into ``V``.

    ``cursor`` (shape (B,), int64) holds each member's run of its previous read: the run of the new
    sample is searched from there (:func:`fmus_src.nck.sampling.find_run_from`, the same run as the
    binary search finds) and stored back.
    """
    k0, k1, frac = sample_position(kf, n_samples)
    for b in range(V.shape[1]):
        g0 = offset[b] + min(k0, length[b])
        i0 = find_run_from(run_key, g0, cursor[b])
        cursor[b] = i0
        px, py, pz, fd, sr, sa, ln, tl = read_run(b, g0, i0, k1, frac, position, offset, length, run_key, run_feed,
                                                  run_sref, run_sact, run_line, run_tool)
        V[base, b] = px
        V[base + 1, b] = py
        V[base + 2, b] = pz
        V[base + 3, b] = fd
        V[base + 4, b] = sr
        V[base + 5, b] = sa
        V[base + 6, b] = ln
        V[base + 7, b] = tl
        V[base + 8, b] = 1.0 if k0 >= done_index[b] else 0.0


@njit_borrowed
def _any_new_bad(V: np.ndarray, rows: np.ndarray, lo: np.ndarray, hi: np.ndarray, failed: np.ndarray) -> bool:
    """True when a member not yet failed has a non-finite value on a checked row or one outside its bounds."""
    for i in range(rows.shape[0]):
        r = rows[i]
        bounded = not (math.isnan(lo[i]) and math.isnan(hi[i]))
        for b in range(V.shape[1]):
            if failed[b]:
                continue
            x = V[r, b]
            if not math.isfinite(x):
                return True
            if bounded and (x < lo[i] or x > hi[i]):
                return True
    return False


@njit_borrowed
def _blank(V: np.ndarray, c: int, rows_ptr: np.ndarray, rows: np.ndarray, comp_failed: np.ndarray) -> None:
    """Real outputs of the failed members of component ``c`` are NaN (``Component._blank_failed_outputs``)."""
    for i in range(rows_ptr[c], rows_ptr[c + 1]):
        r = rows[i]
        for b in range(V.shape[1]):
            if comp_failed[c, b]:
                V[r, b] = math.nan


@njit_nogil
def run_chunk(
    k: int, k_limit: int, max_steps: int, t0: float, h: float, n_fine: int, check_every: int, decimation: int,
    V: np.ndarray,
    tick_ptr: np.ndarray, tick_comp: np.ndarray, comp_kind: np.ndarray, comp_index: np.ndarray,
    comp_rate: np.ndarray, comp_base: np.ndarray,
    wire_ptr: np.ndarray, wire_src: np.ndarray, wire_dst: np.ndarray, wire_factor: np.ndarray,
    check_rows: np.ndarray, check_lo: np.ndarray, check_hi: np.ndarray,
    stop_rows: np.ndarray, stopped_at: np.ndarray, failed: np.ndarray,
    probe_rows: np.ndarray, probe_factor: np.ndarray, rec_t: np.ndarray, rec: np.ndarray, n_rec: int,
    real_ptr: np.ndarray, real_rows: np.ndarray, comp_failed: np.ndarray, comp_has_failed: np.ndarray,
    nck: tuple, mcu: tuple, drives: tuple, cut: tuple, zmap: tuple, stop_record: bool, all_done_at: np.ndarray,
) -> tuple[int, int, int, int, int, int, int]:
    """Advance from step ``k`` until an event (see module docstring).

    Parameters
    ----------
    k, k_limit, max_steps : int
        Current step, step after which the chunk ends, last step of the run.
    t0, h : float
        Start time and communication step, s.
    n_fine, check_every, decimation : int
        Fine ticks per step; divergence-check and recording periods in steps.
    V : ndarray, shape (n_rows, B)
        Every input and output of every component (updated in place).
    tick_ptr, tick_comp : ndarray of int64
        Components stepped in fine tick ``j``: ``tick_comp[tick_ptr[j]:tick_ptr[j + 1]]`` (execution order).
    comp_kind, comp_index, comp_rate, comp_base : ndarray of int64, shape (n_comp,)
        Kind, index within the kind, rate and first row in ``V`` of each component.
    wire_ptr, wire_src, wire_dst, wire_factor : ndarray
        Connections into component ``c``: ``wire_ptr[c]:wire_ptr[c + 1]`` (connection order).
    check_rows, check_lo, check_hi : ndarray
        Rows checked for divergence (connection sources, then limits) with bounds (NaN: finiteness only).
    stop_rows : ndarray of int64
        Rows of the stop signals (empty: run to the time limit).
    stopped_at : ndarray, shape (B,)
        Time each member first met the stop condition (NaN before), updated.
    failed : ndarray of bool, shape (B,)
        Failed members (read only here; the master marks them).
    probe_rows, probe_factor : ndarray
        Recorded rows and their unit factors.
    rec_t, rec : ndarray, shapes (capacity,), (n_probes, capacity, B)
        Recording buffers; ``n_rec`` samples are already in.
    real_ptr, real_rows : ndarray of int64
        Real outputs of component ``c``: ``real_rows[real_ptr[c]:real_ptr[c + 1]]``.
    comp_failed, comp_has_failed : ndarray of bool, shapes (n_comp, B), (n_comp,)
        Members each component has failed (their real outputs are NaN after every step of it).
    nck, mcu, drives, cut, zmap : tuple
        Kernel data of each kind (see :mod:`.layout`).
    stop_record : bool
        False: return ``EV_STOP`` at the first step where every member meets the stop condition.
        True (a block of members run on its own, :mod:`.blocks`): never return ``EV_STOP``; write whether
        every member of the block meets it at the top of step ``k`` to ``all_done_at[k - k_start]``.
    all_done_at : ndarray of bool, shape (>= k_limit - k + 1,) when ``stop_record``
        Written only when ``stop_record``.

    Returns
    -------
    k, n_rec, event, component, code, tick, item : int
        Step reached, samples recorded, event (``EV_*``), and for ``EV_FAIL``
        the component, its kernel's code, the fine tick and the position in the tick's
        schedule. ``EV_FAIL`` returns right after the kernel call (state advanced), before the
        component's own failure handling.
    """
    c_par = cut[0]
    c_alpha = cut[7]
    c_cflu = cut[23]  # the table's station cutters: the rotation cache holds the most teeth of any of them
    intervals, acc, rot, rot_key = path_work(c_alpha.shape[1], max(max_flutes(c_par),
                                                                   c_cflu.max() if c_cflu.shape[0] else 1))
    cursor = np.zeros(V.shape[1], dtype=np.int64)
    d_work = np.empty((ROWS_WORK, V.shape[1]))
    d_memo = np.full((drives[0].shape[0], 2, V.shape[1]), np.nan)
    comp_h = np.empty(comp_rate.shape[0])
    for c in range(comp_rate.shape[0]):
        comp_h[c] = h / comp_rate[c]
    return _run_chunk(k, k_limit, max_steps, t0, h, n_fine, check_every, decimation, V, tick_ptr, tick_comp,
                      comp_kind, comp_index, comp_rate, comp_base, wire_ptr, wire_src, wire_dst, wire_factor,
                      check_rows, check_lo, check_hi, stop_rows, stopped_at, failed, probe_rows, probe_factor,
                      rec_t, rec, n_rec, real_ptr, real_rows, comp_failed, comp_has_failed, nck, mcu, drives, cut,
                      zmap, stop_record, all_done_at, cursor, intervals, acc, rot, rot_key, comp_h, d_work, d_memo)


@njit_borrowed
def _run_chunk(
    k: int, k_limit: int, max_steps: int, t0: float, h: float, n_fine: int, check_every: int, decimation: int,
    V: np.ndarray,
    tick_ptr: np.ndarray, tick_comp: np.ndarray, comp_kind: np.ndarray, comp_index: np.ndarray,
    comp_rate: np.ndarray, comp_base: np.ndarray,
    wire_ptr: np.ndarray, wire_src: np.ndarray, wire_dst: np.ndarray, wire_factor: np.ndarray,
    check_rows: np.ndarray, check_lo: np.ndarray, check_hi: np.ndarray,
    stop_rows: np.ndarray, stopped_at: np.ndarray, failed: np.ndarray,
    probe_rows: np.ndarray, probe_factor: np.ndarray, rec_t: np.ndarray, rec: np.ndarray, n_rec: int,
    real_ptr: np.ndarray, real_rows: np.ndarray, comp_failed: np.ndarray, comp_has_failed: np.ndarray,
    nck: tuple, mcu: tuple, drives: tuple, cut: tuple, zmap: tuple, stop_record: bool, all_done_at: np.ndarray,
    nck_cursor: np.ndarray, c_intervals: np.ndarray, c_acc: np.ndarray, c_rot: np.ndarray, c_rot_key: np.ndarray,
    comp_h: np.ndarray, d_work: np.ndarray, d_memo: np.ndarray,
) -> tuple[int, int, int, int, int, int, int]:
    """:func:`run_chunk`'s loop, on the work space it allocates (compiled without reference counting).

    Parameters
    ----------
    k ... all_done_at
        As :func:`run_chunk`.
    nck_cursor : ndarray of int64, shape (B,)
        Each member's run of its last NC plan read (:func:`_nck_step`).
    c_intervals, c_acc, c_rot, c_rot_key : ndarray
        Work space of the path-mode cutting kernel (:func:`fmus_src.cutting.path_kernel.path_work`).
    comp_h : ndarray, shape (n_comp,)
        Each component's step ``h / comp_rate[c]``, s.
    d_work : ndarray, shape (ROWS_WORK, B)
        Work space of :func:`fmus_src.servo.exponential_rows.exponential_rows`.
    d_memo : ndarray, shape (n_drives, 2, B)
        Its ``memo`` of each drive (NaN at the start of the chunk).

    Returns
    -------
    k, n_rec, event, component, code, tick, item : int
        As :func:`run_chunk`.
    """


    (n_samples, n_pos, n_offset, n_length, n_key, n_feed, n_sref, n_sact, n_line, n_tool, n_done, n_period,
     n_t0) = nck
    (m_gains, m_state, m_width, m_ratio, m_tp, m_tv, m_ticks, m_next, m_inpos, m_limits, m_alarm) = mcu
    (d_params, d_pos, d_vel, d_dir, d_step, d_integ, d_status) = drives
    (c_par, c_st, c_engaged, c_verts, c_vs, c_ds, c_count, c_alpha, c_beta, c_top, c_zfloor, c_margin, c_tol,
     c_maxsub, c_time, c_torque, c_angle, c_status, c_ka, c_axa, c_axj, c_zold, c_crad, c_cflu) = cut
    (z_heights, z_grid, z_cells, z_rho, z_points, z_arc, z_head, z_count, z_spacing, z_lag, z_prev, z_theta,
     z_radius, z_flutes, z_steps, z_kt, z_ke, z_ka, z_time, z_torque, z_angle, z_status, z_diag, z_maxsub,
     z_tnum, z_trad, z_tflu) = zmap
    n_zmap = len(ZMAP_ROWS)
    B = V.shape[1]
    m_tp2 = m_tp * m_tp
    n_stop = stop_rows.shape[0]
    n_probe = probe_rows.shape[0]
    h_fine = h / n_fine
    k_start = k
    while True:
        t = t0 + k * h
        if n_stop > 0:
            all_done = True
            for b in range(B):
                flag = True
                for i in range(n_stop):
                    if V[stop_rows[i], b] == 0.0:
                        flag = False
                if flag and math.isnan(stopped_at[b]):
                    stopped_at[b] = t
                if not (flag or failed[b]):
                    all_done = False
            if stop_record:
                all_done_at[k - k_start] = all_done
            elif all_done:
                return k, n_rec, EV_STOP, -1, 0, 0, 0
        if k >= max_steps:
            return k, n_rec, EV_TIME, -1, 0, 0, 0
        for j in range(n_fine):
            t_tick = t0 + (k * n_fine + j) * h_fine
            for item in range(tick_ptr[j], tick_ptr[j + 1]):
                c = tick_comp[item]
                for w in range(wire_ptr[c], wire_ptr[c + 1]):
                    src = wire_src[w]
                    dst = wire_dst[w]
                    f = wire_factor[w]
                    if f == 1.0:
                        for b in range(B):
                            V[dst, b] = V[src, b]
                    else:
                        for b in range(B):
                            V[dst, b] = V[src, b] * f
                kind = comp_kind[c]
                base = comp_base[c]
                h_i = comp_h[c]
                if kind == KIND_MCU and B >= ROWS_MIN_BATCH:  # mcu_kernel, members innermost (same operations)
                    k0 = m_next[0]
                    n_alarm = mcu_rows(k0, m_ticks, m_ratio, m_tp, m_tv, m_tp2, m_gains, m_state, V, base, m_width,
                                       m_limits, m_alarm)
                    m_next[0] = k0 + m_ticks
                    if n_alarm > 0:
                        return k, n_rec, EV_FAIL, c, n_alarm, j, item
                elif kind == KIND_MCU:  # mcu_kernel, member by member on scalars (same operations)
                    k0 = m_next[0]
                    n_alarm = 0
                    for b in range(B):
                        in_pos = True
                        code = 0
                        for i in range(3):
                            ref = V[base + i, b]
                            pos = V[base + 3 + i, b]
                            vel = V[base + 6 + i, b]
                            cmd, v_cmd, still = axis_member(k0, m_ticks, m_ratio, m_tp, m_tv, m_tp2, m_gains,
                                                            m_state, i, b, ref, pos, vel)
                            V[base + 9 + i, b] = cmd
                            V[base + 12 + i, b] = v_cmd
                            err = abs(ref - pos)
                            if not err <= m_width[b]:
                                in_pos = False
                            if code == 0:
                                code = axis_alarm(i, err, still, m_limits[0, i, b], m_limits[1, i, b],
                                                  m_limits[2, i, b])
                        V[base + 15, b] = 1.0 if in_pos else 0.0
                        m_alarm[b] = code
                        if code != 0:
                            n_alarm += 1
                    m_next[0] = k0 + m_ticks
                    if n_alarm > 0:
                        return k, n_rec, EV_FAIL, c, n_alarm, j, item
                elif kind == KIND_DRIVE:
                    i = comp_index[c]
                    if d_integ[i] == INTEGRATOR_EXPONENTIAL and B >= ROWS_MIN_BATCH:  # members innermost
                        status = exponential_rows(V, base, d_params[i], d_pos[i], d_vel[i], d_dir[i], h_i, d_step[i],
                                                  d_status[i], d_work, d_memo[i])
                    elif d_integ[i] == INTEGRATOR_EXPONENTIAL:  # exponential_kernel, member by member
                        status = OK
                        for b in range(B):
                            u, x, v, dd, ff, code = exponential_member(
                                V[base, b], V[base + 1, b], d_params[i, 0, b], d_params[i, 1, b], d_params[i, 2, b],
                                d_params[i, 3, b], d_params[i, 4, b], d_params[i, 5, b], d_params[i, 6, b],
                                d_params[i, 7, b], d_params[i, 8, b], d_params[i, 9, b], d_params[i, 10, b],
                                d_params[i, 11, b], d_pos[i, b], d_vel[i, b], float(d_dir[i, b]), h_i, d_step[i, b])
                            V[base + 4, b] = u
                            V[base + 2, b] = x
                            V[base + 3, b] = v
                            V[base + 5, b] = ff
                            d_pos[i, b] = x
                            d_vel[i, b] = v
                            d_dir[i, b] = np.int8(dd)
                            d_status[i, b] = code
                            if code != OK and status == OK:
                                status = code
                    else:
                        status = advance_kernel(V[base], V[base + 1], d_params[i], d_pos[i], d_vel[i], d_dir[i],
                                                h_i, d_step[i], V[base + 4], V[base + 2], V[base + 3], V[base + 5],
                                                d_status[i])
                    if status != OK:
                        return k, n_rec, EV_FAIL, c, status, j, item
                    for b in range(B):
                        V[base + 6, b] = d_pos[i, b]
                elif kind == KIND_NCK:
                    _nck_step((t_tick + h_i - n_t0) / n_period, base, V, n_samples, n_pos, n_offset, n_length,
                              n_key, n_feed, n_sref, n_sact, n_line, n_tool, n_done, nck_cursor)
                elif kind == KIND_ZMAP:  # CuttingLoad._do_step, effect terms off
                    n_bad = zmap_component_step(
                        h_i, V[base:base + n_zmap], z_heights, z_grid, z_cells, z_rho, z_points, z_arc, z_head,
                        z_count, z_spacing, z_lag, z_prev, z_theta, z_radius, z_flutes, z_steps, z_kt, z_ke, z_ka,
                        comp_failed[c], z_time, z_torque, z_angle, z_status, z_diag, z_maxsub, z_tnum, z_trad, z_tflu)
                    if n_bad != 0:  # members needing too many substeps (held, blanked): the component fails them
                        return k, n_rec, EV_FAIL, c, n_bad, j, item
                else:  # KIND_CUT
                    for b in range(B):
                        c_zold[b] = c_st[ST_Z, b]
                    station_cutters(c_par, c_st, c_crad, c_cflu, c_ds)  # several cutters: each station's own
                    n_bad = path_step_into(h_i, V[base:base + 4], c_par, c_st, V[base + 4:base + 16], c_engaged,
                                           c_verts, c_vs, c_ds, c_count, c_alpha, c_beta, c_top, c_zfloor, c_margin,
                                           c_tol, c_maxsub, c_status, c_intervals, c_acc, c_rot, c_rot_key)
                    # the end edges (axial chip) from the table's stations, as PathCuttingLoad._do_step
                    path_axial(V[base + 4:base + 16], V[base + _ROW_FZ], c_st, c_zold, V[base:base + 4], c_par, c_ka,
                               h_i, c_axa, c_axj, c_ds)
                    if n_bad != 0:  # members off the path or with too many substeps: the component fails them
                        return k, n_rec, EV_FAIL, c, n_bad, j, item
                    for b in range(B):  # engaged teeth, and CuttingLoad._finish_effects with the effects off
                        V[base + 16, b] = c_engaged[b]
                        actual = V[base + 3, b]
                        if V[base + _OUT_MRR, b] > 0.0:
                            c_time[b] += h_i
                        c_torque[b] = V[base + _OUT_TORQUE, b]
                        c_angle[b] += max(actual, 0.0) * h_i
                        V[base + 17, b] = actual
                        V[base + 20, b] = c_time[b]
                if comp_has_failed[c]:
                    _blank(V, c, real_ptr, real_rows, comp_failed)
        k += 1
        t = t0 + k * h
        if k % check_every == 0 and _any_new_bad(V, check_rows, check_lo, check_hi, failed):
            return k, n_rec, EV_CHECK, -1, 0, 0, 0
        if k % decimation == 0:
            rec_t[n_rec] = t
            for p in range(n_probe):
                r = probe_rows[p]
                f = probe_factor[p]
                for b in range(B):
                    rec[p, n_rec, b] = V[r, b] * f
            n_rec += 1
        if k >= k_limit:
            return k, n_rec, EV_CHUNK, -1, 0, 0, 0


def recording_buffers(capacity: int, n_probe: int, batch: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row-major recording storage and the ``rec_t``, ``rec`` views :func:`run_chunk` writes through.

    Returns
    -------
    rows : ndarray, shape (capacity, 1 + n_probe * batch)
        Sample ``i`` is row ``i``: its time, then each probe's members (the layout of
        :meth:`orchestrator.recording.Recording.from_rows`, which wraps it without a copy).
    rec_t : ndarray, shape (capacity,)
        View of the time column.
    rec : ndarray, shape (n_probe, capacity, batch)
        View of the probe columns.
    """
    rows = np.empty((capacity, 1 + n_probe * batch))
    return rows, rows[:, 0], rows[:, 1:].reshape(capacity, n_probe, batch).transpose(1, 0, 2)


@njit
def sample(t: float, V: np.ndarray, probe_rows: np.ndarray, probe_factor: np.ndarray, rec_t: np.ndarray,
           rec: np.ndarray, n_rec: int) -> int:
    """Record the probes at ``t`` as :func:`run_chunk` does; returns the new sample count."""
    rec_t[n_rec] = t
    for p in range(probe_rows.shape[0]):
        for b in range(V.shape[1]):
            rec[p, n_rec, b] = V[probe_rows[p], b] * probe_factor[p]
    return n_rec + 1


# the cached loop links the kernels' code: recompile it when any of their modules changes
for _fn in (run_chunk, _run_chunk):
    guard_cache(_fn, control_numba, control_rows, exponential_rows_module, stick_slip, stick_slip_numba,
                exponential_numba, path_kernel, cutting_kernel,
                sampling, zmap_numba, cutting_stock, cutting_engagement, cutting_axial, cutting_path_axial)
guard_cache(_nck_step, sampling)
