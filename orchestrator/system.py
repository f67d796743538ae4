"""System description: components wired by variable name.

A :class:`System` holds named components (native or FMU-backed, anything that
follows :class:`fmus_src.component.Component`'s protocol) and connections
``"source_component.output" -> "target_component.input"``. Units are checked
when a connection is made; compatible units of different scale (mm and m)
are converted by a factor carried on the connection, units with an offset
(``degC`` and ``K``, defined by an FMU's ``<UnitDefinitions>``) by a factor
and an offset. A variable that declares no unit (``Variable.unit is None``)
connects to anything unchanged.

Each component has a *rate*: how many times it is stepped per communication
step (a servo loop at 250 µs inside a 1 ms communication step has rate 4).
Components of the same rate exchange values at their own, finer step.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Iterable, Protocol

import numpy as np

from fmus_src.component import Variable
from fmus_src.units import UnitError, conversion

from .errors import SystemDescriptionError

log = logging.getLogger(__name__)


def unit_conversion(source: Variable, target: Variable, what: str) -> tuple[float, float]:
    """Affine map ``(factor, offset)``: value in ``target``'s unit = factor × value in ``source``'s + offset.

    * The same symbol, known or not: ``(1, 0)``. A foreign FMU may declare
      units this project does not know; a value can still be recorded in
      its own unit and passed to a variable of the same unit.
    * No declared unit on either side (``unit is None``): ``(1, 0)``; an
      undeclared unit is unknown, not dimensionless, so nothing is checked.
    * Otherwise :func:`fmus_src.units.conversion`: units of
      :mod:`fmus_src.units`, else the variables' own unit definitions (an
      FMU's ``<UnitDefinitions>``), e.g. ``kN`` → ``N`` is ``(1000, 0)``,
      ``degC`` → ``K`` is ``(1, 273.15)``.

    Parameters
    ----------
    source, target : Variable
        The two declarations.
    what : str
        What is converted, for the message (``"a.y [kV] -> b.u [V]"``).

    Raises
    ------
    SystemDescriptionError
        Different symbols of which one is neither known nor defined, or of different SI base units.
    """
    if source.unit is None or target.unit is None:
        return 1.0, 0.0
    try:
        return conversion(source.unit, target.unit, source.unit_definition, target.unit_definition)
    except UnitError as exc:
        raise SystemDescriptionError(f"{what}: {exc}") from None


def unit_factor(source: str, target: str, what: str) -> float:
    """Factor ``k`` with value in ``target`` = k × value in ``source`` (units without offset).

    The factor-only case of :func:`unit_conversion`, for two unit symbols
    without definitions.

    Raises
    ------
    SystemDescriptionError
        See :func:`unit_conversion`.
    """
    factor, _ = unit_conversion(Variable("a", "output", source), Variable("b", "input", target), what)
    return factor


def unit_text(unit: str | None) -> str:
    """``unit`` for messages: the symbol, or ``"no unit declared"``."""
    return "no unit declared" if unit is None else unit


class ComponentLike(Protocol):
    """What the master needs from a component (native or FMU)."""

    name: str
    batch: int
    values: dict

    def variable(self, name: str) -> Variable: ...
    def setup(self, t0: float = 0.0) -> None: ...
    def do_step(self, t: float, h: float) -> None: ...
    def reset(self) -> None: ...
    def terminate(self) -> None: ...


@dataclass(frozen=True)
class Connection:
    """One wire from an output to an input.

    Attributes
    ----------
    source, target : str
        ``"component.variable"`` of the output and of the input.
    factor, offset : float
        Unit conversion: input value = factor × output value + offset (offset
        0 but for units such as ``degC`` → ``K``).
    """

    source: str
    target: str
    factor: float = 1.0
    offset: float = 0.0

    @property
    def source_component(self) -> str:
        return self.source.split(".", 1)[0]

    @property
    def source_variable(self) -> str:
        return self.source.split(".", 1)[1]

    @property
    def target_component(self) -> str:
        return self.target.split(".", 1)[0]

    @property
    def target_variable(self) -> str:
        return self.target.split(".", 1)[1]


def split_reference(reference: str) -> tuple[str, str]:
    """Split ``"component.variable"`` into its two parts."""
    if reference.count(".") < 1:
        raise SystemDescriptionError(f"{reference!r}: expected 'component.variable'")
    comp, var = reference.split(".", 1)
    return comp, var


class System:
    """Components plus connections by name.

    Examples
    --------
    >>> from orchestrator import System
    >>> system = System("demo")            # doctest: +SKIP
    >>> system.add(nck); system.add(mcu, rate=4)   # doctest: +SKIP
    >>> system.connect("nck.x_ref", "mcu.x_ref")   # doctest: +SKIP
    """

    def __init__(self, name: str = "system") -> None:
        self.name = name
        self.components: dict[str, ComponentLike] = {}
        self.rates: dict[str, int] = {}
        self.connections: list[Connection] = []
        self._order: list[str] | None = None

    # ----------------------------------------------------------------- building
    def add(self, component: ComponentLike, rate: int = 1) -> ComponentLike:
        """Add a component, stepped ``rate`` times per communication step."""
        if component.name in self.components:
            raise SystemDescriptionError(f"{self.name}: a component named {component.name!r} already exists")
        if "." in component.name:
            raise SystemDescriptionError(f"component name {component.name!r} must not contain '.'")
        if int(rate) != rate or rate < 1:
            raise SystemDescriptionError(f"{component.name}: rate must be a positive integer, got {rate!r}")
        if self.components:
            batch = self.batch
            if component.batch != batch:
                raise SystemDescriptionError(
                    f"{component.name}: batch {component.batch} differs from the system's batch {batch}"
                )
        self.components[component.name] = component
        self.rates[component.name] = int(rate)
        return component

    def component(self, name: str) -> ComponentLike:
        """The component called ``name``."""
        try:
            return self.components[name]
        except KeyError:
            raise SystemDescriptionError(
                f"{self.name}: no component {name!r}; it has {sorted(self.components)}"
            ) from None

    def _variable(self, reference: str) -> Variable:
        comp, var = split_reference(reference)
        try:
            return self.component(comp).variable(var)
        except SystemDescriptionError:
            raise
        except Exception as exc:  # the component's own "no such variable" error, any type
            raise SystemDescriptionError(f"{reference}: {exc}") from None

    def connect(self, source: str, target: str) -> Connection:
        """Wire output ``source`` to input ``target`` (``"component.variable"`` each).

        Raises
        ------
        SystemDescriptionError
            Unknown component or variable, wrong causality, incompatible units,
            or an input that is already connected.

        Notes
        -----
        A side without a declared unit passes the value unchanged (factor 1),
        logged once at info level naming both ends.
        """
        src, dst = self._variable(source), self._variable(target)
        if src.causality != "output":
            raise SystemDescriptionError(f"{source} is a {src.causality}, not an output")
        if dst.causality != "input":
            raise SystemDescriptionError(f"{target} is a {dst.causality}, not an input")
        if src.type == "String" or dst.type == "String":
            raise SystemDescriptionError(f"{source} -> {target}: string variables cannot be connected")
        factor, offset = unit_conversion(
            src, dst, f"{source} [{unit_text(src.unit)}] -> {target} [{unit_text(dst.unit)}]")
        for existing in self.connections:
            if existing.target == target:
                raise SystemDescriptionError(f"{target} is already connected to {existing.source}")
            if self._canonical(existing.target) == self._canonical(target):
                raise SystemDescriptionError(f"{target} is an alias of {self._canonical(target)} (one FMU variable), "
                                             f"which {existing.target} already feeds from {existing.source}")
        if (src.unit is None or dst.unit is None) and src.type == "Real":
            log.info("%s: %s [%s] -> %s [%s]: no unit declared on %s; the value is passed unchanged",
                     self.name, source, unit_text(src.unit), target, unit_text(dst.unit),
                     "either side" if src.unit is None and dst.unit is None else
                     ("the source" if src.unit is None else "the target"))
        connection = Connection(source, target, factor, offset)
        self.connections.append(connection)
        return connection

    def _canonical(self, reference: str) -> str:
        """``"component.input"`` of the input that ``reference`` names: an FMU's input alias names another
        (``FMUComponent.canonical``); every other reference names itself."""
        comp, var = split_reference(reference)
        canonical = getattr(self.component(comp), "canonical", None)
        return f"{comp}.{canonical(var)}" if canonical is not None else reference

    def connect_many(self, pairs: Iterable[tuple[str, str]]) -> None:
        """Connect several ``(source, target)`` pairs."""
        for source, target in pairs:
            self.connect(source, target)

    # ----------------------------------------------------------------- queries
    @property
    def batch(self) -> int:
        """Batch size shared by all components (1 for an empty system)."""
        return next(iter(self.components.values())).batch if self.components else 1

    @property
    def substeps(self) -> int:
        """Fine ticks per communication step: the least common multiple of the rates."""
        return math.lcm(*self.rates.values()) if self.rates else 1

    def set_execution_order(self, names: Iterable[str]) -> None:
        """Fix the Gauss–Seidel order explicitly (a permutation of all component names).

        Use it where the signal-flow order is not the physical one, e.g. a
        sampled controller that must read its command of the *current* period
        before the command generator advances.
        """
        order = list(names)
        if sorted(order) != sorted(self.components):
            raise SystemDescriptionError(
                f"{self.name}: execution order {order} must name every component once: {sorted(self.components)}"
            )
        self._order = order

    def execution_order(self) -> list[str]:
        """Order in which components step within a tick (Gauss–Seidel order).

        The explicit order when one was set; otherwise Kahn's topological
        sort of the connection graph, where inside a feedback loop (no
        component free of unmet inputs) the earliest-added component of the
        loop goes first. Ties follow the order of addition.
        """
        if self._order is not None:
            return list(self._order)
        names = list(self.components)
        preds: dict[str, set[str]] = {n: set() for n in names}
        for c in self.connections:
            if c.source_component != c.target_component:
                preds[c.target_component].add(c.source_component)
        done: list[str] = []
        remaining = list(names)
        while remaining:
            ready = [n for n in remaining if preds[n] <= set(done)]
            pick = ready[0] if ready else remaining[0]
            done.append(pick)
            remaining.remove(pick)
        return done

    def unconnected_inputs(self) -> list[str]:
        """Inputs that no connection feeds (they keep their start or set values)."""
        fed = {c.target for c in self.connections}
        out = []
        for name, comp in self.components.items():
            names = comp.names("input") if hasattr(comp, "names") else []
            out.extend(f"{name}.{v}" for v in names if f"{name}.{v}" not in fed)
        return out

    def value(self, reference: str) -> np.ndarray:
        """Current value of ``"component.variable"`` (shape ``(B,)``)."""
        comp, var = split_reference(reference)
        self._variable(reference)
        return np.asarray(self.component(comp).values[var])
