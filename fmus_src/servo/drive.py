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
"""
from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from ..component import Component, Variable
from ._jit import NUMBA_AVAILABLE
from .errors import ServoError
from .friction import StribeckParameters
from .stick_slip import SlipState, advance, friction_force
from .stick_slip_numba import OK, advance_kernel, pack_parameters, raise_reference_error

#: Default internal step [s]. With the Table 1 parameters the fastest time
#: scale of the table is the Stribeck growth rate (Fs - Fc) / (vs Ms) <= 530 1/s
#: (Y positive: 254 N / 0.6 mm/s / 800 kg); at 125 us its product with the step
#: is 0.07, where the RK4 truncation error is ~1e-8 relative, and a 250 us
#: velocity-loop tick is integrated in 2 substeps. The viscous decay rate
#: mu_v / Ms <= 20 1/s is far from any stability limit.
DEFAULT_INTEGRATION_STEP = 125e-6

#: The internal step is further capped so that (Stribeck growth rate) x step <= this value, where the
#: growth rate is max(0, (Fs - Fc) / vs - mu_v) / Ms, the largest positive eigenvalue of the sliding
#: dynamics. Inactive for Table 1 values (cap >= 480 us); it keeps a GA's extreme trial parameters
#: (vs = 0.1 mm/s, Fs - Fc = 700 N, 600 kg: cap ~ 21 us) about as accurate as the paper's, at the
#: price of more substeps for the whole batch.
STRIBECK_STEP_FACTOR = 0.25


def _p(name: str, unit: str, start: float, description: str) -> Variable:
    return Variable(name, "parameter", unit, start, description)


def stribeck_step_cap(friction: StribeckParameters, mass: np.ndarray) -> float:
    """Largest internal step [s] with (Stribeck growth rate) x step <= ``STRIBECK_STEP_FACTOR`` (whole batch).

    Parameters
    ----------
    friction : StribeckParameters
        Both branches, shape (B,).
    mass : ndarray, shape (B,)
        Moving mass [kg].
    """
    rates = [
        np.maximum(0.0, (friction.static_pos - friction.coulomb_pos) / friction.stribeck_velocity_pos
                   - friction.viscous_pos) / mass,
        np.maximum(0.0, (friction.static_neg - friction.coulomb_neg) / friction.stribeck_velocity_neg
                   - friction.viscous_neg) / mass,
    ]
    worst = float(max(np.max(r) for r in rates))
    return math.inf if worst == 0.0 else STRIBECK_STEP_FACTOR / worst


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
        Variable("current_cmd", "input", "A", 0.0, "torque (current) command Atc from the MCU"),
        Variable("disturbance_force", "input", "N", 0.0, "disturbance Fd resisting positive motion (cutting force)"),
        Variable("position", "output", "m", 0.0, "table position x"),
        Variable("velocity", "output", "m/s", 0.0, "table velocity dx/dt"),
        Variable("motor_force", "output", "N", 0.0, "driving force u = Atc kt 2 pi / Lb"),
        Variable("friction_force", "output", "N", 0.0, "friction force Ff (static reaction when stuck)"),
    )

    #: Run the compiled kernel (True, default when numba is importable) or the numpy reference (False).
    use_compiled: ClassVar[bool] = NUMBA_AVAILABLE

    # ------------------------------------------------------------------ helpers
    def _check_parameters(self) -> None:
        positive = ("mass", "torque_constant", "screw_lead", "stribeck_velocity_positive",
                    "stribeck_velocity_negative", "integration_step")
        non_negative = ("coulomb_positive", "static_positive", "viscous_positive",
                        "coulomb_negative", "static_negative", "viscous_negative")
        for name in positive:
            arr = self.values[name]
            if not np.all(np.isfinite(arr) & (arr > 0.0)):
                raise ServoError(f"{self.name}.{name} must be finite and > 0, got {arr!r}")
        for name in non_negative:
            arr = self.values[name]
            if not np.all(np.isfinite(arr) & (arr >= 0.0)):
                raise ServoError(f"{self.name}.{name} must be finite and >= 0 (a magnitude), got {arr!r}")

    def _force_constant(self) -> np.ndarray:
        """kt 2 pi / Lb [N/A], shape (B,)."""
        return self.values["torque_constant"] * (2.0 * math.pi) / self.values["screw_lead"]

    def _net_force(self) -> np.ndarray:
        u = self.values["current_cmd"] * self._kf
        self.values["motor_force"][...] = u
        return u - self.values["disturbance_force"]

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
        self._step = min(float(np.min(v["integration_step"])), stribeck_step_cap(self._friction, self._mass))
        self._state = SlipState(
            position=v["initial_position"].astype(float).copy(),
            velocity=np.zeros(self.batch),
            direction=np.zeros(self.batch, dtype=np.int8),
        )
        self._params = pack_parameters(self._friction, self._mass, self._kf)
        self._publish(friction_force(self._state, self._net_force(), self._friction))

    def _publish(self, ff: np.ndarray) -> None:
        self.values["position"][...] = self._state.position
        self.values["velocity"][...] = self._state.velocity
        self.values["friction_force"][...] = ff

    def _do_step(self, t: float, h: float) -> None:
        if self.use_compiled:
            v, s = self.values, self._state
            status = advance_kernel(v["current_cmd"], v["disturbance_force"], self._params, s.position, s.velocity,
                                    s.direction, float(h), self._step, v["motor_force"], v["position"],
                                    v["velocity"], v["friction_force"])
            if status != OK:
                raise_reference_error(s, self._net_force(), self._mass, self._friction, h, self._step, status,
                                      self.name)
            return
        force = self._net_force()
        try:
            ff = advance(self._state, force, self._mass, self._friction, h, self._step)
        except ServoError as err:
            raise ServoError(f"{self.name}: {err}") from err
        self._publish(ff)

    def _reset(self) -> None:
        self.__dict__.pop("_state", None)
