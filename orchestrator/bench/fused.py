"""The fused reference: the twin's servo equations in ONE compiled loop, no component boundaries.

A lower bound for the cost of a twin step: everything the native twin does
between two NC samples, but without a master, without Python per step and
without component adapters. :func:`fused_servo_loop` (numba) advances all
members through ``n_steps`` communication steps; per step it runs the
velocity-loop ticks of the MCU (:func:`fmus_src.servo.control_numba.axis_member`,
member by member) and of the three drives (the twin's integrator:
:func:`fmus_src.servo.exponential_numba.exponential_member` or
:func:`fmus_src.servo.stick_slip_numba.advance_kernel`) in the twin's order
(MCU, X, Y, Z drive per tick; the NC sample of the current period held over the ticks),
then applies a simple cutting load.

What is precomputed (outside the timed loop), :func:`prepare_fused`:

* the NC reference (``x_ref, y_ref, z_ref``): the NC kernel has no inputs, so
  its output is the same open-loop signal in the twin and here;
* the *engagement*: the cutting component run open loop along that reference
  (tool at the reference position), giving the step-mean force
  ``F_ref[k]`` on the workpiece of step ``k``.

The simple cutting load of the fused loop is linear in the feed per tooth (the
chip thickness ``h = f_t sin φ`` is): ``F[k] = F_ref[k] · |Δp_xy actual| /
|Δp_xy reference|`` over the step (``F_ref[k]`` where the reference does not
move), fed to the X/Y drives in the next step as the twin's connection
``cutting.f{x,y}_mean -> {x,y}_drive.disturbance_force`` does. It ignores the
change of engagement (radial immersion, depth) caused by the following error,
which the twin's Z-map model sees: the servo traces agree to rounding in an
air cut and to a small fraction of a micrometre when cutting (tested).

The drives are the baseline model (Eq. 1-3); the optional effect terms of
:class:`~fmus_src.servo.drive.DriveAxis` (gravity, reversal friction, ripple,
screw compliance, ...) must be off, which is the machine file's default.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fmus_src.jit import njit
from fmus_src.jit_cache import guard_cache
from fmus_src.servo import control_numba, exponential_numba, stick_slip, stick_slip_numba
from fmus_src.servo.control_numba import axis_member
from fmus_src.servo.exponential_numba import exponential_member
from fmus_src.servo.stick_slip_numba import OK, advance_kernel

from ..case import Case
from ..errors import CncTwinError
from ..machine import AXES
from ..master import Master, MasterSettings, Probe
from ..system import System
from ..twin import TwinOptions, build_twin

#: Below this XY reference move per step (m) the engagement force is applied unscaled.
MIN_MOVE = 1e-12


@njit
def fused_servo_loop(
    n_steps: int, n_ticks: int, ratio: int, tp: float, tv: float, h_tick: float,
    gains: np.ndarray, mcu_state: np.ndarray, width: np.ndarray, limits: np.ndarray,
    drive_params: np.ndarray, max_steps: np.ndarray,
    position: np.ndarray, velocity: np.ndarray, direction: np.ndarray,
    ref: np.ndarray, force_ref: np.ndarray, move_ref: np.ndarray, force0: np.ndarray,
    out_position: np.ndarray, out_current: np.ndarray, exponential: bool,
) -> int:
    """Run ``n_steps`` twin steps of the servo loop of every member (compiled).

    Parameters
    ----------
    n_steps, n_ticks : int
        Communication steps; velocity-loop ticks per step.
    ratio : int
        Position-loop period / velocity-loop period.
    tp, tv, h_tick : float
        Position- and velocity-loop periods and the drive step per tick, s.
    gains : ndarray, shape (6, 3, B)
        MCU gain block.
    mcu_state : ndarray, shape (7, 3, B)
        MCU state block (updated in place).
    limits : ndarray, shape (3, 3, B)
        MCU excess-error limit block (alarms are not reported: the fused loop is a timing reference).
    width : ndarray, shape (B,)
        In-position width, m.
    drive_params : ndarray, shape (3, 12, B)
        Packed drive parameters per axis.
    max_steps : ndarray, shape (3, B)
        Largest internal drive substep per axis and member, s.
    position, velocity : ndarray, shape (3, B)
        Drive state (updated in place), m and m/s.
    direction : ndarray of int8, shape (3, B)
        Stick/slip state (updated in place).
    ref : ndarray, shape (n_steps + 1, 3)
        NC reference at ``t0 + k h``, m.
    force_ref : ndarray, shape (n_steps + 1, 2)
        Engagement: step-mean force on the workpiece of step ``k - 1`` along the reference, N (row 0: 0).
    move_ref : ndarray, shape (n_steps + 1,)
        XY reference move of step ``k - 1``, m.
    force0 : ndarray, shape (2, B)
        Disturbance force during the first step, N (updated in place: the last one).
    out_position, out_current : ndarray, shape (n_steps + 1, 3, B)
        Drive position (m) and current command (A) at ``t0 + k h`` (row 0 written by the caller).
    exponential : bool
        Drives by :func:`~fmus_src.servo.exponential_numba.exponential_member` (the twin's default
        integrator) instead of the RK4 kernel.

    Returns
    -------
    int
        0, or the drive kernel's status of the first failure.
    """
    B = position.shape[1]
    refs = np.empty((3, B))
    pos_out = np.empty((3, B))
    vel_out = np.empty((3, B))
    cur = np.empty((3, B))
    motor = np.empty(B)
    ffric = np.empty(B)
    dist = np.zeros((3, B))
    member_status = np.zeros(B, dtype=np.int8)
    tp2 = tp * tp
    for i in range(3):
        for b in range(B):
            pos_out[i, b] = position[i, b]
            vel_out[i, b] = velocity[i, b]
            cur[i, b] = out_current[0, i, b]
    for b in range(B):
        dist[0, b] = force0[0, b]
        dist[1, b] = force0[1, b]
    for k in range(n_steps):
        for i in range(3):
            for b in range(B):
                refs[i, b] = ref[k, i]
        for j in range(n_ticks):
            for b in range(B):  # the MCU's control law, member by member (no alarms: a timing reference)
                for i in range(3):
                    cur[i, b] = axis_member(k * n_ticks + j, 1, ratio, tp, tv, tp2, gains, mcu_state, i, b,
                                            refs[i, b], pos_out[i, b], vel_out[i, b])[0]
            for i in range(3):
                if exponential:
                    for b in range(B):
                        p = drive_params[i]
                        u, x, v, d, ff, status = exponential_member(
                            cur[i, b], dist[i, b], p[0, b], p[1, b], p[2, b], p[3, b], p[4, b], p[5, b], p[6, b],
                            p[7, b], p[8, b], p[9, b], p[10, b], p[11, b], position[i, b], velocity[i, b],
                            float(direction[i, b]), h_tick, max_steps[i, b])
                        if status != OK:
                            return status
                        position[i, b] = x
                        velocity[i, b] = v
                        direction[i, b] = np.int8(d)
                        pos_out[i, b] = x
                        vel_out[i, b] = v
                else:
                    status = advance_kernel(cur[i], dist[i], drive_params[i], position[i], velocity[i], direction[i],
                                            h_tick, max_steps[i], motor, pos_out[i], vel_out[i], ffric, member_status)
                    if status != OK:
                        return status
        # simple cutting load from the precomputed engagement, applied in the next step
        for b in range(B):
            dx = pos_out[0, b] - out_position[k, 0, b]
            dy = pos_out[1, b] - out_position[k, 1, b]
            scale = math.hypot(dx, dy) / move_ref[k + 1] if move_ref[k + 1] > MIN_MOVE else 1.0
            dist[0, b] = force_ref[k + 1, 0] * scale
            dist[1, b] = force_ref[k + 1, 1] * scale
        for i in range(3):
            for b in range(B):
                out_position[k + 1, i, b] = pos_out[i, b]
                out_current[k + 1, i, b] = cur[i, b]
    for b in range(B):
        force0[0, b] = dist[0, b]
        force0[1, b] = dist[1, b]
    return 0


# the cached loop links the kernels' code: recompile it when their modules change
guard_cache(fused_servo_loop, control_numba, stick_slip, stick_slip_numba, exponential_numba)


@dataclass
class FusedProblem:
    """Everything :func:`fused_servo_loop` needs for one case, batch and length (from :func:`prepare_fused`).

    Attributes
    ----------
    n_steps : int
        Communication steps.
    step : float
        Communication step, s.
    batch : int
        Members ``B`` (identical copies).
    ref : ndarray, shape (n_steps + 1, 3)
        NC reference, m.
    force_ref : ndarray, shape (n_steps + 1, 2)
        Engagement force (zeros for an air cut), N.
    move_ref : ndarray, shape (n_steps + 1,)
        XY reference move per step, m.
    """

    n_steps: int
    step: float
    batch: int
    ref: np.ndarray
    force_ref: np.ndarray
    move_ref: np.ndarray
    _scalars: tuple
    _gains: np.ndarray
    _state0: tuple

    def run(self) -> tuple[np.ndarray, np.ndarray]:
        """Run the fused loop from the initial state.

        Returns
        -------
        position, current : ndarray, shape (n_steps + 1, 3, B)
            Drive positions (m) and current commands (A) at ``t0 + k h``.

        Raises
        ------
        CncTwinError
            The drive kernel failed (status named).
        """
        mcu_state, width, limits, params, max_steps, pos, vel, dirn, cur0 = (
            np.array(a, copy=True) for a in self._state0)
        n_ticks, ratio, tp, tv, h_tick, exponential = self._scalars
        out_pos = np.empty((self.n_steps + 1, 3, self.batch))
        out_cur = np.empty((self.n_steps + 1, 3, self.batch))
        out_pos[0] = pos
        out_cur[0] = cur0
        force0 = np.zeros((2, self.batch))
        status = fused_servo_loop(self.n_steps, n_ticks, ratio, tp, tv, h_tick, self._gains, mcu_state, width,
                                  limits, params, max_steps, pos, vel, dirn, self.ref, self.force_ref, self.move_ref,
                                  force0, out_pos, out_cur, exponential)
        if status != 0:
            raise CncTwinError(f"fused reference: drive kernel failed with status {status}")
        return out_pos, out_cur


def _initialise(system: System, t0: float) -> None:
    """Set up every component along the execution order, connected inputs first (as the master does)."""
    for name in system.execution_order():
        for c in system.connections:
            if c.target_component == name:
                src = system.components[c.source_component].values[c.source_variable]
                np.multiply(src, c.factor, out=system.components[name].values[c.target_variable], casting="unsafe")
        system.components[name].setup(t0)


def reference_run(case: Case, n_steps: int, step: float = 1e-3, cutting: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """NC reference and engagement force along it (open loop, batch 1).

    Returns
    -------
    ref : ndarray, shape (n_steps + 1, 3)
        ``nck.{x,y,z}_ref`` at ``t0 + k h``, m.
    force : ndarray, shape (n_steps + 1, 2)
        ``cutting.f{x,y}_mean`` of the cutting load with the tool on the reference, N (zeros without a stock).
    """
    twin = build_twin(case, batch=1, options=TwinOptions(step=step, cutting=cutting))
    system = System("fused_reference")
    system.add(twin.nck)
    probes = [Probe(f"{a}_ref", f"nck.{a}_ref") for a in AXES]
    if twin.cutting is not None:
        system.add(twin.cutting)
        for a in AXES:
            system.connect(f"nck.{a}_ref", f"cutting.{a}_position")
        system.connect("nck.spindle_speed", "cutting.spindle_speed")
        probes += [Probe("fx", "cutting.fx_mean"), Probe("fy", "cutting.fy_mean")]
    run = Master(system, MasterSettings(step=step, time_limit=n_steps * step), probes).run()
    if not run.success or run.steps != n_steps:
        raise CncTwinError(f"fused reference: open-loop reference run failed: {run.message}")
    rec = run.recording
    ref = np.stack([rec[f"{a}_ref"] for a in AXES], axis=1)
    force = (np.stack([rec["fx"], rec["fy"]], axis=1) if twin.cutting is not None else np.zeros((n_steps + 1, 2)))
    return ref, force


def prepare_fused(case: Case, n_steps: int, batch: int = 1, step: float = 1e-3, cutting: bool = True,
                  reference: tuple[np.ndarray, np.ndarray] | None = None) -> FusedProblem:
    """Build the fused problem of ``case``: initial servo state as the twin's, reference and engagement.

    Parameters
    ----------
    case : Case
        Program, stock, tool, machine (as for :func:`~orchestrator.twin.build_twin`).
    n_steps : int
        Communication steps to run.
    batch : int
        Identical members ``B``.
    step : float
        Communication step, s.
    cutting : bool
        Apply the cutting load (needs a stock in the case).
    reference : (ref, force), optional
        Output of :func:`reference_run` for at least ``n_steps`` (reused across batch sizes).
    """
    ref, force = reference if reference is not None else reference_run(case, n_steps, step, cutting)
    if ref.shape[0] < n_steps + 1:
        raise CncTwinError(f"fused reference: reference has {ref.shape[0] - 1} steps, {n_steps} needed")
    ref, force = np.ascontiguousarray(ref[: n_steps + 1]), np.ascontiguousarray(force[: n_steps + 1])
    if not cutting:
        force = np.zeros_like(force)
    move = np.zeros(n_steps + 1)
    move[1:] = np.hypot(np.diff(ref[:, 0]), np.diff(ref[:, 1]))
    # the twin's MCU and drives, set up exactly as the master sets them up (same parameter blocks and state)
    twin = build_twin(case, batch=batch, options=TwinOptions(step=step, cutting=False))
    _initialise(twin.system, 0.0)
    mcu, drives = twin.mcu, [twin.drives[a] for a in AXES]
    for d in drives:
        on = [flag for flag in ("_load_on", "_reversal_on", "_table_on") if getattr(d, flag, False)]
        if on:
            raise CncTwinError(f"fused reference: {d.name} has drive effect terms on ({on}); the fused loop "
                               f"covers the baseline drive (Sim & Lee 2023, Eq. 1-3) only")
    n_ticks = int(twin.system.rates["mcu"])
    if any(int(twin.system.rates[f"{a}_drive"]) != n_ticks for a in AXES):
        raise CncTwinError("fused reference: MCU and drives must run at the same rate")
    # internal blocks of the components (read once; the fused loop runs the same kernels on copies)
    gains = mcu._gain_block  # noqa: SLF001
    state0 = (
        mcu._state.block, mcu.values["in_position_width"], mcu._limit_block,  # noqa: SLF001
        np.stack([d._params for d in drives]),  # noqa: SLF001
        np.stack([d._step for d in drives]),  # noqa: SLF001
        np.stack([d._state.position for d in drives]), np.stack([d._state.velocity for d in drives]),  # noqa: SLF001
        np.stack([d._state.direction for d in drives]),  # noqa: SLF001
        np.stack([mcu.values[f"{a}_current_cmd"] for a in AXES]),
    )
    integrators = {str(d.values["integrator"]) for d in drives}
    if len(integrators) != 1:
        raise CncTwinError(f"fused reference: the drives must share one integrator, got {sorted(integrators)}")
    scalars = (n_ticks, int(mcu._ratio), float(mcu._tp), float(mcu._tv), step / n_ticks,  # noqa: SLF001
               integrators == {"exponential"})
    for comp in twin.system.components.values():
        comp.terminate()
    return FusedProblem(n_steps, step, batch, ref, force, move, scalars, np.ascontiguousarray(gains), state0)
