"""The component protocol shared by native models and FMUs.

Every model of the twin (NC kernel, MCU, drive axis, cutting load) is a
:class:`Component`. The protocol follows FMI 2.0 co-simulation in spelling and
semantics, with Python names:

========================  =====================================
FMI 2.0                   here
========================  =====================================
fmi2Instantiate           ``Component(name, batch=B, **params)``
fmi2SetupExperiment +     ``setup(t0)``
Enter/ExitInitialization
fmi2SetReal/Integer/...   ``set(name, value)``
fmi2DoStep                ``do_step(t, h)``
fmi2GetReal/Integer/...   ``get(name)``
fmi2Reset                 ``reset()``
fmi2Terminate             ``terminate()``
========================  =====================================

Native components carry a *batch* dimension: one instance holds ``B``
independent copies of the model and every numeric variable is an array of
shape ``(B,)``. A whole GA population then advances in one ``do_step`` call.
``B = 1`` is the ordinary case.

This module depends on numpy only, so that the FMU wrappers in ``fmus_src``
can ship it inside an FMU.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Literal, Mapping

import numpy as np

from .errors import CncTwinError

if TYPE_CHECKING:  # only for the annotation: this module needs numpy alone at run time
    from .units import UnitDefinition

Causality = Literal["parameter", "input", "output"]
VariableType = Literal["Real", "Integer", "Boolean", "String"]

_NUMPY_TYPES: dict[str, type] = {"Real": np.float64, "Integer": np.int64, "Boolean": np.bool_}
#: An array element's structured name: an identifier and 1-based indices (``u[1]``, ``A[2,3]``).
_ELEMENT_NAME = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)\[[1-9][0-9]*(?:,[1-9][0-9]*)*\]")


def is_element_name(name: str) -> bool:
    """Whether ``name`` is an array element's structured name (``"u[1]"``, ``"A[2,3]"``; indices from 1)."""
    found = _ELEMENT_NAME.fullmatch(name)
    return found is not None and found.group(1).isidentifier()


class ComponentError(CncTwinError):
    """A component was used against the protocol (unknown variable, wrong state, bad value)."""


@dataclass(frozen=True)
class Variable:
    """Declaration of one variable of a component.

    Parameters
    ----------
    name : str
        Python identifier, unique within the component (e.g. ``"x_ref"``), or
        the structured name of an element of an FMU's array variable: an
        identifier with 1-based indices (``"u[1]"``, ``"A[2,3]"``).
    causality : {"parameter", "input", "output"}
        FMI 2.0 causality.
    unit : str or None
        Unit symbol (see :mod:`fmus_src.units`); ``"1"`` for dimensionless.
        SI inside the physics. None: no unit declared (a foreign FMU's
        variable without ``unit``): unknown, which is not dimensionless;
        connected and recorded unchanged.
    start : float or str
        Start value; for parameters the default value.
    description : str
        One line for humans and for ``modelDescription.xml``.
    type : {"Real", "Integer", "Boolean", "String"}
        FMI base type. String variables are shared by the whole batch.
    unit_definition : UnitDefinition, optional
        How ``unit`` maps to SI when its source defined it (an FMU's
        ``<UnitDefinitions>``); used to convert units that
        :mod:`fmus_src.units` does not know (``kN``, ``degC``).
    """

    name: str
    causality: Causality
    unit: str | None = "1"
    start: float | str = 0.0
    description: str = ""
    type: VariableType = "Real"
    unit_definition: "UnitDefinition | None" = None

    def __post_init__(self) -> None:
        if not (self.name.isidentifier() or is_element_name(self.name)):
            raise ComponentError(f"variable name {self.name!r} is not an identifier (nor an array element "
                                 "such as 'u[1]' or 'A[2,3]')")
        if self.causality not in ("parameter", "input", "output"):
            raise ComponentError(f"variable {self.name!r}: unknown causality {self.causality!r}")
        if self.type not in ("Real", "Integer", "Boolean", "String"):
            raise ComponentError(f"variable {self.name!r}: unknown type {self.type!r}")


class Component:
    """Base class of native components (batch-capable).

    Subclasses declare ``variables`` (a tuple of :class:`Variable`) and
    implement ``_setup(t0)`` (compute initial outputs from parameters and
    inputs) and ``_do_step(t, h)`` (advance from ``t`` to ``t + h`` and
    write outputs valid at ``t + h``). They read and write their variables
    through ``self.values[name]``, arrays of shape ``(batch,)``, always
    **in place** (``self.values["x"][...] = ...``): the master binds to these
    arrays once.

    A component may substep internally: ``do_step(t, h)`` with ``h`` larger
    than its own loop period runs several internal periods.

    **Per-member failures.** When some batch members cannot go on (an
    integrator error, a servo alarm) but the others can, the component calls
    :meth:`fail_members` with a mask and a reason instead of raising. From
    then on the real-valued outputs of those members are NaN after every step
    (they never look good, and a component that freezes them stops spending
    effort on them); a master collects the reasons with
    :meth:`take_failures`. When every member has failed there is nothing left
    to compute and :meth:`fail_members` raises the error, so a single run
    (``B = 1``) still ends with a clear exception.

    Parameters
    ----------
    name : str
        Instance name, unique within a system (e.g. ``"x_drive"``).
    batch : int
        Number of independent copies ``B`` held by this instance.
    **parameters
        Values for variables of causality ``parameter``; scalars are
        broadcast to ``(B,)``. Unknown names raise :class:`ComponentError`.
    """

    variables: ClassVar[tuple[Variable, ...]] = ()

    def __init__(self, name: str = "", batch: int = 1, **parameters: object) -> None:
        if int(batch) != batch or batch < 1:
            raise ComponentError(f"batch must be a positive integer, got {batch!r}")
        self.name = name or type(self).__name__
        self.batch = int(batch)
        self._by_name: dict[str, Variable] = {v.name: v for v in self.declared_variables()}
        if len(self._by_name) != len(self.declared_variables()):
            raise ComponentError(f"{self.name}: duplicate variable names")
        unknown = [k for k in parameters if k not in self._by_name or self._by_name[k].causality != "parameter"]
        if unknown:
            known = sorted(v.name for v in self._by_name.values() if v.causality == "parameter")
            raise ComponentError(f"{self.name}: unknown parameter(s) {unknown}; expected some of {known}")
        self._init_parameters: dict[str, object] = dict(parameters)
        self.values: dict[str, np.ndarray | str] = {}
        self.state = "instantiated"
        self._load_start_values()
        self._clear_failures()

    # ------------------------------------------------------------------ declarations
    def declared_variables(self) -> tuple[Variable, ...]:
        """Variables of this instance (class-level declaration by default)."""
        return self.variables

    def variable(self, name: str) -> Variable:
        """Return the declaration of variable ``name``."""
        try:
            return self._by_name[name]
        except KeyError:
            raise ComponentError(
                f"{self.name}: no variable {name!r}; it has {sorted(self._by_name)}"
            ) from None

    def names(self, causality: Causality) -> list[str]:
        """Names of all variables of one causality, in declaration order."""
        return [v.name for v in self.declared_variables() if v.causality == causality]

    # ------------------------------------------------------------------ values
    def _coerce(self, var: Variable, value: object) -> np.ndarray | str:
        if var.type == "String":
            if not isinstance(value, str):
                raise ComponentError(f"{self.name}.{var.name}: expected a string, got {type(value).__name__}")
            return value
        arr = np.asarray(value, dtype=_NUMPY_TYPES[var.type])
        if arr.ndim == 0:
            return np.full(self.batch, arr, dtype=arr.dtype)
        if arr.shape != (self.batch,):
            raise ComponentError(
                f"{self.name}.{var.name}: expected a scalar or shape ({self.batch},), got {arr.shape}"
            )
        return arr.copy()

    def _load_start_values(self) -> None:
        for var in self.declared_variables():
            self.values[var.name] = self._coerce(var, var.start)
        for key, value in self._init_parameters.items():
            self.values[key] = self._coerce(self._by_name[key], value)

    def set(self, name: str, value: object) -> None:
        """Set a parameter (before ``setup``) or an input (any time).

        Parameters
        ----------
        name : str
            Variable name.
        value : scalar, array of shape (B,), or str
            New value; scalars are broadcast over the batch.
        """
        var = self.variable(name)
        if var.causality == "output":
            raise ComponentError(f"{self.name}.{name} is an output and cannot be set")
        if var.causality == "parameter" and self.state != "instantiated":
            raise ComponentError(f"{self.name}.{name} is a parameter; set it before setup()")
        new = self._coerce(var, value)
        if isinstance(new, str):
            self.values[name] = new
        else:
            self.values[name][...] = new  # type: ignore[index]

    def get(self, name: str) -> np.ndarray | str:
        """Return the current value of a variable (a copy, shape ``(B,)``, or a str)."""
        value = self.values[self.variable(name).name]
        return value if isinstance(value, str) else value.copy()

    # ------------------------------------------------------------------ lifecycle
    def setup(self, t0: float = 0.0) -> None:
        """Set up the experiment at ``t0`` and initialise (outputs valid at ``t0``)."""
        if self.state != "instantiated":
            raise ComponentError(f"{self.name}: setup() called in state {self.state!r}")
        self.t0 = float(t0)
        self._setup(self.t0)
        self.state = "initialized"

    def do_step(self, t: float, h: float) -> None:
        """Advance from ``t`` to ``t + h``; outputs are then valid at ``t + h``."""
        if self.state != "initialized":
            raise ComponentError(f"{self.name}: do_step() called in state {self.state!r}")
        if not h > 0.0:
            raise ComponentError(f"{self.name}: step size must be positive, got {h!r}")
        self._t_step = t
        self._do_step(t, h)
        if self._failed_outputs:
            self._blank_failed_outputs()

    def reset(self) -> None:
        """Return to the state right after instantiation (parameters kept)."""
        self._load_start_values()
        self._clear_failures()
        self._reset()
        self.state = "instantiated"

    # ------------------------------------------------------------------ per-member failures
    def _clear_failures(self) -> None:
        self.failed_members = np.zeros(self.batch, dtype=bool)
        self._pending_failures: list[tuple[np.ndarray, str, float]] = []
        self._failed_outputs: list[np.ndarray] = []
        self._t_step = float("nan")

    def fail_members(self, mask: np.ndarray, reason: str, error: type[CncTwinError] = ComponentError) -> None:
        """Mark batch members as failed; the others carry on.

        Parameters
        ----------
        mask : ndarray of bool, shape (B,)
            Members that fail now (members that already failed are ignored).
        reason : str
            What went wrong, starting with the component name (e.g.
            ``"mcu: SV0411 excess error in motion on X ..."``).
        error : type of CncTwinError
            Raised (with ``reason``) when no member is left.

        Raises
        ------
        error
            When every member has failed.
        """
        new = np.asarray(mask, dtype=bool) & ~self.failed_members
        if not new.any():
            return
        self.failed_members |= new
        self._pending_failures.append((np.flatnonzero(new), reason, self._t_step))
        self._failed_outputs = [arr for v in self.declared_variables() if v.causality == "output"
                                for arr in (self.values[v.name],) if getattr(arr, "dtype", None) == np.float64]
        if self.failed_members.all():
            more = "" if self.batch == 1 else f" (all {self.batch} members have failed)"
            raise error(f"{reason}{more}")

    def take_failures(self) -> list[tuple[np.ndarray, str, float]]:
        """Failures recorded since the last call, and clear them.

        Returns
        -------
        list of (members, reason, t)
            ``members``: int array of batch indices; ``reason``: text;
            ``t``: start of the step in which they failed, s (NaN outside a step).
        """
        out, self._pending_failures = self._pending_failures, []
        return out

    def _blank_failed_outputs(self) -> None:
        """Real outputs of failed members are NaN (called after every step once a member failed)."""
        for arr in self._failed_outputs:
            arr[self.failed_members] = np.nan

    def terminate(self) -> None:
        """End the simulation; the instance can no longer be stepped."""
        self._terminate()
        self.state = "terminated"

    # ------------------------------------------------------------------ hooks
    def _setup(self, t0: float) -> None:
        raise NotImplementedError

    def _do_step(self, t: float, h: float) -> None:
        raise NotImplementedError

    def _reset(self) -> None:
        """Clear internal state (override when the component has any)."""

    def _terminate(self) -> None:
        """Release resources (override when needed)."""

    def parameter_values(self) -> Mapping[str, np.ndarray | str]:
        """Current parameter values by name."""
        return {n: self.values[n] for n in self.names("parameter")}
