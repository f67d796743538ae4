"""``PathCuttingLoad``: the cutting load of a batch that follows one tool path, from an engagement table.

Same inputs, outputs, units and mechanics as :class:`.component.CuttingLoad`,
and the same parameters (so the twin can pass ``cutting_parameters(case)``
unchanged) plus ``engagement_table`` and ``path_tolerance``. Instead of a
Z-map per member, all members read one :class:`.table.EngagementTable`
built once by a reference pass along the path (see :mod:`.table`); each
member has its own position on the path (arc length), spindle angle, chip
thickness (feed per tooth from its own displacement and spindle speed),
flutes, ``Kt`` and ``Ke``. The whole batch advances in one compiled call
(:func:`.path_kernel.path_step`).

Valid when every member follows the reference path up to small deviations
(following error, corner rounding): engagement is read at the member's
projection on the path, so a lateral offset ``e`` changes the radial
immersion by ``e`` that the table does not see. A member farther than
``path_tolerance`` from the path where the table has material is an error.

The effect terms are those of :class:`.component.CuttingLoad` (same
parameters and outputs); with runout, helix, edge force, deflection or
chatter on the step runs in :func:`.path_effects.path_step_effects`.

Several cutters (a tool table): a table built with the cutter of each path
point (:func:`.table.build_engagement_table`'s ``cutters``) gives each
station's radius and teeth, and every member cuts with the cutter of the
station it is at (:func:`.path_kernel.station_cutters`); each of them must be
in the members' tool table, and the effect terms that depend on the teeth
(runout, helix, edge force, deflection, chatter) are refused with them.

The table is handed over either as a Python object
(:meth:`PathCuttingLoad.attach_table`, before ``setup``) or as an ``.npz``
file named by the String parameter ``engagement_table`` (FMU use).
"""
from __future__ import annotations

import math

import numpy as np

from ..component import Variable
from . import path_kernel as pk
from .component import MAX_SUBSTEPS, CuttingError, CuttingLoad
from .effect_model import HISTORY_PER_PITCH, runout_reach
from .path_axial import path_axial
from .path_effects import path_step_effects
from .table import EngagementTable
from .tool_table import ToolTable

#: Relative mismatch of tool radius / stock tolerated between parameters and table.
MATCH_TOL = 1e-9

_INPUTS = ("x_position", "y_position", "z_position", "spindle_speed")
_OUTPUTS = ("fx", "fy", "fc", "fc_peak", "fx_mean", "fy_mean", "spindle_torque", "spindle_power", "mrr",
            "spindle_angle", "axial_depth", "chip_thickness")


class PathCuttingLoad(CuttingLoad):
    """Cutting load of a batch on one tool path, from a shared engagement table (see module docstring).

    Variables
    ---------
    Those of :class:`.component.CuttingLoad` plus the parameters
    ``engagement_table`` (String, ``.npz`` path; empty when attached in Python)
    and ``path_tolerance`` (m). ``stock_cell`` and the stock block are checked
    against the table (they are the table's, not re-used).
    """

    variables = CuttingLoad.variables + (
        Variable("engagement_table", "parameter", "1", "", "engagement table file (.npz) of the tool path", "String"),
        Variable("path_tolerance", "parameter", "m", 5e-4,
                 "largest distance of the tool from the reference path where the table has material"),
    )

    def __init__(self, name: str = "", batch: int = 1, **parameters: object) -> None:
        self._table: EngagementTable | None = None
        super().__init__(name, batch, **parameters)

    # ------------------------------------------------------------------ packed storage
    def _load_start_values(self) -> None:
        """Start values, with inputs and real outputs as rows of two packed arrays (one kernel call)."""
        super()._load_start_values()
        self._inp = np.stack([np.asarray(self.values[n], dtype=np.float64) for n in _INPUTS])
        self._out = np.stack([np.asarray(self.values[n], dtype=np.float64) for n in _OUTPUTS])
        for i, n in enumerate(_INPUTS):
            self.values[n] = self._inp[i]
        for i, n in enumerate(_OUTPUTS):
            self.values[n] = self._out[i]

    # ------------------------------------------------------------------ table
    def attach_table(self, table: EngagementTable) -> None:
        """Use ``table`` (shared, not copied) for the next ``setup``; overrides ``engagement_table``."""
        if self.state != "instantiated":
            raise CuttingError(f"{self.name}: attach_table() must be called before setup()")
        self._table = table

    @property
    def table(self) -> EngagementTable:
        """The engagement table in use."""
        if self._table is None:
            raise CuttingError(f"{self.name}: no engagement table; call attach_table() or set engagement_table")
        return self._table

    def _check_table(self, table: EngagementTable) -> None:
        v = self.values
        radius = 0.5 * np.asarray(v["tool_diameter"], dtype=np.float64)
        if not np.allclose(radius, table.radius, rtol=MATCH_TOL, atol=0.0):
            raise CuttingError(
                f"{self.name}.tool_diameter: {sorted(set((2 * radius).tolist()))} m; the engagement table was built "
                f"for {2 * table.radius} m"
            )
        for k, a in enumerate("xyz"):
            for side, ref in (("min", table.stock_lower[k]), ("max", table.stock_upper[k])):
                name = f"stock_{a}_{side}"
                got = np.asarray(v[name], dtype=np.float64)
                if not np.allclose(got, ref, rtol=MATCH_TOL, atol=1e-12):
                    raise CuttingError(
                        f"{self.name}.{name}: {sorted(set(got.tolist()))} m; the engagement table was built for "
                        f"{ref} m (rebuild the table for this stock)"
                    )

    def _check_cutters(self, table: EngagementTable) -> None:
        """The members' tool table matches the engagement table's cutters.

        A table of one cutter: the tool table lists no cutter other than ``tool_diameter`` / ``flutes``. A
        table of several cutters (:attr:`.table.EngagementTable.several_cutters`): every station's cutter is
        one of each member's tool table (``tool_diameter`` / ``flutes`` or a listed slot), and no effect term
        that depends on the teeth (runout, helix, edge force, deflection, chatter) is on.
        """
        tools = ToolTable.from_values(self.values, self.batch, self.name, CuttingError)
        if table.several_cutters:
            for r, z in table.cutters():
                have = (np.abs(tools.radius - r) <= MATCH_TOL * r) & (tools.flutes == z) & (tools.number != 0)
                missing = np.flatnonzero(~have.any(axis=1))
                if missing.size:
                    raise CuttingError(
                        f"{self.name}: the engagement table's path is cut with a {2e3 * r:g} mm, {z}-flute cutter "
                        f"that member {int(missing[0])}'s tool table (tool_diameter / flutes, tool_<i>_*) does not "
                        "list; expected the tool table the engagement table was built with")
            if self._eff.geometric:
                raise CuttingError(
                    f"{self.name}: the engagement table's path is cut with several cutters and an effect term "
                    "that depends on the teeth (runout, helix, edge force, deflection or chatter) is on; the path "
                    "mode models those for one cutter: run this program on the Z-map cutting load (CuttingLoad)")
            return
        other = (tools.radius != tools.radius[:, :1]) | (tools.flutes != tools.flutes[:, :1])
        if other.any():
            m, k = (int(i[0]) for i in np.nonzero(other))
            raise CuttingError(
                f"{self.name}: the tool table lists T{int(tools.number[m, k])} ({2e3 * tools.radius[m, k]:g} mm, "
                f"{int(tools.flutes[m, k])} flutes) beside the {2e3 * tools.radius[m, 0]:g} mm, "
                f"{int(tools.flutes[m, 0])}-flute tool_diameter / flutes, but the engagement table was built for one "
                "cutter: build it with the cutter of each path point (build_engagement_table's cutters, "
                "orchestrator.twin.engagement_table does) or run on the Z-map cutting load (CuttingLoad)")

    # ------------------------------------------------------------------ lifecycle
    def _setup(self, t0: float) -> None:
        v = self.values
        self._check_parameters()
        tol = np.asarray(v["path_tolerance"], dtype=np.float64)
        if not np.all(np.isfinite(tol) & (tol > 0)):
            raise CuttingError(f"{self.name}.path_tolerance: {tol.tolist()}; expected a positive length in m")
        if self._table is None:
            fname = str(v["engagement_table"])
            if not fname:
                raise CuttingError(f"{self.name}: no engagement table; call attach_table() or set engagement_table "
                                   "to an .npz written by EngagementTable.save")
            self._table = EngagementTable.load(fname)
        table = self._table
        self._check_table(table)
        position = self._position()
        self._par = np.stack([
            0.5 * np.asarray(v["tool_diameter"], dtype=np.float64),
            np.asarray(v["flutes"], dtype=np.float64),
            np.asarray(v["kt"], dtype=np.float64),
            np.asarray(v["ke"], dtype=np.float64),
            np.asarray(v["angle_steps_per_tooth"], dtype=np.float64),
        ])
        self._st = np.zeros((pk.ST_ROWS, self.batch))  # state rows ST_*, the chip history empty
        self._status = np.zeros(self.batch, dtype=np.int64)  # per-member error kind of the last step
        self._ka = np.array(np.broadcast_to(np.asarray(v["ka"], dtype=np.float64), (self.batch,)))
        self._z_old = np.zeros(self.batch)  # tip height at the step's start (the end edges, path_axial)
        v["fz"][...] = 0.0
        theta = np.mod(np.asarray(v["initial_spindle_angle"], dtype=np.float64), 2.0 * math.pi)
        self._st[pk.ST_THETA] = theta
        self._st[pk.ST_X:pk.ST_Z + 1] = position.T
        for m in range(self.batch):  # global search once: nearest point, smallest s among ties
            seg, s, dist = pk.locate(position[m, 0], position[m, 1], position[m, 2], 0, 0.0, math.inf,
                                     table.vertices, table.vertex_s)
            self._st[pk.ST_SEG, m] = seg
            self._st[pk.ST_S, m] = s
            self._st[pk.ST_DIST, m] = dist
        self._tolerance = float(tol.min())
        self._margin = max(4.0 * table.spacing, 1e-4)
        self._out[...] = 0.0
        self._out[pk.OUT_ANGLE] = theta
        v["engaged_teeth"][...] = 0
        self._setup_effects(theta)
        self._check_cutters(table)
        flutes = np.asarray(v["flutes"], dtype=np.int64)
        self._runout = self._eff.runout_offsets(flutes, int(flutes.max()))
        self._passes = self._eff.passes(flutes)
        # a tooth standing out by runout is tested for material in the table's runout ring (built once)
        self._reach, _ = runout_reach(self._runout, self._passes, self._eff.radius_offsets(flutes, int(flutes.max())))
        self._ring = table.runout_ring() if np.any(self._reach > 0.0) else table
        self._epar = self._eff.packed()
        self._gap = 2.0 * math.pi / flutes / HISTORY_PER_PITCH

    def _reset(self) -> None:
        self.__dict__.pop("_st", None)

    # ------------------------------------------------------------------ step
    def _do_step(self, t: float, h: float) -> None:
        tb = self._table
        eff = self._eff
        actual = self._actual_speed()
        inp = self._inp
        if np.any(eff.droop != 0):
            inp = self._inp.copy()
            inp[3] = actual
        pk.station_cutters(self._par, self._st, tb.cutter_radius, tb.cutter_flutes, tb.spacing)  # several cutters
        par = self._par
        wear = self._wear()
        if np.any(eff.wear_rate != 0):
            par = self._par.copy()
            par[pk.PAR_KT] *= wear
        self._z_old[...] = self._st[pk.ST_Z]
        if eff.geometric:
            es = self._effect_state
            coef = np.stack([par[pk.PAR_KT], par[pk.PAR_KE], eff.kte * wear, eff.kre * wear])
            code = path_step_effects(
                h, inp, par, self._st, self._out, self.values["engaged_teeth"], tb.vertices, tb.vertex_s,
                tb.spacing, tb.count, tb.alpha, tb.beta, tb.top, tb.z_floor, float(tb.stock_upper[2]), self._margin,
                self._tolerance, MAX_SUBSTEPS, coef, self._epar, self._runout, self._passes, es.mode, es.ht, es.hx,
                es.hy, es.meta, es.angle, self._gap, self._status, self._ring.count, self._ring.alpha,
                self._ring.beta, self._ring.top, self._reach,
            )
        else:
            code = pk.path_step(
                h, inp, par, self._st, self._out, self.values["engaged_teeth"], tb.vertices, tb.vertex_s,
                tb.spacing, tb.count, tb.alpha, tb.beta, tb.top, tb.z_floor, self._margin, self._tolerance,
                MAX_SUBSTEPS, self._status,
            )
        path_axial(self._out, self.values["fz"], self._st, self._z_old, inp, par, self._ka, h, tb.axial_area,
                   tb.axial_span, tb.spacing)  # the end edges (axial chip), from the table's stations
        self._finish_effects(h, np.maximum(actual, 0.0), actual)
        if code:
            self._fail_status(h)

    def _fail_status(self, h: float) -> None:
        """Fail the members the kernel reported in ``_status`` with their reasons (raises when none is left)."""
        status = self._status
        for kind in np.unique(status[status != 0]):
            members = status == kind
            if kind == pk.ERR_STALLED:  # a crash: each member with its own time, position and speed
                status[members] = 0
                self._fail_stalled(members, h)
                continue
            m = int(np.flatnonzero(members)[0])
            p = self._inp[:3, m].tolist()
            more = "" if members.sum() == 1 else f" (and {int(members.sum()) - 1} more)"
            if kind == pk.ERR_SUBSTEPS:
                reason = (f"{self.name}: step of {h} s of member {m}{more} needs more than {MAX_SUBSTEPS} substeps "
                          f"(spindle speed {self._inp[3, m]:.4g} rad/s, position {p} m)")
            else:
                reason = (f"{self.name}: member {m}{more} at {p} m is farther than path_tolerance = {self._tolerance} m "
                          f"from the engagement table's path (last projection at s = {self._st[pk.ST_S, m]:.6g} m); "
                          "expected every member to follow the reference path")
            status[members] = 0
            self.fail_members(members, reason, CuttingError)
