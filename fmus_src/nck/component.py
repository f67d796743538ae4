"""``NCKernel``: the NC kernel as a batch-capable co-simulation component.

The whole program is planned at ``setup`` (see :mod:`.planner`) into a ragged
batch plan (:mod:`.batch_plan`: memory grows with the sum of the members'
lengths); ``do_step(t, h)`` reads the planned samples at ``t + h`` with
:func:`.sampling.read_plan` (linear interpolation between interpolation
periods for Real outputs when ``t + h`` is not on the grid).

Before planning, the interpreted path is checked against the stored stroke limits of the axes whose
``<a>_stroke_check`` is on (:mod:`.stroke`; the machine file's ``[axis.<a>] stroke_min_mm/stroke_max_mm``).

Frames: ``{x,y,z}_initial`` and the outputs ``{x,y,z}_ref`` are in the twin's axis frame; the work offsets
``g54_x`` … ``g59_z``, the reference positions and the stroke limits are machine coordinates, which are the
axis frame minus ``machine_zero_{x,y,z}`` (default 0: the same; see :mod:`.settings`).

The program comes from the String parameter ``program_file`` or, in Python,
from the ``program_text`` keyword of the constructor / :meth:`NCKernel.set_program_text`
(text wins when both are given).
"""
from __future__ import annotations

from pathlib import Path
from typing import ClassVar, Mapping

import numpy as np

from ..component import Component, ComponentError, Variable
from .blocks import Block, Program
from .cycles import CycleMachine
from .decimal_input import DECIMAL_INPUTS
from .errors import NCParameterError
from .interpreter import interpret
from .lexer import split_lines, without_dos_eof
from .m_aliases import DEFAULT_M_CODES, format_m_codes, parse_m_codes
from .overrides import apply_overrides
from .params import NCParams
from .planner import BatchPlan, Schedule, build_schedule, plan_batch
from .sampling import read_plan
from .settings import (
    DEFAULT_REFERENCE, TOOL_CHANGE_RETRACTS, TOOL_CHANGE_SPINDLES, TWIN_OFFSET_REGISTERS, InterpreterSettings,
)
from .source import read_program
from .stroke import StrokeLimits, check_stroke

#: Number of tool length offset parameters ``tool_length_1 .. tool_length_N`` (H1..HN).
N_TOOL_LENGTHS = TWIN_OFFSET_REGISTERS
#: Number of tool radius offset parameters ``tool_radius_1 .. tool_radius_N`` (D1..DN), as many as H.
N_TOOL_RADII = N_TOOL_LENGTHS
WORK_OFFSETS = (54, 55, 56, 57, 58, 59)

_D = NCParams()


def _variables() -> tuple[Variable, ...]:
    p = "parameter"
    v: list[Variable] = [
        Variable("program_file", p, "1", "", "path of the G-code program file", "String"),
        Variable("interpolation_period", p, "s", _D.interpolation_period, "interpolation period Ts"),
        Variable("lookahead_blocks", p, "1", _D.lookahead_blocks, "look-ahead window in blocks", "Integer"),
        Variable("max_cutting_feed", p, "m/s", _D.max_cutting_feed, "maximum cutting feed (FANUC No. 1430)"),
        Variable("accel_before_interp", p, "m/s2", _D.accel_before_interp,
                 "tangential acceleration of acc/dec before interpolation (No. 1660)"),
        Variable("accel_change_time_before_interp", p, "s", _D.accel_change_time_before_interp,
                 "acceleration change time of bell-shaped acc/dec before interpolation (No. 1772); 0 = trapezoidal"),
        Variable("corner_velocity_difference", p, "m/s", _D.corner_velocity_difference,
                 "allowable per-axis velocity difference at corners (No. 1783)"),
        Variable("arc_accel", p, "m/s2", _D.arc_accel, "allowable centripetal acceleration on arcs (No. 1735)"),
        Variable("cutting_time_constant", p, "s", _D.cutting_time_constant,
                 "time constant of acc/dec after interpolation in cutting feed (No. 1769)"),
        Variable("cutting_filter", p, "1", _D.cutting_filter, "after-interpolation filter in cutting: linear|bell",
                 "String"),
        Variable("rapid_time_constant", p, "s", _D.rapid_time_constant, "time constant of rapid acc/dec (No. 1620)"),
        Variable("rapid_filter", p, "1", _D.rapid_filter, "after-interpolation filter in rapid: linear|bell", "String"),
        Variable("in_position_width", p, "m", _D.in_position_width, "in-position width (No. 1826)"),
        Variable("in_position_before_rapid", p, "1", _D.in_position_before_rapid,
                 "a rapid after cutting feed waits until the modelled servo deviation is within in_position_width "
                 "on every axis (FANUC in-position check before a positioning block)", "Boolean"),
        Variable("spindle_max_speed", p, "rad/s", _D.spindle_max_speed, "maximum spindle speed (S is clamped)"),
        Variable("spindle_ramp", p, "rad/s2", _D.spindle_ramp, "spindle acceleration"),
        Variable("spindle_speed_arrival_tolerance", p, "1", _D.spindle_speed_arrival_tolerance,
                 "spindle speed arrival tolerance as a fraction of the command"),
        Variable("spindle_power", p, "W", 11000.0, "spindle motor power (accepted, not used by the NC kernel)"),
    ]
    for a in "xyz":
        v.append(Variable(f"{a}_rapid_feed", p, "m/s", getattr(_D, f"{a}_rapid_feed"), f"{a.upper()} rapid traverse rate"))
    for a in "xyz":
        v.append(Variable(f"{a}_position_gain", p, "1/s", getattr(_D, f"{a}_position_gain"),
                          f"{a.upper()} position loop gain Kv x scale of the servo model of in_position_before_rapid"))
    for a in "xyz":
        v.append(Variable(f"{a}_initial", p, "m", 0.0, f"{a.upper()} tool position at program start, axis frame"))
    for a in "xyz":
        v.append(Variable(f"machine_zero_{a}", p, "m", 0.0,
                          f"{a.upper()} of machine zero in the axis frame: machine coordinates (G53, reference "
                          "positions, work offsets, stroke limits) = axis frame - machine_zero"))
    for g in WORK_OFFSETS:
        for a in "xyz":
            v.append(Variable(f"g{g}_{a}", p, "m", 0.0,
                              f"G{g} work offset, {a.upper()}: machine coordinate of the work zero (the axis-frame "
                              f"origin is -machine_zero_{a})"))
    for h in range(1, N_TOOL_LENGTHS + 1):
        v.append(Variable(f"tool_length_{h}", p, "m", 0.0, f"tool length offset H{h} (added to Z with G43)"))
    for d in range(1, N_TOOL_RADII + 1):
        v.append(Variable(f"tool_radius_{d}", p, "m", 0.0,
                          f"tool radius offset D{d} (G41/G42 are accepted only while it is 0)"))
    v.append(Variable("tool_change_time", p, "s", _D.tool_change_time, "M6 tool change time (assumption: 3 s)"))
    for i, a in enumerate("xyz"):
        v.append(Variable(f"reference_{a}", p, "m", DEFAULT_REFERENCE[i],
                          f"{a.upper()} of the G28 reference position, machine coordinates (FANUC No. 1240)"))
    for n in (2, 3, 4):
        for i, a in enumerate("xyz"):
            v.append(Variable(f"reference{n}_{a}", p, "m", DEFAULT_REFERENCE[i],
                              f"{a.upper()} of the {n}{'nd' if n == 2 else 'rd' if n == 3 else 'th'} reference "
                              f"position (G30 P{n}), machine coordinates (FANUC No. {1239 + n}; "
                              "default: the default 1st one)"))
    v.append(Variable("g73_retract", p, "m", CycleMachine().g73_retract,
                      "return amount d of the G73 high-speed peck cycle (FANUC No. 5114)"))
    v.append(Variable("g83_clearance", p, "m", CycleMachine().g83_clearance,
                      "clearance d of the G83 peck cycle above the previous bottom (FANUC No. 5115)"))
    v.append(Variable("rigid_tapping_mode", p, "1", "M29",
                      "G84/G74 are rigid tapping after M29 (M29) or always (always; FANUC No. 5200#0)", "String"))
    v.append(Variable("boring_shift", p, "1", CycleMachine().boring_shift,
                      "G76/G87 shift direction after the spindle orientation: +X|-X|+Y|-Y (FANUC No. 5101 #4/#5)",
                      "String"))
    v.append(Variable("rigid_tapping_time_constant", p, "s", _D.rigid_tapping_time_constant,
                      "rigid-tapping linear acc/dec time to the maximum spindle speed (FANUC No. 5261)"))
    v.append(Variable("decimal_point_input", p, "1", "calculator",
                      "FANUC No. 3401#0 DPI: a number without a decimal point is in mm/inch (calculator, DPI = 1) "
                      "or in least input increments, X10 = 0.010 mm (increment, DPI = 0)", "String"))
    v.append(Variable("tool_change_retract", p, "1", "off",
                      "M6 first moves Z at rapid to the 1st (G28) or 2nd (G30) reference position Z; off: M6 is "
                      "tool_change_time alone", "String"))
    v.append(Variable("tool_change_spindle", p, "1", "stop",
                      "M6 and the spindle: stop (M6 stops a turning spindle with the retract, tool_change_time "
                      "starts with it at rest, and it stays stopped until M3/M4) or keep (it turns on through the "
                      "change)", "String"))
    v.append(Variable("block_delete", p, "1", False, "block delete switch: skip blocks starting with /", "Boolean"))
    for a in "xyz":
        v.append(Variable(f"{a}_stroke_check", p, "1", False,
                          f"stored stroke check 1 of {a.upper()}: the planned path must stay within "
                          f"{a}_stroke_min..{a}_stroke_max (FANUC No. 1320/1321); off: {a.upper()} is not checked",
                          "Boolean"))
        v.append(Variable(f"{a}_stroke_min", p, "m", 0.0,
                          f"{a.upper()} - stroke limit, machine coordinates (FANUC No. 1321; with {a}_stroke_check)"))
        v.append(Variable(f"{a}_stroke_max", p, "m", 0.0,
                          f"{a.upper()} + stroke limit, machine coordinates (FANUC No. 1320; with {a}_stroke_check)"))
    v.append(Variable("m_codes", p, "1", format_m_codes(DEFAULT_M_CODES),
                      "machine builder's M codes: alias=standard codes;... (machine file [nck.m_codes])", "String"))
    o = "output"
    v += [
        Variable("x_ref", o, "m", 0.0, "X reference position after acc/dec after interpolation"),
        Variable("y_ref", o, "m", 0.0, "Y reference position after acc/dec after interpolation"),
        Variable("z_ref", o, "m", 0.0, "Z reference position after acc/dec after interpolation"),
        Variable("feed_ref", o, "m/s", 0.0, "path speed before the after-interpolation filter"),
        Variable("spindle_ref", o, "rad/s", 0.0, "commanded spindle speed (+ M3, - M4, 0 stopped)"),
        Variable("spindle_speed", o, "rad/s", 0.0, "actual (ramped) spindle speed"),
        Variable("line", o, "1", 0, "source line executing", "Integer"),
        Variable("done", o, "1", False, "program finished and in position", "Boolean"),
        Variable("tool", o, "1", 0, "tool in the spindle", "Integer"),
    ]
    return tuple(v)


def _rigid_always(mode: str, name: str) -> bool:
    """``rigid_tapping_mode`` → :attr:`CycleMachine.rigid_always` ("M29": False, "always": True)."""
    if mode not in ("M29", "always"):
        raise NCParameterError(f"{name}.rigid_tapping_mode must be 'M29' or 'always', got {mode!r}")
    return mode == "always"


def _decimal_input(mode: str, name: str) -> str:
    """``decimal_point_input`` checked: "calculator" (FANUC No. 3401#0 DPI = 1) or "increment" (DPI = 0)."""
    if mode not in DECIMAL_INPUTS:
        raise NCParameterError(f"{name}.decimal_point_input must be one of {list(DECIMAL_INPUTS)}, got {mode!r}")
    return mode


def _tool_change_retract(mode: str, name: str) -> str:
    """``tool_change_retract`` checked: "off", "G28" or "G30" (:func:`.machine_moves.tool_change_retract`)."""
    if mode not in TOOL_CHANGE_RETRACTS:
        raise NCParameterError(f"{name}.tool_change_retract must be one of {list(TOOL_CHANGE_RETRACTS)}, "
                               f"got {mode!r}")
    return mode


def _tool_change_spindle(mode: str, name: str) -> str:
    """``tool_change_spindle`` checked: "stop" or "keep" (:func:`.auxiliary_functions.auxiliary_blocks`)."""
    if mode not in TOOL_CHANGE_SPINDLES:
        raise NCParameterError(f"{name}.tool_change_spindle must be one of {list(TOOL_CHANGE_SPINDLES)}, "
                               f"got {mode!r}")
    return mode


class NCKernel(Component):
    """NC kernel: interpreter, look-ahead interpolator, acc/dec, spindle.

    Parameters
    ----------
    name : str
        Instance name.
    batch : int
        Number of batch members B.
    program_text : str, optional
        Program source given directly (Python only); otherwise ``program_file`` is read.
    **parameters
        Values of the parameters listed in :attr:`variables` (SI).

    Attributes
    ----------
    blocks_ : tuple of Block
        Typed blocks after setup (with spindle commands inserted for spindle overrides).
    program_ : Program
        The interpreted program.
    duration_ : ndarray (B,)
        Planned program time until done (s).
    plan_ : BatchPlan
        The sampled references of all members, stored ragged (:mod:`.batch_plan`; its ``position``,
        ``feed`` … properties rebuild padded (B, K) copies for inspection).
    """

    variables: ClassVar[tuple[Variable, ...]] = _variables()

    def __init__(self, name: str = "", batch: int = 1, program_text: str | None = None, **parameters: object) -> None:
        super().__init__(name, batch, **parameters)
        self._text: str | None = program_text
        self._text_file = "<text>"
        self._feed_over: dict[int, object] = {}
        self._spindle_over: dict[int, object] = {}
        self._per_rev_over: dict[int, object] = {}

    # ------------------------------------------------------------------ Python-side inputs
    def set_program_text(self, text: str, file: str = "<text>") -> None:
        """Give the program as text (before ``setup``); ``file`` names it in messages."""
        if self.state != "instantiated":
            raise ComponentError(f"{self.name}: set_program_text() must be called before setup()")
        self._text = text
        self._text_file = file

    def set_overrides(self, feed: Mapping[int, object] | None = None, spindle: Mapping[int, object] | None = None,
                      feed_per_rev: Mapping[int, object] | None = None) -> None:
        """Replace F and S of source lines per batch member (before ``setup``).

        Parameters
        ----------
        feed : mapping line -> scalar or array (B,), m/s
            New feed of the given 1-based source lines under G94 (modal, like rewriting the F word there).
        spindle : mapping line -> scalar or array (B,), rad/s
            New spindle speed of the given lines (like rewriting the S word there).
        feed_per_rev : mapping line -> scalar or array (B,), m/rev, optional
            New feed per revolution of the given lines under G95 (like rewriting their F word in mm/rev; the
            feed is then this value x the member's spindle speed in effect, see :mod:`.overrides`).
        """
        if self.state != "instantiated":
            raise ComponentError(f"{self.name}: set_overrides() must be called before setup()")
        self._feed_over = dict(feed or {})
        self._spindle_over = dict(spindle or {})
        self._per_rev_over = dict(feed_per_rev or {})

    # ------------------------------------------------------------------ helpers
    def _uniform(self, name: str) -> float:
        arr = self.values[name]
        assert isinstance(arr, np.ndarray)
        if not np.all(arr == arr[0]):
            raise NCParameterError(f"{self.name}.{name} must be the same for all batch members, got {arr.tolist()}")
        return float(arr[0])

    def stroke_limits(self) -> StrokeLimits:
        """The stored stroke limits of the parameters ``{x,y,z}_stroke_check/_min/_max`` (m, machine coordinates)."""
        pairs = {}
        for a in "xyz":
            flags = np.asarray(self.values[f"{a}_stroke_check"])
            if not np.all(flags == flags[0]):
                raise NCParameterError(f"{self.name}.{a}_stroke_check must be the same for all batch members, "
                                       f"got {flags.tolist()}")
            if bool(flags[0]):
                pairs[a] = (self._uniform(f"{a}_stroke_min"), self._uniform(f"{a}_stroke_max"))
        try:
            return StrokeLimits(**pairs)
        except NCParameterError as exc:
            raise NCParameterError(f"{self.name}: {exc}") from None

    def _machine_zero(self) -> tuple[float, float, float]:
        """``machine_zero_{x,y,z}`` (m), checked finite."""
        zero = tuple(self._uniform(f"machine_zero_{a}") for a in "xyz")
        if not all(np.isfinite(zero)):
            raise NCParameterError(f"{self.name}: machine_zero_x/y/z must be finite, got {zero}")
        return zero  # type: ignore[return-value]

    def _read_program(self) -> tuple[str, str]:
        if self._text is not None:
            return self._text, self._text_file
        path = str(self.values["program_file"])
        if not path:
            raise ComponentError(f"{self.name}: no program: set program_file or give program_text")
        if not Path(path).is_file():
            raise ComponentError(f"{self.name}: program_file {path!r} not found")
        return read_program(path), path

    def _member_params(self, b: int) -> NCParams:
        kw = {}
        for name in NCParams.names():
            val = self.values[name]
            kw[name] = val if isinstance(val, str) else val[b].item()
        return NCParams(**kw)

    # ------------------------------------------------------------------ protocol
    def _setup(self, t0: float) -> None:
        schedule, params, feeds, speeds = self.planning_inputs()
        self.plan_: BatchPlan = plan_batch(schedule, params, feeds, speeds)
        self.duration_ = self.plan_.duration.astype(float)
        self._write(0.0)

    def planning_inputs(self) -> tuple[Schedule, list[NCParams], np.ndarray, np.ndarray]:
        """Interpret the program with the overrides: the arguments of :func:`.planner.plan_batch`.

        Sets ``program_`` and ``blocks_`` (as ``setup`` does).

        Returns
        -------
        schedule : Schedule
        params : list of NCParams, length B
        feeds, speeds : ndarray (B, n_blocks)
            Feed (m/s) of each feed block and speed (rad/s) of each spindle command per member, NaN elsewhere.
        """
        text, file = self._read_program()
        settings = InterpreterSettings(
            initial=tuple(self._uniform(f"{a}_initial") for a in "xyz"),  # type: ignore[arg-type]
            work_offsets={g: tuple(self._uniform(f"g{g}_{a}") for a in "xyz") for g in WORK_OFFSETS},  # type: ignore[misc]
            tool_lengths=[self._uniform(f"tool_length_{h}") for h in range(1, N_TOOL_LENGTHS + 1)],
            tool_radii=[self._uniform(f"tool_radius_{d}") for d in range(1, N_TOOL_RADII + 1)],
            block_delete=bool(self.values["block_delete"][0]),  # type: ignore[index]
            reference=tuple(self._uniform(f"reference_{a}") for a in "xyz"),  # type: ignore[arg-type]
            reference2=tuple(self._uniform(f"reference2_{a}") for a in "xyz"),  # type: ignore[arg-type]
            reference3=tuple(self._uniform(f"reference3_{a}") for a in "xyz"),  # type: ignore[arg-type]
            reference4=tuple(self._uniform(f"reference4_{a}") for a in "xyz"),  # type: ignore[arg-type]
            cycles=CycleMachine(self._uniform("g73_retract"), self._uniform("g83_clearance"),
                                _rigid_always(str(self.values["rigid_tapping_mode"]), self.name),
                                str(self.values["boring_shift"])),
            m_codes=parse_m_codes(str(self.values["m_codes"]), f"{self.name}.m_codes"),
            decimal_input=_decimal_input(str(self.values["decimal_point_input"]), self.name),
            tool_change_retract=_tool_change_retract(str(self.values["tool_change_retract"]), self.name),
            tool_change_spindle=_tool_change_spindle(str(self.values["tool_change_spindle"]), self.name),
            machine_zero=self._machine_zero(),
        )
        for n in (1, 2, 3, 4):
            if not all(np.isfinite(settings.reference_position(n))):
                name = "reference" if n == 1 else f"reference{n}"
                raise NCParameterError(f"{self.name}: {name}_x/y/z must be finite, "
                                       f"got {settings.reference_position(n)}")
        self.program_: Program = interpret(text, file, settings)
        check_stroke(self.program_.blocks, settings.initial, self.stroke_limits(), file,
                     split_lines(without_dos_eof(text)), settings.machine_zero)
        blocks: tuple[Block, ...]
        blocks, feeds, speeds = apply_overrides(self.program_, self.batch, self._feed_over, self._spindle_over,
                                                self._per_rev_over)
        self.blocks_ = blocks
        self._uniform("interpolation_period")
        params = [self._member_params(b) for b in range(self.batch)]
        return build_schedule(blocks, settings.initial, file), params, feeds, speeds

    def _write(self, kf: float) -> None:
        plan = self.plan_
        v = self.values
        read_plan(float(kf), plan.n_samples, *plan.arrays(), v["x_ref"], v["y_ref"], v["z_ref"], v["feed_ref"],
                  v["spindle_ref"], v["spindle_speed"], v["line"], v["tool"], v["done"])

    def _do_step(self, t: float, h: float) -> None:
        self._write((t + h - self.t0) / self.plan_.period)

    def _reset(self) -> None:
        for name in ("plan_", "blocks_", "program_", "duration_"):
            self.__dict__.pop(name, None)
