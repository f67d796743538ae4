"""Map machine-file sections (already in SI, suffix stripped) to servo component parameters.

``fmus_src`` must not import ``orchestrator``; these helpers take the plain
dicts returned by ``Machine.si(section)``::

    m = load_machine("default")
    DriveAxis("x_drive", **drive_parameters(m.si("axis.x"), m.si("axis.x.friction.positive"),
                                            m.si("axis.x.friction.negative")))
    MCU("mcu", **mcu_parameters({a: m.si(f"axis.{a}") for a in "xyz"}, m.si("servo")))
"""
from __future__ import annotations

from typing import Mapping

_MCU_AXIS_KEYS = (
    "position_gain", "velocity_p_gain", "velocity_i_gain", "position_scale", "velocity_p_scale",
    "velocity_i_scale", "velocity_feedforward", "acceleration_feedforward", "peak_current", "mass",
    "torque_constant", "screw_lead",
)
#: Optional per-axis MCU keys (the component default applies when a section lacks them).
_MCU_OPTIONAL_AXIS_KEYS = ("excess_error_in_motion", "excess_error_at_stop")
_FRICTION_KEYS = ("coulomb", "static", "stribeck_velocity", "viscous")


def mcu_parameters(
    axes: Mapping[str, Mapping[str, float | str]], servo: Mapping[str, float | str] | None = None
) -> dict[str, float]:
    """MCU parameters from ``{"x": si("axis.x"), ...}`` and ``si("servo")``.

    Parameters
    ----------
    axes : mapping
        Axis letter -> SI section of ``[axis.<a>]`` (the excess-error limits
        ``excess_error_in_motion`` / ``excess_error_at_stop`` are taken when present).
    servo : mapping, optional
        SI section ``[servo]`` (``position_loop_period``, ``velocity_loop_period``).

    Returns
    -------
    dict
        ``{"x_position_gain": ..., ..., "position_loop_period": ...}``.
    """
    out: dict[str, float] = {}
    for a, section in axes.items():
        for key in _MCU_AXIS_KEYS:
            out[f"{a}_{key}"] = float(section[key])
        for key in _MCU_OPTIONAL_AXIS_KEYS:
            if key in section:
                out[f"{a}_{key}"] = float(section[key])
    if servo is not None:
        for key in ("position_loop_period", "velocity_loop_period"):
            out[key] = float(servo[key])
    return out


def drive_parameters(
    axis: Mapping[str, float | str], positive: Mapping[str, float | str], negative: Mapping[str, float | str]
) -> dict[str, float]:
    """DriveAxis parameters from the SI sections ``[axis.<a>]`` and its two friction tables.

    Returns
    -------
    dict
        ``mass``, ``torque_constant``, ``screw_lead`` and the eight
        ``{coulomb,static,stribeck_velocity,viscous}_{positive,negative}`` values.
    """
    out = {k: float(axis[k]) for k in ("mass", "torque_constant", "screw_lead")}
    for key in _FRICTION_KEYS:
        out[f"{key}_positive"] = abs(float(positive[key]))
        out[f"{key}_negative"] = abs(float(negative[key]))
    return out


#: DriveAxis effect parameters (the stripped keys of ``[axis.<a>.effects]``, SI).
DRIVE_EFFECT_KEYS = (
    "gravity_force", "gravity_spring", "reversal_friction_peak", "reversal_friction_decay", "ripple_amplitude",
    "ripple_period", "screw_stiffness", "backlash_width", "pitch_slope", "pitch_amplitude", "pitch_period",
    "thermal_drift_rate",
)
#: MCU effect parameters per axis (``{a}_<key>``).
MCU_EFFECT_KEYS = ("servo_delay",)


def effect_parameters(axis: str, effects: Mapping[str, float | str]) -> tuple[dict[str, float], dict[str, float]]:
    """Split an SI ``[axis.<a>.effects]`` section into DriveAxis and MCU parameters.

    Parameters
    ----------
    axis : str
        ``"x"``, ``"y"`` or ``"z"``.
    effects : mapping
        Stripped SI keys (``{"gravity_force": 600.0, "servo_delay": 0.0005, ...}``).

    Returns
    -------
    drive, mcu : dict
        ``{"gravity_force": ...}`` for ``DriveAxis`` and ``{"z_servo_delay": ...}`` for ``MCU``.

    Raises
    ------
    KeyError
        For a key that is neither a drive nor an MCU effect parameter.
    """
    drive: dict[str, float] = {}
    mcu: dict[str, float] = {}
    for key, value in effects.items():
        if key in DRIVE_EFFECT_KEYS:
            drive[key] = float(value)
        elif key in MCU_EFFECT_KEYS:
            mcu[f"{axis}_{key}"] = float(value)
        else:
            raise KeyError(f"[axis.{axis}.effects] has no parameter {key!r}; expected one of "
                           f"{sorted(DRIVE_EFFECT_KEYS + MCU_EFFECT_KEYS)}")
    return drive, mcu
