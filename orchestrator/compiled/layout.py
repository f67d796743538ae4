"""Which systems the compiled loop runs, and how a system maps onto its arrays.

:class:`Layout` is built from a :class:`~orchestrator.master.Master` *before*
set-up: it decides whether the compiled loop covers the system (raising
:class:`Unsupported` with the reason otherwise), assigns every input and
output a row of the value array ``V``, and resolves connections, probes,
stop signals, limits and the multi-rate schedule to index arrays. After the
components' ``setup``, :meth:`Layout.bind` gathers their kernel data (plans,
parameter blocks, state arrays); :meth:`Layout.pack` / :meth:`Layout.unpack`
copy values between the components and ``V``.

Covered (each checked per component; anything else runs on the Python master):

* :class:`~fmus_src.nck.component.NCKernel` (at most one);
* :class:`~fmus_src.servo.mcu.MCU` (at most one, compiled, no ``servo_delay``);
* :class:`~fmus_src.servo.drive.DriveAxis` (compiled, no effect terms, either integrator);
* :class:`~fmus_src.cutting.path_component.PathCuttingLoad` (at most one, baseline parameters only);
* :class:`~fmus_src.cutting.component.CuttingLoad` (Z-map; at most one, compiled, every effect term off): the
  arrays of :meth:`~fmus_src.cutting.component.CuttingLoad.compiled_step_arrays` (stock heights, path ring
  buffer, start position, spindle angle, effect clocks) are the component's own, stepped in place by
  :func:`~fmus_src.cutting.zmap_numba.zmap_component_step`, which is also the component's own step;
* Gauss-Seidel coupling, connections between Real variables and, unscaled, between Integer ones (the tool
  in the spindle, ``nck.tool -> cutting.tool``; T numbers are exact in float64), probes / stop signals /
  limits on inputs and outputs.

A parameter these classes gain later (an effect term) is accepted only at its
off value (0 or an empty string), so a new term never runs silently without
its physics.
"""
from __future__ import annotations

import math

import numpy as np

from fmus_src.cutting.component import BASELINE_PARAMETERS, MAX_SUBSTEPS, CuttingLoad
from fmus_src.cutting.path_component import PathCuttingLoad
from fmus_src.cutting.tool_table import TABLE_PARAMETERS
from fmus_src.nck.component import NCKernel
from fmus_src.servo.drive import DriveAxis
from fmus_src.servo.mcu import MCU, TICK_RTOL

from ..errors import CncTwinError
from ..master import probe_conversion, probe_unit
from ..system import split_reference
from .loop import (CUT_ROWS, DRIVE_ROWS, INTEGRATOR_EXPONENTIAL, INTEGRATOR_RK4,
                   KIND_CUT, KIND_DRIVE, KIND_MCU, KIND_NCK, KIND_ZMAP, MCU_ROWS, NCK_ROWS, ZMAP_ROWS)


class Unsupported(CncTwinError):
    """The system is outside what the compiled loop covers (the message says why)."""


# parameters each covered class had when the loop was written; others must be at their off value
_DRIVE_KNOWN = frozenset((
    "mass", "torque_constant", "screw_lead", "coulomb_positive", "static_positive", "stribeck_velocity_positive",
    "viscous_positive", "coulomb_negative", "static_negative", "stribeck_velocity_negative", "viscous_negative",
    "initial_position", "integration_step", "integrator", *DriveAxis.LOAD_PARAMETERS, *DriveAxis.TABLE_PARAMETERS,
    "reversal_friction_peak", "reversal_friction_decay", "ripple_period", "pitch_period",
))
_MCU_KNOWN = frozenset(
    [f"{a}_{s}" for a in "xyz" for s in (
        "position_gain", "velocity_p_gain", "velocity_i_gain", "position_scale", "velocity_p_scale",
        "velocity_i_scale", "velocity_feedforward", "acceleration_feedforward", "peak_current", "mass",
        "torque_constant", "screw_lead", "servo_delay", "excess_error_in_motion", "excess_error_at_stop")]
    + ["position_loop_period", "velocity_loop_period", "in_position_width"])
_CUT_KNOWN = frozenset((
    "tool_diameter", "flutes", "kt", "ke", "stock_x_min", "stock_y_min", "stock_z_min", "stock_x_max",
    "stock_y_max", "stock_z_max", "stock_cell", "angle_steps_per_tooth", "initial_spindle_angle",
    "engagement_table", "path_tolerance",
    "ka",  # the end edges' thrust ratio (fmus_src.cutting.path_axial)
)) | TABLE_PARAMETERS  # the tool table (PathCuttingLoad checks it against its table's cutters)

_INTEGRATORS = {"rk4": INTEGRATOR_RK4, "exponential": INTEGRATOR_EXPONENTIAL}


def _is_off(value: object) -> bool:
    if isinstance(value, str):
        return value == ""
    return bool(np.all(np.asarray(value) == 0))


def _unknown_parameters_off(comp: object, known: frozenset) -> None:
    for name in comp.names("parameter"):
        if name not in known and not _is_off(comp.values[name]):
            raise Unsupported(f"{comp.name}.{name} = {comp.values[name]!r} is not covered by the compiled loop")


def _compiled_kernel_on(comp: object, known: frozenset) -> None:
    """``comp`` runs its compiled kernel and every parameter outside ``known`` is off."""
    if not comp.use_compiled:
        raise Unsupported(f"{comp.name}: use_compiled is False (numpy reference)")
    _unknown_parameters_off(comp, known)


def _same_variables(comp: object, rows: tuple[str, ...]) -> None:
    have = set(comp.names("input")) | set(comp.names("output"))
    if have != set(rows):
        raise Unsupported(f"{comp.name}: inputs/outputs {sorted(have ^ set(rows))} differ from the compiled "
                          f"loop's {type(comp).__name__}")


def _kind(comp: object) -> tuple[int, tuple[str, ...]]:
    """Kind and V-block rows of ``comp``; raises :class:`Unsupported`."""
    cls = type(comp)
    if cls is NCKernel:
        _same_variables(comp, NCK_ROWS)
        return KIND_NCK, NCK_ROWS
    if cls is MCU:
        _compiled_kernel_on(comp, _MCU_KNOWN)
        if not all(_is_off(comp.values[f"{a}_servo_delay"]) for a in "xyz"):
            raise Unsupported(f"{comp.name}: servo_delay (an effect term) is on")
        _same_variables(comp, MCU_ROWS)
        return KIND_MCU, MCU_ROWS
    if cls is DriveAxis:
        _compiled_kernel_on(comp, _DRIVE_KNOWN)
        v = comp.values
        on = [n for n in DriveAxis.LOAD_PARAMETERS + DriveAxis.TABLE_PARAMETERS if not _is_off(v[n])]
        if np.any((v["reversal_friction_peak"] != 0.0) & (v["reversal_friction_decay"] > 0.0)):
            on.append("reversal_friction_peak")
        if on:
            raise Unsupported(f"{comp.name}: effect terms {on} are on")
        if str(v.get("integrator", "rk4")) not in _INTEGRATORS:
            raise Unsupported(f"{comp.name}: unknown integrator {v.get('integrator')!r}")
        _same_variables(comp, DRIVE_ROWS)
        return KIND_DRIVE, DRIVE_ROWS
    if cls is PathCuttingLoad:
        _unknown_parameters_off(comp, _CUT_KNOWN)
        _same_variables(comp, CUT_ROWS)
        return KIND_CUT, CUT_ROWS
    if cls is CuttingLoad:
        _compiled_kernel_on(comp, BASELINE_PARAMETERS)
        _same_variables(comp, ZMAP_ROWS)
        return KIND_ZMAP, ZMAP_ROWS
    raise Unsupported(f"{comp.name}: {cls.__module__}.{cls.__name__} has no compiled kernel in the loop")


class Layout:
    """Rows, index arrays and kernel data of one system for :func:`.loop.run_chunk` (see module docstring).

    Parameters
    ----------
    master : Master
        The master about to run (system, settings, probes); nothing is set up yet.

    Raises
    ------
    Unsupported
        The compiled loop does not cover this system.
    """

    def __init__(self, master: object) -> None:
        system = master.system
        s = master.settings
        if s.method != "gauss-seidel":
            raise Unsupported(f"coupling method {s.method!r} (the compiled loop is Gauss-Seidel)")
        self.system = system
        self.batch = system.batch
        self.order = list(master.order)
        self.index = {name: c for c, name in enumerate(self.order)}
        kinds, rows, base, n_rows = [], {}, [], 0
        count = {KIND_NCK: 0, KIND_MCU: 0, KIND_DRIVE: 0, KIND_CUT: 0, KIND_ZMAP: 0}
        comp_index = []
        for name in self.order:
            comp = system.components[name]
            kind, block = _kind(comp)
            comp_index.append(count[kind])
            count[kind] += 1
            kinds.append(kind)
            base.append(n_rows)
            for offset, var in enumerate(block):
                rows[(name, var)] = n_rows + offset
            n_rows += len(block)
        for kind, what in ((KIND_NCK, "NC kernel"), (KIND_MCU, "MCU"), (KIND_CUT, "cutting load"),
                           (KIND_ZMAP, "Z-map cutting load")):
            if count[kind] > 1:
                raise Unsupported(f"{count[kind]} components of kind {what} (the compiled loop takes one)")
        self.kinds, self.rows, self.n_rows, self.counts = kinds, rows, n_rows, count
        self.comp_kind = np.array(kinds, dtype=np.int64)
        self.comp_index = np.array(comp_index, dtype=np.int64)
        self.comp_base = np.array(base, dtype=np.int64)
        self.comp_rate = np.array([system.rates[n] for n in self.order], dtype=np.int64)
        self.n_fine = system.substeps
        # multi-rate schedule, as Master.run builds it
        ptr, items = [0], []
        for j in range(self.n_fine):
            for name in self.order:
                if j % (self.n_fine // system.rates[name]) == 0:
                    items.append(self.index[name])
            ptr.append(len(items))
        self.tick_ptr = np.array(ptr, dtype=np.int64)
        self.tick_comp = np.array(items, dtype=np.int64)
        # connections grouped by target component, in connection order
        wires: list[list[tuple[int, int, float]]] = [[] for _ in self.order]
        for c in system.connections:
            types = {system.components[comp].variable(var).type
                     for comp, var in (split_reference(c.source), split_reference(c.target))}
            if types != {"Real"} and not (types == {"Integer"} and c.factor == 1.0 and c.offset == 0.0):
                raise Unsupported(f"connection {c.source} -> {c.target}: {sorted(types)} variables (the compiled "
                                  "loop connects Real ones, and Integer ones unscaled)")
            if c.offset != 0.0:  # the loop scales only; the Python loop applies factor and offset
                raise Unsupported(f"connection {c.source} -> {c.target} converts units with an offset "
                                  f"({c.offset!r}); the compiled loop applies factors only")
            wires[self.index[c.target_component]].append(
                (self._row(c.source), self._row(c.target), float(c.factor)))
        flat = [w for ws in wires for w in ws]
        self.wire_ptr = np.cumsum([0] + [len(ws) for ws in wires]).astype(np.int64)
        self.wire_src = np.array([w[0] for w in flat], dtype=np.int64)
        self.wire_dst = np.array([w[1] for w in flat], dtype=np.int64)
        self.wire_factor = np.array([w[2] for w in flat], dtype=np.float64)
        # divergence checks: every connection source (finite), then the limits (bounds)
        checks = [(self._row(c.source), math.nan, math.nan) for c in system.connections]
        checks += [(self._row(ref), float(lo), float(hi)) for ref, (lo, hi) in s.limits.items()]
        self.check_rows = np.array([c[0] for c in checks], dtype=np.int64)
        self.check_lo = np.array([c[1] for c in checks], dtype=np.float64)
        self.check_hi = np.array([c[2] for c in checks], dtype=np.float64)
        self.stop_rows = np.array([self._row(ref) for ref in master.settings.stop_signals()], dtype=np.int64)
        # probes: rows and unit factors (as the master's recorder)
        self.probe_rows, factors, self.channels = [], [], []
        for p in master.probes:
            factor, offset = probe_conversion(system, p)
            if offset != 0.0:
                raise Unsupported(f"probe {p.channel!r} converts {p.reference} with an offset ({offset!r}); the "
                                  "compiled loop applies factors only")
            self.probe_rows.append(self._row(p.reference))
            factors.append(factor)
            self.channels.append((p.channel, probe_unit(system, p)))
        self.probe_rows = np.array(self.probe_rows, dtype=np.int64)
        self.probe_factor = np.array(factors, dtype=np.float64)
        # real outputs of each component (NaN for its failed members, Component._blank_failed_outputs)
        real = [[rows[(name, v.name)] for v in system.components[name].declared_variables()
                 if v.causality == "output" and v.type == "Real"] for name in self.order]
        self.real_ptr = np.cumsum([0] + [len(r) for r in real]).astype(np.int64)
        self.real_rows = np.array([r for rs in real for r in rs], dtype=np.int64)
        self.comp_failed = np.zeros((len(self.order), self.batch), dtype=np.bool_)
        self.comp_has_failed = np.zeros(len(self.order), dtype=np.bool_)
        # MCU ticks per call (the MCU raises for a step that is not a whole number of ticks: not covered)
        self.mcu_ticks = 0
        for name, kind in zip(self.order, kinds):
            if kind == KIND_MCU:
                comp = system.components[name]
                tv = np.asarray(comp.values["velocity_loop_period"], dtype=float)
                h_i = s.step / system.rates[name]
                n = round(h_i / float(tv[0])) if tv.size and np.all(tv == tv[0]) and tv[0] > 0 else 0
                if n < 1 or abs(n * float(tv[0]) - h_i) > TICK_RTOL * max(h_i, float(tv[0])):
                    raise Unsupported(f"{name}: step {h_i!r} s is not a whole number of velocity-loop periods")
                self.mcu_ticks = int(n)
        self.bound = False

    def _row(self, reference: str) -> int:
        comp, var = split_reference(reference)
        try:
            return self.rows[(comp, var)]
        except KeyError:
            raise Unsupported(f"{reference} is not an input or output of a covered component") from None

    # ------------------------------------------------------------------ after set-up
    def bind(self) -> None:
        """Gather the kernel data of the set-up components (plans, parameter blocks, states)."""
        comps = self.system.components
        B = self.batch
        by_kind: dict[int, list] = {KIND_NCK: [], KIND_MCU: [], KIND_DRIVE: [], KIND_CUT: [], KIND_ZMAP: []}
        for name, kind in zip(self.order, self.kinds):
            by_kind[kind].append(comps[name])
        # NC kernel
        if by_kind[KIND_NCK]:
            nck = by_kind[KIND_NCK][0]
            p = nck.plan_
            self.nck = (p.n_samples,) + tuple(np.ascontiguousarray(a) for a in p.arrays()) + (
                float(p.period), float(nck.t0))
        else:
            z = np.zeros(B, dtype=np.int64)
            self.nck = (1, np.zeros((1, 3)), z, z, np.zeros(1, dtype=np.int64), np.zeros(1), np.zeros(1), np.zeros(1),
                        np.zeros(1, dtype=np.int64), np.zeros(1, dtype=np.int64), z, 1.0, 0.0)
        # MCU
        if by_kind[KIND_MCU]:
            m = by_kind[KIND_MCU][0]
            self._mcu = m
            self.mcu = (m._gain_block, m._state.block, np.asarray(m.values["in_position_width"], dtype=np.float64),  # noqa: SLF001
                        int(m._ratio), float(m._tp), float(m._tv), self.mcu_ticks,  # noqa: SLF001
                        np.array([m._next_tick], dtype=np.int64), np.zeros(B, dtype=np.bool_),  # noqa: SLF001
                        m._limit_block, m._alarm)  # noqa: SLF001 - shared with the component's alarm handling
        else:
            self._mcu = None
            self.mcu = (np.zeros((6, 3, B)), np.zeros((7, 3, B)), np.zeros(B), 1, 1.0, 1.0, 1,
                        np.zeros(1, dtype=np.int64), np.zeros(B, dtype=np.bool_), np.zeros((3, 3, B)),
                        np.zeros(B, dtype=np.int8))
        # drives
        drives = by_kind[KIND_DRIVE]
        self._drives = drives
        if drives:
            self.drives = (
                np.ascontiguousarray(np.stack([d._params for d in drives])),  # noqa: SLF001
                np.stack([d._state.position for d in drives]).astype(np.float64),  # noqa: SLF001
                np.stack([d._state.velocity for d in drives]).astype(np.float64),  # noqa: SLF001
                np.stack([d._state.direction for d in drives]).astype(np.int8),  # noqa: SLF001
                np.stack([np.broadcast_to(np.asarray(d._step, dtype=np.float64), (B,)) for d in drives]),  # noqa: SLF001
                np.array([_INTEGRATORS[str(d.values.get("integrator", "rk4"))] for d in drives], dtype=np.int64),
                np.zeros((len(drives), B), dtype=np.int8),
            )
        else:
            self.drives = (np.zeros((0, 12, B)), np.zeros((0, B)), np.zeros((0, B)), np.zeros((0, B), dtype=np.int8),
                           np.zeros((0, B)), np.zeros(0, dtype=np.int64), np.zeros((0, B), dtype=np.int8))
        # path-mode cutting
        if by_kind[KIND_CUT]:
            c = by_kind[KIND_CUT][0]
            self._cut = c
            tb = c.table
            self.cut = (c._par, c._st, np.zeros(B, dtype=np.int64),  # noqa: SLF001
                        np.ascontiguousarray(tb.vertices, dtype=np.float64),
                        np.ascontiguousarray(tb.vertex_s, dtype=np.float64), float(tb.spacing),
                        np.ascontiguousarray(tb.count, dtype=np.int64),
                        np.ascontiguousarray(tb.alpha, dtype=np.float64), np.ascontiguousarray(tb.beta, dtype=np.float64),
                        np.ascontiguousarray(tb.top, dtype=np.float64), float(tb.z_floor),
                        float(c._margin), float(c._tolerance), int(MAX_SUBSTEPS),  # noqa: SLF001
                        c._effect_state.cutting_time, c._effect_state.torque, c._effect_state.angle,  # noqa: SLF001
                        c._status, c._ka, np.ascontiguousarray(tb.axial_area, dtype=np.float64),  # noqa: SLF001
                        np.ascontiguousarray(tb.axial_span, dtype=np.float64), c._z_old,  # noqa: SLF001
                        np.ascontiguousarray(tb.cutter_radius, dtype=np.float64),
                        np.ascontiguousarray(tb.cutter_flutes, dtype=np.int64))
        else:
            self._cut = None
            self.cut = (np.zeros((5, B)), np.zeros((7, B)), np.zeros(B, dtype=np.int64), np.zeros((1, 3)),
                        np.zeros(1), 1.0, np.zeros(1, dtype=np.int64), np.zeros((1, 1)), np.zeros((1, 1)),
                        np.zeros((1, 1)), 0.0, 0.0, 0.0, 1, np.zeros(B), np.zeros(B), np.zeros(B),
                        np.zeros(B, dtype=np.int64), np.zeros(B), np.zeros(1), np.zeros(1), np.zeros(B),
                        np.zeros(0), np.zeros(0, dtype=np.int64))
        self._bind_zmap(by_kind[KIND_ZMAP][0] if by_kind[KIND_ZMAP] else None)
        self.bound = True

    def _bind_zmap(self, c: CuttingLoad | None) -> None:
        """The ``zmap`` tuple of :func:`.loop.run_chunk` (the component's own arrays where they can be shared)."""
        B = self.batch
        self._zmap_comp = c
        if c is None:
            f, i = np.zeros(B), np.zeros(B, dtype=np.int64)
            self.zmap = (np.zeros((B, 1, 1), dtype=np.float32), np.ones((B, 5)), np.zeros((B, 2), dtype=np.int64),
                         f, np.zeros((B, 3, 3)), np.zeros((B, 3)), i, i.copy(), f, f, np.zeros((B, 3)), f.copy(),
                         f, i, f, f, f, f, f.copy(), f.copy(), f.copy(), i.copy(), np.zeros((2, B)), 1,
                         np.full((B, 1), -1, dtype=np.int64), np.zeros((B, 1)), np.zeros((B, 1), dtype=np.int64))
            return
        path = c.path
        for name, dtype in (("points", np.float64), ("arc", np.float64), ("head", np.int64), ("count", np.int64)):
            value = getattr(path, name)  # as zmap_numba.commit does: kept in place from then on
            if value.dtype != dtype or not value.flags.c_contiguous or not value.flags.writeable:
                setattr(path, name, np.array(value, dtype=dtype))
        self.zmap = c.compiled_step_arrays()  # the component's own arrays: it steps them in place too
        for i, name, dtype in ((0, "heights", np.float32), (10, "start position", np.float64),
                               (11, "spindle angle", np.float64), (18, "cutting_time", np.float64),
                               (19, "torque", np.float64), (20, "angle", np.float64)):
            arr = self.zmap[i]
            if arr.dtype != dtype or not arr.flags.c_contiguous:
                raise Unsupported(f"{c.name}: {name} is not a C-contiguous array of the kernel's type")

    def pack(self, V: np.ndarray | None = None) -> np.ndarray:
        """``V`` (new, or refreshed in place) and the loop's state copies from the components' current values."""
        if V is None:
            V = np.zeros((self.n_rows, self.batch))
        comps = self.system.components
        for (name, var), row in self.rows.items():
            V[row] = comps[name].values[var]
        if self.bound:
            _, pos, vel, dirn, _, _, _ = self.drives
            for i, d in enumerate(self._drives):
                pos[i] = d._state.position  # noqa: SLF001
                vel[i] = d._state.velocity  # noqa: SLF001
                dirn[i] = d._state.direction  # noqa: SLF001
            if self._mcu is not None:
                self.mcu[7][0] = self._mcu._next_tick  # noqa: SLF001
            for c, name in enumerate(self.order):
                failed = getattr(comps[name], "failed_members", None)
                if failed is not None:
                    self.comp_failed[c] = failed
            self.comp_has_failed[:] = self.comp_failed.any(axis=1)
            if self._zmap_comp is not None:
                self._check_zmap_shared()
        return V

    def _check_zmap_shared(self) -> None:
        """The arrays shared with the Z-map cutting load are still its own (it keeps them in place)."""
        c = self._zmap_comp
        st = c._effect_state  # noqa: SLF001
        own = (c._zmap.heights, c.path.points, c.path.arc, c.path.head, c.path.count,  # noqa: SLF001
               c._motion, c._theta, st.cutting_time, st.torque, st.angle,  # noqa: SLF001
               c.path.spacing, c.path.lag, c._radius, c._flutes)  # noqa: SLF001 - a tool change replaces these
        shared = tuple(self.zmap[i] for i in (0, 4, 5, 6, 7, 10, 11, 18, 19, 20, 8, 9, 12, 13))
        if any(a is not b for a, b in zip(own, shared)):
            raise CncTwinError(f"compiled loop: {c.name} replaced an array the loop shares with it "
                               "(stock heights, path ring buffer, cutter in the spindle or effect clocks)")

    def unpack(self, V: np.ndarray) -> None:
        """Write ``V`` and the loop's state copies back into the components (values, drive states, MCU tick)."""
        comps = self.system.components
        for (name, var), row in self.rows.items():
            target = comps[name].values[var]
            target[...] = V[row] if target.dtype.kind == "f" else (
                V[row] != 0.0 if target.dtype.kind == "b" else V[row].astype(target.dtype))
        if self._mcu is not None:
            self._mcu._next_tick = int(self.mcu[7][0])  # noqa: SLF001
        _, pos, vel, dirn, _, _, _ = self.drives
        for i, d in enumerate(self._drives):
            d._state.position[...] = pos[i]  # noqa: SLF001
            d._state.velocity[...] = vel[i]  # noqa: SLF001
            d._state.direction[...] = dirn[i]  # noqa: SLF001

    def kernel_data(self) -> tuple:
        """The ``nck, mcu, drives, cut, zmap`` tuples of :func:`.loop.run_chunk`."""
        return self.nck, self.mcu, self.drives, self.cut, self.zmap
