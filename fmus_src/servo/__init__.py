"""Servo package: MCU cascade loops and feed-drive axes with Stribeck friction.

Components
----------
:class:`MCU`
    Position P / velocity PI cascade of the X, Y, Z axes (Sim & Lee 2023, Section 2.3).
:class:`DriveAxis`
    One feed-drive axis, ``Ms x'' = u - Ff - Fd`` with stick/slip Stribeck friction (Section 2.2).

Both run numba-compiled kernels (:mod:`.control_numba`, :mod:`.stick_slip_numba`)
by default; the numpy modules :mod:`.control` and :mod:`.stick_slip` are the
reference they are tested against (``MCU.use_compiled = False``,
``DriveAxis.use_compiled = False`` select them).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy_exports import lazy_exports

#: Public name -> submodule that defines it, imported on first access (PEP 562): a machine file's check of
#: the drive step (:mod:`.step_cap`, :mod:`.friction`) does not load numba through the components.
_LAZY = {
    "NUMBA_AVAILABLE": "..jit",
    **dict.fromkeys(("CascadeGains", "CascadeState", "position_loop", "velocity_loop"), ".control"),
    **dict.fromkeys(("DEFAULT_INTEGRATION_STEP", "DriveAxis"), ".drive"),
    "stribeck_step_cap": ".step_cap",
    "ServoError": ".errors",
    "StribeckParameters": ".friction", "stribeck_force": ".friction",
    "MCU": ".mcu",
    **dict.fromkeys(("DRIVE_EFFECT_KEYS", "MCU_EFFECT_KEYS", "drive_parameters", "effect_parameters",
                     "mcu_parameters"), ".params"),
    "SlipState": ".stick_slip", "advance": ".stick_slip",
}

__all__ = [
    "MCU", "DriveAxis", "ServoError", "DEFAULT_INTEGRATION_STEP", "stribeck_step_cap", "CascadeGains", "CascadeState",
    "position_loop", "velocity_loop", "StribeckParameters", "stribeck_force", "SlipState", "advance",
    "mcu_parameters", "drive_parameters", "effect_parameters", "DRIVE_EFFECT_KEYS", "MCU_EFFECT_KEYS",
    "NUMBA_AVAILABLE",
]


#: Imports a public name on first access (PEP 562); submodules import as usual.
__getattr__, __dir__ = lazy_exports(__name__, _LAZY, globals(), __all__)


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs
    from ..jit import NUMBA_AVAILABLE
    from .control import CascadeGains, CascadeState, position_loop, velocity_loop
    from .drive import DEFAULT_INTEGRATION_STEP, DriveAxis
    from .errors import ServoError
    from .friction import StribeckParameters, stribeck_force
    from .mcu import MCU
    from .params import DRIVE_EFFECT_KEYS, MCU_EFFECT_KEYS, drive_parameters, effect_parameters, mcu_parameters
    from .step_cap import stribeck_step_cap
    from .stick_slip import SlipState, advance
