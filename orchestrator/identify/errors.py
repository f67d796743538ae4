"""Errors of the identification package."""
from __future__ import annotations

from ..errors import CncTwinError


class IdentificationError(CncTwinError):
    """A recording or case cannot be used for identification (missing columns, no usable segment, NaN, ...).

    The message names the file and says what is missing and what was expected.
    """
