"""``CuttingLoad``: milling force from the actual tool motion and a Z-map stock.

A thin adapter around :mod:`.stock`, :mod:`.engagement`, :mod:`.force` and
:mod:`.kernel` (the step itself).

Time discretisation of one communication step ``[t, t + h]``
-----------------------------------------------------------
* The position inputs read by ``do_step(t, h)`` are taken as the tool-tip
  position at ``t + h``; the tool moves linearly from the previous inputs to
  them. (With a Jacobi master, whose inputs are the drive outputs at ``t``,
  this delays the force by one step but does not change its magnitude.)
* The spindle speed input is held over the step; the spindle angle integrates
  it (``theta += omega h``, wrapped to ``[0, 2 pi)``).
* The step is cut into ``n`` substeps so that the spindle turns at most
  ``pitch / angle_steps_per_tooth`` and the tool moves at most ``R / 20`` per
  substep. Forces are evaluated at the ``n + 1`` substep instants.
* Step means (``fx_mean``, ``fy_mean``, torque, power, MRR) integrate each
  tooth exactly over each substep (closed-form integrals of the chip-thickness
  trigonometry, :func:`.force.interval_mean_quantities`, with the mean of the
  axial depths at the two ends); where a tooth enters or leaves material
  inside a substep the instant is located to 1/4096 of the substep (three
  rounds of 16 sections, vectorised over all teeth), so the
  means do not suffer from the angular sampling of the entry/exit jumps.
* ``fc_peak`` is the largest ``Fc`` over the substep instants of the step and
  over the entry/exit instants so located.
"""
from __future__ import annotations

import math

import numpy as np

from ..component import Component, Variable
from ..errors import CncTwinError
from .engagement import SweptPath
from .kernel import cut_step
from .stock import ZMapStock

#: Refuse steps needing more substeps than this (spindle speed or jump far too large).
MAX_SUBSTEPS = 100_000
#: XY spacing of the stored near-field path, as a fraction of the tool radius.
PATH_SPACING = 0.1


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
    """

    variables = (
        _p("tool_diameter", "m", 6e-3, "flat end mill diameter"),
        _p("flutes", "1", 2, "number of teeth", "Integer"),
        _p("kt", "N/m2", 1.23e9, "tangential cutting coefficient (A6061, Sim & Lee 2023)"),
        _p("ke", "1", 0.5, "radial / tangential force ratio (A6061, Sim & Lee 2023)"),
        _p("stock_x_min", "m", 0.0, "stock block lower x, work coordinates"),
        _p("stock_y_min", "m", 0.0, "stock block lower y, work coordinates"),
        _p("stock_z_min", "m", 0.0, "stock block lower z, work coordinates"),
        _p("stock_x_max", "m", 0.0, "stock block upper x (zero volume = air cutting only)"),
        _p("stock_y_max", "m", 0.0, "stock block upper y"),
        _p("stock_z_max", "m", 0.0, "stock block upper z (top face)"),
        _p("stock_cell", "m", 1e-4, "Z-map cell edge (upper bound; cells divide the block exactly)"),
        _p("angle_steps_per_tooth", "1", 36, "spindle-angle samples per tooth pitch", "Integer"),
        _p("initial_spindle_angle", "rad", 0.0, "angle of tooth 0 at t0, clockwise from +y"),
        Variable("x_position", "input", "m", 0.0, "actual tool-tip x, work coordinates"),
        Variable("y_position", "input", "m", 0.0, "actual tool-tip y, work coordinates"),
        Variable("z_position", "input", "m", 0.0, "actual tool-tip z, work coordinates"),
        Variable("spindle_speed", "input", "rad/s", 0.0, "actual spindle speed (M03 positive)"),
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
    )

    # ------------------------------------------------------------------ lifecycle
    def _setup(self, t0: float) -> None:
        v = self.values
        self._check_parameters()
        self._radius = 0.5 * np.asarray(v["tool_diameter"], dtype=np.float64)
        self._flutes = np.asarray(v["flutes"], dtype=np.int64)
        lower = np.stack([v["stock_x_min"], v["stock_y_min"], v["stock_z_min"]], axis=1)
        upper = np.stack([v["stock_x_max"], v["stock_y_max"], v["stock_z_max"]], axis=1)
        self.stock = ZMapStock(lower, upper, np.asarray(v["stock_cell"], dtype=np.float64))
        position = self._position()
        spacing = PATH_SPACING * self._radius
        lag = self._radius + 2.0 * np.maximum(self.stock.dx, self.stock.dy)
        capacity = int(np.ceil(np.max(lag / spacing))) + 4
        self.path = SweptPath(position, spacing, lag, capacity)
        self._p_prev = position
        self._theta = np.mod(np.asarray(v["initial_spindle_angle"], dtype=np.float64), 2.0 * math.pi)
        # no motion known at t0: no chip, no force
        for name in ("fx", "fy", "fc", "fc_peak", "fx_mean", "fy_mean", "spindle_torque", "spindle_power",
                     "mrr", "axial_depth", "chip_thickness"):
            v[name][...] = 0.0
        v["engaged_teeth"][...] = 0
        v["spindle_angle"][...] = self._theta

    def _reset(self) -> None:
        self.__dict__.pop("stock", None)
        self.__dict__.pop("path", None)

    def _check_parameters(self) -> None:
        v = self.values
        checks = (
            ("tool_diameter", lambda a: np.isfinite(a) & (a > 0), "a positive length in m"),
            ("flutes", lambda a: a >= 1, "an integer >= 1"),
            ("kt", lambda a: np.isfinite(a) & (a >= 0), "a non-negative coefficient in N/m2"),
            ("ke", lambda a: np.isfinite(a), "a finite ratio"),
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

    def _position(self) -> np.ndarray:
        v = self.values
        pos = np.stack([v["x_position"], v["y_position"], v["z_position"]], axis=1).astype(np.float64)
        if not np.all(np.isfinite(pos)):
            bad = int(np.flatnonzero(~np.isfinite(pos).all(axis=1))[0])
            raise CuttingError(f"{self.name}: tool position of member {bad} is {pos[bad].tolist()}; expected finite m")
        return pos

    # ------------------------------------------------------------------ step
    def _substeps(self, omega: np.ndarray, move: np.ndarray, h: float) -> int:
        steps = np.asarray(self.values["angle_steps_per_tooth"], dtype=np.float64)
        pitch = 2.0 * math.pi / self._flutes
        # at most pitch/steps and at most pi/2 per substep (interval_mean_quantities needs < pi)
        n_angle = np.ceil(omega * h / np.minimum(pitch / steps, 0.5 * math.pi) - 1e-9).max()
        n_move = np.ceil(move / (0.05 * self._radius) - 1e-9).max()
        n = int(max(1.0, n_angle, n_move))
        if n > MAX_SUBSTEPS:
            raise CuttingError(
                f"{self.name}: step of {h} s needs {n} substeps (spindle speed up to {omega.max():.4g} rad/s, "
                f"tool move up to {move.max():.4g} m); expected at most {MAX_SUBSTEPS}"
            )
        return n

    def _do_step(self, t: float, h: float) -> None:
        v = self.values
        p_new = self._position()
        omega = np.maximum(np.asarray(v["spindle_speed"], dtype=np.float64), 0.0)
        dp = p_new - self._p_prev
        n = self._substeps(omega, np.hypot(dp[:, 0], dp[:, 1]), h)
        r = cut_step(
            self.stock, self.path.near_field(), self._p_prev, p_new, self._theta, omega, h, n,
            self._radius, self._flutes, np.asarray(v["kt"], dtype=np.float64), np.asarray(v["ke"], dtype=np.float64),
        )
        v["fx"][...] = -r.force[:, 0]
        v["fy"][...] = -r.force[:, 1]
        v["fc"][...] = np.hypot(r.force[:, 0], r.force[:, 1])
        v["fc_peak"][...] = r.fc_peak
        v["fx_mean"][...] = -r.mean[:, 0]
        v["fy_mean"][...] = -r.mean[:, 1]
        v["spindle_torque"][...] = r.mean[:, 2]
        v["spindle_power"][...] = r.mean[:, 2] * omega
        v["mrr"][...] = r.mean[:, 3]
        v["axial_depth"][...] = r.axial_depth
        v["chip_thickness"][...] = r.chip_thickness
        v["engaged_teeth"][...] = r.engaged_teeth
        self._theta = np.mod(self._theta + omega * h, 2.0 * math.pi)
        v["spindle_angle"][...] = self._theta
        self._p_prev = p_new
        self._commit(p_new)

    def _commit(self, position: np.ndarray) -> None:
        """Store the new tool position and move old path segments into the Z-map."""
        self.path.advance(position)
        while True:
            start, end, mask = self.path.pop_ready(force_room=True)
            if not np.any(mask):
                break
            self.stock.remove_sweep(start, end, self._radius, mask)
