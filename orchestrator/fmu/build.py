"""Export: one FMI 2.0 co-simulation FMU per component, built with pythonfmu.

:func:`build_fmu` wraps any :class:`fmus_src.component.Component` subclass
(batch 1) in :class:`fmus_src.fmu.slave.ComponentSlave`, ships the
``fmus_src`` package as project files (so ``import fmus_src`` works from the
FMU's ``resources/``), and post-processes ``modelDescription.xml`` (units,
``<UnitDefinitions>``, ``<InitialUnknowns>``; see
:mod:`orchestrator.fmu.model_description`).

:func:`build_fmus` builds the four components of the twin with the machine
file's values as parameter start values.
"""
from __future__ import annotations

import hashlib
import importlib
import inspect
import sys
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np
from pythonfmu import FmuBuilder

import fmus_src
from fmus_src.component import Component

from ..machine import AXES, Machine, frame_parameters, load_machine
from .errors import FMUError
from .model_description import annotate_model_description, rewrite_member
from .paths import DEFAULT_OUT_DIR

#: Communication step written as ``<DefaultExperiment stepSize>``, s.
DEFAULT_STEP = 1e-3


# ----------------------------------------------------------------------------- parameter mapping
def _declared(component_cls: type[Component], mapping: Mapping[str, object]) -> dict[str, object]:
    names = {v.name for v in component_cls.variables if v.causality == "parameter"}
    return {k: v for k, v in mapping.items() if k in names}


def _nck_parameters(machine: Machine, cls: type[Component]) -> dict[str, object]:
    params: dict[str, object] = dict(machine.si("nck"))
    params.update(frame_parameters(machine))  # machine zero in the axis frame, default work offsets
    for n in (2, 3, 4):
        for a in AXES:
            if f"reference_{a}" in params:
                params.setdefault(f"reference{n}_{a}", params[f"reference_{a}"])
    params.update({f"spindle_{k}": v for k, v in machine.si("spindle").items()})
    for a in AXES:
        params[f"{a}_rapid_feed"] = machine.si(f"axis.{a}")["rapid_feed"]
    for a, (lo, hi) in machine.stroke_limits().items():  # stored stroke check of the axes with limits
        params.update({f"{a}_stroke_check": True, f"{a}_stroke_min": lo, f"{a}_stroke_max": hi})
    return _declared(cls, params)


def _mcu_parameters(machine: Machine, cls: type[Component]) -> dict[str, object]:
    params: dict[str, object] = dict(machine.si("servo"))
    for a in AXES:
        params.update({f"{a}_{k}": v for k, v in machine.si(f"axis.{a}").items()})
    return _declared(cls, params)


def _drive_parameters(machine: Machine, cls: type[Component], axis: str = "x") -> dict[str, object]:
    params: dict[str, object] = dict(machine.si(f"axis.{axis}"))
    for direction in ("positive", "negative"):
        params.update({f"{k}_{direction}": v for k, v in machine.si(f"axis.{axis}.friction.{direction}").items()})
    return _declared(cls, params)


def _cutting_parameters(machine: Machine, cls: type[Component]) -> dict[str, object]:
    # tool, stock and material come from a case; the FMU keeps the component defaults
    return {}


def _twin_helper(name: str) -> Callable[..., dict[str, object]] | None:
    """The lead's mapping function ``orchestrator.twin.<name>`` when the twin imports cleanly."""
    try:
        twin = importlib.import_module("orchestrator.twin")
    except ImportError:
        return None
    return getattr(twin, name, None)


def machine_parameters(kind: str, machine: Machine, cls: type[Component]) -> dict[str, object]:
    """Parameter values (SI) of component ``kind`` from a machine file.

    Uses ``orchestrator.twin.{nck,mcu,drive}_parameters`` when the twin
    module imports, else the same mapping implemented here:
    NCKernel = ``si("nck")`` + ``spindle_<k>`` of ``si("spindle")`` +
    ``<a>_rapid_feed``; MCU = ``si("servo")`` + ``<a>_<k>`` of
    ``si("axis.<a>")``; DriveAxis = ``si("axis.x")`` + ``<k>_<direction>``
    of the X friction sections; CuttingLoad = component defaults (tool,
    stock and material belong to a case).

    Parameters
    ----------
    kind : {"NCKernel", "MCU", "DriveAxis", "CuttingLoad"}
    machine : Machine
    cls : type of Component
        The component class (only its declared parameters are kept).
    """
    if kind == "NCKernel":
        helper = _twin_helper("nck_parameters")
        return dict(helper(machine)) if helper else _nck_parameters(machine, cls)
    if kind == "MCU":
        helper = _twin_helper("mcu_parameters")
        return dict(helper(machine)) if helper else _mcu_parameters(machine, cls)
    if kind == "DriveAxis":
        helper = _twin_helper("drive_parameters")
        return dict(helper(machine, "x")) if helper else _drive_parameters(machine, cls)
    if kind == "CuttingLoad":
        return _cutting_parameters(machine, cls)
    raise FMUError(f"unknown component kind {kind!r}; expected one of {sorted(COMPONENTS)}")


@dataclass(frozen=True)
class ComponentSpec:
    """Where a twin component class lives."""

    module: str
    class_name: str

    def load(self) -> type[Component]:
        """Import the class.

        Raises
        ------
        FMUError
            The module does not import (e.g. not written yet).
        """
        try:
            module = importlib.import_module(self.module)
        except ImportError as exc:
            raise FMUError(f"cannot export {self.class_name}: module {self.module} does not import ({exc})") from None
        cls = getattr(module, self.class_name, None)
        if cls is None:
            raise FMUError(f"cannot export {self.class_name}: {self.module} has no class {self.class_name}")
        return cls


#: The twin's components, in the order :func:`build_fmus` builds them.
COMPONENTS: dict[str, ComponentSpec] = {
    "NCKernel": ComponentSpec("fmus_src.nck.component", "NCKernel"),
    "MCU": ComponentSpec("fmus_src.servo.mcu", "MCU"),
    "DriveAxis": ComponentSpec("fmus_src.servo.drive", "DriveAxis"),
    "CuttingLoad": ComponentSpec("fmus_src.cutting.component", "CuttingLoad"),
}


def available_components() -> list[str]:
    """Names of the entries of :data:`COMPONENTS` whose class imports cleanly."""
    out = []
    for name, spec in COMPONENTS.items():
        try:
            spec.load()
        except FMUError:
            continue
        out.append(name)
    return out


# ----------------------------------------------------------------------------- one FMU
def _plain(value: object) -> object:
    if isinstance(value, str):
        return value
    arr = np.asarray(value)
    if arr.ndim != 0:
        raise FMUError(f"start value {value!r} must be a scalar (the FMU has batch 1)")
    return arr.item()


def _script(cls: type[Component], model_name: str, start_values: Mapping[str, object], description: str) -> str:
    lines = [
        f'"""FMU script generated by cnctwin (orchestrator.fmu.build) for {cls.__module__}.{cls.__qualname__}."""',
        "import fmus_src.fmu.slave as _slave",
        f"import {cls.__module__} as _component_module",
        "",
        "",
        f"class {model_name}(_slave.ComponentSlave):",
        f"    description = {description!r}",
        f"    component_class = _component_module.{cls.__qualname__}",
        f"    start_values = {dict(start_values)!r}",
        "",
        "",
        "# pythonfmu 0.7.0 releases one reference to this namespace per fmi2Instantiate that it does not own;",
        "# see fmus_src.fmu.slave.compensate_namespace_release",
        "_NAMESPACE_PINS = [globals()] * _slave.NAMESPACE_MARGIN",
        "",
    ]
    return "\n".join(lines)


def _module_file(cls: type[Component]) -> Path | None:
    """Source file of ``cls`` when it lives outside ``fmus_src`` (must then be shipped too)."""
    package_dir = Path(fmus_src.__file__).resolve().parent
    source = Path(inspect.getfile(cls)).resolve()
    if package_dir in source.parents:
        return None
    if "." in cls.__module__:
        raise FMUError(
            f"cannot ship {cls.__module__}.{cls.__qualname__}: components outside fmus_src must be top-level modules"
        )
    return source


def build_fmu(
    component_class: type[Component],
    out_dir: str | Path,
    start_values: Mapping[str, object] | None = None,
    model_name: str | None = None,
) -> Path:
    """Build one FMI 2.0 co-simulation FMU around a component class.

    Parameters
    ----------
    component_class : type of Component
        The class to wrap (batch 1). Classes outside ``fmus_src`` must live in
        a top-level module, which is shipped next to the script.
    out_dir : str or Path
        Folder for ``<model_name>.fmu`` (created if missing).
    start_values : Mapping[str, object], optional
        Parameter values (SI) baked in as FMU start values.
    model_name : str, optional
        Model identifier and file stem; the class name by default.

    Returns
    -------
    Path
        The FMU file.

    Raises
    ------
    FMUError
        Unknown parameter names, non-scalar start values, pythonfmu failure.
    """
    model_name = model_name or component_class.__name__
    if not model_name.isidentifier():
        raise FMUError(f"model name {model_name!r} must be an identifier")
    values = {k: _plain(v) for k, v in (start_values or {}).items()}
    # constructing the component validates the parameter names (ComponentError is a CncTwinError)
    variables = component_class(name=model_name, batch=1, **values).declared_variables()
    doc = (inspect.getdoc(component_class) or model_name).splitlines()[0]
    digest = hashlib.sha1(repr((component_class.__module__, model_name, sorted(values.items()))).encode()).hexdigest()[:10]
    module_name = f"cnctwin_{model_name.lower()}_{digest}"
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    project_files = [Path(fmus_src.__file__).resolve().parent]
    extra = _module_file(component_class)
    if extra is not None:
        project_files.append(extra)
    with tempfile.TemporaryDirectory(prefix="cnctwin_fmu_") as tmp:
        script = Path(tmp) / f"{module_name}.py"
        script.write_text(_script(component_class, model_name, values, doc), encoding="utf-8")
        saved_path = list(sys.path)
        try:
            fmu = Path(FmuBuilder.build_FMU(script, dest=out_dir / f"{model_name}.fmu", project_files=project_files))
        finally:
            sys.path[:] = saved_path
            sys.modules.pop(module_name, None)
    with zipfile.ZipFile(fmu) as zf:
        xml = zf.read("modelDescription.xml")
        names = zf.namelist()
    _strip_check(fmu, names)
    rewrite_member(fmu, "modelDescription.xml", annotate_model_description(xml, variables))
    return fmu


def _strip_check(fmu: Path, names: Sequence[str]) -> None:
    if "resources/fmus_src/component.py" not in names:
        raise FMUError(f"{fmu}: the fmus_src package was not packed into resources/")


# ----------------------------------------------------------------------------- all FMUs
def build_fmus(
    out_dir: str | Path = DEFAULT_OUT_DIR,
    machine: str | Path | Machine = "default",
    components: Sequence[str] | None = None,
) -> list[Path]:
    """Build one FMU per twin component with the machine file's values as start values.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (default ``models/fmus``).
    machine : str, Path or Machine
        Machine parameter set (name, TOML path or loaded).
    components : sequence of str, optional
        Subset of :data:`COMPONENTS` (default: all four).

    Returns
    -------
    list of Path
        The FMU files, in the order of ``components``.

    Raises
    ------
    FMUError
        Unknown component name, or a component class that does not import.
    MachineFileError
        Bad machine file.
    """
    machine = machine if isinstance(machine, Machine) else load_machine(machine)
    names = list(components) if components is not None else list(COMPONENTS)
    unknown = [n for n in names if n not in COMPONENTS]
    if unknown:
        raise FMUError(f"unknown component(s) {unknown}; expected some of {list(COMPONENTS)}")
    paths = []
    for name in names:
        cls = COMPONENTS[name].load()
        paths.append(build_fmu(cls, out_dir, machine_parameters(name, machine, cls), model_name=name))
    return paths
