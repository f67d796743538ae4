"""Component roles: what an FMU must expose to stand in for a part of the twin.

A role lists the variables the twin wires (``required``) and those it only
records (``optional``), each with causality, unit and type, in the names of
the native components (see :mod:`orchestrator.twin`). A foreign FMU can use
other names through a mapping ``{our_name: their_name}``.
"""
from __future__ import annotations

from dataclasses import dataclass

from fmus_src.component import Variable

from .errors import FMUError

_AXES = ("x", "y", "z")


@dataclass(frozen=True)
class Role:
    """What the twin needs from one component.

    Attributes
    ----------
    name : str
        ``"nck"``, ``"mcu"``, ``"drive"`` or ``"cutting"``.
    required : tuple of Variable
        Variables the twin connects (inputs it drives, outputs it reads,
        the stop signal).
    optional : tuple of Variable
        Variables the twin only records or sets (parameters; they fix the
        units a mapping converts to).
    """

    name: str
    required: tuple[Variable, ...]
    optional: tuple[Variable, ...] = ()

    def variables(self) -> tuple[Variable, ...]:
        """Required then optional variables."""
        return self.required + self.optional

    def variable(self, name: str) -> Variable | None:
        """The role's declaration of ``name``, or None."""
        return next((v for v in self.variables() if v.name == name), None)


def _in(name: str, unit: str, type_: str = "Real") -> Variable:
    return Variable(name, "input", unit, 0.0 if type_ == "Real" else 0, "", type_)  # type: ignore[arg-type]


def _out(name: str, unit: str, type_: str = "Real") -> Variable:
    start: float | int | bool = {"Real": 0.0, "Integer": 0, "Boolean": False}[type_]
    return Variable(name, "output", unit, start, "", type_)  # type: ignore[arg-type]


#: The roles of the default twin (names and units of the native components).
ROLES: dict[str, Role] = {
    "nck": Role(
        "nck",
        required=tuple(_out(f"{a}_ref", "m") for a in _AXES)
        + (_out("spindle_speed", "rad/s"), _out("done", "1", "Boolean")),
        optional=(_out("line", "1", "Integer"), _out("spindle_ref", "rad/s"), _out("feed_ref", "m/s")),
    ),
    "mcu": Role(
        "mcu",
        required=tuple(v for a in _AXES for v in (_in(f"{a}_ref", "m"), _in(f"{a}_position", "m"),
                                                  _in(f"{a}_velocity", "m/s")))
        + tuple(_out(f"{a}_current_cmd", "A") for a in _AXES)
        + (_out("in_position", "1", "Boolean"),),
        optional=tuple(_out(f"{a}_velocity_cmd", "m/s") for a in _AXES),
    ),
    "drive": Role(
        "drive",
        required=(_in("current_cmd", "A"), _in("disturbance_force", "N"), _out("position", "m"),
                  _out("velocity", "m/s")),
        optional=(_out("motor_force", "N"), _out("friction_force", "N")) + tuple(
            Variable(n, "parameter", u, 0.0) for n, u in (
                ("mass", "kg"), ("torque_constant", "N.m/A"), ("screw_lead", "m"), ("initial_position", "m"),
                *((f"{k}_{d}", u2) for d in ("positive", "negative") for k, u2 in (
                    ("coulomb", "N"), ("static", "N"), ("stribeck_velocity", "m/s"), ("viscous", "N.s/m"))),
            )
        ),
    ),
    "cutting": Role(
        "cutting",
        required=tuple(_in(f"{a}_position", "m") for a in _AXES)
        + (_in("spindle_speed", "rad/s"), _out("fx", "N"), _out("fy", "N")),
        optional=(_out("fc", "N"), _out("fc_peak", "N"), _out("spindle_torque", "N.m")),
    ),
}


def get_role(name: str) -> Role:
    """The role called ``name``.

    Raises
    ------
    FMUError
        Unknown role.
    """
    try:
        return ROLES[name]
    except KeyError:
        raise FMUError(f"unknown role {name!r}; expected one of {sorted(ROLES)}") from None
