"""``CuttingLoad``: milling force from the actual tool motion and a Z-map stock.

A thin adapter around :mod:`.stock`, :mod:`.engagement`, :mod:`.force` and
:mod:`.kernel` (the step itself; compiled: :mod:`.zmap_numba`, same results).

Time discretisation of one communication step ``[t, t + h]``
-----------------------------------------------------------
* The position inputs read by ``do_step(t, h)`` are taken as the tool-tip
  position at ``t + h``; the tool moves linearly from the previous inputs to
  them. (With a Jacobi master, whose inputs are the drive outputs at ``t``,
  this delays the force by one step but does not change its magnitude.)
* The spindle speed input is held over the step; the spindle angle integrates
  it (``theta += omega h``, wrapped to ``[0, 2 pi)``).
* The chip of a step is the tool-centre displacement over the last tooth
  period, ``c(t + h) - c(t + h - T)`` (what the previous tooth left; Sim & Lee
  2023 Eq. 10-11, :func:`.kernel.chord_feed`), read from the member's record of
  its last :data:`.kernel.CHIP_HISTORY_STEPS` steps (the tool moves linearly
  within each); the step velocity times ``T`` when ``T <= h``, at the start, after
  the spindle starts and while the record is younger than ``T``. With runout or
  chatter a tooth may cut a surface left ``i + 1`` teeth back: its chip is the
  displacement over ``i + 1`` periods from the same record
  (:func:`.kernel.chords_back`), ``i + 1`` times the chord where the record
  does not reach back that far.
* The step is cut into ``n`` substeps so that the spindle turns at most
  ``pitch / angle_steps_per_tooth`` and the tool moves at most ``R / 20`` per
  substep (with chatter on, also at least 32 substeps per period of the tool
  mode). Forces are evaluated at the ``n + 1`` substep instants. ``n`` is
  **per member**: the kernels take one count per member (a member with
  fewer substeps than the largest leaves the extra instants out), so a
  member's figures are those of its solo run, bit for bit, whatever batch
  it is in, and the whole batch is still one kernel call. A member needing
  more than :data:`MAX_SUBSTEPS` fails alone
  (:meth:`~fmus_src.component.Component.fail_members`, the message names
  it); a single run raises :class:`CuttingError`.
* Step means (``fx_mean``, ``fy_mean``, torque, power, MRR) integrate each
  tooth exactly over each substep (closed-form integrals of the chip-thickness
  trigonometry, :func:`.force.interval_mean_quantities`, with the mean of the
  axial depths at the two ends); where a tooth enters or leaves material
  inside a substep the instant is located to 1/4096 of the substep (three
  rounds of 16 sections, vectorised over all teeth), so the
  means do not suffer from the angular sampling of the entry/exit jumps.
* ``fc_peak`` is the largest ``Fc`` over the substep instants of the step and
  over the entry/exit instants so located.

Several tools (the tool table)
------------------------------
The Integer input ``tool`` is the tool in the spindle (the NC kernel's ``tool``);
the slot parameters ``tool_<i>_number`` / ``_diameter`` / ``_flutes``
(:mod:`.tool_table`) give listed tools their own cutter, every other tool is
cut with ``tool_diameter`` and ``flutes``. At the start of a step, a member
whose tool's cutter differs from its current one commits its whole recent
path (to the tool at the step's start) to the Z-map with the old radius, then
takes the new radius and teeth and the near-field spacing and lag derived
from the radius (:meth:`CuttingLoad._switch_tools`; compiled:
:func:`.zmap_numba.switch_tool`). With every slot empty, or every listed
cutter equal to the default, nothing ever switches: the one-tool model bit
for bit.

Feeding into material with the spindle stopped (a crash)
--------------------------------------------------------
The chip per tooth of a tool that does not turn is unbounded. A member whose
step feeds the tool into material (a tooth with a chip and an axial depth)
while its spindle is below 1 rpm (:func:`.kernel.stalled_cut`; M4 counts as
stopped, the end mill cuts clockwise) fails
(:meth:`~fmus_src.component.Component.fail_members`, a single run raises
:class:`CuttingError`) with a message naming the time, the tool position in
mm and the spindle speed in rpm (:meth:`CuttingLoad.stalled_reason`); its
step's force is not passed on. A stopped spindle in the air, or a tool at
rest in material, is fine.

Effect terms (diagnosis, issue 8)
---------------------------------
Runout, helix, edge force, static tool deflection, tool wear, spindle droop
and regenerative chatter are parameters, all 0 (off, the paper's model) by
default (:mod:`.effect_model`, physics in :mod:`.effects` and :mod:`.chip`).
With runout, helix, edge force, deflection or chatter on for a member, its
step runs in :func:`.kernel_effects.cut_step_effects` (members without them
stay on :func:`.kernel.cut_step`, as alone); wear (``Kt x (1 + rate t_cut)``)
and droop (spindle speed minus ``droop x`` the previous step's torque) only
change the inputs of :func:`.kernel.cut_step`, so with every term off the
outputs are those of the baseline bit for bit.
"""
from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from ..component import Component, Variable
from ..errors import CncTwinError
from ..jit import NUMBA_AVAILABLE
from .axial import AX_MRR, AX_THRUST, AX_TORQUE, AXIAL_RATIO_DEFAULT, axial_cuts, stalled_plunges
from .effect_model import CHATTER_SUBSTEPS_PER_PERIOD, MAX_PASSES, EffectParameters, EffectState
from .engagement import PATH_SPACING, NearField, SweptPath, path_capacity
from .kernel import (CHIP_HISTORY_WIDTH, StepResult, chord_advance_all, chord_feeds, chords_back_all, cut_step,
                     stalled_cuts)
from .kernel_effects import cut_step_effects
from .stock import ZMapStock
from .tool_table import TABLE_PARAMETERS, ToolTable, slots, table_variables
from .zmap_numba import (ERR_STALLED, ERR_SUBSTEPS, IO_FX, IO_FZ, IO_INPUTS, IO_ROWS, ZMapArrays, _ring, commit,
                         cut_step_compiled, flush, zmap_component_step)

#: Refuse steps needing more substeps than this (spindle speed or jump far too large).
MAX_SUBSTEPS = 100_000


#: Parameters of the baseline model (Eq. 10-13 on a Z-map stock); every other parameter is an effect term,
#: off at 0 (:meth:`CuttingLoad.effects_off`).
BASELINE_PARAMETERS = frozenset((
    "tool_diameter", "flutes", "kt", "ke", "ka", "stock_x_min", "stock_y_min", "stock_z_min", "stock_x_max",
    "stock_y_max", "stock_z_max", "stock_cell", "angle_steps_per_tooth", "initial_spindle_angle",
)) | TABLE_PARAMETERS


class CuttingError(CncTwinError):
    """Invalid cutting-load parameters or inputs."""


def _p(name: str, unit: str, start: float, description: str, type_: str = "Real") -> Variable:
    return Variable(name, "parameter", unit, start, description, type_)  # type: ignore[arg-type]


class CuttingLoad(Component):
    """Cutting load of a flat end mill in a Z-map stock (batched).

    Variables
    ---------
    See :attr:`variables`. Forces ``fx``, ``fy`` are on the **workpiece**, in
    machine axes (the drives use ``Fd = +F_workpiece``).

    The members without effect terms step in the compiled kernel
    (:func:`.zmap_numba.cut_step_compiled`, same results as the numpy
    :func:`.kernel.cut_step`) when :attr:`use_compiled` is true.
    """

    #: Step the baseline members (and the Z-map removal) in the compiled kernels of :mod:`.zmap_numba`
    #: (default: when numba is available); False: the numpy reference :func:`.kernel.cut_step`.
    use_compiled: ClassVar[bool] = NUMBA_AVAILABLE

    variables = (
        _p("tool_diameter", "m", 6e-3, "flat end mill diameter"),
        _p("flutes", "1", 2, "number of teeth", "Integer"),
        _p("kt", "N/m2", 1.23e9, "tangential cutting coefficient (A6061, Sim & Lee 2023)"),
        _p("ke", "1", 0.5, "radial / tangential force ratio (A6061, Sim & Lee 2023)"),
        _p("ka", "1", AXIAL_RATIO_DEFAULT,
           "axial (thrust) / tangential force ratio of the end edges (axial chip of plunges; Altintas Kac/Ktc)"),
        _p("stock_x_min", "m", 0.0, "stock block lower x, work coordinates"),
        _p("stock_y_min", "m", 0.0, "stock block lower y, work coordinates"),
        _p("stock_z_min", "m", 0.0, "stock block lower z, work coordinates"),
        _p("stock_x_max", "m", 0.0, "stock block upper x (zero volume = air cutting only)"),
        _p("stock_y_max", "m", 0.0, "stock block upper y"),
        _p("stock_z_max", "m", 0.0, "stock block upper z (top face)"),
        _p("stock_cell", "m", 1e-4, "Z-map cell edge (upper bound; cells divide the block exactly)"),
        _p("angle_steps_per_tooth", "1", 36, "spindle-angle samples per tooth pitch", "Integer"),
        _p("initial_spindle_angle", "rad", 0.0, "angle of tooth 0 at t0, clockwise from +y"),
        # effect terms (diagnosis, issue 8): all 0 = off = the paper's model
        _p("runout_eccentricity", "m", 0.0, "cutter eccentricity (runout); 0 = off"),
        _p("runout_phase", "rad", 0.0, "angle of the eccentricity from tooth 0, clockwise like phi"),
        _p("helix_angle", "rad", 0.0, "flute helix angle (lag along the axial depth); 0 = straight flutes"),
        _p("edge_force_tangential", "N/m", 0.0, "tangential edge (ploughing) force per axial depth, Kte; 0 = off"),
        _p("edge_force_radial", "N/m", 0.0, "radial edge (ploughing) force per axial depth, Kre; 0 = off"),
        _p("tool_stiffness", "N/m", 0.0, "static tool bending stiffness; 0 = rigid tool"),
        _p("wear_rate", "1/s", 0.0, "growth of the cutting coefficients per second of cutting time; 0 = off"),
        _p("spindle_droop", "rad/(s.N.m)", 0.0, "spindle speed drop per cutting torque; 0 = off"),
        _p("chatter_frequency", "Hz", 0.0, "natural frequency of the tool mode (x and y); 0 = no chatter"),
        _p("chatter_damping", "1", 0.0, "damping ratio of the tool mode"),
        _p("chatter_stiffness", "N/m", 0.0, "modal stiffness of the tool mode"),
        *table_variables(),
        Variable("x_position", "input", "m", 0.0, "actual tool-tip x, work coordinates"),
        Variable("y_position", "input", "m", 0.0, "actual tool-tip y, work coordinates"),
        Variable("z_position", "input", "m", 0.0, "actual tool-tip z, work coordinates"),
        Variable("spindle_speed", "input", "rad/s", 0.0, "actual spindle speed (M03 positive)"),
        Variable("tool", "input", "1", 0, "tool in the spindle (T number, the NC kernel's tool): its cutter from "
                 "the tool table (tool_<i>_*), tool_diameter and flutes when unlisted", "Integer"),
        Variable("fx", "output", "N", 0.0, "x force on the workpiece at t + h"),
        Variable("fy", "output", "N", 0.0, "y force on the workpiece at t + h"),
        Variable("fc", "output", "N", 0.0, "cutting load sqrt(fx^2 + fy^2) at t + h (Eq. 13)"),
        Variable("fc_peak", "output", "N", 0.0, "largest cutting load within the last step"),
        Variable("fx_mean", "output", "N", 0.0, "x force on the workpiece, mean over the last step"),
        Variable("fy_mean", "output", "N", 0.0, "y force on the workpiece, mean over the last step"),
        Variable("spindle_torque", "output", "N.m", 0.0, "cutting torque on the spindle, mean over the last step"),
        Variable("spindle_power", "output", "W", 0.0, "cutting power, mean over the last step"),
        Variable("mrr", "output", "m3/s", 0.0, "material removal rate, mean over the last step"),
        Variable("spindle_angle", "output", "rad", 0.0, "angle of tooth 0 at t + h, [0, 2 pi)"),
        Variable("axial_depth", "output", "m", 0.0, "largest axial depth over engaged teeth at t + h"),
        Variable("chip_thickness", "output", "m", 0.0, "largest chip thickness over engaged teeth at t + h"),
        Variable("engaged_teeth", "output", "1", 0, "teeth in material with a positive chip at t + h", "Integer"),
        Variable("spindle_speed_actual", "output", "rad/s", 0.0,
                 "spindle speed under load over the last step (= spindle_speed without droop)"),
        Variable("tool_vibration_x", "output", "m", 0.0, "x displacement of the tool mode at t + h (chatter)"),
        Variable("tool_vibration_y", "output", "m", 0.0, "y displacement of the tool mode at t + h (chatter)"),
        Variable("cutting_time", "output", "s", 0.0, "time with material removal since t0 (tool wear clock)"),
        Variable("fz", "output", "N", 0.0,
                 "z force on the workpiece (end-edge thrust of the axial chip, <= 0), mean over the last step"),
    )

    # ------------------------------------------------------------------ lifecycle
    def _setup(self, t0: float) -> None:
        v = self.values
        self._check_parameters()
        # the cutter in the spindle per member (own arrays: a tool change replaces them in place)
        self._radius = np.array(0.5 * np.asarray(v["tool_diameter"], dtype=np.float64))
        self._flutes = np.array(np.broadcast_to(np.asarray(v["flutes"], dtype=np.int64), (self.batch,)))
        self._tools = ToolTable.from_values(v, self.batch, self.name, CuttingError)
        lower = np.stack([v["stock_x_min"], v["stock_y_min"], v["stock_z_min"]], axis=1)
        upper = np.stack([v["stock_x_max"], v["stock_y_max"], v["stock_z_max"]], axis=1)
        self.stock = ZMapStock(lower, upper, np.asarray(v["stock_cell"], dtype=np.float64))
        self._zmap = ZMapArrays.of(self.stock)
        position = self._position()
        spacing = PATH_SPACING * self._radius
        lag = self._radius + 2.0 * np.maximum(self.stock.dx, self.stock.dy)
        capacity = path_capacity(lag, spacing)
        if self._tools.listed:  # room for the near field of the smallest cutter of the table
            smallest = self._tools.smallest_radius()
            cell = 2.0 * np.maximum(self.stock.dx, self.stock.dy)
            capacity = max(capacity, path_capacity(smallest + cell, PATH_SPACING * smallest))
        self.path = SweptPath(position, spacing, lag, capacity)
        # motion state per member: the tool tip at the start of the step, then its chip history (kernel.chord_feed)
        self._motion = np.zeros((self.batch, 3 + CHIP_HISTORY_WIDTH))
        self._motion[:, :3] = position
        self._theta = np.mod(np.asarray(v["initial_spindle_angle"], dtype=np.float64), 2.0 * math.pi)
        self._setup_effects(self._theta)
        # the whole step compiled (zmap_component_step) when no effect term is on
        self._whole_step_compiled = self.use_compiled and self.effects_off()
        self._io = np.zeros((len(IO_ROWS), self.batch))
        self._kernel_status = np.zeros(self.batch, dtype=np.int64)
        self._kernel_diag = np.zeros((2, self.batch))
        # no motion known at t0: no chip, no force
        for name in ("fx", "fy", "fc", "fc_peak", "fx_mean", "fy_mean", "spindle_torque", "spindle_power",
                     "mrr", "axial_depth", "chip_thickness", "fz"):
            v[name][...] = 0.0
        v["engaged_teeth"][...] = 0
        v["spindle_angle"][...] = self._theta

    def _setup_effects(self, theta: np.ndarray) -> None:
        """Check the effect parameters and start their state (shared with the path mode)."""
        v = self.values
        self._eff = EffectParameters.from_values(v, self.name, CuttingError)
        self._effect_state = EffectState(self.batch, theta, self._eff.chatter)
        v["spindle_speed_actual"][...] = v["spindle_speed"]
        for name in ("tool_vibration_x", "tool_vibration_y", "cutting_time"):
            v[name][...] = 0.0

    def _actual_speed(self) -> np.ndarray:
        """Spindle speed under the previous step's torque, rad/s (the input itself without droop)."""
        cmd = np.asarray(self.values["spindle_speed"], dtype=np.float64)
        droop = self._eff.droop
        if not np.any(droop != 0):
            return cmd
        drop = droop * self._effect_state.torque
        return np.where((droop != 0) & (cmd > 0), np.maximum(cmd - drop, 0.0), cmd)

    def _wear(self) -> np.ndarray:
        """Factor on the cutting coefficients from tool wear, ``1 + rate t_cut`` (1 without wear)."""
        return 1.0 + self._eff.wear_rate * self._effect_state.cutting_time

    def _finish_effects(self, h: float, omega: np.ndarray, actual: np.ndarray) -> None:
        """Advance the effect clocks after a step and write their outputs."""
        v = self.values
        st = self._effect_state
        st.cutting_time += np.where(np.asarray(v["mrr"]) > 0.0, h, 0.0)
        st.torque[...] = v["spindle_torque"]
        st.angle += omega * h
        v["spindle_speed_actual"][...] = actual
        v["tool_vibration_x"][...] = st.mode[:, 0]
        v["tool_vibration_y"][...] = st.mode[:, 1]
        v["cutting_time"][...] = st.cutting_time

    def _reset(self) -> None:
        self.__dict__.pop("stock", None)
        self.__dict__.pop("path", None)
        self.__dict__.pop("_zmap", None)

    def _check_parameters(self) -> None:
        v = self.values
        checks = (
            ("tool_diameter", lambda a: np.isfinite(a) & (a > 0), "a positive length in m"),
            ("flutes", lambda a: a >= 1, "an integer >= 1"),
            ("kt", lambda a: np.isfinite(a) & (a >= 0), "a non-negative coefficient in N/m2"),
            ("ke", lambda a: np.isfinite(a), "a finite ratio"),
            ("ka", lambda a: np.isfinite(a) & (a >= 0), "a non-negative ratio"),
            ("angle_steps_per_tooth", lambda a: a >= 1, "an integer >= 1"),
            ("initial_spindle_angle", np.isfinite, "a finite angle in rad"),
        )
        for name, ok, expected in checks:
            values = np.asarray(v[name])
            bad = np.flatnonzero(~ok(values))
            if bad.size:
                raise CuttingError(
                    f"{self.name}.{name}: member {int(bad[0])} has {values[bad[0]]!r}; expected {expected}"
                )

    @property
    def _p_prev(self) -> np.ndarray:
        """Tool-tip position at the start of the step, shape (B, 3), m (a view of the motion state)."""
        return self._motion[:, :3]

    def _position(self) -> np.ndarray:
        v = self.values
        pos = np.stack([v["x_position"], v["y_position"], v["z_position"]], axis=1).astype(np.float64)
        if not np.all(np.isfinite(pos)):
            bad = int(np.flatnonzero(~np.isfinite(pos).all(axis=1))[0])
            raise CuttingError(f"{self.name}: tool position of member {bad} is {pos[bad].tolist()}; expected finite m")
        return pos

    # ------------------------------------------------------------------ step
    def _substeps(self, omega: np.ndarray, move: np.ndarray, h: float) -> np.ndarray:
        """Substeps each member needs for a step, shape (B,) int (capped at ``MAX_SUBSTEPS + 1``).

        Parameters
        ----------
        omega : ndarray, shape (B,)
            Spindle speed over the step, rad/s (>= 0).
        move : ndarray, shape (B,)
            XY tool move over the step, m.
        h : float
            Step length, s.
        """
        steps = np.asarray(self.values["angle_steps_per_tooth"], dtype=np.float64)
        pitch = 2.0 * math.pi / self._flutes
        # at most pitch/steps and at most pi/2 per substep (interval_mean_quantities needs < pi)
        n_angle = np.ceil(omega * h / np.minimum(pitch / steps, 0.5 * math.pi) - 1e-9)
        n_move = np.ceil(move / (0.05 * self._radius) - 1e-9)
        # the tool mode (chatter) is stepped exactly per substep under the substep-mean force
        n_mode = np.ceil(h * self._eff.chatter_wn / (2.0 * math.pi) * CHATTER_SUBSTEPS_PER_PERIOD - 1e-9)
        n = np.maximum(np.maximum(np.maximum(n_angle, n_move), n_mode), 1.0)
        return np.minimum(n, MAX_SUBSTEPS + 1.0).astype(np.int64)

    def _fail_substeps(self, bad: np.ndarray, omega: np.ndarray, move: np.ndarray, h: float) -> None:
        """Fail the members ``bad`` (shape (B,) bool) needing over ``MAX_SUBSTEPS`` (raises when none is left)."""
        m = int(np.flatnonzero(bad)[0])
        more = "" if bad.sum() == 1 else f" (and {int(bad.sum()) - 1} more)"
        reason = (f"{self.name}: step of {h} s of member {m}{more} needs more than {MAX_SUBSTEPS} substeps "
                  f"(spindle speed {omega[m]:.4g} rad/s, tool move {move[m]:.4g} m); expected a spindle speed "
                  "and a tool move per step within that (one is far too large)")
        self.fail_members(bad, reason, CuttingError)

    def stalled_reason(self, m: int, h: float) -> str:
        """Why member ``m`` fails when its step ``[t, t + h]`` fed into material with a stalled spindle.

        Names the component, the time ``t + h`` (s), the tool-tip position there
        (work coordinates, mm) and the spindle speed input (rpm); the same text
        whichever kernel or master loop stepped the member.
        """
        v = self.values
        speed = float(np.asarray(v["spindle_speed"])[m])
        rpm = speed * 60.0 / (2.0 * math.pi)
        x, y, z = (float(np.asarray(v[f"{a}_position"])[m]) * 1e3 for a in "xyz")
        if speed < 0.0:
            how = f"with the spindle turning backwards ({rpm:.4g} rpm, M4; the case's end mill cuts clockwise)"
        else:
            how = f"with the spindle stopped ({abs(rpm):.3g} rpm)"
        return (f"{self.name}: the tool feeds into the stock {how} at t = {self._t_step + h:.6f} s, tool at "
                f"X{x:.3f} Y{y:.3f} Z{z:.3f} mm: a crash; start the spindle (M3) before the cut")

    def _fail_stalled(self, bad: np.ndarray, h: float) -> None:
        """Fail the members ``bad`` (shape (B,) bool) that fed into material with a stalled spindle, each with
        its own :meth:`stalled_reason` (raises when none is left)."""
        for m in np.flatnonzero(bad):
            mask = np.zeros(self.batch, dtype=bool)
            mask[m] = True
            self.fail_members(mask, self.stalled_reason(int(m), h), CuttingError)

    def _step_inputs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Tool position (B, 3) m, actual spindle speed (B,) rad/s and the members with non-finite inputs.

        Non-finite inputs come from a member that failed or diverged upstream (the
        master reports it with the reason): that member is held where it was, with
        the spindle stopped, and its outputs are blanked to NaN after the step.
        """
        v = self.values
        p_new = np.stack([v["x_position"], v["y_position"], v["z_position"]], axis=1).astype(np.float64)
        actual = np.asarray(self._actual_speed(), dtype=np.float64)
        lost = ~(np.isfinite(p_new).all(axis=1) & np.isfinite(actual))
        if lost.any():
            p_new[lost] = self._p_prev[lost]
            actual = np.where(lost, 0.0, actual)
        return p_new, actual, lost

    def _blank(self, lost: np.ndarray) -> None:
        """NaN outputs (spindle angle kept, no engaged tooth) for the members in ``lost``, shape (B,)."""
        for var in self.declared_variables():
            if var.causality == "output" and var.name != "spindle_angle":
                self.values[var.name][lost] = 0 if var.type == "Integer" else np.nan

    def _geometric_members(self) -> np.ndarray:
        """Members with a term that changes the chip or the force law (runout, helix, edge, deflection, chatter)."""
        e = self._eff
        return ((e.eccentricity != 0) | (e.tan_helix != 0) | (e.kte != 0) | (e.kre != 0) | (e.stiffness != 0)
                | (e.chatter_wn != 0))

    def effects_off(self) -> bool:
        """Every parameter beyond :data:`BASELINE_PARAMETERS` is at its off value (0) for every member."""
        return all(np.all(np.asarray(self.values[name]) == 0)
                   for name in self.names("parameter") if name not in BASELINE_PARAMETERS)

    def compiled_step_arrays(self) -> tuple:
        """The arrays :func:`.zmap_numba.zmap_component_step` steps, after ``io``, without ``failed``.

        The component's own arrays (stock heights, path ring buffer, motion state (start position and
        chip history), spindle angle, effect clocks, failure status, the cutter in the spindle (radius,
        teeth) and the path's ``spacing`` and ``lag``, which a tool change replaces) are returned, not copies,
        so the compiled master loop can step them in place; the coefficients are fresh arrays; the tool table
        (:class:`.tool_table.ToolTable`) comes last.
        """
        v = self.values
        z = self._zmap
        path = self.path
        st = self._effect_state
        return (z.heights, z.grid, z.cells, z.rho, path.points, path.arc, path.head, path.count,
                np.ascontiguousarray(path.spacing, dtype=np.float64), np.ascontiguousarray(path.lag, dtype=np.float64),
                self._motion, self._theta, np.ascontiguousarray(self._radius, dtype=np.float64),
                np.ascontiguousarray(self._flutes, dtype=np.int64),
                np.array(v["angle_steps_per_tooth"], dtype=np.float64), np.array(v["kt"], dtype=np.float64),
                np.array(v["ke"], dtype=np.float64), np.array(v["ka"], dtype=np.float64), st.cutting_time,
                st.torque, st.angle, self._kernel_status, self._kernel_diag, int(MAX_SUBSTEPS), self._tools.number,
                self._tools.radius, self._tools.flutes)

    def fail_kernel_substeps(self, h: float) -> None:
        """Fail the members :func:`.zmap_numba.zmap_component_step` reported; clear them.

        First those needing too many substeps (``ERR_SUBSTEPS``, held by the kernel), then those that fed
        into material with a stalled spindle (``ERR_STALLED``), as :meth:`_do_step` does.
        """
        status = self._kernel_status
        over = status == ERR_SUBSTEPS
        stalled = status == ERR_STALLED
        status[...] = 0
        if over.any():
            self._fail_substeps(over, self._kernel_diag[0].copy(), self._kernel_diag[1].copy(), h)
        if stalled.any():
            self._fail_stalled(stalled, h)

    def _switch_tools(self) -> None:
        """Each member takes the cutter of the tool in its spindle (the ``tool`` input) from the tool table.

        A member whose radius or teeth change first commits its recent path with the old cutter
        (:meth:`_flush_path`); its near-field spacing and lag become the new cutter's. The numpy form of
        :func:`.zmap_numba.switch_tool` (the same numbers).
        """
        table = self._tools
        if not table.listed:
            return
        k = slots(table, self.values["tool"])
        rows = np.arange(self.batch)
        r_new = table.radius[rows, k]
        z_new = table.flutes[rows, k]
        change = (r_new != self._radius) | (z_new != self._flutes)
        if not change.any():
            return
        self._flush_path(change)
        self._radius[change] = r_new[change]
        self._flutes[change] = z_new[change]
        self.path.spacing[change] = PATH_SPACING * r_new[change]
        self.path.lag[change] = r_new[change] + 2.0 * np.maximum(self.stock.dx, self.stock.dy)[change]

    def _flush_path(self, mask: np.ndarray) -> None:
        """Commit the whole recent path of the members ``mask`` (shape (B,) bool), to the tool at the step's
        start, to the Z-map with their current radius (a tool change; :func:`.zmap_numba.flush_member`)."""
        if self.use_compiled:
            flush(self._zmap, self.path, mask, self._p_prev, self._radius)
            return
        path = self.path
        p = self._p_prev
        rows = np.flatnonzero(mask)
        last_i = path._index(path.count - 1)[rows]  # noqa: SLF001 - the ring buffer's own indexing
        new_i = (path.head[rows] + path.count[rows]) % path.capacity
        step = np.hypot(p[rows, 0] - path.points[rows, last_i, 0], p[rows, 1] - path.points[rows, last_i, 1])
        path.points[rows, new_i] = p[rows]
        path.arc[rows, new_i] = path.arc[rows, last_i] + step
        path.count[rows] += 1
        every = np.arange(self.batch)
        while True:
            pop = mask & (path.count >= 2)
            if not pop.any():
                break
            first = path.points[every, path.head]
            second = path.points[every, (path.head + 1) % path.capacity]
            path.head = np.where(pop, (path.head + 1) % path.capacity, path.head)
            path.count = np.where(pop, path.count - 1, path.count)
            self.stock.remove_sweep(first, second, self._radius, pop)
        # the previous tool position (the slot after the last point, SweptPath.advance) is the tool's
        path.points[rows, (path.head[rows] + path.count[rows]) % path.capacity] = p[rows]

    def _do_step(self, t: float, h: float) -> None:
        if self._whole_step_compiled:
            self._do_step_compiled(h)
            return
        self._switch_tools()
        v = self.values
        p_new, actual, held = self._step_inputs()
        failed = self.failed_members & ~held
        if failed.any():  # failed here earlier: held still like a lost member, outputs NaN
            p_new[failed] = self._p_prev[failed]
            actual = np.where(failed, 0.0, actual)
            held = held | failed
        omega = np.maximum(actual, 0.0)
        dp = p_new - self._p_prev
        move = np.hypot(dp[:, 0], dp[:, 1])
        n = self._substeps(omega, move, h)
        too_many = (n > MAX_SUBSTEPS) & ~held
        if too_many.any():
            self._fail_substeps(too_many, omega, move, h)
            p_new[too_many] = self._p_prev[too_many]
            actual = np.where(too_many, 0.0, actual)
            omega = np.where(too_many, 0.0, omega)
            held = held | too_many
        feed = chord_feeds(self._motion[:, 3:], dp, h, omega, self._flutes)
        r = self._cut(p_new, omega, h, n, held, feed)
        ax = self._axial(p_new, omega, h, held)  # the end edges (axial chip), before the commit
        torque = r.mean[:, 2] + ax[:, AX_TORQUE]
        v["fx"][...] = -r.force[:, 0]
        v["fy"][...] = -r.force[:, 1]
        v["fc"][...] = np.hypot(r.force[:, 0], r.force[:, 1])
        v["fc_peak"][...] = r.fc_peak
        v["fx_mean"][...] = -r.mean[:, 0]
        v["fy_mean"][...] = -r.mean[:, 1]
        v["spindle_torque"][...] = torque
        v["spindle_power"][...] = torque * omega
        v["mrr"][...] = r.mean[:, 3] + ax[:, AX_MRR]
        v["fz"][...] = -ax[:, AX_THRUST]
        v["axial_depth"][...] = r.axial_depth
        v["chip_thickness"][...] = r.chip_thickness
        v["engaged_teeth"][...] = r.engaged_teeth
        self._theta = np.mod(self._theta + omega * h, 2.0 * math.pi)
        v["spindle_angle"][...] = self._theta
        self._finish_effects(h, omega, actual)
        chord_advance_all(self._motion[:, 3:], h, dp, omega, held)
        self._motion[:, :3] = p_new
        self._commit(p_new)
        if held.any():
            self._blank(held)
        stalled = ~held & (stalled_cuts(omega, r.fc_peak, r.mean[:, 0], r.mean[:, 1])
                           | stalled_plunges(omega, ax[:, AX_MRR]))
        if stalled.any():
            self._fail_stalled(stalled, h)

    def _do_step_compiled(self, h: float) -> None:
        """:meth:`_do_step` with every effect term off, in one compiled call (the same numbers)."""
        v = self.values
        io = self._io
        for r in IO_INPUTS:
            io[r] = v[IO_ROWS[r]]
        arrays = self.compiled_step_arrays()
        n_bad = zmap_component_step(h, io, *arrays[:18], self.failed_members, *arrays[18:])
        for r in range(IO_FX, IO_FZ + 1):  # outputs
            v[IO_ROWS[r]][...] = io[r]
        if n_bad:
            self.fail_kernel_substeps(h)

    def _axial(self, p_new: np.ndarray, omega: np.ndarray, h: float, held: np.ndarray) -> np.ndarray:
        """End-edge thrust on the tool (N), torque (N.m) and removal rate (m3/s) of every member, shape (B, 3).

        :func:`.axial.axial_cuts` on the stock and the recent path before this step's commit (columns
        ``AX_THRUST``, ``AX_TORQUE``, ``AX_MRR``); ``Kt`` with tool wear, as the periphery's.
        """
        v = self.values
        z = self._zmap
        path = self.path
        kt = np.asarray(v["kt"], dtype=np.float64) * self._wear()
        ka = np.asarray(v["ka"], dtype=np.float64)
        ones = np.ones(self.batch)
        return axial_cuts(z.heights, z.grid, z.cells, *_ring(path), np.ascontiguousarray(self._p_prev),
                          np.ascontiguousarray(p_new), np.ascontiguousarray(self._radius, dtype=np.float64),
                          np.ascontiguousarray(omega, dtype=np.float64), kt * ones, ka * ones, float(h),
                          np.ascontiguousarray(held))

    def _cut(self, p_new: np.ndarray, omega: np.ndarray, h: float, n: np.ndarray, held: np.ndarray,
             feed: np.ndarray) -> StepResult:
        """Kernel results of one step for every member.

        Parameters
        ----------
        p_new : ndarray, shape (B, 3)
            Tool-tip position at ``t + h``, m.
        omega : ndarray, shape (B,)
            Spindle speed over the step, rad/s (>= 0).
        h : float
            Step length, s.
        n : ndarray of int, shape (B,)
            Substeps per member (:meth:`_substeps`).
        held : ndarray of bool, shape (B,)
            Members not computed (lost or failed): zero results.
        feed : ndarray, shape (B, 2)
            Feed per tooth vector (the tooth-period chord, :func:`.kernel.chord_feeds`), m.

        Returns
        -------
        StepResult
            Shapes (B, ...). One kernel call per kernel in use: members with an
            effect term that changes the chip or the force law run in
            :func:`.kernel_effects.cut_step_effects`, the others in
            :func:`.kernel.cut_step`, as each would alone.
        """
        geometric = self._geometric_members()
        # the compiled kernel reads the path's ring buffer itself
        near = self.path.near_field() if (geometric.any() or not self.use_compiled) else None
        live = ~held
        if live.all() and (geometric.all() or not geometric.any()):
            return self._cut_rows(None, near, p_new, omega, h, n, bool(geometric[0]), feed)
        B = self.batch
        force, mean = np.zeros((B, 2)), np.zeros((B, 4))
        peak, axial, chip = np.zeros(B), np.zeros(B), np.zeros(B)
        engaged = np.zeros(B, dtype=np.int64)
        for kind in (False, True):
            rows = np.flatnonzero(live & (geometric == kind))
            if rows.size == 0:
                continue
            r = self._cut_rows(rows, near, p_new, omega, h, n, kind, feed)
            force[rows], mean[rows], peak[rows] = r.force, r.mean, r.fc_peak
            axial[rows], chip[rows], engaged[rows] = r.axial_depth, r.chip_thickness, r.engaged_teeth
        return StepResult(force=force, fc_peak=peak, mean=mean, axial_depth=axial, chip_thickness=chip,
                          engaged_teeth=engaged)

    def _cut_rows(self, rows: np.ndarray | None, near: NearField | None, p_new: np.ndarray, omega: np.ndarray,
                  h: float, n: np.ndarray, geometric: bool, feed: np.ndarray) -> StepResult:
        """One kernel call for the members ``rows`` (``None``: all); ``n``, ``feed`` as :meth:`_cut`.

        ``near`` is the path's near field (``None`` only with :attr:`use_compiled` and no effect terms).
        """
        v = self.values
        sel = slice(None) if rows is None else rows
        wear = self._wear()[sel]
        kt = np.asarray(v["kt"], dtype=np.float64)[sel] * wear
        ke = np.asarray(v["ke"], dtype=np.float64)[sel]
        if geometric:
            coefficients = np.stack([kt, ke, self._eff.kte[sel] * wear, self._eff.kre[sel] * wear])
            # the surfaces left 1 .. passes teeth back: the tool-centre displacement since each was left
            flutes = np.ascontiguousarray(self._flutes[sel])
            back = np.zeros((flutes.shape[0], MAX_PASSES, 2))
            chords_back_all(np.ascontiguousarray(self._motion[sel, 3:]), p_new[sel] - self._p_prev[sel], h,
                            np.ascontiguousarray(omega[sel], dtype=np.float64), flutes,
                            np.ascontiguousarray(feed[sel]), self._eff.passes(self._flutes)[sel], back)
            return cut_step_effects(
                self.stock, near, self._p_prev[sel], p_new[sel], self._theta[sel], omega[sel], h, n[sel],
                self._radius[sel], self._flutes[sel],
                np.asarray(v["angle_steps_per_tooth"], dtype=np.float64)[sel], coefficients, self._eff,
                self._effect_state, np.asarray(v["stock_z_max"], dtype=np.float64)[sel], rows, feed[sel], back,
            )
        if self.use_compiled:
            return cut_step_compiled(self._zmap, self.path, self._p_prev[sel], p_new[sel], self._theta[sel],
                                     omega[sel], h, n[sel], self._radius[sel], self._flutes[sel], kt, ke, rows,
                                     feed[sel])
        near = self.path.near_field() if near is None else near
        return cut_step(self.stock, near, self._p_prev[sel], p_new[sel], self._theta[sel], omega[sel], h, n[sel],
                        self._radius[sel], self._flutes[sel], kt, ke, rows, feed[sel])

    def _commit(self, position: np.ndarray) -> None:
        """Store the new tool position and move old path segments into the Z-map."""
        if self.use_compiled:
            commit(self._zmap, self.path, position, self._radius)
            return
        self.path.advance(position)
        while True:
            start, end, mask = self.path.pop_ready(force_room=True)
            if not np.any(mask):
                break
            self.stock.remove_sweep(start, end, self._radius, mask)
