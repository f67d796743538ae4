"""Errors of the servo package (MCU and drive axes)."""
from __future__ import annotations

from ..component import ComponentError


class ServoError(ComponentError):
    """A servo component got an invalid parameter, step size or time instant.

    The message names the component instance, the offending variable or value
    and what was expected.
    """
