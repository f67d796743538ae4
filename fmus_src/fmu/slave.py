"""Generic pythonfmu adapter: one :class:`Component` (batch 1) behind ``Fmi2Slave``.

Mapping of the FMI 2.0 co-simulation calls (as pythonfmu forwards them)::

    fmi2Instantiate            ComponentSlave(instance_name=..., resources=...)
                               -> component_class(instance_name, batch=1, **start_values)
    fmi2SetupExperiment        setup_experiment(start_time, ...)   (remembers t0)
    fmi2Set*/fmi2Get*          getters/setters on component.values[name][0]
    fmi2ExitInitializationMode component.setup(t0)
    fmi2DoStep                 component.do_step(t, h)
    fmi2Terminate              component.terminate()

Every declared :class:`~fmus_src.component.Variable` becomes a scalar
variable with the same name, causality and start value. Variabilities are
chosen so that the model description is valid FMI 2.0: parameters are
``fixed``; Real inputs/outputs are ``continuous``; Integer, Boolean and
String inputs/outputs are ``discrete``. Outputs are ``initial="calculated"``
(they are computed by ``setup``); units and ``<InitialUnknowns>`` are added
to ``modelDescription.xml`` by the builder (:mod:`orchestrator.fmu.build`),
because pythonfmu writes neither.

This module imports pythonfmu, which the builder ships inside each FMU.
"""
from __future__ import annotations

import sys
from typing import Any, Callable, ClassVar, Mapping

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real, String
from pythonfmu.enums import Fmi2Status

from ..component import Component, Variable
from ..errors import CncTwinError

_SCALAR_TYPES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}
_CAUSALITY = {
    "parameter": Fmi2Causality.parameter,
    "input": Fmi2Causality.input,
    "output": Fmi2Causality.output,
}
_PYTHON_TYPES: dict[str, Callable[[Any], Any]] = {"Real": float, "Integer": int, "Boolean": bool, "String": str}

#: Extra references to the namespaces of FMU script modules (see :func:`compensate_namespace_release`).
_PINNED_NAMESPACES: list[dict] = []

#: References to a script module's namespace taken when it is first imported (safety margin).
NAMESPACE_MARGIN = 8


def compensate_namespace_release(module_name: str) -> None:
    """Give back the reference pythonfmu 0.7.0 takes from an FMU script's namespace.

    pythonfmu 0.7.0's ``findClass`` (PySlaveInstance.cpp) calls
    ``Py_DECREF`` on the *borrowed* ``PyModule_GetDict`` of the script module
    at every ``fmi2Instantiate``. Without compensation the namespace is freed
    after the first instantiation and the second one crashes the process.
    The generated scripts hold :data:`NAMESPACE_MARGIN` references from
    import time; every :class:`ComponentSlave` construction (which directly
    follows ``findClass``) adds one back here.
    """
    module = sys.modules.get(module_name)
    if module is not None:
        _PINNED_NAMESPACES.append(vars(module))


def fmi_variability(var: Variable) -> Fmi2Variability:
    """FMI 2.0 variability of a component variable.

    Parameters
    ----------
    var : Variable
        The declaration.

    Returns
    -------
    Fmi2Variability
        ``fixed`` for parameters, ``continuous`` for Real inputs/outputs,
        ``discrete`` for Integer/Boolean/String inputs/outputs.
    """
    if var.causality == "parameter":
        return Fmi2Variability.fixed
    return Fmi2Variability.continuous if var.type == "Real" else Fmi2Variability.discrete


class ComponentSlave(Fmi2Slave):
    """pythonfmu slave around one component instance with batch 1.

    Subclasses set :attr:`component_class` (and optionally
    :attr:`start_values`, the parameter values baked in as FMU start
    values). The FMU instance name becomes the component name.

    Attributes
    ----------
    component_class : type of Component
        The wrapped component class.
    start_values : Mapping[str, object]
        Parameter values (SI) passed to the component constructor; they
        become the ``start`` attributes of the FMU parameters.
    component : Component
        The wrapped instance (batch 1).
    """

    component_class: ClassVar[type[Component]]
    start_values: ClassVar[Mapping[str, object]] = {}

    def __init__(self, **kwargs: Any) -> None:
        compensate_namespace_release(type(self).__module__)
        super().__init__(**kwargs)
        self.component = self.component_class(name=self.instance_name, batch=1, **dict(self.start_values))
        self._t0 = 0.0
        self._failure: str | None = None
        for var in self.component.declared_variables():
            self.register_variable(self._scalar_variable(var), nested=False)

    # ------------------------------------------------------------------ registration
    def _getter(self, var: Variable) -> Callable[[], Any]:
        values = self.component.values
        name = var.name
        if var.type == "String":
            return lambda: values[name]
        convert = _PYTHON_TYPES[var.type]
        return lambda: convert(values[name][0])

    def _setter(self, var: Variable) -> Callable[[Any], None] | None:
        if var.causality == "output":
            return None
        component = self.component
        name = var.name
        if var.causality == "parameter" or var.type == "String":
            # goes through Component.set: type checks, "parameters only before setup"
            return lambda value: component.set(name, value)
        values = component.values
        convert = _PYTHON_TYPES[var.type]

        def set_input(value: Any) -> None:
            values[name][0] = convert(value)

        return set_input

    def _scalar_variable(self, var: Variable) -> Real | Integer | Boolean | String:
        cls = _SCALAR_TYPES[var.type]
        return cls(
            var.name,
            causality=_CAUSALITY[var.causality],
            variability=fmi_variability(var),
            description=var.description or None,
            getter=self._getter(var),
            setter=self._setter(var),
        )

    # ------------------------------------------------------------------ FMI calls
    def setup_experiment(self, start_time: float, stop_time: float | None = None, tolerance: float | None = None) -> None:
        """fmi2SetupExperiment: remember the start time for :meth:`exit_initialization_mode`."""
        self._t0 = float(start_time)

    def exit_initialization_mode(self) -> None:
        """fmi2ExitInitializationMode: ``component.setup(t0)`` (outputs valid at t0).

        pythonfmu 0.7 turns every Python exception into fmi2Fatal, after
        which not even fmi2FreeInstance may be called (and pythonfmu crashes
        if it is). A :class:`~fmus_src.errors.CncTwinError` from ``setup``
        (bad parameter, missing program file) is therefore logged with
        status error and remembered; the first ``do_step`` then returns
        fmi2Discard, so the importer ends the run with the logged message.
        """
        try:
            self.component.setup(self._t0)
        except CncTwinError as exc:
            self._failure = f"{type(exc).__name__} in setup: {exc}"
            self.log(self._failure, Fmi2Status.error)

    def do_step(self, current_time: float, step_size: float) -> bool:
        """fmi2DoStep: ``component.do_step(t, h)``.

        A :class:`~fmus_src.errors.CncTwinError` (a modelling failure the
        component reports on purpose) is logged with status error and the
        step returns False, which pythonfmu reports as fmi2Discard; the
        importer ends the run with the logged message. Any other exception is
        a bug and pythonfmu turns it into fmi2Fatal.
        """
        if self._failure is not None:
            self.log(self._failure, Fmi2Status.error)
            return False
        try:
            self.component.do_step(float(current_time), float(step_size))
        except CncTwinError as exc:
            self.log(f"{type(exc).__name__}: {exc}", Fmi2Status.error)
            return False
        return True

    def terminate(self) -> None:
        """fmi2Terminate: ``component.terminate()``."""
        if self._failure is None:
            self.component.terminate()
