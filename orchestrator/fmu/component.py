"""Import: any FMI 2.0 or FMI 3.0 co-simulation FMU behind the component protocol (through fmpy).

:class:`FMUComponent` looks to the master exactly like a native
:class:`fmus_src.component.Component` with batch 1: ``name``, ``batch``,
``values`` (numpy arrays of shape ``(1,)`` that the master reads and writes
in place), ``variable``, ``names``, ``setup``, ``do_step``, ``reset``,
``terminate`` and ``state``. ``do_step`` pushes the inputs held in
``values`` into the FMU, calls ``fmi2DoStep`` (``fmi3DoStep``) and pulls the
outputs back.

FMI 3.0 (:mod:`orchestrator.fmu.fmi3`): variables of every type but
``Binary`` and ``Clock`` (``Float64``/``Float32`` are Real, ``Int8`` ...
``UInt64`` Integer). An array variable (``<Dimension>``) is exposed as its
elements with FMI's structured names (``u[1]``, ``A[2,3]``; see
:mod:`orchestrator.fmu.arrays`), each a scalar signal with the array's unit,
exchanged together in one get/set call on the array's value reference with
``nValues`` = the element count. The instance is made with
``eventModeUsed = false`` and ``earlyReturnAllowed = false``; a step that
returns ``terminateSimulation`` or ``earlyReturn`` raises :class:`FMUError`.

A foreign FMU whose variables are named differently stands in for a role of
the twin through ``mapping={our_name: their_name}``; units are checked and
converted with :mod:`fmus_src.units` (``values`` always holds our units),
units the table lacks through the FMU's ``<UnitDefinitions>``
(:func:`unit_definitions`; each :class:`Variable` carries its unit's
definition). A variable without a declared unit has ``unit = None``
(unknown, not ``"1"``).

Every FMI call goes through :meth:`FMUComponent._fmi`, the one place where
status codes are checked: fmi2Discard, fmi2Error and fmi2Fatal (fmi3Discard,
fmi3Error, fmi3Fatal) raise :class:`~orchestrator.fmu.errors.FMUError` naming
the component, the FMI function, the time, the status and the FMU's last log
messages.
"""
from __future__ import annotations

import ctypes
import itertools
import logging
import math
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

from . import fmi3
from . import arrays

from fmus_src.component import Variable, is_element_name
from fmus_src.units import UnitDefinition, UnitError, conversion, disagreement

from .binary_check import shared_library_problem
from .extraction import extract_fmu
from .errors import FMUError, status_name
from .roles import Role, get_role

log = logging.getLogger(__name__)

PLATFORM = "linux64"
_SUFFIX = ".so"
_TYPES = ("Real", "Integer", "Boolean", "String")
_DTYPES = {"Real": np.float64, "Integer": np.int64, "Boolean": np.bool_}
#: fmi2Pending: an asynchronous fmi2DoStep (not supported; see FMUComponent._failure)
PENDING = 5


@dataclass(frozen=True)
class _Native:
    """How one FMI variable type is exchanged.

    Attributes
    ----------
    ours : str
        Our type (``"Real"``, ``"Integer"``, ``"Boolean"``, ``"String"``).
    ctype : type
        ctypes element of the value buffer.
    setter, getter : str
        FMI functions (``"fmi2SetReal"``, ``"fmi3GetFloat32"``).
    counted : bool
        The functions take ``nValues`` after the value array (FMI 3.0).
    """

    ours: str
    ctype: Any
    setter: str
    getter: str
    counted: bool


def _fmi2_native(ours: str, ctype: Any) -> _Native:
    return _Native(ours, ctype, f"fmi2Set{ours}", f"fmi2Get{ours}", False)


_NATIVE_FMI2 = {
    "Real": _fmi2_native("Real", ctypes.c_double),
    "Integer": _fmi2_native("Integer", ctypes.c_int),
    "Enumeration": _fmi2_native("Integer", ctypes.c_int),
    "Boolean": _fmi2_native("Boolean", ctypes.c_int),
    "String": _fmi2_native("String", ctypes.c_char_p),
}
_NATIVE_FMI3 = {
    name: _Native(ours, ctype, f"fmi3Set{suffix}", f"fmi3Get{suffix}", True)
    for name, (ours, ctype, suffix) in fmi3.NATIVE_TYPES.items()
}


def _native(variable: ScalarVariable, version: str) -> _Native | None:
    """How ``variable`` is exchanged, None for a type the twin does not exchange (FMI 3.0 Binary, Clock)."""
    table = _NATIVE_FMI3 if fmi3.is_fmi3(version) else _NATIVE_FMI2
    return table.get(variable.type)

@dataclass(frozen=True)
class LoadedFMU:
    """A checked, extracted FMU (shared by all instances made from the same file)."""

    path: Path
    model_description: ModelDescription
    unzip_dir: Path
    #: names of the variables with ``relativeQuantity="true"`` (read here: fmpy 0.3 tests the attribute with
    #: ``in`` on the element, which looks at its children, and never sets it for a variable)
    relative: frozenset[str] = frozenset()
    #: names of the ``<DisplayUnit inverse="true">`` of FMI 3.0 (not parsed by fmpy 0.3): not a linear map
    inverse_display_units: frozenset[str] = frozenset()


def load_fmu(path: str | Path) -> LoadedFMU:
    """Check and extract an FMI 2.0 or 3.0 co-simulation FMU (cached per file and modification time).

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
        FMI version other than 2.0 or 3.x (FMI 1.0), an FMU without a
        co-simulation interface (model exchange or scheduled execution only),
        no binary for this platform.
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
    if version != "2.0" and not fmi3.is_fmi3(version):
        raise FMUError(
            f"{path}: FMI version {version!r}; only FMI 2.0 and FMI 3.0 co-simulation FMUs are supported",
            path=str(path),
        )
    cs = root.find("CoSimulation")
    if cs is None:
        interfaces = [label for tag, label in (("ModelExchange", "model-exchange"),
                                               ("ScheduledExecution", "scheduled-execution"))
                      if root.find(tag) is not None]
        if len(interfaces) == 1:
            kind = f"{interfaces[0]}-only FMU"
        elif interfaces:
            kind = "FMU with model-exchange and scheduled-execution interfaces only"
        else:
            kind = "FMU without <CoSimulation>"
        raise FMUError(f"{path}: {kind}; a co-simulation FMU is required", path=str(path))
    identifier = cs.get("modelIdentifier", "")
    platform = fmi3.PLATFORM if fmi3.is_fmi3(version) else PLATFORM
    binary = f"binaries/{platform}/{identifier}{_SUFFIX}"
    if binary not in names:
        platforms = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
        has = f"the FMU has binaries for {platforms}" if platforms else "the FMU has no binaries"
        if any(n.startswith("sources/") and n.endswith(".c") for n in names):
            has += (f" and C sources: compile them for {platform} first (e.g. "
                    "fmpy.util.compile_platform_binary, or the exporting tool)")
        raise FMUError(f"{path}: no binary {binary} for this platform ({has})", path=str(path))
    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:  # fmpy raises a plain Exception for an illegal description (e.g. a causality)
        raise FMUError(f"{path}: cannot read modelDescription.xml ({exc})", path=str(path)) from None
    inverse = frozenset(d.get("name", "") for d in root.iterfind("UnitDefinitions/Unit/DisplayUnit")
                        if d.get("inverse") in ("true", "1"))
    return LoadedFMU(path, md, extract_fmu(path, identifier), _relative_quantities(root), inverse)


def _relative_quantities(root: ET.Element) -> frozenset[str]:
    """Names of the variables whose own type element says ``relativeQuantity="true"`` (FMI 2.0 and 3.0)."""
    out = set()
    for element in root.iterfind("ModelVariables/*"):
        typed = [element] + list(element)  # FMI 3.0: <Float64 .../>; FMI 2.0: <ScalarVariable><Real .../>
        if any(e.get("relativeQuantity") in ("true", "1") for e in typed):
            out.add(element.get("name", ""))
    return frozenset(out)


def fmu_unit(variable: ScalarVariable) -> str | None:
    """Unit symbol of an FMU variable (own ``unit`` or its declared type's), None when undeclared."""
    if variable.unit:
        return variable.unit
    declared = getattr(variable, "declaredType", None)
    return getattr(declared, "unit", None) or None


def unit_definitions(md: ModelDescription, source: str,
                     inverse: frozenset[str] = frozenset()) -> dict[str, UnitDefinition]:
    """The ``<UnitDefinitions>`` of a model description that define a ``<BaseUnit>``, by unit name.

    A ``<Unit>`` without ``<BaseUnit>`` (allowed by FMI 2.0 and 3.0) defines
    nothing to convert with and is left out. Its ``<DisplayUnit>`` elements
    are definitions too (FMI 2.0 and 3.0: value_display = factor × value_unit
    + offset), so a probe can record in an FMU's display unit (``degF`` of a
    variable in ``K``); a unit of the same name wins over a display unit.

    Parameters
    ----------
    md : ModelDescription
        fmpy's model description (FMI 2.0 or 3.0).
    source : str
        The FMU, for messages.
    inverse : frozenset of str
        Display units with FMI 3.0 ``inverse="true"`` (not a linear map; left out).

    Raises
    ------
    FMUError
        A definition that is not usable (a zero or non-finite factor, an unknown base unit).
    """
    out: dict[str, UnitDefinition] = {}
    displays: dict[str, UnitDefinition] = {}
    for u in md.unitDefinitions or []:
        base = u.baseUnit
        if base is None or not u.name:
            continue
        try:
            out[u.name] = UnitDefinition.from_base(
                u.name, {b: getattr(base, b, 0) for b in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")},
                float(base.factor), float(base.offset), source)
        except UnitError as exc:
            raise FMUError(f"{source}: modelDescription.xml <UnitDefinitions>: {exc}", path=source) from None
        problem = disagreement(out[u.name])
        if problem is not None:
            log.warning("%s: %s", source, problem)
        unit = out[u.name]
        for d in getattr(u, "displayUnits", None) or []:
            if not d.name or d.name in inverse or d.name in displays:
                continue
            factor, offset = float(d.factor), float(d.offset)
            if not (math.isfinite(factor) and factor != 0.0 and math.isfinite(offset)):
                raise FMUError(f"{source}: modelDescription.xml <UnitDefinitions>: display unit {d.name!r} of "
                               f"{u.name!r}: factor {factor!r} and offset {offset!r} must be finite and the factor "
                               "non-zero", path=source)
            # value_unit = (value_display - offset) / factor, value_SI = unit.factor x value_unit + unit.offset
            displays[d.name] = UnitDefinition(d.name, unit.exponents, unit.factor / factor,
                                              unit.offset - unit.factor * offset / factor, source)
    for name, definition in displays.items():
        out.setdefault(name, definition)
    return out


def variable_unit_definition(variable: ScalarVariable, definitions: Mapping[str, UnitDefinition],
                             relative: frozenset[str] = frozenset()) -> UnitDefinition | None:
    """The definition of ``variable``'s unit, without its offset when the variable is a relative quantity.

    FMI: a ``relativeQuantity="true"`` variable (a temperature *difference*
    in ``degC``) converts without the unit's offset; ``relative`` names the
    variables that say so themselves (:attr:`LoadedFMU.relative`), a
    declared type may say so too.
    """
    found = definitions.get(fmu_unit(variable) or "")
    if found is not None and found.offset != 0.0 and (variable.name in relative or _relative(variable)):
        found = UnitDefinition(found.name, found.exponents, found.factor, 0.0, found.source)
    return found


def _relative(variable: ScalarVariable) -> bool:
    if getattr(variable, "relativeQuantity", False):
        return True
    declared = getattr(variable, "declaredType", None)
    return bool(getattr(declared, "relativeQuantity", False))


def no_variable_error(component: str, path: Path, name: str, exposed: Mapping[str, object],
                      md: ModelDescription) -> FMUError:
    """The :class:`FMUError` for a name that is not an exposed variable, saying why.

    Shared by :class:`FMUComponent` and
    :class:`~orchestrator.fmu.isolated.IsolatedFMUComponent`: a structured FMU
    name (``gain.k``, ``der(x)``) is reachable through ``mapping``; a local or
    independent variable is not exchanged; an index outside an array
    (``u[4]`` of an array of 3) names the array and its shape.

    Parameters
    ----------
    component : str
        Instance name.
    path : Path
        The FMU file.
    name : str
        The name asked for.
    exposed : Mapping
        The exposed variables by our name.
    md : ModelDescription
        The FMU's model description.
    """
    theirs = {v.name: v for v in md.modelVariables}.get(name)
    array = arrays.bad_element_reason(name, arrays.arrays_among(exposed))
    if array is not None:
        why = array  # "u[4]" of an array of 3, or an array's own name where a scalar is needed
    elif theirs is not None and theirs.causality in ("parameter", "input", "output"):
        # an FMU name the twin cannot address (structured names "gain.k", "der(x)")
        why = (f"the FMU's {theirs.causality} {name!r} is not an identifier; give it one through "
               f"mapping={{'your_name': {name!r}}}")
    elif theirs is not None:
        why = f"the FMU's {name!r} is a {theirs.causality} variable, which the twin does not exchange"
    else:
        why = "no such variable"
    return FMUError(f"{component} ({path.name}): no variable {name!r} ({why}); it has {sorted(exposed)}",
                    path=str(path), component=component)


def our_type(type_name: str) -> str:
    """Our type for an FMI 2.0 or 3.0 type name (``"Float32"`` -> ``"Real"``); the name itself when not exchanged."""
    if type_name in _TYPES:
        return type_name
    if type_name == "Enumeration":
        return "Integer"
    ours = fmi3.NATIVE_TYPES.get(type_name)
    return ours[0] if ours is not None else type_name


def _start(variable: ScalarVariable, type_: str, raw: Any = None) -> Any:
    """Start value of ``variable`` in our type (``raw``: an array element's own start text)."""
    raw = variable.start if raw is None else raw
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
    to_fmu: float  # their value = to_fmu × our value + offset (Real only)
    native: _Native  # how it is exchanged (FMI type, functions)
    offset: float = 0.0  # their value at our 0 (an affine unit: degC for our K), Real only
    element: int = -1  # an FMI 3.0 array's element: its row-major position (0-based); -1 for a scalar
    count: int = 1  # values behind the value reference (the array's element count; 1 for a scalar)

    @property
    def key(self) -> tuple[str, int, int]:
        """(setter, value reference, element): what one value of the FMU is (aliases share it)."""
        return self.native.setter, int(self.theirs.valueReference), self.element


class _Block:
    """Preallocated ctypes buffers for variables of one FMI type exchanged together.

    ``args`` are the arguments of the get/set call after the instance:
    ``(vr, nvr, values)`` (FMI 2.0) or ``(vr, nvr, values, nValues)`` (FMI 3.0).
    An FMI 3.0 array contributes its value reference once and all its
    elements, row-major, in a row (``nValues`` > ``nvr``); the bindings must
    hold every element of each array they touch, in order.
    Reals are converted with ``to_fmu`` and ``offset`` (their value = to_fmu × ours + offset); String
    values are held in ``values`` as str, the others in arrays of shape (1,).
    """

    def __init__(self, values: dict, bindings: list[_Binding], native: _Native) -> None:
        n = len(bindings)
        self.n = n
        self.native = native
        self.values = values
        self.names = [b.ours.name for b in bindings]
        vrs = _value_references(bindings)
        self.nvr = len(vrs)
        self.vr = (ctypes.c_uint * self.nvr)(*vrs)
        self.buffer = (native.ctype * n)()
        self.args = (self.vr, self.nvr, self.buffer) + ((n,) if native.counted else ())
        self.fast = native.ctype is ctypes.c_double  # vectorised Real path (the common case)
        self.view = np.ctypeslib.as_array(self.buffer) if self.fast and n else np.empty(0)
        self.arrays = [values[name] for name in self.names] if native.ours != "String" else []
        self.to_fmu = np.array([b.to_fmu for b in bindings])
        self.from_fmu = 1.0 / self.to_fmu if n else self.to_fmu
        self.offset = np.array([b.offset for b in bindings], dtype=float)
        #: where an offset applies (elsewhere nothing is added, as in the compiled FMU loop: -0.0 stays -0.0)
        self.shifted = self.offset != 0.0
        self.affine = bool(self.shifted.any())

    def pack(self) -> None:
        """Our values -> the buffer (in the FMU's units)."""
        kind = self.native.ours
        if self.fast:
            for i, arr in enumerate(self.arrays):
                self.view[i] = arr[0]
            self.view *= self.to_fmu
            if self.affine:
                np.add(self.view, self.offset, out=self.view, where=self.shifted)
        elif kind == "Real":
            for i, arr in enumerate(self.arrays):
                value = float(arr[0]) * self.to_fmu[i]
                self.buffer[i] = value + self.offset[i] if self.shifted[i] else value
        elif kind == "String":
            for i, name in enumerate(self.names):
                self.buffer[i] = str(self.values[name]).encode("utf-8")
        elif kind == "Boolean":
            for i, arr in enumerate(self.arrays):
                self.buffer[i] = bool(arr[0])
        else:
            for i, arr in enumerate(self.arrays):
                self.buffer[i] = int(arr[0])

    def unpack(self) -> None:
        """The buffer -> our values (in our units)."""
        kind = self.native.ours
        if self.fast:
            if self.affine:
                np.subtract(self.view, self.offset, out=self.view, where=self.shifted)
            self.view *= self.from_fmu
            for i, arr in enumerate(self.arrays):
                arr[0] = self.view[i]
        elif kind == "Real":
            for i, arr in enumerate(self.arrays):
                raw = float(self.buffer[i])
                arr[0] = (raw - self.offset[i] if self.shifted[i] else raw) * self.from_fmu[i]
        elif kind == "String":
            for i, name in enumerate(self.names):
                self.values[name] = (self.buffer[i] or b"").decode("utf-8")
        else:
            for i, arr in enumerate(self.arrays):
                arr[0] = self.buffer[i]


def _value_references(bindings: list[_Binding]) -> list[int]:
    """The value references of one get/set call: a scalar's each, an array's once (at its first element).

    Raises
    ------
    FMUError
        An array whose elements are not all there in row-major order (an internal error).
    """
    vrs: list[int] = []
    expected = 0  # the next element of the array being read
    for b in bindings:
        if b.element < 0 and expected == 0:
            vrs.append(int(b.theirs.valueReference))
            continue
        if b.element != expected or (expected and int(b.theirs.valueReference) != vrs[-1]):
            raise FMUError(f"internal error: array {b.theirs.name!r} exchanged without all its elements in order "
                           f"({b.ours.name!r} at position {expected})")
        if expected == 0:
            vrs.append(int(b.theirs.valueReference))
        expected = 0 if b.element + 1 == b.count else b.element + 1
    if expected:
        raise FMUError(f"internal error: array {bindings[-1].theirs.name!r} exchanged without its last elements")
    return vrs


def _blocks(values: dict, bindings: list[_Binding]) -> list[_Block]:
    """Bindings grouped by FMI type (Reals first, then in model-description order), one block each."""
    groups: dict[str, list[_Binding]] = {}
    for b in sorted(bindings, key=lambda b: b.native.ours != "Real"):
        groups.setdefault(b.native.setter, []).append(b)
    return [_Block(values, group, group[0].native) for group in groups.values()]


#: ``generationTool`` prefixes of FMUs whose ``fmi2FreeInstance`` corrupts the host process's heap: PythonFMU 0.7
#: (NTNU-IHB/PythonFMU#228; "corrupted double-linked list", an abort at interpreter exit in about half of the
#: processes that freed one). Their instances are left allocated until the process ends.
NO_FREE_TOOLS = ("PythonFMU 0.7",)


def _free_instance(slave: Any, alive: list[bool], free: bool = True, function: str = "fmi2FreeInstance") -> None:
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
            getattr(slave, function)(slave.component)


#: The live instance of each FMU with ``canBeInstantiatedOnlyOncePerProcess="true"``, by extracted folder.
_ONCE_PER_PROCESS: dict[Path, "weakref.ref[FMUComponent]"] = {}

#: Components by the ``componentEnvironment`` key their FMI 2.0 instance logs with (see :func:`_route_fmi2_log`).
_LOG_TARGETS: weakref.WeakValueDictionary[int, "FMUComponent"] = weakref.WeakValueDictionary()
_LOG_KEYS = itertools.count(1)


def _route_fmi2_log(env: Any, instance: bytes, status: int, category: bytes, message: bytes) -> None:
    """The FMI 2.0 logger of every instance: hands the message to the component that ``env`` names.

    A message without a living component (an instance freed by the garbage
    collector logging in ``fmi2FreeInstance``) goes to this module's logger.
    """
    target = _LOG_TARGETS.get(int(env or 0))
    if target is not None:
        target._log(status, message)  # noqa: SLF001 - same module
    else:
        log.debug("%s: [%s] %s", (instance or b"?").decode("utf-8", "replace"), status_name(status),
                  (message or b"").decode("utf-8", "replace"))


_FMI2_LOGGER = fmi2CallbackLoggerTYPE(_route_fmi2_log)


class FMUComponent:
    """An FMI 2.0 or FMI 3.0 co-simulation FMU behind the component protocol (batch 1).

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
        variables, unknown mapping or parameter names (an index outside an
        FMI 3.0 array names the array and its shape), an array sized by a
        tunable structural parameter or one whose size the FMU reports
        differently after instantiation, instantiation failure.

    Attributes
    ----------
    fmi_version : str
        ``"2.0"`` or the FMI 3 version of the model description (``"3.0"``).
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
        self.fmi_version = md.fmiVersion
        self._v3 = fmi3.is_fmi3(md.fmiVersion)
        self._prefix = "fmi3" if self._v3 else "fmi2"
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
        #: FMI 3.0 arrays addressable as a whole by their (our) name: name -> (shape, element names)
        self._whole = arrays.complete_arrays(self._by_name)
        #: alias -> the variable its name set shares one value with (inputs and parameters; see _alias_sets)
        self._alias_of = self._alias_sets()
        #: the inputs among them: one input, written once per step, connected under any of its names
        self._input_alias = {a: h for a, h in self._alias_of.items() if self._by_name[a].ours.causality == "input"}
        self.values: dict[str, np.ndarray | str] = {}
        self._load_start_values()
        self._init_parameters: dict[str, object] = self._expand(dict(parameters or {}))
        #: names given a value by the caller (constructor parameters, set()); see _settable_bindings
        self._explicit: set[str] = set()
        for key in self._init_parameters:
            var = self.variable(key)
            if var.causality == "output":
                raise FMUError(f"{self.name}.{key} is an output and cannot be given as a parameter",
                               path=str(self.path), component=self.name)
        self._apply_init_parameters()
        self._in_blocks = _blocks(self.values, [b for b in self._bindings if b.ours.causality == "input"
                                                and b.ours.name not in self._input_alias])
        self._out_blocks = _blocks(self.values, [b for b in self._bindings if b.ours.causality == "output"])
        self._step_flags = fmi3.StepFlags() if self._v3 else None
        self.messages: deque[str] = deque(maxlen=log_capacity)
        self._worst_logged = 0
        self.time = float("nan")
        self.state = "instantiated"
        self._check_binary()
        self._instantiate()

    # ------------------------------------------------------------------ binding
    def _bind(self, md: ModelDescription) -> list[_Binding]:
        fmu_vars = {v.name: v for v in md.modelVariables}
        where = f"{self.path}"
        #: FMI 3.0 arrays among the exchanged variables: their name -> shape (see orchestrator.fmu.arrays)
        self._shapes: dict[str, tuple[int, ...]] = {
            v.name: arrays.shape_of(v, md, where) for v in md.modelVariables
            if v.causality in ("parameter", "input", "output") and arrays.is_array(v)}
        element_vars = {name for v, shape in self._shapes.items() for name in arrays.element_names(v, shape)}
        reverse: dict[str, str] = {}
        for ours, theirs in self.mapping.items():
            if theirs not in fmu_vars and theirs not in element_vars:
                reason = arrays.bad_element_reason(theirs, self._shapes)
                raise FMUError(
                    f"{where}: mapping {ours!r} -> {theirs!r}: the FMU has no variable {theirs!r}"
                    + (f" ({reason})" if reason else "") + f"; it has {sorted(fmu_vars)}",
                    path=str(self.path), component=self.name,
                )
            if not (ours.isidentifier() or is_element_name(ours)):
                raise FMUError(f"{where}: mapping target name {ours!r} is not an identifier", path=str(self.path))
            if theirs in reverse:
                raise FMUError(f"{where}: mapping {reverse[theirs]!r} and {ours!r} both -> {theirs!r}; map each FMU "
                               "variable to one name", path=str(self.path), component=self.name)
            reverse[theirs] = ours
        bindings: list[_Binding] = []
        problems: list[str] = []
        definitions = unit_definitions(md, where, self._fmu.inverse_display_units)
        self._unit_definitions = definitions
        for v in md.modelVariables:
            if v.causality not in ("parameter", "input", "output"):
                continue
            native = _native(v, md.fmiVersion)
            if native is None:
                continue  # FMI 3.0 Binary or Clock: not exchanged, shown by check_fmu
            elements = self._elements(v, reverse, where)
            named = [e for e in elements if e[0].isidentifier() or is_element_name(e[0])]
            # others, e.g. "der(x)" or "gain.k": not addressable by the twin, shown by check_fmu
            if named and len(named) != len(elements):  # an array is exchanged whole: every element needs a name
                raise FMUError(
                    f"{where}: array {v.name!r}: elements {[e[0] for e in elements if e not in named]} have no name "
                    f"the twin can address, and the array is exchanged whole; map the array (mapping={{'your_name': "
                    f"{v.name!r}}}) or every element", path=str(self.path), component=self.name)
            for ours, element, count, raw_start in named:
                found = self._binding(v, native, ours, element, count, raw_start, definitions, problems, where)
                if found is not None:
                    bindings.append(found)
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
        seen: dict[str, str] = {}
        for b in bindings:
            first = seen.setdefault(b.ours.name, b.theirs.name)
            if first != b.theirs.name:
                # two FMU variables under one name would share one value array (silently wrong values)
                mapped, own = (first, b.theirs.name) if reverse.get(first) == b.ours.name else (b.theirs.name, first)
                raise FMUError(
                    f"{where}: mapping {b.ours.name!r} -> {mapped!r}: the FMU has its own variable {own!r}, which "
                    f"would share the name; map it to another name too (e.g. mapping={{..., "
                    f"{own + '_fmu'!r}: {own!r}}})", path=str(self.path), component=self.name,
                )
        return bindings

    def _elements(self, v: ScalarVariable, reverse: Mapping[str, str],
                  where: str) -> list[tuple[str, int, int, str | None]]:
        """(our name, element, element count, start text) of each value of ``v``: one for a scalar, one per
        element (row-major) for an FMI 3.0 array, named ``base[i,j]`` after the array's own or mapped name
        unless the element is mapped itself."""
        if v.name not in self._shapes:
            return [(reverse.get(v.name, v.name), -1, 1, None)]
        shape = self._shapes[v.name]
        theirs = arrays.element_names(v.name, shape)
        ours = arrays.element_names(reverse.get(v.name, v.name), shape)
        starts = arrays.start_values(v, len(theirs), where)
        return [(reverse.get(t, o), k, len(theirs), start)
                for k, (t, o, start) in enumerate(zip(theirs, ours, starts))]

    def _binding(self, v: ScalarVariable, native: _Native, ours: str, element: int, count: int,
                 raw_start: str | None, definitions: Mapping[str, UnitDefinition], problems: list[str],
                 where: str) -> _Binding | None:
        """The binding of one value of ``v`` under our name ``ours`` (None, and a problem noted, when it does
        not fit the role)."""
        type_ = native.ours
        their_name = v.name if element < 0 else arrays.element_name(
            v.name, [int(i) + 1 for i in np.unravel_index(element, self._shapes[v.name])])
        their_unit = fmu_unit(v) if type_ == "Real" else None
        their_definition = variable_unit_definition(v, definitions, self._fmu.relative) if type_ == "Real" else None
        spec = self.role.variable(ours) if self.role else None
        our_unit: str | None = their_unit if type_ == "Real" else "1"
        our_definition = their_definition
        factor, offset = 1.0, 0.0
        if spec is not None:
            if spec.causality != v.causality:
                problems.append(f"{ours!r} (FMU {their_name!r}) is a {v.causality}, the role needs a {spec.causality}")
                return None
            if spec.type != type_:
                problems.append(f"{ours!r} (FMU {their_name!r}) is {type_}, the role needs {spec.type}")
                return None
            our_unit, our_definition = spec.unit, None
            if their_unit is None and type_ == "Real":
                log.info("%s: %r (FMU %r) declares no unit; taken as the role's %s", where, ours, their_name,
                         spec.unit)
            if their_unit is not None and type_ == "Real":
                try:
                    factor, offset = conversion(our_unit, their_unit, None, their_definition)
                except UnitError as exc:
                    problems.append(f"{ours!r} (FMU {their_name!r} [{their_unit}]): {exc}")
                    return None
        try:
            start = _start(v, type_, raw_start)
        except ValueError:
            raise FMUError(
                f"{where}: modelDescription.xml: variable {their_name!r}: start={raw_start or v.start!r} is not a "
                f"{v.type} value; expected a number", path=str(self.path), component=self.name,
            ) from None
        if type_ == "Real" and (factor != 1.0 or offset != 0.0):
            start = (start - offset) / factor  # their start in our unit
        declared = Variable(ours, v.causality, our_unit, start, v.description or "", type_,  # type: ignore[arg-type]
                            our_definition)
        return _Binding(declared, v, factor, native, offset, element, count)

    def _alias_sets(self) -> dict[str, str]:
        """Inputs and parameters that alias another (same causality, value reference and FMI type) -> that one.

        FMI 3.0 ``<Alias>`` elements (fmpy lists them after every variable,
        with the variable's value reference, causality, unit and start) and
        FMI 2.0 variables sharing a value reference (where one of them carries
        the start). The names of one set share one value array, that of the
        set's variable with a ``start`` (else its first): setting any name sets
        them all, and an input is written once per step (two names written in
        one call would let a stale one win). A parameter alias that converts
        differently (one name mapped to a role unit) keeps a value of its own.

        Raises
        ------
        FMUError
            Two names of one input converted differently (one mapped to a role unit).
        """
        sets: dict[tuple[str, str, int, int], list[_Binding]] = {}
        for b in self._bindings:
            if b.ours.causality in ("input", "parameter") and b.theirs.variability != "constant":
                sets.setdefault((b.ours.causality, *b.key), []).append(b)
        out: dict[str, str] = {}
        for group in sets.values():
            head = next((b for b in group if b.theirs.start is not None), group[0])
            for b in group:
                if b is head:
                    continue
                if (head.to_fmu, head.offset) != (b.to_fmu, b.offset):
                    if b.ours.causality == "input":
                        raise FMUError(
                            f"{self.path}: inputs {head.ours.name!r} [{head.ours.unit}] and {b.ours.name!r} "
                            f"[{b.ours.unit}] are aliases (value reference {b.theirs.valueReference}) exchanged in "
                            "different units; map only one of them to a role name", path=str(self.path),
                            component=self.name)
                    continue
                out[b.ours.name] = head.ours.name
        return out

    def unit_definition(self, symbol: str) -> UnitDefinition | None:
        """How the FMU defines unit ``symbol`` (a ``<Unit>`` or a ``<DisplayUnit>`` of its ``<UnitDefinitions>``),
        None when it does not; a probe in such a unit converts with it (:func:`orchestrator.master.probe_conversion`)."""
        return self._unit_definitions.get(symbol)

    def canonical(self, name: str) -> str:
        """The variable whose value ``name`` shares (an alias; see :meth:`_alias_sets`), else ``name`` itself."""
        return self._alias_of.get(name, name)

    def display_unit(self, name: str) -> str | None:
        """The FMU's ``displayUnit`` of variable ``name`` (an FMI 3.0 ``<Alias>`` has its own), None if none.

        Values are always exchanged in the variable's ``unit``; the display unit is how the
        exporting tool shows it (:func:`~orchestrator.fmu.check_fmu` lists it).
        """
        binding = self._by_name.get(name)
        if binding is None:
            raise no_variable_error(self.name, self.path, name, self._by_name, self.model_description)
        return getattr(binding.theirs, "displayUnit", None) or None

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
            raise no_variable_error(self.name, self.path, name, self._by_name, self.model_description) from None

    def names(self, causality: str) -> list[str]:
        """Names of the exposed variables of one causality, in model-description order (an input once: without
        its aliases, which :meth:`variable` still resolves)."""
        return [b.ours.name for b in self._bindings if b.ours.causality == causality
                and b.ours.name not in self._input_alias]

    # ------------------------------------------------------------------ values
    def _load_start_values(self) -> None:
        for b in self._bindings:
            var = b.ours
            if var.name in self._alias_of:
                continue  # shares the value of its set's variable (below)
            if var.type == "String":
                self.values[var.name] = str(var.start)
            elif var.name in self.values:
                self.values[var.name][...] = var.start  # type: ignore[index]
            else:
                self.values[var.name] = np.full(1, var.start, dtype=_DTYPES[var.type])
        for alias, head in self._alias_of.items():
            self.values[alias] = self.values[head]  # the same array (a str for a String variable)

    def _apply_init_parameters(self) -> None:
        """Store the constructor's parameters (and inputs); two names of one alias set must agree.

        Raises
        ------
        FMUError
            Two aliases given different values.
        """
        self._explicit = set()
        given: dict[str, dict[str, object]] = {}
        for key, value in self._init_parameters.items():
            given.setdefault(self.canonical(key), {})[key] = value
        for names in given.values():
            if len(names) > 1 and len({str(np.asarray(v).tolist()) for v in names.values()}) > 1:
                vr = self._by_name[next(iter(names))].theirs.valueReference
                raise FMUError(f"{self.name}: {sorted(names)} are aliases (value reference {vr}) and were given "
                               "different values; give one", path=str(self.path), component=self.name)
        for key, value in self._init_parameters.items():
            self._store(self.variable(key), value)
            self._explicit.add(key)

    def _store(self, var: Variable, value: object) -> None:
        if var.type == "String":
            if not isinstance(value, str):
                raise FMUError(f"{self.name}.{var.name}: expected a string, got {type(value).__name__}",
                               path=str(self.path), component=self.name)
            head = self.canonical(var.name)
            for name in (head, *(a for a, h in self._alias_of.items() if h == head)):
                self.values[name] = value
            return
        arr = np.asarray(value, dtype=_DTYPES[var.type])
        if arr.size != 1:
            raise FMUError(f"{self.name}.{var.name}: expected a scalar (batch 1), got shape {arr.shape}",
                           path=str(self.path), component=self.name)
        self.values[var.name][...] = arr.reshape(1)  # type: ignore[index]

    def _expand(self, values: Mapping[str, object]) -> dict[str, object]:
        """``values`` with each whole array (``"A": [[...], ...]``) replaced by its elements (``"A[1,1]"``, ...).

        Raises
        ------
        FMUError
            A whole-array value of another shape.
        """
        out: dict[str, object] = {}
        for name, value in values.items():
            if name in self._whole and name not in self._by_name:
                shape, elements = self._whole[name]
                out.update(arrays.expand(name, value, elements, shape, f"{self.name} ({self.path.name})"))
            else:
                out[name] = value
        return out

    def set(self, name: str, value: object) -> None:
        """Set a parameter (before :meth:`setup`) or an input (any time), in our units.

        An FMI 3.0 array is set element by element (``"A[2,3]"``) or whole by
        its name (``"A"``, a nested list or an array of its shape, or flat row-major).
        """
        if name in self._whole and name not in self._by_name:
            for element, each in self._expand({name: value}).items():
                self.set(element, each)
            return
        var = self.variable(name)
        if var.causality == "output":
            raise FMUError(f"{self.name}.{name} is an output and cannot be set", path=str(self.path), component=self.name)
        if var.causality == "parameter" and self.state != "instantiated":
            raise FMUError(f"{self.name}.{name} is a parameter; set it before setup()", path=str(self.path),
                           component=self.name)
        self._store(var, value)
        self._explicit.add(var.name)

    def get(self, name: str) -> np.ndarray | str:
        """Current value of a variable (copy of shape ``(1,)``, or a str); of a whole FMI 3.0 array by its name,
        an array of its shape."""
        if name in self._whole and name not in self._by_name:
            shape, elements = self._whole[name]
            return np.array([self.values[e][0] for e in elements]).reshape(shape)  # type: ignore[index]
        value = self.values[self.variable(name).name]
        return value if isinstance(value, str) else value.copy()

    def parameter_values(self) -> dict[str, np.ndarray | str]:
        """Current parameter values by name."""
        return {n: self.values[n] for n in self.names("parameter")}

    # ------------------------------------------------------------------ FMI calls (status checked here only)
    def _fmi(self, function: str, *args: Any) -> Any:
        """Call ``function`` (``"fmi2DoStep"``, ``"fmi3GetFloat64"``) through fmpy; a status worse than warning
        raises FMUError."""
        try:
            return getattr(self._slave, function)(self._slave.component, *args)
        except FMICallException as exc:
            raise self._failure(function, int(exc.status)) from None

    def _status_name(self, status: int) -> str:
        return fmi3.status_name(status) if self._v3 else status_name(status)

    def _failure(self, function: str, status: int, verb: str = "returned") -> FMUError:
        what = f"{verb} {self._status_name(status)}"
        if status == PENDING and not self._v3:
            # FMI 2.0, 4.2.2: fmi2Pending means the FMU runs the step asynchronously (canRunAsynchronuously)
            what += (" (the FMU runs the step asynchronously; asynchronous steps are not supported: cnctwin's "
                     "master steps every FMU synchronously and does not wait for fmi2StepFinished)")
            if function == "fmi2DoStep":
                return self._end(function, what, status, self._cancel_step())
        return self._end(function, what, status)

    def _cancel_step(self) -> str:
        """``fmi2CancelStep`` after a ``fmi2DoStep`` that returned ``fmi2Pending``; what happened, for the message.

        FMI 2.0, 4.2.2: a step in progress is cancelled with ``fmi2CancelStep``;
        afterwards only ``fmi2Terminate``, ``fmi2Reset`` and ``fmi2FreeInstance``
        are allowed (the caller frees the instance). When the cancel itself
        fails, the step may still be running in the FMU, so the instance is
        abandoned, not freed (a few kB until the process ends).
        """
        try:
            status = int(self._slave.fmi2CancelStep(self._slave.component))
        except FMICallException as exc:
            status = int(exc.status)
        if status <= 1:
            return f"fmi2CancelStep returned {status_name(status)}, the step was cancelled"
        self._alive[0] = False  # not freed: the asynchronous step may still run
        return (f"fmi2CancelStep returned {status_name(status)}: the step may still run, so the instance is "
                "left allocated (not freed)")

    def _end(self, function: str, what: str, status: int | None, then: str = "") -> FMUError:
        """The FMUError for a failed call (``what`` happened in ``function``, ``then`` what the master did about
        it); frees or abandons the instance."""
        at = "" if np.isnan(self.time) else f" at t = {self.time:.6f} s"
        detail = (f"; {then}" if then else "") + ("; FMU log: " + " | ".join(self.messages) if self.messages else "")
        error = FMUError(
            f"{self.name}: {function} {what}{at} (FMU {self.path}){detail}",
            path=str(self.path), component=self.name, function=function,
            time=None if np.isnan(self.time) else self.time, status=status,
        )
        if status is not None and status >= 4 and not (status == PENDING and not self._v3):
            # fmi2Fatal / fmi3Fatal (or an illegal status): no further FMI call is allowed on any instance
            # (FMI 2.0, 2.1.3; FMI 3.0, 2.2.3), not even the FreeInstance; the instance is abandoned. A cancelled
            # fmi2Pending step is freed (_cancel_step leaves it allocated when the cancel failed)
            self._alive[0] = False
        else:
            self._close()
        self.state = "terminated"
        return error

    def _log(self, status: int, message: bytes | None) -> None:
        text = message.decode("utf-8", "replace") if message else ""
        label = self._status_name(status)
        self._worst_logged = max(self._worst_logged, int(status))
        self.messages.append(f"[{label}] {text}")
        log.debug("%s: [%s] %s", self.name, label, text)

    def _logger3(self, env: Any, status: int, category: bytes, message: bytes) -> None:
        self._log(status, message)

    def _instantiate(self) -> None:
        md = self.model_description
        self._claim_once_per_process()
        self._log_key = next(_LOG_KEYS)
        _LOG_TARGETS[self._log_key] = self
        if self._v3:
            self._instantiate3()
        else:
            self._instantiate2()
        self._alive = [True]
        tool = md.generationTool or ""
        frees = not tool.startswith(NO_FREE_TOOLS)
        self._finalizer = weakref.finalize(self, _free_instance, self._slave, self._alive, frees,
                                           f"{self._prefix}FreeInstance")
        self._check_dimensions()

    def _check_dimensions(self) -> None:
        """Read the structural parameters that size the exchanged arrays and compare with the shapes in use.

        Raises
        ------
        FMUError
            The FMU reports another size than its parameter's ``start`` (the
            instance is freed): the element names and buffers were made for that.
        """
        md = self.model_description
        variables = {v.name: v for v in md.modelVariables}
        for name, shape in self._shapes.items():
            holders = arrays.dimension_holders(variables[name], md)
            actual = []
            for _, holder in holders:
                native = _native(holder, md.fmiVersion)
                if native is None or native.ours != "Integer":
                    raise FMUError(f"{self.path}: array {name!r}: its dimension {holder.name!r} is a {holder.type}; "
                                   "expected an integer structural parameter", path=str(self.path),
                                   component=self.name)
                buffer = (native.ctype * 1)()
                self._fmi(native.getter, (ctypes.c_uint * 1)(int(holder.valueReference)), 1, buffer,
                          *((1,) if native.counted else ()))
                actual.append(int(buffer[0]))
            problem = arrays.dimension_problem(variables[name], shape, holders, actual)
            if problem is not None:
                self._close()
                raise FMUError(f"{self.name}: {problem} (FMU {self.path})", path=str(self.path),
                               component=self.name)

    def _claim_once_per_process(self) -> None:
        """Refuse a second live instance of an FMU with ``canBeInstantiatedOnlyOncePerProcess="true"``.

        Such an FMU keeps its state in the shared library (Simulink and other
        code generators), so a second instance in one loaded copy would share
        or corrupt the first's. Instances made from one file share one loaded
        library (the file is extracted once); a copy of the file is another
        library.

        Raises
        ------
        FMUError
            Another instance of the same extracted FMU is alive (not freed).
        """
        if not getattr(self.model_description.coSimulation, "canBeInstantiatedOnlyOncePerProcess", False):
            return
        holder = _ONCE_PER_PROCESS.get(self._fmu.unzip_dir)
        other = holder() if holder is not None else None
        if other is not None and other is not self and getattr(other, "_alive", [False])[0]:
            raise FMUError(
                f"{self.name}: {self.path.name} declares canBeInstantiatedOnlyOncePerProcess=\"true\" and its instance "
                f"{other.name!r} is alive in this process; close() that one first, or load each instance as "
                "orchestrator.fmu.isolated.IsolatedFMUComponent (one worker process each)",
                path=str(self.path), component=self.name, function=f"{self._prefix}Instantiate"
                + ("CoSimulation" if self._v3 else ""))
        _ONCE_PER_PROCESS[self._fmu.unzip_dir] = weakref.ref(self)

    def _check_binary(self) -> None:
        """Refuse a binary that is not a complete shared library before it is loaded (a truncated one would
        kill the process with SIGBUS inside ``dlopen``; see :mod:`.binary_check`)."""
        platform = fmi3.PLATFORM if self._v3 else PLATFORM
        member = f"binaries/{platform}/{self.model_description.coSimulation.modelIdentifier}{_SUFFIX}"
        problem = shared_library_problem((self._fmu.unzip_dir / member).read_bytes(), platform)
        if problem is not None:
            raise FMUError(f"{self.path}: {member} {problem}; expected a shared library for this platform "
                           f"({platform}) that the FMU's tool built", path=str(self.path), component=self.name)

    def _instantiate_failed(self) -> FMUError:
        detail = "; FMU log: " + " | ".join(self.messages) if self.messages else ""
        function = "fmi3InstantiateCoSimulation" if self._v3 else "fmi2Instantiate"
        md = self.model_description
        if getattr(md.coSimulation, "needsExecutionTool", False):
            detail += (f"; the FMU declares needsExecutionTool=\"true\": it runs only where its tool "
                       f"({md.generationTool or 'generationTool not given'}) is installed (and licensed)")
        return FMUError(f"{self.name}: {function} failed (FMU {self.path}){detail}",
                        path=str(self.path), component=self.name, function=function)

    def _instantiate3(self) -> None:
        md = self.model_description
        try:
            slave, log_cb, update_cb = fmi3.instantiate_co_simulation(
                md.coSimulation.modelIdentifier, md.guid, self._fmu.unzip_dir, self.name, self._logger3)
        except (OSError, AttributeError) as exc:
            raise FMUError(f"{self.path}: cannot load the FMU's shared library ({exc})", path=str(self.path),
                           component=self.name) from None
        self._slave = slave
        self._callbacks = (log_cb, update_cb)
        if not slave.component:
            raise self._instantiate_failed()

    def _instantiate2(self) -> None:
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
        # one process-wide logger, routed by componentEnvironment: fmpy's variadic-formatting proxy keeps a single
        # Python logger for the whole process (the last one added), so per-instance loggers would send every
        # FMI 2.0 instance's messages to the instance made last
        callbacks.logger = _FMI2_LOGGER
        callbacks.componentEnvironment = self._log_key
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
            raise self._instantiate_failed()
        self._slave.component = component
        self._slave.callbacks = callbacks

    def _close(self) -> None:
        """Free the FMU instance and its library (idempotent)."""
        if getattr(self, "_finalizer", None) is not None:
            self._finalizer()

    close = _close

    # -- typed transfers (all through _fmi)
    def _settable_bindings(self, causalities: tuple[str, ...]) -> tuple[list[_Binding], list[_Binding]]:
        """The bindings :meth:`setup` writes, and those it leaves to the FMU (read back after initialisation).

        Variables of one alias set (FMI 2.0: the same value reference and type)
        are written once: the one the caller gave a value, else the one with a
        ``start`` in the model description (FMI 2.0 allows ``start`` on one
        variable of the set only). A variable without ``start`` that the
        caller did not set is not written, so the FMU's own value stands
        (writing our placeholder 0 would overwrite the alias's start value);
        inputs are always written (the master hands connected values through
        ``values``).

        Raises
        ------
        FMUError
            Two aliases of one set given different values.
        """
        groups: dict[tuple[str, int, int], list[_Binding]] = {}
        for b in self._bindings:
            if b.ours.causality in causalities and b.theirs.variability != "constant":
                groups.setdefault(b.key, []).append(b)
        write: list[_Binding] = []
        keep: list[_Binding] = []
        for group in groups.values():
            given = [b for b in group if b.ours.name in self._explicit]
            if len(given) > 1:
                values = {b.ours.name: self.values[b.ours.name] for b in given}
                if len({str(np.asarray(v).tolist()) for v in values.values()}) > 1:
                    raise FMUError(f"{self.name}: {sorted(values)} are aliases (value reference "
                                   f"{group[0].theirs.valueReference}) and were given different values; give one",
                                   path=str(self.path), component=self.name)
            # inputs are always written: the master puts connected values into ``values`` before setup()
            chosen = (given[:1] or [b for b in group if b.theirs.start is not None][:1]
                      or [b for b in group if b.ours.causality == "input"][:1])
            write += chosen
            keep += [b for b in group if b not in chosen]
        return write, keep

    def _set_all(self, causalities: tuple[str, ...]) -> list[_Binding]:
        """Write parameters and inputs (see :meth:`_settable_bindings`); returns the bindings left unwritten.

        An FMI 3.0 array is written whole (one call, every element): elements
        that would otherwise be left to the FMU get its current values first.
        """
        write, keep = self._settable_bindings(causalities)
        chosen = {b.key for b in write}
        touched = {b.key[:2] for b in write if b.element >= 0}
        fill = [b for b in keep if b.element >= 0 and b.key[:2] in touched and b.key not in chosen]
        if fill:
            unique = list({b.key: b for b in fill}.values())
            whole = [b for b in self._bindings if b.key[:2] in {b.key[:2] for b in unique}
                     and b.ours.name not in self._alias_of]
            scratch = {b.ours.name: np.zeros(1, dtype=_DTYPES.get(b.ours.type, object)) for b in whole}
            for block in _blocks(scratch, whole):  # the FMU's current values of those arrays
                self._fmi(block.native.getter, *block.args)
                block.unpack()
            for b in unique:
                if b.ours.type != "String":
                    self.values[b.ours.name][...] = scratch[self.canonical(b.ours.name)]
            write += unique
            keep = [b for b in keep if b.key not in {u.key for u in unique}]
        position = {id(b): i for i, b in enumerate(self._bindings)}
        write.sort(key=lambda b: position[id(b)])  # an array's elements in a row, row-major
        keep.sort(key=lambda b: position[id(b)])
        for block in _blocks(self.values, write):
            block.pack()
            self._fmi(block.native.setter, *block.args)
        return keep

    def _pull_outputs(self) -> None:
        for block in self._out_blocks:
            self._fmi(block.native.getter, *block.args)
            block.unpack()

    def _get_discrete_outputs(self) -> None:
        """Read the outputs :class:`~.fast_loop.FastFMULoop` does not read every step.

        Those are the Integer, Boolean and String outputs, and for FMI 3.0 also the
        ``Float32`` ones (the compiled loop reads Real outputs with ``fmi2GetReal`` or
        ``fmi3GetFloat64`` only).
        """
        for block in self._out_blocks:
            if block.native.getter not in ("fmi2GetReal", "fmi3GetFloat64"):
                self._fmi(block.native.getter, *block.args)
                block.unpack()

    def _push_inputs(self) -> None:
        for block in self._in_blocks:
            block.pack()
            self._fmi(block.native.setter, *block.args)

    # ------------------------------------------------------------------ lifecycle
    def setup(self, t0: float = 0.0) -> None:
        """Set up the experiment at ``t0``, apply parameters and inputs, initialise, read outputs."""
        if self.state != "instantiated":
            raise FMUError(f"{self.name}: setup() called in state {self.state!r}", path=str(self.path),
                           component=self.name)
        self.t0 = float(t0)
        self.time = self.t0
        if self._v3:
            # no tolerance, start time t0, no stop time
            self._fmi("fmi3EnterInitializationMode", False, 0.0, self.t0, False, 0.0)
        else:
            self._fmi("fmi2SetupExperiment", 0, 0.0, self.t0, 0, 0.0)
            self._fmi("fmi2EnterInitializationMode")
        unwritten = self._set_all(("parameter", "input"))
        self._worst_logged = 0
        exit_init = f"{self._prefix}ExitInitializationMode"
        self._fmi(exit_init)
        if self._worst_logged >= 3:
            # the initialisation failed but the FMU could not say so in its status (pythonfmu: see
            # fmus_src.fmu.slave.ComponentSlave.exit_initialization_mode); the log names the cause
            raise self._failure(exit_init, self._worst_logged, "logged")
        for block in _blocks(self.values, unwritten):  # aliases and start-less variables: the FMU's values
            self._fmi(block.native.getter, *block.args)
            block.unpack()
        self._pull_outputs()
        self.state = "initialized"

    def do_step(self, t: float, h: float) -> None:
        """Push inputs, ``fmi2DoStep(t, h)`` or ``fmi3DoStep``, pull outputs (valid at ``t + h``).

        Raises
        ------
        FMUError
            A status worse than warning; for FMI 3.0 also ``terminateSimulation = true``
            (the FMU asks to end the simulation) and ``earlyReturn = true`` (not allowed:
            the instance was made with ``earlyReturnAllowed = false``).
        """
        if self.state != "initialized":
            raise FMUError(f"{self.name}: do_step() called in state {self.state!r}", path=str(self.path),
                           component=self.name)
        if not h > 0.0:
            raise FMUError(f"{self.name}: step size must be positive, got {h!r}", path=str(self.path),
                           component=self.name)
        self.time = t
        self._push_inputs()
        if self._v3:
            self._do_step3(float(t), float(h))
        else:
            self._fmi("fmi2DoStep", float(t), float(h), 1)
        self.time = t + h
        self._pull_outputs()

    def _do_step3(self, t: float, h: float) -> None:
        flags = self._step_flags
        flags.terminate_simulation.value = False
        flags.early_return.value = False
        # noSetFMUStatePriorToCurrentPoint = true: the master never rolls back
        self._fmi("fmi3DoStep", t, h, True, *flags.args)
        problem = fmi3.step_problem(flags, t, h)  # earlyReturn or terminateSimulation (also FastFMULoop's text)
        if problem is not None:
            raise self._end("fmi3DoStep", problem, None)

    def reset(self) -> None:
        """Back to the instantiated state with start values and the constructor's parameters."""
        if self._alive[0]:
            self._fmi(f"{self._prefix}Reset")
        else:
            self._instantiate()
        self._load_start_values()
        self._apply_init_parameters()
        self.time = float("nan")
        self.state = "instantiated"

    def terminate(self) -> None:
        """``fmi2Terminate`` / ``fmi3Terminate`` (when initialised); the instance stays allocated for :meth:`reset`."""
        if self.state == "initialized":
            self._fmi(f"{self._prefix}Terminate")
        self.state = "terminated"

    def __repr__(self) -> str:
        return f"FMUComponent({str(self.path)!r}, name={self.name!r}, state={self.state!r})"

