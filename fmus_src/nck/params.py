"""NC kernel parameters of one batch member (SI), with defaults = models/machines/default.toml."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

from .errors import NCParameterError

RPM = 2.0 * math.pi / 60.0
MM_PER_MIN = 1e-3 / 60.0

FILTER_KINDS = ("linear", "bell")

#: Smallest position loop gain Kv (1/s) of the in-position model (:mod:`.servo_settle`): FANUC No. 1825's
#: smallest setting (1 in units of 0.01/s). The model's memory is SERVO_MEMORY / (Kv Ts) periods and its wait
#: ln(e0 / width) / Kv, both unbounded as Kv -> 0.
MIN_POSITION_GAIN = 0.01


@dataclass(frozen=True)
class NCParams:
    """Scalar NC parameters (one batch member), SI units.

    Defaults are the values of ``models/machines/default.toml`` ([nck], [spindle],
    [axis.*] rapid_feed); ``tool_change_time`` (3 s) is an assumption. ``rigid_tapping_time_constant`` (s,
    FANUC No. 5261): linear acc/dec time of rigid tapping to ``spindle_max_speed`` (see :mod:`.tapping`).
    ``in_position_before_rapid``: a rapid after cutting feed waits until the servo's modelled deviation is within
    ``in_position_width`` on every axis (FANUC's in-position check before a positioning block; False: the rapid
    starts as soon as the feed's interpolation ends); ``{x,y,z}_position_gain`` (1/s): the position loop gains
    Kv of that model (:mod:`.servo_settle`), default.toml's 50/s x scale 1.
    """

    interpolation_period: float = 1e-3
    lookahead_blocks: int = 40
    max_cutting_feed: float = 10000.0 * MM_PER_MIN
    accel_before_interp: float = 2.0
    accel_change_time_before_interp: float = 0.032
    corner_velocity_difference: float = 400.0 * MM_PER_MIN
    arc_accel: float = 1.0
    cutting_time_constant: float = 0.016
    cutting_filter: str = "linear"
    rapid_time_constant: float = 0.060
    rapid_filter: str = "bell"
    in_position_width: float = 0.02e-3
    spindle_max_speed: float = 8000.0 * RPM
    spindle_ramp: float = 4000.0 * RPM
    spindle_speed_arrival_tolerance: float = 0.05
    x_rapid_feed: float = 36000.0 * MM_PER_MIN
    y_rapid_feed: float = 36000.0 * MM_PER_MIN
    z_rapid_feed: float = 30000.0 * MM_PER_MIN
    tool_change_time: float = 3.0
    rigid_tapping_time_constant: float = 2.0
    in_position_before_rapid: bool = True
    x_position_gain: float = 50.0
    y_position_gain: float = 50.0
    z_position_gain: float = 50.0

    def __post_init__(self) -> None:
        positive = ("interpolation_period", "max_cutting_feed", "accel_before_interp", "corner_velocity_difference",
                    "arc_accel", "in_position_width", "spindle_max_speed", "spindle_ramp",
                    "x_rapid_feed", "y_rapid_feed", "z_rapid_feed", "x_position_gain", "y_position_gain",
                    "z_position_gain")
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise NCParameterError(f"NC parameter {name} must be a finite number > 0, got {value!r}")
        for name in ("x_position_gain", "y_position_gain", "z_position_gain"):
            if not getattr(self, name) >= MIN_POSITION_GAIN:
                raise NCParameterError(f"NC parameter {name} must be at least {MIN_POSITION_GAIN} 1/s (the position "
                                       f"loop gain of the in-position model), got {getattr(self, name)!r}")
        for name in ("accel_change_time_before_interp", "cutting_time_constant", "rapid_time_constant",
                     "tool_change_time", "rigid_tapping_time_constant"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise NCParameterError(f"NC parameter {name} must be a finite number >= 0, got {value!r}")
        if not 0.0 <= self.spindle_speed_arrival_tolerance < 1.0:
            raise NCParameterError(
                f"spindle_speed_arrival_tolerance must be in [0, 1), got {self.spindle_speed_arrival_tolerance!r}")
        if int(self.lookahead_blocks) != self.lookahead_blocks or self.lookahead_blocks < 1:
            raise NCParameterError(f"lookahead_blocks must be an integer >= 1, got {self.lookahead_blocks!r}")
        for name in ("cutting_filter", "rapid_filter"):
            if getattr(self, name) not in FILTER_KINDS:
                raise NCParameterError(f"{name} must be one of {FILTER_KINDS}, got {getattr(self, name)!r}")

    @property
    def rapid_feed(self) -> tuple[float, float, float]:
        """Per-axis rapid traverse rates (m/s)."""
        return (self.x_rapid_feed, self.y_rapid_feed, self.z_rapid_feed)

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """Field names."""
        return tuple(f.name for f in fields(cls))
