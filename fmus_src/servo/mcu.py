"""Motion control unit (MCU) component: cascade servo loops of the X, Y, Z axes.

A thin adapter around :mod:`fmus_src.servo.control`. ``do_step(t, h)`` runs
``round(h / velocity_loop_period)`` velocity-loop ticks (``h`` must be an
integer multiple of the period within 1e-9 relative). The position loop runs
on the ticks whose absolute index ``k = round((t - t0) / Tv)`` is a multiple
of ``Tp / Tv``, so stepping at 250 us or at 1 ms gives identical results when
the inputs are the same.

Two implementations of one control law: by default ``do_step`` runs the
compiled kernel :func:`fmus_src.servo.control_numba.mcu_kernel` (all ticks,
axes and members in one call, outputs written in place); with
``MCU.use_compiled = False`` (class or instance attribute, read at every step)
it runs the numpy reference of :mod:`fmus_src.servo.control`. Both share the
state block, so the switch may even be flipped between steps.

Excess following-error alarm (FANUC SV0411 in motion / SV0410 at stop,
parameters No. 1828 / No. 1829): ``{a}_excess_error_in_motion`` and
``{a}_excess_error_at_stop`` (0 = off). After each step, a member whose
following error ``|ref - position|`` on some axis exceeds the limit of its
state (see :mod:`fmus_src.servo.control`) is failed with a reason naming the
alarm, the axis, the error and the limit
(:meth:`~fmus_src.component.Component.fail_members`); a single run raises
:class:`ServoError`.

Timing convention: all ticks inside one ``do_step`` use the inputs set before
the call (values at ``t``). The outputs after the call are those of the last
tick, i.e. the command a drive applies during the *next* communication
interval. Stepped at ``Tv`` by a Jacobi master this is a one-tick
computation delay, as in a digital servo amplifier.
"""
from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from ..component import Component, Variable
from ..jit import NUMBA_AVAILABLE
from .control import (CascadeGains, CascadeState, ExcessErrorLimits, excess_error_alarm, position_loop,
                      settle_ticks, velocity_loop)
from .control_numba import mcu_kernel
from .effects import DelayLine
from .errors import ServoError

AXES = ("x", "y", "z")

#: Relative tolerance on ``h / Tv``, ``Tp / Tv`` and ``(t - t0) / Tv`` being integers.
TICK_RTOL = 1e-9

# default per-axis parameters: (suffix, unit, {axis: value}, description); values from default.toml
_AXIS_PARAMETERS: tuple[tuple[str, str, dict[str, float], str], ...] = (
    ("position_gain", "1/s", {"x": 50.0, "y": 50.0, "z": 50.0}, "position loop gain Pp"),
    ("velocity_p_gain", "A/(m/s)", {"x": 720.0, "y": 960.0, "z": 600.0}, "velocity loop proportional gain Vp"),
    ("velocity_i_gain", "A/m", {"x": 90000.0, "y": 120000.0, "z": 75000.0}, "velocity loop integral gain Vi"),
    ("position_scale", "1", {"x": 1.0, "y": 1.0, "z": 1.0}, "scale factor Spp on Pp"),
    ("velocity_p_scale", "1", {"x": 1.0, "y": 1.0, "z": 1.0}, "scale factor Svp on Vp"),
    ("velocity_i_scale", "1", {"x": 1.0, "y": 1.0, "z": 1.0}, "scale factor Svi on Vi"),
    ("velocity_feedforward", "1", {"x": 0.0, "y": 0.0, "z": 0.0}, "velocity feed-forward gain (0 = off)"),
    ("acceleration_feedforward", "1", {"x": 0.0, "y": 0.0, "z": 0.0}, "acceleration feed-forward gain (0 = off)"),
    ("peak_current", "A", {"x": 40.0, "y": 40.0, "z": 40.0}, "amplifier peak current (saturation)"),
    ("mass", "kg", {"x": 600.0, "y": 800.0, "z": 500.0}, "moving mass Ms (acceleration feed-forward)"),
    ("torque_constant", "N.m/A", {"x": 1.0, "y": 1.0, "z": 1.0}, "motor torque constant kt (acceleration feed-forward)"),
    ("screw_lead", "m", {"x": 0.012, "y": 0.012, "z": 0.012}, "ball-screw lead Lb (acceleration feed-forward)"),
    ("servo_delay", "s", {"x": 0.0, "y": 0.0, "z": 0.0},
     "extra pure delay of the current command inside the loop (diagnosis effect; 0 = off)"),
    # off by default in the bare component (unit tests drive it with arbitrary errors); the machine file sets them
    ("excess_error_in_motion", "m", {"x": 0.0, "y": 0.0, "z": 0.0},
     "excess following-error limit while the reference moves (FANUC No. 1828, alarm SV0411; 0 = off)"),
    ("excess_error_at_stop", "m", {"x": 0.0, "y": 0.0, "z": 0.0},
     "excess following-error limit once the reference has stopped (FANUC No. 1829, alarm SV0410; 0 = off)"),
)

#: Alarm names and FANUC parameter numbers by "at stop" flag.
_ALARMS = {False: ("SV0411 excess error in motion", "excess_error_in_motion", 1828),
           True: ("SV0410 excess error at stop", "excess_error_at_stop", 1829)}


def _declare() -> tuple[Variable, ...]:
    out: list[Variable] = []
    for a in AXES:
        for suffix, unit, defaults, text in _AXIS_PARAMETERS:
            out.append(Variable(f"{a}_{suffix}", "parameter", unit, defaults[a], f"{a.upper()}: {text}"))
    out.append(Variable("position_loop_period", "parameter", "s", 1e-3, "position loop period Tp"))
    out.append(Variable("velocity_loop_period", "parameter", "s", 250e-6, "velocity loop period Tv"))
    out.append(Variable("in_position_width", "parameter", "m", 20e-6,
                        "in-position width (FANUC No. 1826): |ref - actual| below it on every axis sets in_position"))
    for a in AXES:
        out.append(Variable(f"{a}_ref", "input", "m", 0.0, f"{a.upper()}: reference position from the NC kernel"))
        out.append(Variable(f"{a}_position", "input", "m", 0.0, f"{a.upper()}: actual position (drive feedback)"))
        out.append(Variable(f"{a}_velocity", "input", "m/s", 0.0, f"{a.upper()}: actual velocity (drive feedback)"))
    for a in AXES:
        out.append(Variable(f"{a}_current_cmd", "output", "A", 0.0, f"{a.upper()}: current (torque) command Atc"))
        out.append(Variable(f"{a}_velocity_cmd", "output", "m/s", 0.0, f"{a.upper()}: velocity command of the position loop"))
    out.append(Variable("in_position", "output", "1", False,
                        "all axes within in_position_width of their reference (servo position deviation)", "Boolean"))
    return tuple(out)


def _integer_ratio(num: float, den: float, what: str, owner: str) -> int:
    n = round(num / den)
    if n < 0 or abs(n * den - num) > TICK_RTOL * max(abs(num), den):
        raise ServoError(f"{owner}: {what} = {num!r} s is not an integer multiple of the velocity loop period {den!r} s")
    return int(n)


class MCU(Component):
    """Cascade P (position) / PI (velocity) servo controller of three axes with current saturation.

    Per axis ``a`` in x, y, z: parameters ``{a}_position_gain`` ... ``{a}_screw_lead``
    (see ``MCU.variables``), inputs ``{a}_ref``, ``{a}_position``, ``{a}_velocity``, outputs
    ``{a}_current_cmd``, ``{a}_velocity_cmd``; shared ``position_loop_period``,
    ``velocity_loop_period``. Defaults are the values of ``default.toml``, except the
    excess-error limits ``{a}_excess_error_in_motion`` / ``{a}_excess_error_at_stop``: 0 (off)
    unless set (the twin sets them from the machine file).
    """

    variables = _declare()

    #: Run the compiled kernel (True, default when numba is importable) or the numpy reference (False).
    use_compiled: ClassVar[bool] = NUMBA_AVAILABLE

    def _stack(self, suffix: str) -> np.ndarray:
        return np.stack([np.asarray(self.values[f"{a}_{suffix}"], dtype=float) for a in AXES])

    def _shared_period(self, name: str) -> float:
        arr = self.values[name]
        if not np.all(np.isfinite(arr) & (arr > 0.0)):
            raise ServoError(f"{self.name}.{name} must be finite and > 0, got {arr!r}")
        if not np.all(arr == arr[0]):
            raise ServoError(f"{self.name}.{name} must be the same for all batch members, got {arr!r}")
        return float(arr[0])

    def _setup(self, t0: float) -> None:
        self._tv = self._shared_period("velocity_loop_period")
        self._tp = self._shared_period("position_loop_period")
        self._ratio = _integer_ratio(self._tp, self._tv, "position_loop_period", self.name)
        if self._ratio < 1:
            raise ServoError(f"{self.name}: position_loop_period must be >= velocity_loop_period")
        for name in ("peak_current", "mass", "torque_constant", "screw_lead"):
            arr = self._stack(name)
            if not np.all(np.isfinite(arr) & (arr > 0.0)):
                raise ServoError(f"{self.name}: {{x,y,z}}_{name} must be finite and > 0, got {arr!r}")
        force_per_amp = self._stack("torque_constant") * 2.0 * math.pi / self._stack("screw_lead")
        self._gains = CascadeGains(
            position=self._stack("position_gain") * self._stack("position_scale"),
            velocity_p=self._stack("velocity_p_gain") * self._stack("velocity_p_scale"),
            velocity_i=self._stack("velocity_i_gain") * self._stack("velocity_i_scale"),
            velocity_ff=self._stack("velocity_feedforward"),
            accel_ff_current=self._stack("acceleration_feedforward") * self._stack("mass") / force_per_amp,
            peak_current=self._stack("peak_current"),
        )
        self._gain_block = self._gains.block()
        self._state = CascadeState.initial(self._stack("ref"))
        for name in ("excess_error_in_motion", "excess_error_at_stop"):
            arr = self._stack(name)
            if not np.all(np.isfinite(arr) & (arr >= 0.0)):
                raise ServoError(f"{self.name}: {{x,y,z}}_{name} must be finite and >= 0 (0 = off), got {arr!r}")
        self._limit_block = ExcessErrorLimits(
            in_motion=self._stack("excess_error_in_motion"), at_stop=self._stack("excess_error_at_stop"),
            settle_ticks=settle_ticks(self._gains.position, self._tp),
        ).block()
        self._limits = ExcessErrorLimits(*self._limit_block)  # views: the kernel and the reference share them
        self._alarm = np.zeros(self.batch, dtype=np.int8)
        v = self.values
        self._kernel_io = (
            *(v[f"{a}_ref"] for a in AXES), *(v[f"{a}_position"] for a in AXES), *(v[f"{a}_velocity"] for a in AXES),
            v["in_position_width"], *(v[f"{a}_current_cmd"] for a in AXES), *(v[f"{a}_velocity_cmd"] for a in AXES),
            v["in_position"], self._limit_block, self._alarm,
        )
        self._next_tick = 0
        self._last_h: float | None = None
        self._last_n = 0
        delay = self._stack("servo_delay")
        if not np.all(np.isfinite(delay) & (delay >= 0.0)):
            raise ServoError(f"{self.name}: {{x,y,z}}_servo_delay must be finite and >= 0, got {delay!r}")
        self._delay = delay
        self._delay_line: DelayLine | None = None
        if np.any(delay > 0.0):
            capacity = int(math.ceil(float(np.max(delay)) / self._tv)) + 3
            self._delay_line = DelayLine(delay.shape, capacity, self._state.current_cmd)
            self._delay_line.push(t0, self._state.current_cmd)
        self._publish()

    def _publish(self) -> None:
        for i, a in enumerate(AXES):
            self.values[f"{a}_current_cmd"][...] = self._state.current_cmd[i]
            self.values[f"{a}_velocity_cmd"][...] = self._state.velocity_cmd[i]
        deviation = np.abs(self._stack("ref") - self._stack("position"))
        self.values["in_position"][...] = np.all(deviation <= self.values["in_position_width"], axis=0)

    def _ticks(self, t: float, h: float) -> tuple[int, int]:
        """(first tick index, number of ticks) of ``do_step(t, h)``; checks divisibility and contiguity.

        Fast path for the usual case (same ``h`` as last time, ``t`` at the expected tick within
        ``TICK_RTOL``); anything else goes through :func:`_integer_ratio` for the error message.
        """
        if h != self._last_h:
            n = _integer_ratio(h, self._tv, "step size h", self.name)
            if n < 1:
                raise ServoError(
                    f"{self.name}: step size h = {h!r} s is shorter than the velocity loop period {self._tv!r} s")
            self._last_h, self._last_n = h, n
        k0 = self._next_tick
        elapsed = t - self.t0
        if abs(k0 * self._tv - elapsed) > TICK_RTOL * max(abs(elapsed), self._tv):
            k = _integer_ratio(elapsed, self._tv, "t - t0", self.name)
            raise ServoError(
                f"{self.name}: do_step at t = {t!r} s (tick {k}) but the controller is at tick {k0} "
                f"(t = {self.t0 + k0 * self._tv!r} s); steps must be contiguous"
            )
        return k0, self._last_n

    def _apply_delay(self, t_end: float) -> None:
        """Publish the current command of ``t_end - servo_delay`` (the delay line holds step-end commands)."""
        line = self._delay_line
        if line is None:
            return
        line.push(t_end, self._state.current_cmd)
        delayed = line.read(t_end, self._delay)
        for i, a in enumerate(AXES):
            self.values[f"{a}_current_cmd"][...] = delayed[i]

    def _do_step(self, t: float, h: float) -> None:
        self._step_ticks(t, h)
        self._apply_delay(self.t0 + self._next_tick * self._tv)

    def _step_ticks(self, t: float, h: float) -> None:
        k0, n = self._ticks(t, h)
        if self.use_compiled:
            n_alarm = mcu_kernel(k0, n, self._ratio, self._tp, self._tv, self._gain_block, self._state.block,
                                 *self._kernel_io)
        else:
            ref = self._stack("ref")
            pos = self._stack("position")
            vel = self._stack("velocity")
            for k in range(k0, k0 + n):
                if k % self._ratio == 0:
                    position_loop(self._state, self._gains, ref, pos, self._tp)
                velocity_loop(self._state, self._gains, vel, self._tv)
            self._publish()
            self._alarm[...] = excess_error_alarm(self._state, self._limits, ref, pos)
            n_alarm = int(np.count_nonzero(self._alarm))
        self._next_tick = k0 + n
        if n_alarm:
            self._raise_alarms()

    def _raise_alarms(self) -> None:
        """Fail the members with an excess-error alarm (code ``1 + 2 axis + at_stop``), naming axis, error, limit."""
        for b in np.flatnonzero(self._alarm):
            if self.failed_members[b]:
                continue
            code = int(self._alarm[b]) - 1
            axis, at_stop = AXES[code // 2], bool(code % 2)
            alarm, key, number = _ALARMS[at_stop]
            error = abs(float(self.values[f"{axis}_ref"][b]) - float(self.values[f"{axis}_position"][b]))
            limit = float(self.values[f"{axis}_{key}"][b])
            mask = np.zeros(self.batch, dtype=bool)
            mask[b] = True
            self._limit_block[:2, :, b] = 0.0  # an alarmed member is not checked again
            self.fail_members(mask, f"{self.name}: {alarm} on {axis.upper()}: following error {error * 1e3:.4g} mm "
                                    f"exceeds {axis}_{key} = {limit * 1e3:g} mm (FANUC No. {number})", ServoError)

    def _reset(self) -> None:
        self.__dict__.pop("_state", None)
