"""An FMU in its own worker process: a crashing FMU cannot take the caller down.

:class:`FMUComponent` loads the FMU's shared library into the calling
process; a segmentation fault or ``abort()`` inside the FMU's C code then
kills the whole simulation (and a GA run with it) without a message.
:class:`IsolatedFMUComponent` has the same protocol (``name``, ``batch = 1``,
``values`` updated in place, ``variable``, ``names``, ``set``, ``get``,
``setup``, ``do_step``, ``reset``, ``terminate``, ``state``) but runs an
:class:`FMUComponent` in a worker process: a fresh interpreter (as the
*spawn* start method, so no state is inherited), connected by one
:class:`multiprocessing.connection.Connection` over a socket pair. Unlike
``multiprocessing.Process`` with spawn, the worker does not re-import the
caller's ``__main__`` script, so scripts need no ``if __name__ ==
"__main__"`` guard and are never run twice. Each ``do_step`` sends the inputs
and receives the outputs: about 0.1 ms per step on top of the FMU's own time;
starting a worker costs about 2 s (it imports :mod:`orchestrator`).

When the worker dies (signal or exit) during a call, the call raises
:class:`FMUError` ``"<name>: the FMU crashed (signal 11, SIGSEGV) in
fmi2DoStep at t = 0.004 s ..."`` naming the component, the FMI function and
the time. The master turns that into ``success = False`` with the recording
up to the failure kept, like any other component failure. The component is
then ``"terminated"``; :meth:`reset` starts a fresh worker.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import weakref
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from fmus_src.component import Variable
from fmus_src.units import UnitDefinition

from . import arrays
from .component import _DTYPES, FMUComponent, load_fmu, no_variable_error, unit_definitions
from .errors import FMUError

#: Seconds to wait for the worker to start and load the FMU.
START_TIMEOUT = 120.0


# ----------------------------------------------------------------------------- worker side
def _serve(fd: int) -> None:  # pragma: no cover - runs in the child process
    """Entry point of the worker process: receive (path, kwargs) on ``fd`` and serve."""
    conn = Connection(fd)
    path, kwargs = conn.recv()
    _worker(conn, path, kwargs)


def _worker(conn: Any, path: str, kwargs: dict) -> None:  # pragma: no cover - runs in the child process
    """Serve one FMUComponent over ``conn`` until told to close (or until the FMU kills the process)."""
    from ..errors import CncTwinError

    try:
        comp = FMUComponent(path, **kwargs)
    except CncTwinError as exc:
        conn.send(("error", type(exc).__name__, str(exc), _error_fields(exc)))
        return
    variables = comp.declared_variables()
    conn.send(("ok", variables, _snapshot(comp, [v.name for v in variables]), dict(comp._alias_of)))
    outputs = comp.names("output")
    while True:
        try:
            request = conn.recv()
        except EOFError:
            return
        op = request[0]
        try:
            if op == "close":
                comp.close()
                conn.send(("ok",))
                return
            if op == "do_step":
                _, t, h, inputs = request
                _load(comp, inputs)
                comp.do_step(t, h)
                conn.send(("ok", _snapshot(comp, outputs), list(comp.messages)))
            elif op == "setup":
                _, t0, values = request
                _load(comp, values)
                comp.setup(t0)
                conn.send(("ok", _snapshot(comp, [v.name for v in variables]), list(comp.messages)))
            elif op == "terminate":
                comp.terminate()
                conn.send(("ok",))
            elif op == "reset":
                comp.reset()
                conn.send(("ok", _snapshot(comp, [v.name for v in variables])))
            else:
                conn.send(("error", "FMUError", f"unknown request {op!r}", {}))
        except CncTwinError as exc:
            conn.send(("error", type(exc).__name__, str(exc), _error_fields(exc)))


def _load(comp: FMUComponent, values: Mapping[str, Any]) -> None:
    for name, value in values.items():
        if isinstance(value, str):
            comp.values[name] = value
        else:
            comp.values[name][0] = value


def _snapshot(comp: FMUComponent, names: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for name in names:
        v = comp.values[name]
        out[name] = v if isinstance(v, str) else v[0].item()
    return out


def _error_fields(exc: BaseException) -> dict[str, Any]:
    return {k: getattr(exc, k, None) for k in ("path", "component", "function", "time", "status")}


# ----------------------------------------------------------------------------- caller side
class _Process:
    """The worker process (a :class:`subprocess.Popen`) with the few ``multiprocessing.Process`` calls used here."""

    def __init__(self, popen: subprocess.Popen) -> None:
        self.popen = popen
        self.pid = popen.pid

    def is_alive(self) -> bool:
        return self.popen.poll() is None

    @property
    def exitcode(self) -> int | None:
        """None while running; negative signal number when killed by a signal (as multiprocessing)."""
        return self.popen.poll()

    def join(self, timeout: float | None = None) -> None:
        try:
            self.popen.wait(timeout)
        except subprocess.TimeoutExpired:
            pass

    def kill(self) -> None:
        if self.is_alive():
            self.popen.kill()


def _stop_worker(process: Any, conn: Any) -> None:
    """Ask the worker to close; kill it if it does not (used by close() and the finaliser)."""
    if process.is_alive():
        try:
            conn.send(("close",))
            if conn.poll(5.0):
                conn.recv()
        except (OSError, EOFError):
            pass
        process.join(5.0)
        if process.is_alive():
            process.kill()
            process.join(5.0)
    conn.close()


def _signal_name(number: int) -> str:
    try:
        return signal.Signals(number).name
    except ValueError:
        return f"signal {number}"


class IsolatedFMUComponent:
    """An FMI 2.0 or 3.0 co-simulation FMU run in a worker process, behind the component protocol (batch 1).

    Parameters
    ----------
    path : str or Path
        The ``.fmu`` file (checked here, before any process starts).
    name : str, optional
        Instance name (default: the model identifier).
    role, mapping, parameters, log_capacity
        As for :class:`~orchestrator.fmu.FMUComponent` (the worker builds one with them).
    batch : int
        Must be 1.
    timeout : float, optional
        Seconds one FMI call may take before the worker is killed and the call raises
        :class:`FMUError` (a hung FMU). None: wait as long as the worker lives.

    Raises
    ------
    FMUError
        Everything :class:`FMUComponent` raises (bad file, role, mapping, parameters), and a
        worker that dies or does not answer.
    """

    def __init__(
        self,
        path: str | Path,
        name: str | None = None,
        *,
        role: str | None = None,
        mapping: Mapping[str, str] | None = None,
        parameters: Mapping[str, object] | None = None,
        batch: int = 1,
        log_capacity: int = 20,
        timeout: float | None = None,
    ) -> None:
        loaded = load_fmu(path)  # file errors without starting a process
        self.path = loaded.path
        self.fmi_version = loaded.model_description.fmiVersion
        self._model_description = loaded.model_description
        self._unit_definitions = unit_definitions(loaded.model_description, str(loaded.path),
                                                  loaded.inverse_display_units)
        self._prefix = "fmi3" if self.fmi_version.startswith("3.") else "fmi2"
        self.name = name or loaded.model_description.coSimulation.modelIdentifier
        if batch != 1:
            raise FMUError(f"{self.name}: an FMU instance has batch 1, got batch={batch!r}; "
                           "make one IsolatedFMUComponent per population member",
                           path=str(self.path), component=self.name)
        self.batch = 1
        self.timeout = timeout
        self._kwargs = {"name": self.name, "role": role, "mapping": dict(mapping or {}),
                        "parameters": dict(parameters or {}), "log_capacity": log_capacity}
        self.messages: list[str] = []
        self.time = float("nan")
        self.values: dict[str, np.ndarray | str] = {}
        self._start()

    # ------------------------------------------------------------------ worker management
    def _start(self) -> None:
        parent_sock, child_sock = socket.socketpair()
        fd = child_sock.fileno()
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
        code = "import sys; from orchestrator.fmu.isolated import _serve; _serve(int(sys.argv[1]))"
        popen = subprocess.Popen([sys.executable, "-c", code, str(fd)], pass_fds=(fd,), env=env,
                                 stdin=subprocess.DEVNULL)
        child_sock.close()
        process, parent = _Process(popen), Connection(parent_sock.detach())
        self._process, self._conn = process, parent
        try:
            parent.send((str(self.path), self._kwargs))
        except OSError:
            pass  # a worker that died at once is reported by the first _call
        self._finalizer = weakref.finalize(self, _stop_worker, process, parent)
        self.state = "starting"
        instantiate = "fmi3InstantiateCoSimulation" if self._prefix == "fmi3" else "fmi2Instantiate"
        reply = self._call(None, instantiate, timeout=max(self.timeout or 0.0, START_TIMEOUT))
        variables: tuple[Variable, ...] = reply[1]
        self._variables = variables
        self._by_name = {v.name: v for v in variables}
        #: FMI 3.0 arrays addressable as a whole (as the worker's FMUComponent): name -> (shape, element names)
        self._whole = arrays.complete_arrays(self._by_name)
        for var in variables:
            start = reply[2][var.name]
            if var.type == "String":
                self.values[var.name] = start
            elif var.name in self.values:
                self.values[var.name][0] = start  # type: ignore[index]
            else:
                self.values[var.name] = np.full(1, start, dtype=_DTYPES[var.type])
        #: alias -> the variable whose value it shares (as the worker's FMUComponent); the inputs among them
        self._alias_of: dict[str, str] = reply[3]
        self._input_alias = {a: h for a, h in self._alias_of.items() if self._by_name[a].causality == "input"}
        for alias, head in self._alias_of.items():
            self.values[alias] = self.values[head]
        self._inputs = [v.name for v in variables if v.causality == "input" and v.name not in self._input_alias]
        self._settable = [v.name for v in variables if v.causality in ("parameter", "input")]
        self.state = "instantiated"

    def _dead(self, function: str, waited: float | None = None) -> FMUError:
        """The error for a worker that died (or hung ``waited`` s) during ``function``; stops the worker."""
        if waited is not None:
            self._process.kill()
        self._process.join(5.0)
        code = self._process.exitcode
        if waited is not None:
            how = f"did not answer within {waited:g} s (worker killed)"
        elif code is not None and code < 0:
            how = f"crashed (signal {-code}, {_signal_name(-code)})"
        elif code is None:
            how = "stopped answering"
        else:
            how = f"exited with status {code}"
        at = "" if np.isnan(self.time) else f" at t = {self.time:.6f} s"
        detail = "; FMU log: " + " | ".join(self.messages) if self.messages else ""
        self._finalizer()
        self.state = "terminated"
        return FMUError(f"{self.name}: the FMU {how} in {function}{at} (FMU {self.path}, run isolated in "
                        f"process {self._process.pid}){detail}",
                        path=str(self.path), component=self.name, function=function,
                        time=None if np.isnan(self.time) else self.time)

    def _call(self, request: tuple | None, function: str, timeout: float | None = None) -> tuple:
        """Send ``request`` (None: only wait for a reply) and return the worker's reply."""
        limit = self.timeout if timeout is None else timeout
        try:
            if request is not None:
                self._conn.send(request)
            waited = 0.0
            while not self._conn.poll(0.2):
                waited += 0.2
                if not self._process.is_alive():
                    raise self._dead(function)
                if limit is not None and waited >= limit:
                    raise self._dead(function, waited)
            reply = self._conn.recv()
        except (EOFError, OSError):
            raise self._dead(function) from None
        if reply[0] == "error":
            _, _kind, message, fields = reply
            if self.state == "starting":
                self._finalizer()  # the worker has returned; reap it
            elif fields.get("function") is not None:
                self.state = "terminated"  # an FMI call failed: the worker's FMUComponent is terminated
            raise FMUError(message, **fields)
        return reply

    def close(self) -> None:
        """Stop the worker process (idempotent)."""
        self._finalizer()

    @property
    def pid(self) -> int | None:
        """Process id of the worker (None before it started)."""
        return self._process.pid

    # ------------------------------------------------------------------ declarations
    def declared_variables(self) -> tuple[Variable, ...]:
        """Exposed variables (our names and units)."""
        return self._variables

    def variable(self, name: str) -> Variable:
        """Declaration of variable ``name``; unknown names raise :class:`FMUError`."""
        try:
            return self._by_name[name]
        except KeyError:
            raise no_variable_error(self.name, self.path, name, self._by_name, self._model_description) from None

    def names(self, causality: str) -> list[str]:
        """Names of the exposed variables of one causality (an input without its aliases)."""
        return [v.name for v in self._variables if v.causality == causality and v.name not in self._input_alias]

    def unit_definition(self, symbol: str) -> UnitDefinition | None:
        """How the FMU defines unit ``symbol`` (``FMUComponent.unit_definition``), None when it does not."""
        return self._unit_definitions.get(symbol)

    def canonical(self, name: str) -> str:
        """The variable whose value ``name`` shares, else ``name`` (``FMUComponent.canonical``)."""
        return self._alias_of.get(name, name)

    # ------------------------------------------------------------------ values
    def set(self, name: str, value: object) -> None:
        """Set a parameter (before :meth:`setup`) or an input (any time), in our units; an FMI 3.0 array by
        element (``"A[2,3]"``) or whole by its name (``FMUComponent.set``)."""
        if name in self._whole and name not in self._by_name:
            shape, elements = self._whole[name]
            for element, each in arrays.expand(name, value, elements, shape,
                                               f"{self.name} ({self.path.name})").items():
                self.set(element, each)
            return
        var = self.variable(name)
        if var.causality == "output":
            raise FMUError(f"{self.name}.{name} is an output and cannot be set", path=str(self.path),
                           component=self.name)
        if var.causality == "parameter" and self.state != "instantiated":
            raise FMUError(f"{self.name}.{name} is a parameter; set it before setup()", path=str(self.path),
                           component=self.name)
        if var.type == "String":
            if not isinstance(value, str):
                raise FMUError(f"{self.name}.{name}: expected a string, got {type(value).__name__}",
                               path=str(self.path), component=self.name)
            head = self.canonical(name)
            for each in (head, *(a for a, h in self._alias_of.items() if h == head)):
                self.values[each] = value
            return
        arr = np.asarray(value, dtype=_DTYPES[var.type])
        if arr.size != 1:
            raise FMUError(f"{self.name}.{name}: expected a scalar (batch 1), got shape {arr.shape}",
                           path=str(self.path), component=self.name)
        self.values[name][...] = arr.reshape(1)  # type: ignore[index]

    def get(self, name: str) -> np.ndarray | str:
        """Current value (copy of shape ``(1,)``, or a str); of a whole FMI 3.0 array, an array of its shape."""
        if name in self._whole and name not in self._by_name:
            shape, elements = self._whole[name]
            return np.array([self.values[e][0] for e in elements]).reshape(shape)  # type: ignore[index]
        value = self.values[self.variable(name).name]
        return value if isinstance(value, str) else value.copy()

    def parameter_values(self) -> dict[str, np.ndarray | str]:
        """Current parameter values by name."""
        return {n: self.values[n] for n in self.names("parameter")}

    def _current(self, names: list[str]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name in names:
            v = self.values[name]
            out[name] = v if isinstance(v, str) else v[0].item()
        return out

    def _store(self, snapshot: Mapping[str, Any]) -> None:
        for name, value in snapshot.items():
            if isinstance(value, str):
                self.values[name] = value
            else:
                self.values[name][0] = value  # type: ignore[index]

    # ------------------------------------------------------------------ lifecycle
    def _require(self, state: str, what: str) -> None:
        if self.state != state:
            raise FMUError(f"{self.name}: {what} called in state {self.state!r}", path=str(self.path),
                           component=self.name)

    def setup(self, t0: float = 0.0) -> None:
        """Set up and initialise the FMU at ``t0`` with the current parameters and inputs; read outputs."""
        self._require("instantiated", "setup()")
        self.t0 = float(t0)
        self.time = self.t0
        reply = self._call(("setup", self.t0, self._current(self._settable)), f"{self._prefix}ExitInitializationMode")
        self._store(reply[1])
        self.messages = reply[2]
        self.state = "initialized"

    def do_step(self, t: float, h: float) -> None:
        """Send the inputs, ``fmi2DoStep(t, h)`` (``fmi3DoStep``) in the worker, receive the outputs (at ``t + h``)."""
        self._require("initialized", "do_step()")
        if not h > 0.0:
            raise FMUError(f"{self.name}: step size must be positive, got {h!r}", path=str(self.path),
                           component=self.name)
        self.time = float(t)
        reply = self._call(("do_step", float(t), float(h), self._current(self._inputs)), f"{self._prefix}DoStep")
        self._store(reply[1])
        self.messages = reply[2]
        self.time = float(t) + float(h)

    def terminate(self) -> None:
        """``fmi2Terminate`` (``fmi3Terminate``) in the worker (when initialised); it stays for :meth:`reset`."""
        if self.state == "initialized":
            self._call(("terminate",), f"{self._prefix}Terminate")
        self.state = "terminated"

    def reset(self) -> None:
        """Back to the instantiated state; a dead worker is replaced by a fresh one."""
        if self._process.is_alive() and self.state != "starting":
            reply = self._call(("reset",), f"{self._prefix}Reset")
            self._store(reply[1])
            self.state = "instantiated"
        else:
            self._start()
        self.time = float("nan")

    def __repr__(self) -> str:
        return f"IsolatedFMUComponent({str(self.path)!r}, name={self.name!r}, state={self.state!r})"
