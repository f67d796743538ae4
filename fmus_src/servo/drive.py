"""Feed-drive axis component: table mass, ball-screw drive and Stribeck friction.

One class, instantiated once per axis (Sim & Lee 2023, Eq. 1-3)::

    Ms x'' = u - Ff(x') - Fd,     u = Atc kt 2 pi / Lb

``current_cmd`` (``Atc``, from the MCU) and ``disturbance_force`` (``Fd``,
the cutting force on the workpiece in machine axes; positive ``Fd`` pushes
the table towards negative positions) are held constant over each
``do_step``. Friction follows the stick/slip state machine of
:mod:`fmus_src.servo.stick_slip`.

By default ``do_step`` runs the compiled kernel
:func:`fmus_src.servo.stick_slip_numba.advance_kernel` (net force, all
substeps, crossings and friction of every member in one call, outputs written
in place); ``DriveAxis.use_compiled = False`` (class or instance attribute,
read at every step) selects the numpy reference
:func:`fmus_src.servo.stick_slip.advance`. Both update the same state arrays.

Each member integrates with its own internal substep (its ``integration_step``
capped by its own Stribeck time scale, :func:`.step_cap.stribeck_step_cap`), so a member
gives bit for bit the result of its solo run whatever the rest of the batch.
A member whose stick/slip step fails (see :mod:`.stick_slip`) is failed alone
(:meth:`~fmus_src.component.Component.fail_members`) and frozen; a single run
(``B = 1``) raises :class:`ServoError`.
"""
from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from ..component import Component, Variable
from ..jit import NUMBA_AVAILABLE
from .effects import TableState, axis_load, reversal_friction, table_position, update_travel
from .errors import ServoError
from .friction import StribeckParameters
from .stick_slip import OK, SlipState, advance, failure_reason, friction_force, substeps
from .exponential_numba import select_kernel
from .stick_slip_numba import pack_parameters
from .step_cap import STRIBECK_STEP_FACTOR, stribeck_step_cap  # noqa: F401 - re-exported

#: Default internal step [s]. With the Table 1 parameters the fastest time
#: scale of the table is the Stribeck growth rate (Fs - Fc) / (vs Ms) <= 530 1/s
#: (Y positive: 254 N / 0.6 mm/s / 800 kg); at 125 us its product with the step
#: is 0.07, where the RK4 truncation error is ~1e-8 relative, and a 250 us
#: velocity-loop tick is integrated in 2 substeps. The viscous decay rate
#: mu_v / Ms <= 20 1/s is far from any stability limit.
DEFAULT_INTEGRATION_STEP = 125e-6

def _p(name: str, unit: str, start: float, description: str) -> Variable:
    return Variable(name, "parameter", unit, start, description)


class DriveAxis(Component):
    """One feed-drive axis (table + screw + motor) with direction-dependent Stribeck friction.

    Parameters are those of ``[axis.<a>]`` and ``[axis.<a>.friction.<dir>]``
    of the machine file (see :func:`fmus_src.servo.params.drive_parameters`);
    the defaults are the X axis of ``default.toml``.
    """

    variables = (
        _p("mass", "kg", 600.0, "equivalent moving mass Ms"),
        _p("torque_constant", "N.m/A", 1.0, "motor torque constant kt"),
        _p("screw_lead", "m", 0.012, "ball-screw lead Lb"),
        _p("coulomb_positive", "N", 641.6, "Coulomb friction Fc, positive motion"),
        _p("static_positive", "N", 775.2, "static (break-away) friction Fs, positive motion"),
        _p("stribeck_velocity_positive", "m/s", 0.0016, "Stribeck velocity vs, positive motion"),
        _p("viscous_positive", "N.s/m", 7702.0, "viscous coefficient mu_v, positive motion"),
        _p("coulomb_negative", "N", 661.9, "Coulomb friction magnitude Fc, negative motion"),
        _p("static_negative", "N", 756.8, "static friction magnitude Fs, negative motion"),
        _p("stribeck_velocity_negative", "m/s", 0.0014, "Stribeck velocity magnitude vs, negative motion"),
        _p("viscous_negative", "N.s/m", 7242.0, "viscous coefficient mu_v, negative motion"),
        _p("initial_position", "m", 0.0, "table position at t0 (at rest, in stick)"),
        _p("integration_step", "s", DEFAULT_INTEGRATION_STEP,
           "largest internal RK4 substep (further capped by the Stribeck growth rate)"),
        # --- integrator hook (issue 9, fmus_src/servo/exponential_numba.py)
        Variable("integrator", "parameter", "1", "rk4",
                 "compiled drive integrator: rk4 (reference) | exponential (one exponential substep per tick, "
                 "RK4 near stick); the numpy reference (use_compiled False) is always RK4", "String"),
        # effect terms (diagnosis); 0 = off = the paper's baseline, see fmus_src.servo.effects
        _p("gravity_force", "N", 0.0, "unbalanced weight Fg of a vertical axis (> 0 pulls towards negative positions)"),
        _p("gravity_spring", "N/m", 0.0, "counterbalance spring rate: load Fg + k_g x"),
        _p("reversal_friction_peak", "N", 0.0, "extra Coulomb/static friction right after a reversal"),
        _p("reversal_friction_decay", "m", 0.0, "travel over which the reversal friction decays (0 = off)"),
        _p("ripple_amplitude", "N", 0.0, "torque ripple (cogging) amplitude as a force"),
        _p("ripple_period", "m", 0.0, "torque ripple period in motor travel (0 = off)"),
        _p("screw_stiffness", "N/m", 0.0, "axial stiffness of screw, nut and bearings (0 = rigid)"),
        _p("backlash_width", "m", 0.0, "backlash (lost motion) between motor and table"),
        _p("pitch_slope", "1", 0.0, "linear lead error of the screw (m per m)"),
        _p("pitch_amplitude", "m", 0.0, "periodic lead error amplitude"),
        _p("pitch_period", "m", 0.0, "periodic lead error period (0 = off)"),
        _p("thermal_drift_rate", "m/s", 0.0, "growth rate of the table position error (thermal drift)"),
        Variable("current_cmd", "input", "A", 0.0, "torque (current) command Atc from the MCU"),
        Variable("disturbance_force", "input", "N", 0.0, "disturbance Fd resisting positive motion (cutting force)"),
        Variable("position", "output", "m", 0.0, "table position x"),
        Variable("velocity", "output", "m/s", 0.0, "table velocity dx/dt"),
        Variable("motor_force", "output", "N", 0.0, "driving force u = Atc kt 2 pi / Lb"),
        Variable("friction_force", "output", "N", 0.0, "friction force Ff (static reaction when stuck)"),
        Variable("table_position", "output", "m", 0.0,
                 "table position (motor position + lead error - screw deflection, backlash, drift); "
                 "equals position when the effects are off"),
    )

    #: Parameters of the load terms (gravity, ripple) and of the motor-to-table terms.
    LOAD_PARAMETERS = ("gravity_force", "gravity_spring", "ripple_amplitude")
    TABLE_PARAMETERS = ("screw_stiffness", "backlash_width", "pitch_slope", "pitch_amplitude",
                        "thermal_drift_rate")

    #: Run the compiled kernel (True, default when numba is importable) or the numpy reference (False).
    use_compiled: ClassVar[bool] = NUMBA_AVAILABLE

    # ------------------------------------------------------------------ helpers
    def _check_parameters(self) -> None:
        positive = ("mass", "torque_constant", "screw_lead", "stribeck_velocity_positive",
                    "stribeck_velocity_negative", "integration_step")
        non_negative = ("coulomb_positive", "static_positive", "viscous_positive",
                        "coulomb_negative", "static_negative", "viscous_negative", "reversal_friction_decay",
                        "ripple_period", "screw_stiffness", "backlash_width", "pitch_period")
        for name in positive:
            arr = self.values[name]
            if not np.all(np.isfinite(arr) & (arr > 0.0)):
                raise ServoError(f"{self.name}.{name} must be finite and > 0, got {arr!r}")
        for name in self.LOAD_PARAMETERS + self.TABLE_PARAMETERS + ("reversal_friction_peak", "pitch_period"):
            if not np.all(np.isfinite(self.values[name])):
                raise ServoError(f"{self.name}.{name} must be finite, got {self.values[name]!r}")
        for name in non_negative:
            arr = self.values[name]
            if not np.all(np.isfinite(arr) & (arr >= 0.0)):
                raise ServoError(f"{self.name}.{name} must be finite and >= 0 (a magnitude), got {arr!r}")

    def _force_constant(self) -> np.ndarray:
        """kt 2 pi / Lb [N/A], shape (B,)."""
        return self.values["torque_constant"] * (2.0 * math.pi) / self.values["screw_lead"]

    def _disturbance(self) -> np.ndarray:
        """``Fd`` plus the load terms (gravity, spring, ripple) at the current position [N]."""
        fd = self.values["disturbance_force"]
        if not self._load_on:
            return fd
        v = self.values
        return fd + axis_load(self._state.position, v["gravity_force"], v["gravity_spring"],
                              v["ripple_amplitude"], v["ripple_period"])

    def _net_force(self, disturbance: np.ndarray | None = None) -> np.ndarray:
        u = self.values["current_cmd"] * self._kf
        self.values["motor_force"][...] = u
        return u - (self._disturbance() if disturbance is None else disturbance)

    def _step_friction(self) -> tuple[StribeckParameters, np.ndarray]:
        """Friction of this step (reversal friction added) and its packed kernel block."""
        if not self._reversal_on:
            return self._friction, self._params
        extra = reversal_friction(self._table.travel, self.values["reversal_friction_peak"],
                                  self.values["reversal_friction_decay"])
        f = self._friction
        friction = StribeckParameters(
            coulomb_pos=f.coulomb_pos + extra, static_pos=f.static_pos + extra,
            stribeck_velocity_pos=f.stribeck_velocity_pos, viscous_pos=f.viscous_pos,
            coulomb_neg=f.coulomb_neg + extra, static_neg=f.static_neg + extra,
            stribeck_velocity_neg=f.stribeck_velocity_neg, viscous_neg=f.viscous_neg,
        )
        params = self._params.copy()
        for row in (2, 6, 7, 11):  # coulomb_pos, static_pos, coulomb_neg, static_neg; delta unchanged
            params[row] += extra
        return friction, params

    def _update_table(self, old_position: np.ndarray, elapsed: float) -> None:
        """Travel since reversal and the ``table_position`` output after a step."""
        v = self.values
        if self._reversal_on:
            update_travel(self._table, old_position, self._state.position, self._state.velocity)
        if self._table_on:
            v["table_position"][...] = table_position(
                self._table, self._state.position, v["motor_force"], elapsed, v["pitch_slope"],
                v["pitch_amplitude"], v["pitch_period"], v["screw_stiffness"], v["backlash_width"],
                v["thermal_drift_rate"])
        else:
            v["table_position"][...] = self._state.position

    # ------------------------------------------------------------------ protocol
    def _setup(self, t0: float) -> None:
        self._check_parameters()
        v = self.values
        self._friction = StribeckParameters(
            coulomb_pos=v["coulomb_positive"].copy(), static_pos=v["static_positive"].copy(),
            stribeck_velocity_pos=v["stribeck_velocity_positive"].copy(), viscous_pos=v["viscous_positive"].copy(),
            coulomb_neg=v["coulomb_negative"].copy(), static_neg=v["static_negative"].copy(),
            stribeck_velocity_neg=v["stribeck_velocity_negative"].copy(), viscous_neg=v["viscous_negative"].copy(),
        )
        self._mass = v["mass"].copy()
        self._kf = self._force_constant()
        #: internal substep limit of each member [s], shape (B,)
        self._step = np.ascontiguousarray(np.minimum(v["integration_step"], stribeck_step_cap(self._friction, self._mass)))
        self._status = np.zeros(self.batch, dtype=np.int8)
        self._kernel = select_kernel(str(v["integrator"]), self.name)  # integrator hook (issue 9)
        self._state = SlipState(
            position=v["initial_position"].astype(float).copy(),
            velocity=np.zeros(self.batch),
            direction=np.zeros(self.batch, dtype=np.int8),
        )
        self._params = pack_parameters(self._friction, self._mass, self._kf)
        self._load_on = any(bool(np.any(v[n] != 0.0)) for n in self.LOAD_PARAMETERS)
        self._reversal_on = bool(np.any((v["reversal_friction_peak"] != 0.0) & (v["reversal_friction_decay"] > 0.0)))
        self._table_on = any(bool(np.any(v[n] != 0.0)) for n in self.TABLE_PARAMETERS)
        self._table = TableState(table=self._state.position.copy(), travel=np.zeros(self.batch),
                                 last_direction=np.zeros(self.batch))
        self._publish(friction_force(self._state, self._net_force(), self._friction))
        if self._table_on:  # the play starts centred on the nut position (no backlash, no drift at t0)
            zero = np.zeros(self.batch)
            self._table.table[...] = table_position(
                TableState(self._table.table.copy(), zero.copy(), zero.copy()), self._state.position,
                v["motor_force"], 0.0, v["pitch_slope"], v["pitch_amplitude"], v["pitch_period"],
                v["screw_stiffness"], zero, zero)
        self._update_table(self._state.position.copy(), 0.0)

    def _publish(self, ff: np.ndarray) -> None:
        self.values["position"][...] = self._state.position
        self.values["velocity"][...] = self._state.velocity
        self.values["friction_force"][...] = ff

    def _do_step(self, t: float, h: float) -> None:
        old_position = self._state.position.copy() if self._reversal_on else self._state.position
        disturbance = self._disturbance()
        friction, params = self._step_friction()
        if self.use_compiled:
            v, s = self.values, self._state
            status = self._kernel(v["current_cmd"], disturbance, params, s.position, s.velocity,
                                  s.direction, float(h), self._step, v["motor_force"], v["position"],
                                  v["velocity"], v["friction_force"], self._status)
        else:
            force = self._net_force(disturbance)
            ff = advance(self._state, force, self._mass, friction, h, self._step, status=self._status)
            self._publish(ff)
            status = OK if not self._status.any() else int(self._status[np.flatnonzero(self._status)[0]])
        if status != OK:
            self._fail_stick_slip(h)
        self._update_table(old_position, (t + h) - self.t0)

    def _fail_stick_slip(self, h: float) -> None:
        """Fail the members whose stick/slip step failed (state unchanged), then freeze them (NaN state)."""
        bad = self._status != OK
        _, dt = substeps(h, self._step)
        for b in np.flatnonzero(bad):
            reason = f"{self.name}: {failure_reason(int(self._status[b]), float(dt[b]))}"
            mask = np.zeros(self.batch, dtype=bool)
            mask[b] = True
            self.fail_members(mask, reason, ServoError)
        s = self._state
        s.position[bad] = np.nan
        s.velocity[bad] = np.nan
        s.direction[bad] = 0

    def _reset(self) -> None:
        self.__dict__.pop("_state", None)
