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
_FRICTION_KEYS = ("coulomb", "static", "stribeck_velocity", "viscous")


def mcu_parameters(
    axes: Mapping[str, Mapping[str, float | str]], servo: Mapping[str, float | str] | None = None
) -> dict[str, float]:
    """MCU parameters from ``{"x": si("axis.x"), ...}`` and ``si("servo")``.

    Parameters
    ----------
    axes : mapping
        Axis letter -> SI section of ``[axis.<a>]``.
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
