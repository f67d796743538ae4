"""The one exception type of FMU import and export."""
from __future__ import annotations

from ..errors import CncTwinError

#: Names of the FMI 2.0 status codes, by value.
STATUS_NAMES = ("fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal", "fmi2Pending")


class FMUError(CncTwinError):
    """An FMU could not be loaded, built or run.

    Parameters
    ----------
    message : str
        What went wrong, naming the file or component.
    path : str, optional
        The FMU file.
    component : str, optional
        Instance name of the component.
    function : str, optional
        FMI function that failed (``"fmi2DoStep"``).
    time : float, optional
        Simulation time of the failing call, s.
    status : int, optional
        FMI status code returned (2 discard, 3 error, 4 fatal).
    """

    def __init__(
        self,
        message: str,
        *,
        path: str | None = None,
        component: str | None = None,
        function: str | None = None,
        time: float | None = None,
        status: int | None = None,
    ) -> None:
        super().__init__(message)
        self.path = path
        self.component = component
        self.function = function
        self.time = time
        self.status = status


def status_name(status: int) -> str:
    """Readable name of an FMI 2.0 status code (``3`` → ``"fmi2Error"``)."""
    return STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else f"illegal status {status}"
