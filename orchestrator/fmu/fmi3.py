"""FMI 3.0 co-simulation specifics of :class:`~orchestrator.fmu.component.FMUComponent` (through fmpy).

What differs from FMI 2.0 and is kept here:

* the variable types: ``Float64``/``Float32`` are our ``Real``; ``Int8`` ...
  ``UInt64`` and ``Enumeration`` (exchanged as ``Int64``) our ``Integer``;
  ``Boolean`` and ``String`` as in FMI 2.0; ``Binary`` and ``Clock`` are not
  exchanged (:data:`NATIVE_TYPES`);
* the binary folder (platform tuple ``x86_64-linux``) and the status names;
* instantiation (:func:`instantiate_co_simulation`, with
  ``eventModeUsed = earlyReturnAllowed = false`` and no intermediate update);
* the output flags of ``fmi3DoStep`` (:class:`StepFlags`).

Status checks stay in :meth:`FMUComponent._fmi`, the one place for both versions.
"""
from __future__ import annotations

import ctypes
from pathlib import Path
from typing import Any, Callable

from fmpy.fmi3 import FMU3Slave, fmi3IntermediateUpdateCallback, fmi3LogMessageCallback

#: Binary folder of this platform in an FMI 3.0 archive.
PLATFORM = "x86_64-linux"

#: Names of the FMI 3.0 status codes, by value.
STATUS_NAMES = ("fmi3OK", "fmi3Warning", "fmi3Discard", "fmi3Error", "fmi3Fatal")

#: FMI 3.0 type -> (our type, ctypes element type, suffix of the fmi3Get/fmi3Set functions).
NATIVE_TYPES: dict[str, tuple[str, Any, str]] = {
    "Float64": ("Real", ctypes.c_double, "Float64"),
    "Float32": ("Real", ctypes.c_float, "Float32"),
    "Int8": ("Integer", ctypes.c_int8, "Int8"),
    "UInt8": ("Integer", ctypes.c_uint8, "UInt8"),
    "Int16": ("Integer", ctypes.c_int16, "Int16"),
    "UInt16": ("Integer", ctypes.c_uint16, "UInt16"),
    "Int32": ("Integer", ctypes.c_int32, "Int32"),
    "UInt32": ("Integer", ctypes.c_uint32, "UInt32"),
    "Int64": ("Integer", ctypes.c_int64, "Int64"),
    "UInt64": ("Integer", ctypes.c_uint64, "UInt64"),
    "Enumeration": ("Integer", ctypes.c_int64, "Int64"),
    "Boolean": ("Boolean", ctypes.c_bool, "Boolean"),
    "String": ("String", ctypes.c_char_p, "String"),
}


def is_fmi3(version: str) -> bool:
    """Whether an ``fmiVersion`` attribute names FMI 3 (any version starting with ``"3."``)."""
    return version.startswith("3.")


def status_name(status: int) -> str:
    """Readable name of an FMI 3.0 status code (``3`` -> ``"fmi3Error"``)."""
    return STATUS_NAMES[status] if 0 <= status < len(STATUS_NAMES) else f"illegal status {status}"


def instantiate_co_simulation(
    model_identifier: str,
    instantiation_token: str,
    unzip_dir: Path,
    instance_name: str,
    logger: Callable[[Any, int, bytes, bytes], None],
) -> tuple[FMU3Slave, Any, Any]:
    """Load the library and call ``fmi3InstantiateCoSimulation``.

    Parameters
    ----------
    model_identifier, instantiation_token : str
        From ``<CoSimulation>`` and ``<fmiModelDescription>``.
    unzip_dir : Path
        The extracted FMU.
    instance_name : str
        Name of the instance (used in the FMU's log messages).
    logger : callable
        ``logger(instance_environment, status, category, message)``, the FMU's log messages.

    Returns
    -------
    slave : FMU3Slave
        With ``slave.component`` set to the instance pointer (None or 0 when the FMU refused).
    log_callback, update_callback
        ctypes callbacks the caller must keep alive as long as the instance.

    Raises
    ------
    OSError, AttributeError
        The shared library cannot be loaded or lacks FMI 3.0 functions (fmpy).

    Notes
    -----
    ``eventModeUsed = false`` (also for an FMU with ``hasEventMode``: the FMU
    handles its events inside ``fmi3DoStep``), ``earlyReturnAllowed = false``,
    no required intermediate variables and no intermediate-update callback.
    The resource path is the ``resources`` folder with a trailing separator,
    or NULL when the FMU has none.
    """
    slave = FMU3Slave(guid=instantiation_token, unzipDirectory=str(unzip_dir), modelIdentifier=model_identifier,
                      instanceName=instance_name)
    log_callback = fmi3LogMessageCallback(logger)
    update_callback = fmi3IntermediateUpdateCallback()  # NULL: no intermediate update
    resources = unzip_dir / "resources"
    resource_path = (str(resources) + "/").encode("utf-8") if resources.is_dir() else None
    slave.component = slave.fmi3InstantiateCoSimulation(
        instance_name.encode("utf-8"), instantiation_token.encode("utf-8"), resource_path,
        False, True, False, False, None, 0, None, log_callback, update_callback,
    )
    return slave, log_callback, update_callback


class StepFlags:
    """The output arguments of ``fmi3DoStep``, preallocated once per instance.

    Attributes
    ----------
    args : tuple
        ``(eventHandlingNeeded*, terminateSimulation*, earlyReturn*, lastSuccessfulTime*)``
        to append to the call.
    """

    def __init__(self) -> None:
        self.event_handling_needed = ctypes.c_bool(False)
        self.terminate_simulation = ctypes.c_bool(False)
        self.early_return = ctypes.c_bool(False)
        self.last_successful_time = ctypes.c_double(0.0)
        self.args = (ctypes.byref(self.event_handling_needed), ctypes.byref(self.terminate_simulation),
                     ctypes.byref(self.early_return), ctypes.byref(self.last_successful_time))


def step_problem(flags: StepFlags, t: float, h: float) -> str | None:
    """What is wrong with a ``fmi3DoStep(t, h)`` that returned a good status, from its output flags; None if nothing.

    The text completes ``"<instance>: fmi3DoStep ..."``; used by
    :class:`~orchestrator.fmu.component.FMUComponent` and the compiled
    :class:`~orchestrator.fmu.fast_loop.FastFMULoop` (which writes the same flags).

    Parameters
    ----------
    flags : StepFlags
        The flags as the call left them.
    t, h : float
        Communication point and step size of the call, s.

    Returns
    -------
    str or None
        For ``earlyReturn = true`` (checked first: not allowed, the instance was made with
        ``earlyReturnAllowed = false``) or ``terminateSimulation = true``.
    """
    if flags.early_return.value:
        return (f"returned earlyReturn = true (lastSuccessfulTime = {flags.last_successful_time.value:.6f} s, "
                f"expected a full step to t + h = {t + h:.6f} s); early return is not supported (the instance was "
                "made with earlyReturnAllowed = false)")
    if flags.terminate_simulation.value:
        return "returned terminateSimulation = true (the FMU asks to end the simulation)"
    return None
