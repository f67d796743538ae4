"""SSP 1.0 system structure (``.ssd``) and parameter values (``.ssv``).

The twin's system — components, connections, parameter values — is written
as SSP 1.0 files generated from the TOML machine files (the TOML stays the
human-edited source of truth). :func:`read_ssd` reads SSDs written by other
tools as long as they stay within fixed-step co-simulation: components that
are FMUs, connections between component connectors, parameter bindings to
``.ssv`` files or inline parameter values.

cnctwin-specific information travels in SSP annotations (type
``org.cnctwin``), which other tools ignore: the native Python class that
implements a component (so the master can run it without the FMU round trip),
its rate (substeps per communication step), and the master's step size.
"""
from __future__ import annotations

import importlib
import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fmus_src.component import Component, Variable
from fmus_src.units import UnitDefinition, UnitError, base_exponents, conversion, known
from fmus_src.units import unit as lookup_unit

from .atomic import atomic_write_text
from .errors import CncTwinError
from .master import MasterSettings
from .system import System

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "cnctwin": "https://github.com/cnctwin/cnctwin/ssp-annotations",
}
ANNOTATION_TYPE = "org.cnctwin"
FMU_TYPE = "application/x-fmu-sharedlibrary"
_TYPES = ("Real", "Integer", "Boolean", "String")
#: String parameters holding file paths, resolved relative to the SSD's folder.
PATH_PARAMETERS = {"program_file"}

for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)


class SSPError(CncTwinError):
    """An SSD/SSV file is malformed or asks for something fixed-step co-simulation cannot do."""


@dataclass
class Connector:
    """A connector of an element: name, kind, type and unit."""

    name: str
    kind: str
    type: str = "Real"
    unit: str | None = None


@dataclass
class ElementSpec:
    """A component of the system.

    Attributes
    ----------
    name : str
        Element name (the component's instance name).
    source : str or None
        FMU path relative to the SSD (None for purely native elements).
    native : str or None
        ``"module:Class"`` of the native implementation (cnctwin annotation).
    rate : int
        Substeps per communication step (cnctwin annotation, default 1).
    connectors : list of Connector
    parameters : dict
        Parameter name → (value, unit or None).
    """

    name: str
    source: str | None = None
    native: str | None = None
    rate: int = 1
    connectors: list[Connector] = field(default_factory=list)
    parameters: dict[str, tuple[Any, str | None]] = field(default_factory=dict)


@dataclass
class SystemSpec:
    """What an SSD describes, resolved (parameter sets merged in)."""

    name: str
    elements: list[ElementSpec]
    connections: list[tuple[str, str, str, str]]
    step: float = 1e-3
    start_time: float = 0.0
    stop_time: float | None = None
    stop_when: tuple[str, ...] | None = None
    method: str = "gauss-seidel"
    order: tuple[str, ...] | None = None
    folder: Path = Path(".")
    units: dict[str, UnitDefinition] = field(default_factory=dict)


# ---------------------------------------------------------------------------- writing
def _q(prefix: str, tag: str) -> str:
    return f"{{{NS[prefix]}}}{tag}"


def _fmt(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _units_element(parent: ET.Element, prefix: str, symbols: dict[str, UnitDefinition | None]) -> None:
    """``<ssd:Units>``/``<ssv:Units>``: each unit's ``ssc:BaseUnit``.

    A unit of :mod:`fmus_src.units` from the table; any other from the
    definition its variable came with (an FMU's ``<UnitDefinitions>``, with
    its offset); a unit with neither gets an ``ssc:Unit`` without
    ``ssc:BaseUnit`` (SSP allows it: nothing to convert with).
    """
    if not symbols:
        return
    units = ET.SubElement(parent, _q(prefix, "Units"))
    for symbol in sorted(symbols):
        u = ET.SubElement(units, _q("ssc", "Unit"), name=symbol)
        if known(symbol):
            attrs = {k: str(v) for k, v in base_exponents(symbol).items()}
            factor, offset = lookup_unit(symbol).factor, 0.0
        elif symbols[symbol] is not None:
            found = symbols[symbol]
            attrs = {k: str(v) for k, v in found.exponents}
            factor, offset = found.factor, found.offset
        else:
            continue
        if factor != 1.0:
            attrs["factor"] = repr(factor)
        if offset != 0.0:
            attrs["offset"] = repr(offset)
        ET.SubElement(u, _q("ssc", "BaseUnit"), attrs)


def _read_units(path: Path, holder: ET.Element, prefix: str) -> dict[str, UnitDefinition]:
    """The ``ssc:Unit`` definitions under ``holder``'s ``<prefix:Units>`` (those with an ``ssc:BaseUnit``)."""
    out: dict[str, UnitDefinition] = {}
    for u in holder.iterfind(f"{prefix}:Units/ssc:Unit", NS):
        name, base = u.get("name"), u.find("ssc:BaseUnit", NS)
        if not name or base is None:
            continue
        try:
            exps = {k: int(base.get(k, "0")) for k in ("kg", "m", "s", "A", "K", "mol", "cd", "rad")}
            out[name] = UnitDefinition.from_base(name, exps, float(base.get("factor", "1")),
                                                 float(base.get("offset", "0")), str(path))
        except (ValueError, UnitError) as exc:
            raise SSPError(f"{path}: unit {name!r}: malformed ssc:BaseUnit ({exc})") from None
    return out


def _pretty(root: ET.Element) -> str:
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def parameter_set_xml(name: str, parameters: dict[str, tuple[Any, str, str | None]],
                      definitions: dict[str, UnitDefinition | None] | None = None) -> str:
    """SSV text for ``{"comp.param": (value, type, unit)}`` (``definitions``: of units not in :mod:`fmus_src.units`)."""
    root = ET.Element(_q("ssv", "ParameterSet"), version="1.0", name=name)
    params = ET.SubElement(root, _q("ssv", "Parameters"))
    used: dict[str, UnitDefinition | None] = {}
    for pname, (value, vtype, unit) in parameters.items():
        p = ET.SubElement(params, _q("ssv", "Parameter"), name=pname)
        attrs = {"value": _fmt(value)}
        if unit and vtype == "Real":
            attrs["unit"] = unit
            used.setdefault(unit, (definitions or {}).get(unit))
        ET.SubElement(p, _q("ssv", vtype), attrs)
    _units_element(root, "ssv", used)
    return _pretty(root)


def system_to_ssp(
    system: System,
    ssd_path: Path,
    ssv_path: Path,
    settings: MasterSettings | None = None,
    fmu_sources: dict[str, str] | None = None,
    relative_paths: bool = True,
) -> tuple[Path, Path]:
    """Write a native :class:`System` as an SSD plus one SSV with all parameter values.

    Parameters
    ----------
    system : System
        Components (native, B = 1) and connections.
    ssd_path, ssv_path : Path
        Files to write (atomically).
    settings : MasterSettings, optional
        Step size, stop signal and time limit to record.
    fmu_sources : dict, optional
        Element name → FMU path (relative to the SSD) for the ``source``
        attribute, so that other tools can run the system from FMUs.
    relative_paths : bool
        Write file-valued parameters relative to the SSD's folder.
    """
    settings = settings or MasterSettings()
    ssd_path, ssv_path = Path(ssd_path), Path(ssv_path)
    root = ET.Element(_q("ssd", "SystemStructureDescription"), version="1.0", name=system.name)
    sys_el = ET.SubElement(root, _q("ssd", "System"), name=system.name)
    bindings = ET.SubElement(sys_el, _q("ssd", "ParameterBindings"))
    ET.SubElement(bindings, _q("ssd", "ParameterBinding"), source=os.path.relpath(ssv_path, ssd_path.parent))
    elements = ET.SubElement(sys_el, _q("ssd", "Elements"))
    used_units: dict[str, UnitDefinition | None] = {}
    parameters: dict[str, tuple[Any, str, str | None]] = {}
    for name, comp in system.components.items():
        attrs = {"name": name, "type": FMU_TYPE}
        attrs["source"] = (fmu_sources or {}).get(name, f"fmus/{type(comp).__name__}.fmu")
        el = ET.SubElement(elements, _q("ssd", "Component"), attrs)
        conns = ET.SubElement(el, _q("ssd", "Connectors"))
        for var in comp.declared_variables():
            c = ET.SubElement(conns, _q("ssd", "Connector"), name=var.name, kind=var.causality)
            # a variable without a declared unit gets a connector without one (not "1")
            t_attrs = {"unit": var.unit} if var.type == "Real" and var.unit is not None else {}
            if t_attrs:
                used_units.setdefault(var.unit, var.unit_definition)
            ET.SubElement(c, _q("ssc", var.type), t_attrs)
            if var.causality == "parameter":
                value = comp.values[var.name]
                if var.type == "String":
                    if var.name in PATH_PARAMETERS and value and relative_paths:
                        value = os.path.relpath(Path(value).resolve(), ssd_path.parent.resolve())
                else:
                    value = value[0].item()
                parameters[f"{name}.{var.name}"] = (value, var.type, var.unit if var.type == "Real" else None)
        ann = ET.SubElement(ET.SubElement(el, _q("ssc", "Annotations")), _q("ssc", "Annotation"), type=ANNOTATION_TYPE)
        cls = type(comp)
        ET.SubElement(ann, _q("cnctwin", "Component"), native=f"{cls.__module__}:{cls.__qualname__}",
                      rate=str(system.rates[name]))
    connections = ET.SubElement(sys_el, _q("ssd", "Connections"))
    for c in system.connections:
        ET.SubElement(connections, _q("ssd", "Connection"), startElement=c.source_component,
                      startConnector=c.source_variable, endElement=c.target_component, endConnector=c.target_variable)
    _units_element(root, "ssd", used_units)
    experiment = ET.SubElement(root, _q("ssd", "DefaultExperiment"), startTime=repr(settings.t0),
                               stopTime=repr(settings.t0 + settings.time_limit))
    ann = ET.SubElement(ET.SubElement(experiment, _q("ssc", "Annotations")), _q("ssc", "Annotation"), type=ANNOTATION_TYPE)
    master_attrs = {"step": repr(settings.step), "method": settings.method,
                    "order": " ".join(system.execution_order())}
    if settings.stop_signals():
        master_attrs["stopWhen"] = " ".join(settings.stop_signals())
    ET.SubElement(ann, _q("cnctwin", "Master"), master_attrs)
    atomic_write_text(ssv_path, parameter_set_xml(f"{system.name}-parameters", parameters, used_units))
    atomic_write_text(ssd_path, _pretty(root))
    return ssd_path, ssv_path


# ---------------------------------------------------------------------------- reading
def _parse(path: Path) -> ET.Element:
    if not path.is_file():
        raise SSPError(f"{path}: file not found")
    try:
        return ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise SSPError(f"{path}:{exc.position[0]}: not well-formed XML ({exc})") from None


def _typed_value(path: Path, pname: str, holder: ET.Element) -> tuple[Any, str | None]:
    for vtype in _TYPES:
        el = holder.find(f"ssv:{vtype}", NS)
        if el is None:
            continue
        raw = el.get("value")
        if raw is None:
            raise SSPError(f"{path}: parameter {pname!r}: <{vtype}> has no value attribute")
        try:
            if vtype == "Real":
                value: Any = float(raw)
            elif vtype == "Integer":
                value = int(raw)
            elif vtype == "Boolean":
                if raw not in ("true", "false", "1", "0"):
                    raise ValueError(raw)
                value = raw in ("true", "1")
            else:
                value = raw
        except ValueError:
            raise SSPError(f"{path}: parameter {pname!r}: {raw!r} is not a valid {vtype}") from None
        return value, el.get("unit")
    raise SSPError(f"{path}: parameter {pname!r} has no Real/Integer/Boolean/String value")


def read_ssv(path: Path) -> dict[str, tuple[Any, str | None]]:
    """Parameter values of an SSV file: name → (value, unit or None)."""
    root = _parse(Path(path))
    if root.tag != _q("ssv", "ParameterSet"):
        raise SSPError(f"{path}: expected an ssv:ParameterSet root, found {root.tag}")
    return _parameter_set(Path(path), root)


def _parameter_set(path: Path, root: ET.Element) -> dict[str, tuple[Any, str | None]]:
    out = {}
    for p in root.iterfind("ssv:Parameters/ssv:Parameter", NS):
        name = p.get("name")
        if not name:
            raise SSPError(f"{path}: a parameter has no name")
        out[name] = _typed_value(path, name, p)
    return out


def _bindings(path: Path, holder: ET.Element, units: dict[str, UnitDefinition] | None = None
              ) -> dict[str, tuple[Any, str | None]]:
    """Merge the parameter bindings of an element (later bindings win); their unit definitions go into ``units``."""
    values: dict[str, tuple[Any, str | None]] = {}
    units = {} if units is None else units
    for binding in holder.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
        prefix = binding.get("prefix", "")
        source = binding.get("source")
        if source:
            if source.startswith("#"):
                raise SSPError(f"{path}: parameter binding to {source!r}: fragment references are not supported")
            found = read_ssv(path.parent / source)
            units.update(_read_units(path.parent / source, _parse(path.parent / source), "ssv"))
        else:
            inline = binding.find("ssd:ParameterValues/ssv:ParameterSet", NS)
            if inline is None:
                raise SSPError(f"{path}: a ParameterBinding has neither a source nor inline ParameterValues")
            found = _parameter_set(path, inline)
            units.update(_read_units(path, inline, "ssv"))
        for name, value in found.items():
            values[name[len(prefix):] if prefix and name.startswith(prefix) else name] = value
    return values


def read_ssd(path: str | Path) -> SystemSpec:
    """Read an SSD (and the SSV files it binds) into a :class:`SystemSpec`.

    Raises
    ------
    SSPError
        Malformed XML, nested systems, system-level connectors in
        connections, parameters for unknown elements.
    """
    path = Path(path)
    root = _parse(path)
    if root.tag != _q("ssd", "SystemStructureDescription"):
        raise SSPError(f"{path}: expected an ssd:SystemStructureDescription root, found {root.tag}")
    sys_el = root.find("ssd:System", NS)
    if sys_el is None:
        raise SSPError(f"{path}: no ssd:System element")
    elements: list[ElementSpec] = []
    by_name: dict[str, ElementSpec] = {}
    units = _read_units(path, root, "ssd")
    for el in sys_el.iterfind("ssd:Elements/*", NS):
        if el.tag != _q("ssd", "Component"):
            raise SSPError(
                f"{path}: element <{el.tag.split('}')[-1]} name={el.get('name')!r}>: only ssd:Component elements "
                "(FMUs) are supported, not nested systems or signal dictionaries"
            )
        name = el.get("name")
        if not name:
            raise SSPError(f"{path}: a Component has no name")
        comp_type = el.get("type", FMU_TYPE)
        if comp_type != FMU_TYPE:
            raise SSPError(f"{path}: component {name!r} has type {comp_type!r}; only FMUs ({FMU_TYPE}) are supported")
        spec = ElementSpec(name=name, source=el.get("source"))
        for c in el.iterfind("ssd:Connectors/ssd:Connector", NS):
            ctype, unit = "Real", None
            for t in _TYPES:
                te = c.find(f"ssc:{t}", NS)
                if te is not None:
                    ctype, unit = t, te.get("unit")
            spec.connectors.append(Connector(c.get("name", ""), c.get("kind", ""), ctype, unit))
        ann = el.find(f"ssc:Annotations/ssc:Annotation[@type='{ANNOTATION_TYPE}']/cnctwin:Component", NS)
        if ann is not None:
            spec.native = ann.get("native")
            spec.rate = int(ann.get("rate", "1"))
        spec.parameters.update(_bindings(path, el, units))
        elements.append(spec)
        by_name[name] = spec
    for name, value in _bindings(path, sys_el, units).items():
        comp, _, pname = name.partition(".")
        if comp not in by_name or not pname:
            raise SSPError(f"{path}: parameter {name!r} does not name a component's parameter ('component.parameter')")
        by_name[comp].parameters[pname] = value
    connections = []
    for c in sys_el.iterfind("ssd:Connections/ssd:Connection", NS):
        start, end = c.get("startElement"), c.get("endElement")
        if not start or not end:
            raise SSPError(
                f"{path}: connection {c.get('startConnector')} -> {c.get('endConnector')} uses a system-level "
                "connector; connect component connectors directly"
            )
        connections.append((start, c.get("startConnector", ""), end, c.get("endConnector", "")))
    system_spec = SystemSpec(root.get("name", path.stem), elements, connections, folder=path.parent, units=units)
    experiment = root.find("ssd:DefaultExperiment", NS)
    if experiment is not None:
        system_spec.start_time = float(experiment.get("startTime", "0"))
        if experiment.get("stopTime"):
            system_spec.stop_time = float(experiment.get("stopTime"))
        master = experiment.find(f"ssc:Annotations/ssc:Annotation[@type='{ANNOTATION_TYPE}']/cnctwin:Master", NS)
        if master is not None:
            system_spec.step = float(master.get("step", "0.001"))
            stop = master.get("stopWhen")
            system_spec.stop_when = tuple(stop.split()) if stop else None
            system_spec.method = master.get("method", "gauss-seidel")
            order = master.get("order")
            system_spec.order = tuple(order.split()) if order else None
    return system_spec


def _import_native(spec: ElementSpec) -> type[Component]:
    module_name, _, class_name = (spec.native or "").partition(":")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as exc:
        raise SSPError(f"component {spec.name!r}: native class {spec.native!r} cannot be imported ({exc})") from None
    return cls


def _converted(spec: ElementSpec, pname: str, value: Any, unit: str | None, declared: Variable,
               units: dict[str, UnitDefinition]) -> Any:
    """A parameter value in ``unit`` converted to the variable's unit (affine: ``degC`` -> ``K`` adds 273.15).

    Units not in :mod:`fmus_src.units` are converted through the SSP's
    ``ssc:Unit`` definitions and the variable's own (an FMU's
    ``<UnitDefinitions>``); a variable without a declared unit takes the
    value as it is.
    """
    if declared.type != "Real" or unit is None or declared.unit is None or unit == declared.unit:
        return value
    try:
        factor, offset = conversion(unit, declared.unit, units.get(unit),
                                    declared.unit_definition or units.get(declared.unit))
    except UnitError as exc:
        raise SSPError(f"{spec.name}.{pname}: value in {unit!r} for a parameter in {declared.unit!r}: {exc}") from None
    return value * factor + offset if offset != 0.0 else value * factor


def build_system(spec: SystemSpec, native: bool = True, batch: int = 1) -> tuple[System, MasterSettings]:
    """Instantiate the components of an SSD and wire them.

    Parameters
    ----------
    spec : SystemSpec
        From :func:`read_ssd`.
    native : bool
        Use the native implementation of elements that name one (cnctwin
        annotation); otherwise, and for every other element, load the FMU.
    batch : int
        Batch size (native elements only; FMU elements hold one instance).
    """
    system = System(spec.name)
    for el in spec.elements:
        if native and el.native:
            cls = _import_native(el)
            declared = {v.name: v for v in cls.variables}
            params = {}
            for pname, (value, unit) in el.parameters.items():
                if pname not in declared or declared[pname].causality != "parameter":
                    raise SSPError(f"{spec.name}: {el.name}.{pname} is not a parameter of {cls.__name__}")
                var = declared[pname]
                if pname in PATH_PARAMETERS and isinstance(value, str) and value and not Path(value).is_absolute():
                    value = str((spec.folder / value).resolve())
                params[pname] = _converted(el, pname, value, unit, var, spec.units)
            component = cls(el.name, batch=batch, **params)
        else:
            if not el.source:
                raise SSPError(f"{spec.name}: component {el.name!r} has no FMU source and no native implementation")
            if batch != 1:
                raise SSPError(f"{spec.name}: component {el.name!r} is an FMU; FMU elements run with batch 1")
            from .fmu import FMUComponent  # imported here: fmpy is only needed for FMU elements

            component = FMUComponent(spec.folder / el.source, name=el.name)
            for pname, (value, unit) in el.parameters.items():
                var = component.variable(pname)
                if pname in PATH_PARAMETERS and isinstance(value, str) and value and not Path(value).is_absolute():
                    value = str((spec.folder / value).resolve())
                component.set(pname, _converted(el, pname, value, unit, var, spec.units))
        system.add(component, rate=el.rate)
    for start, sc, end, ec in spec.connections:
        system.connect(f"{start}.{sc}", f"{end}.{ec}")
    if spec.order is not None:
        system.set_execution_order(spec.order)
    limit = (spec.stop_time - spec.start_time) if spec.stop_time is not None else 3600.0
    if not (limit > 0 and math.isfinite(limit)):
        raise SSPError(f"{spec.name}: DefaultExperiment stopTime must be after startTime")
    settings = MasterSettings(step=spec.step, t0=spec.start_time, time_limit=limit, stop_when=spec.stop_when,
                              method=spec.method)  # type: ignore[arg-type]
    return system, settings
