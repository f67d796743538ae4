"""Import: any FMI 2.0 co-simulation FMU behind the component protocol (through fmpy).

:class:`FMUComponent` looks to the master exactly like a native
:class:`fmus_src.component.Component` with batch 1: ``name``, ``batch``,
``values`` (numpy arrays of shape ``(1,)`` that the master reads and writes
in place), ``variable``, ``names``, ``setup``, ``do_step``, ``reset``,
``terminate`` and ``state``. ``do_step`` pushes the inputs held in
``values`` into the FMU, calls ``fmi2DoStep`` and pulls the outputs back.

A foreign FMU whose variables are named differently stands in for a role of
the twin through ``mapping={our_name: their_name}``; units are checked and
converted with :mod:`fmus_src.units` (``values`` always holds our units).

Every FMI call goes through :meth:`FMUComponent._fmi`, the one place where
status codes are checked: fmi2Discard, fmi2Error and fmi2Fatal raise
:class:`~orchestrator.fmu.errors.FMUError` naming the component, the FMI
function, the time, the status and the FMU's last log messages.
"""
from __future__ import annotations

import atexit
import ctypes
import logging
import shutil
import tempfile
import weakref
import xml.etree.ElementTree as ET
import zipfile
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from fmpy import calloc, free, read_model_description
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2CallbackAllocateMemoryTYPE
from fmpy.fmi2 import fmi2CallbackFreeMemoryTYPE, fmi2CoSimulation
from fmpy.model_description import ModelDescription, ScalarVariable

from fmus_src.component import Variable
from fmus_src.units import UnitError, conversion_factor

from .errors import FMUError, status_name
from .roles import Role, get_role

log = logging.getLogger(__name__)

PLATFORM = "linux64"
_SUFFIX = ".so"
_TYPES = ("Real", "Integer", "Boolean", "String")
_DTYPES = {"Real": np.float64, "Integer": np.int64, "Boolean": np.bool_}

# ----------------------------------------------------------------------------- archive handling
_EXTRACTED: dict[tuple[str, int, int], Path] = {}


def _cleanup_extracted() -> None:
    for folder in _EXTRACTED.values():
        shutil.rmtree(folder, ignore_errors=True)
    _EXTRACTED.clear()


atexit.register(_cleanup_extracted)


@dataclass(frozen=True)
class LoadedFMU:
    """A checked, extracted FMU (shared by all instances made from the same file)."""

    path: Path
    model_description: ModelDescription
    unzip_dir: Path


def load_fmu(path: str | Path) -> LoadedFMU:
    """Check and extract an FMI 2.0 co-simulation FMU (cached per file and modification time).

    Parameters
    ----------
    path : str or Path
        The ``.fmu`` file.

    Returns
    -------
    LoadedFMU

    Raises
    ------
    FMUError
        Missing file, not a zip archive, no or malformed ``modelDescription.xml``,
        FMI version other than 2.0, model-exchange-only FMU, no binary for
        this platform.
    """
    path = Path(path).resolve()
    if not path.is_file():
        raise FMUError(f"{path}: FMU file not found", path=str(path))
    if not zipfile.is_zipfile(path):
        raise FMUError(f"{path}: not an FMU (not a zip archive)", path=str(path))
    with zipfile.ZipFile(path) as zf:
        names = set(zf.namelist())
        if "modelDescription.xml" not in names:
            raise FMUError(f"{path}: not an FMU (no modelDescription.xml in the archive)", path=str(path))
        xml = zf.read("modelDescription.xml")
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        raise FMUError(f"{path}: modelDescription.xml is not well-formed XML ({exc})", path=str(path)) from None
    version = root.get("fmiVersion", "?")
    if version != "2.0":
        raise FMUError(
            f"{path}: FMI version {version!r}; only FMI 2.0 co-simulation FMUs are supported", path=str(path)
        )
    cs = root.find("CoSimulation")
    if cs is None:
        kind = "model-exchange-only FMU" if root.find("ModelExchange") is not None else "FMU without <CoSimulation>"
        raise FMUError(f"{path}: {kind}; a co-simulation FMU is required", path=str(path))
    identifier = cs.get("modelIdentifier", "")
    binary = f"binaries/{PLATFORM}/{identifier}{_SUFFIX}"
    if binary not in names:
        platforms = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
        raise FMUError(f"{path}: no binary {binary} for this platform (the FMU has {platforms})", path=str(path))
    try:
        md = read_model_description(str(path), validate=False)
    except (ValueError, KeyError, TypeError) as exc:
        raise FMUError(f"{path}: cannot read modelDescription.xml ({exc})", path=str(path)) from None
    stat = path.stat()
    key = (str(path), stat.st_mtime_ns, stat.st_size)
    folder = _EXTRACTED.get(key)
    if folder is None or not folder.is_dir():
        folder = Path(tempfile.mkdtemp(prefix=f"cnctwin_{identifier}_"))
        with zipfile.ZipFile(path) as zf:
            zf.extractall(folder)
        _EXTRACTED[key] = folder
    return LoadedFMU(path, md, folder)


def fmu_unit(variable: ScalarVariable) -> str | None:
    """Unit symbol of an FMU variable (own ``unit`` or its declared type's), None when undeclared."""
    if variable.unit:
        return variable.unit
    declared = getattr(variable, "declaredType", None)
    return getattr(declared, "unit", None) or None


def _fmu_type(variable: ScalarVariable) -> str:
    return "Integer" if variable.type == "Enumeration" else variable.type


def _start(variable: ScalarVariable, type_: str) -> Any:
    raw = variable.start
    if type_ == "String":
        return raw or ""
    if raw is None or raw == "":
        return {"Real": 0.0, "Integer": 0, "Boolean": False}[type_]
    if type_ == "Boolean":
        return str(raw).lower() in ("true", "1")
    return float(raw) if type_ == "Real" else int(raw)


@dataclass
class _Binding:
    """One exposed variable: our name and unit, the FMU's value reference and the unit factor."""

    ours: Variable
    theirs: ScalarVariable
    to_fmu: float  # their value = to_fmu × our value (Real only)


class _Channel:
    """Preallocated ctypes buffers for a block of Real variables exchanged every step."""

    def __init__(self, values: dict, bindings: list[_Binding]) -> None:
        n = len(bindings)
        self.n = n
        self.vr = (ctypes.c_uint * n)(*[b.theirs.valueReference for b in bindings])
        self.buffer = (ctypes.c_double * n)()
        self.view = np.ctypeslib.as_array(self.buffer) if n else np.empty(0)
        self.arrays = [values[b.ours.name] for b in bindings]
        self.to_fmu = np.array([b.to_fmu for b in bindings])
        self.from_fmu = 1.0 / self.to_fmu if n else self.to_fmu

    def pack(self) -> None:
        for i, arr in enumerate(self.arrays):
            self.view[i] = arr[0]
        self.view *= self.to_fmu

    def unpack(self) -> None:
        self.view *= self.from_fmu
        for i, arr in enumerate(self.arrays):
            arr[0] = self.view[i]


#: ``generationTool`` prefixes of FMUs whose ``fmi2FreeInstance`` corrupts the host process's heap: PythonFMU 0.7
#: (NTNU-IHB/PythonFMU#228; "corrupted double-linked list", an abort at interpreter exit in about half of the
#: processes that freed one). Their instances are left allocated until the process ends.
NO_FREE_TOOLS = ("PythonFMU 0.7",)


def _free_instance(slave: FMU2Slave, alive: list[bool], free: bool = True) -> None:
    """Free an FMU instance once (used by close() and the finaliser); ``free=False`` only marks it closed.

    The shared library is deliberately *not* unloaded: an FMU that embeds
    Python (pythonfmu) leaves objects in the interpreter that may refer to
    its code, and several instances share one loaded copy anyway. A loaded
    library costs a few hundred kB for the life of the process; an instance
    of an FMU from :data:`NO_FREE_TOOLS` is not freed either (a few kB).
    """
    if alive[0]:
        alive[0] = False
        if free:
            slave.fmi2FreeInstance(slave.component)


class FMUComponent:
    """An FMI 2.0 co-simulation FMU behind the component protocol (batch 1).

    Parameters
    ----------
    path : str or Path
        The ``.fmu`` file.
    name : str, optional
        Instance name (default: the model identifier).
    role : {"nck", "mcu", "drive", "cutting"}, optional
        Role it stands in for; its required variables must be present
        (through ``mapping``), with compatible units and the right causality.
    mapping : Mapping[str, str], optional
        ``{our_name: their_name}``. ``values`` and :meth:`variable` use our
        names and, when a role is given, the role's units (values are
        converted on every exchange). Unmapped FMU variables keep their own
        names and units.
    parameters : Mapping[str, object], optional
        Parameter (or input) values in our names and units, applied in
        :meth:`setup` (like the keyword parameters of a native component).
    batch : int
        Must be 1; a population needs one FMUComponent per member.

    Raises
    ------
    FMUError
        Bad file (see :func:`load_fmu`), missing or incompatible role
        variables, unknown mapping or parameter names, instantiation failure.
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
    ) -> None:
        self._fmu = load_fmu(path)
        self.path = self._fmu.path
        md = self._fmu.model_description
        self.model_description = md
        self.name = name or md.coSimulation.modelIdentifier
        if batch != 1:
            raise FMUError(
                f"{self.name}: an FMU instance has batch 1, got batch={batch!r}; "
                "make one FMUComponent per population member",
                path=str(self.path), component=self.name,
            )
        self.batch = 1
        self.role: Role | None = get_role(role) if role is not None else None
        self.mapping = dict(mapping or {})
        self._bindings = self._bind(md)
        self._by_name = {b.ours.name: b for b in self._bindings}
        self.values: dict[str, np.ndarray | str] = {}
        self._load_start_values()
        self._init_parameters: dict[str, object] = dict(parameters or {})
        for key in self._init_parameters:
            var = self.variable(key)
            if var.causality == "output":
                raise FMUError(f"{self.name}.{key} is an output and cannot be given as a parameter",
                               path=str(self.path), component=self.name)
        self._apply_init_parameters()
        by_causality: dict[tuple[str, str], list[_Binding]] = {}
        for b in self._bindings:
            by_causality.setdefault((b.ours.causality, b.ours.type), []).append(b)
        self._groups = by_causality
        self._discrete_inputs = [t for (c, t) in by_causality if c == "input" and t != "Real"]
        self._real_in = _Channel(self.values, by_causality.get(("input", "Real"), []))
        self._real_out = _Channel(self.values, by_causality.get(("output", "Real"), []))
        self.messages: deque[str] = deque(maxlen=log_capacity)
        self._worst_logged = 0
        self.time = float("nan")
        self.state = "instantiated"
        self._instantiate()

    # ------------------------------------------------------------------ binding
    def _bind(self, md: ModelDescription) -> list[_Binding]:
        fmu_vars = {v.name: v for v in md.modelVariables}
        where = f"{self.path}"
        reverse: dict[str, str] = {}
        for ours, theirs in self.mapping.items():
            if theirs not in fmu_vars:
                raise FMUError(
                    f"{where}: mapping {ours!r} -> {theirs!r}: the FMU has no variable {theirs!r}; "
                    f"it has {sorted(fmu_vars)}", path=str(self.path), component=self.name,
                )
            if not ours.isidentifier():
                raise FMUError(f"{where}: mapping target name {ours!r} is not an identifier", path=str(self.path))
            reverse[theirs] = ours
        bindings: list[_Binding] = []
        problems: list[str] = []
        for v in md.modelVariables:
            if v.causality not in ("parameter", "input", "output"):
                continue
            type_ = _fmu_type(v)
            if type_ not in _TYPES:
                continue
            ours = reverse.get(v.name, v.name)
            if not ours.isidentifier():
                continue  # e.g. "der(x)" or "a[1]": not addressable by the twin, shown by check_fmu
            their_unit = fmu_unit(v)
            spec = self.role.variable(ours) if self.role else None
            our_unit = their_unit or "1"
            factor = 1.0
            if spec is not None:
                if spec.causality != v.causality:
                    problems.append(f"{ours!r} (FMU {v.name!r}) is a {v.causality}, the role needs a {spec.causality}")
                    continue
                if spec.type != type_:
                    problems.append(f"{ours!r} (FMU {v.name!r}) is {type_}, the role needs {spec.type}")
                    continue
                our_unit = spec.unit
                if their_unit is not None and type_ == "Real":
                    try:
                        factor = conversion_factor(our_unit, their_unit)
                    except UnitError as exc:
                        problems.append(f"{ours!r} (FMU {v.name!r} [{their_unit}]): {exc}")
                        continue
            start = _start(v, type_)
            if type_ == "Real" and factor != 1.0:
                start = start / factor
            declared = Variable(ours, v.causality, our_unit, start, v.description or "", type_)  # type: ignore[arg-type]
            bindings.append(_Binding(declared, v, factor))
        if self.role is not None:
            present = {b.ours.name for b in bindings}
            missing = [r.name for r in self.role.required if r.name not in present]
            if missing or problems:
                text = []
                if missing:
                    text.append(f"missing required variable(s) {missing}")
                text += problems
                raise FMUError(
                    f"{where}: cannot stand in for role {self.role.name!r}: " + "; ".join(text)
                    + f" (give mapping={{our_name: their_name}}; the FMU has {sorted(fmu_vars)})",
                    path=str(self.path), component=self.name,
                )
        return bindings

    # ------------------------------------------------------------------ declarations
    def declared_variables(self) -> tuple[Variable, ...]:
        """Exposed variables (our names and units)."""
        return tuple(b.ours for b in self._bindings)

    def variable(self, name: str) -> Variable:
        """Declaration of variable ``name`` (our name and unit).

        Raises
        ------
        FMUError
            Unknown name.
        """
        try:
            return self._by_name[name].ours
        except KeyError:
            raise FMUError(
                f"{self.name} ({self.path.name}): no variable {name!r}; it has {sorted(self._by_name)}",
                path=str(self.path), component=self.name,
            ) from None

    def names(self, causality: str) -> list[str]:
        """Names of the exposed variables of one causality, in model-description order."""
        return [b.ours.name for b in self._bindings if b.ours.causality == causality]

    # ------------------------------------------------------------------ values
    def _load_start_values(self) -> None:
        for b in self._bindings:
            var = b.ours
            if var.type == "String":
                self.values[var.name] = str(var.start)
            elif var.name in self.values:
                self.values[var.name][...] = var.start  # type: ignore[index]
            else:
                self.values[var.name] = np.full(1, var.start, dtype=_DTYPES[var.type])

    def _apply_init_parameters(self) -> None:
        for key, value in self._init_parameters.items():
            self._store(self.variable(key), value)

    def _store(self, var: Variable, value: object) -> None:
        if var.type == "String":
            if not isinstance(value, str):
                raise FMUError(f"{self.name}.{var.name}: expected a string, got {type(value).__name__}",
                               path=str(self.path), component=self.name)
            self.values[var.name] = value
            return
        arr = np.asarray(value, dtype=_DTYPES[var.type])
        if arr.size != 1:
            raise FMUError(f"{self.name}.{var.name}: expected a scalar (batch 1), got shape {arr.shape}",
                           path=str(self.path), component=self.name)
        self.values[var.name][...] = arr.reshape(1)  # type: ignore[index]

    def set(self, name: str, value: object) -> None:
        """Set a parameter (before :meth:`setup`) or an input (any time), in our units."""
        var = self.variable(name)
        if var.causality == "output":
            raise FMUError(f"{self.name}.{name} is an output and cannot be set", path=str(self.path), component=self.name)
        if var.causality == "parameter" and self.state != "instantiated":
            raise FMUError(f"{self.name}.{name} is a parameter; set it before setup()", path=str(self.path),
                           component=self.name)
        self._store(var, value)

    def get(self, name: str) -> np.ndarray | str:
        """Current value of a variable (copy of shape ``(1,)``, or a str)."""
        value = self.values[self.variable(name).name]
        return value if isinstance(value, str) else value.copy()

    def parameter_values(self) -> dict[str, np.ndarray | str]:
        """Current parameter values by name."""
        return {n: self.values[n] for n in self.names("parameter")}

    # ------------------------------------------------------------------ FMI calls (status checked here only)
    def _fmi(self, function: str, *args: Any) -> Any:
        """Call ``fmi2<function>`` through fmpy; turn any status worse than warning into FMUError."""
        try:
            return getattr(self._slave, function)(self._slave.component, *args)
        except FMICallException as exc:
            raise self._failure(function, int(exc.status)) from None

    def _failure(self, function: str, status: int, verb: str = "returned") -> FMUError:
        at = "" if np.isnan(self.time) else f" at t = {self.time:.6f} s"
        detail = "; FMU log: " + " | ".join(self.messages) if self.messages else ""
        error = FMUError(
            f"{self.name}: {function} {verb} {status_name(status)}{at} (FMU {self.path}){detail}",
            path=str(self.path), component=self.name, function=function,
            time=None if np.isnan(self.time) else self.time, status=status,
        )
        if status >= 4:
            # fmi2Fatal: no further FMI call is allowed on any instance (FMI 2.0, 2.1.3), not even
            # fmi2FreeInstance; the instance is abandoned
            self._alive[0] = False
        else:
            self._close()
        self.state = "terminated"
        return error

    def _logger(self, env: Any, instance: bytes, status: int, category: bytes, message: bytes) -> None:
        text = message.decode("utf-8", "replace") if message else ""
        label = status_name(status)
        self._worst_logged = max(self._worst_logged, int(status))
        self.messages.append(f"[{label}] {text}")
        log.debug("%s: [%s] %s", self.name, label, text)

    def _instantiate(self) -> None:
        md = self.model_description
        try:
            self._slave = FMU2Slave(
                guid=md.guid, unzipDirectory=str(self._fmu.unzip_dir),
                modelIdentifier=md.coSimulation.modelIdentifier, instanceName=self.name,
            )
        except (OSError, AttributeError) as exc:
            raise FMUError(f"{self.path}: cannot load the FMU's shared library ({exc})", path=str(self.path),
                           component=self.name) from None
        callbacks = fmi2CallbackFunctions()
        self._log_callback = fmi2CallbackLoggerTYPE(self._logger)
        callbacks.logger = self._log_callback
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:
            from fmpy.logging import addLoggerProxy  # formats the printf-style variadic messages
        except ImportError:  # pragma: no cover - fmpy without its logging helper library
            addLoggerProxy = None
        if addLoggerProxy is not None:
            addLoggerProxy(ctypes.byref(callbacks))
        self._callbacks = callbacks
        resources = (self._fmu.unzip_dir / "resources").as_uri()
        component = self._slave.fmi2Instantiate(
            self.name.encode("utf-8"), fmi2CoSimulation, md.guid.encode("utf-8"), resources.encode("utf-8"),
            ctypes.byref(callbacks), 0, 1,
        )
        if not component:
            detail = "; FMU log: " + " | ".join(self.messages) if self.messages else ""
            raise FMUError(f"{self.name}: fmi2Instantiate failed (FMU {self.path}){detail}",
                           path=str(self.path), component=self.name, function="fmi2Instantiate")
        self._slave.component = component
        self._slave.callbacks = callbacks
        self._alive = [True]
        tool = md.generationTool or ""
        frees = not tool.startswith(NO_FREE_TOOLS)
        self._finalizer = weakref.finalize(self, _free_instance, self._slave, self._alive, frees)

    def _close(self) -> None:
        """Free the FMU instance and its library (idempotent)."""
        if getattr(self, "_finalizer", None) is not None:
            self._finalizer()

    close = _close

    # -- typed transfers (all through _fmi)
    def _set_all(self, causalities: tuple[str, ...]) -> None:
        for (causality, type_), bindings in self._groups.items():
            if causality not in causalities:
                continue
            settable = [b for b in bindings if b.theirs.variability != "constant"]
            if not settable:
                continue
            n = len(settable)
            vr = (ctypes.c_uint * n)(*[b.theirs.valueReference for b in settable])
            if type_ == "Real":
                data = (ctypes.c_double * n)(*[float(self.values[b.ours.name][0]) * b.to_fmu for b in settable])
                self._fmi("fmi2SetReal", vr, n, data)
            elif type_ == "Integer":
                data = (ctypes.c_int * n)(*[int(self.values[b.ours.name][0]) for b in settable])
                self._fmi("fmi2SetInteger", vr, n, data)
            elif type_ == "Boolean":
                data = (ctypes.c_int * n)(*[int(bool(self.values[b.ours.name][0])) for b in settable])
                self._fmi("fmi2SetBoolean", vr, n, data)
            else:
                data = (ctypes.c_char_p * n)(*[str(self.values[b.ours.name]).encode("utf-8") for b in settable])
                self._fmi("fmi2SetString", vr, n, data)

    def _get_discrete_outputs(self) -> None:
        for (causality, type_), bindings in self._groups.items():
            if causality != "output" or type_ == "Real":
                continue
            n = len(bindings)
            vr = (ctypes.c_uint * n)(*[b.theirs.valueReference for b in bindings])
            if type_ == "String":
                data = (ctypes.c_char_p * n)()
                self._fmi("fmi2GetString", vr, n, data)
                for b, v in zip(bindings, data):
                    self.values[b.ours.name] = (v or b"").decode("utf-8")
                continue
            data = (ctypes.c_int * n)()
            self._fmi("fmi2GetBoolean" if type_ == "Boolean" else "fmi2GetInteger", vr, n, data)
            for b, v in zip(bindings, data):
                self.values[b.ours.name][0] = v  # type: ignore[index]

    def _pull_outputs(self) -> None:
        ch = self._real_out
        if ch.n:
            self._fmi("fmi2GetReal", ch.vr, ch.n, ch.buffer)
            ch.unpack()
        self._get_discrete_outputs()

    def _push_inputs(self) -> None:
        ch = self._real_in
        if ch.n:
            ch.pack()
            self._fmi("fmi2SetReal", ch.vr, ch.n, ch.buffer)
        for type_ in self._discrete_inputs:
            self._set_discrete_input(type_)

    def _set_discrete_input(self, type_: str) -> None:
        bindings = self._groups[("input", type_)]
        n = len(bindings)
        vr = (ctypes.c_uint * n)(*[b.theirs.valueReference for b in bindings])
        if type_ == "String":
            data = (ctypes.c_char_p * n)(*[str(self.values[b.ours.name]).encode("utf-8") for b in bindings])
            self._fmi("fmi2SetString", vr, n, data)
        else:
            data = (ctypes.c_int * n)(*[int(self.values[b.ours.name][0]) for b in bindings])
            self._fmi("fmi2SetBoolean" if type_ == "Boolean" else "fmi2SetInteger", vr, n, data)

    # ------------------------------------------------------------------ lifecycle
    def setup(self, t0: float = 0.0) -> None:
        """Set up the experiment at ``t0``, apply parameters and inputs, initialise, read outputs."""
        if self.state != "instantiated":
            raise FMUError(f"{self.name}: setup() called in state {self.state!r}", path=str(self.path),
                           component=self.name)
        self.t0 = float(t0)
        self.time = self.t0
        self._fmi("fmi2SetupExperiment", 0, 0.0, self.t0, 0, 0.0)
        self._fmi("fmi2EnterInitializationMode")
        self._set_all(("parameter", "input"))
        self._worst_logged = 0
        self._fmi("fmi2ExitInitializationMode")
        if self._worst_logged >= 3:
            # the initialisation failed but the FMU could not say so in its status (pythonfmu: see
            # fmus_src.fmu.slave.ComponentSlave.exit_initialization_mode); the log names the cause
            raise self._failure("fmi2ExitInitializationMode", self._worst_logged, "logged")
        self._pull_outputs()
        self.state = "initialized"

    def do_step(self, t: float, h: float) -> None:
        """Push inputs, ``fmi2DoStep(t, h)``, pull outputs (valid at ``t + h``)."""
        if self.state != "initialized":
            raise FMUError(f"{self.name}: do_step() called in state {self.state!r}", path=str(self.path),
                           component=self.name)
        if not h > 0.0:
            raise FMUError(f"{self.name}: step size must be positive, got {h!r}", path=str(self.path),
                           component=self.name)
        self.time = t
        self._push_inputs()
        self._fmi("fmi2DoStep", float(t), float(h), 1)
        self.time = t + h
        self._pull_outputs()

    def reset(self) -> None:
        """Back to the instantiated state with start values and the constructor's parameters."""
        if self._alive[0]:
            self._fmi("fmi2Reset")
        else:
            self._instantiate()
        self._load_start_values()
        self._apply_init_parameters()
        self.time = float("nan")
        self.state = "instantiated"

    def terminate(self) -> None:
        """``fmi2Terminate`` (when initialised); the instance stays allocated for :meth:`reset`."""
        if self.state == "initialized":
            self._fmi("fmi2Terminate")
        self.state = "terminated"

    def __repr__(self) -> str:
        return f"FMUComponent({str(self.path)!r}, name={self.name!r}, state={self.state!r})"

