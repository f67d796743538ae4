"""Servo package: MCU cascade loops and feed-drive axes with Stribeck friction.

Components
----------
:class:`MCU`
    Position P / velocity PI cascade of the X, Y, Z axes (Sim & Lee 2023, Section 2.3).
:class:`DriveAxis`
    One feed-drive axis, ``Ms x'' = u - Ff - Fd`` with stick/slip Stribeck friction (Section 2.2).
"""
from __future__ import annotations

from .control import CascadeGains, CascadeState, position_loop, velocity_loop
from .drive import DEFAULT_INTEGRATION_STEP, DriveAxis, stribeck_step_cap
from .errors import ServoError
from .friction import StribeckParameters, stribeck_force
from .mcu import MCU
from .params import drive_parameters, mcu_parameters
from .stick_slip import SlipState, advance

__all__ = [
    "MCU", "DriveAxis", "ServoError", "DEFAULT_INTEGRATION_STEP", "stribeck_step_cap", "CascadeGains", "CascadeState",
    "position_loop", "velocity_loop", "StribeckParameters", "stribeck_force", "SlipState", "advance",
    "mcu_parameters", "drive_parameters",
]
