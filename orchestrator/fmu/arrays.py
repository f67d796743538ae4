"""FMI 3.0 array variables (``<Dimension>``): their shape and the scalar elements the twin exposes.

An array variable ``A`` of shape ``(2, 3)`` is exposed as six scalar signals
with FMI's structured names ``A[1,1]``, ``A[1,2]``, ... ``A[2,3]`` (1-based,
row-major: the last index runs fastest, the order in which FMI 3.0 serialises
an array's values, FMI 3.0 §2.4.7.8 and §2.2.6.1). Each element is one value of
one ``fmi3Get<Type>``/``fmi3Set<Type>`` call on the array's value reference
with ``nValues`` = the element count.

Dimensions given by ``start`` are fixed. A dimension given by
``valueReference`` names a structural parameter (or a constant); its value
is the parameter's ``start`` (the shape fmpy computes) and is checked against
the FMU after instantiation (:func:`dimension_problem`). Since the twin
never enters configuration or reconfiguration mode, such a parameter cannot
change afterwards; one declared ``variability="tunable"`` (changeable in
reconfiguration mode) is refused all the same (:func:`shape_of`).

FMI 2.0 has no arrays: its ``a[1]`` is a plain scalar with that name.
"""
from __future__ import annotations

import re
from typing import Any, Iterable, Sequence

import numpy as np
from fmpy.model_description import ModelDescription, ScalarVariable

from .errors import FMUError

#: A structured element name: ``name[1]``, ``name[2,3]`` (1-based indices, no spaces).
ELEMENT = re.compile(r"(?P<base>.+)\[(?P<index>[0-9]+(?:,[0-9]+)*)\]")


def parse_element(name: str) -> tuple[str, tuple[int, ...]] | None:
    """``("A", (2, 3))`` for ``"A[2,3]"`` (1-based, as written), None for a name without an index."""
    found = ELEMENT.fullmatch(name)
    if found is None:
        return None
    return found["base"], tuple(int(i) for i in found["index"].split(","))


def element_name(base: str, index: Sequence[int]) -> str:
    """``"A[2,3]"`` for ``base = "A"`` and the 1-based ``index = (2, 3)``."""
    return f"{base}[{','.join(str(int(i)) for i in index)}]"


def element_names(base: str, shape: Sequence[int]) -> list[str]:
    """Names of all elements of an array of ``shape``, row-major (``A[1,1]``, ``A[1,2]``, ...)."""
    return [element_name(base, [i + 1 for i in index]) for index in np.ndindex(*shape)]


def is_array(variable: ScalarVariable) -> bool:
    """Whether an FMI 3.0 variable has ``<Dimension>`` elements."""
    return bool(getattr(variable, "dimensions", None))


def shape_of(variable: ScalarVariable, md: ModelDescription, where: str) -> tuple[int, ...]:
    """The shape of an array variable (fixed ``start`` dimensions and structural parameters' start values).

    Raises
    ------
    FMUError
        A dimension that names no variable, a variable without an integer
        ``start``, or a ``tunable`` structural parameter (its value could change
        in reconfiguration mode; only fixed dimensions are supported).
    """
    by_vr = {int(v.valueReference): v for v in md.modelVariables if getattr(v, "alias", None) is None}
    shape = []
    for d in variable.dimensions:
        if d.start is not None:
            size = int(d.start)
        else:
            holder = by_vr.get(int(d.valueReference)) if d.valueReference is not None else None
            if holder is None:
                raise FMUError(f"{where}: modelDescription.xml: array {variable.name!r}: <Dimension "
                               f"valueReference={d.valueReference}> names no variable; expected a structural "
                               "parameter", path=where)
            if holder.variability == "tunable":
                raise FMUError(f"{where}: array {variable.name!r}: its dimension is the tunable structural parameter "
                               f"{holder.name!r}, which may change in reconfiguration mode; only dimensions fixed "
                               "after instantiation (a start, a fixed structural parameter or a constant) are "
                               "supported", path=where)
            try:
                size = int(holder.start)
            except (TypeError, ValueError):
                raise FMUError(f"{where}: modelDescription.xml: array {variable.name!r}: its dimension "
                               f"{holder.name!r} has start={holder.start!r}; expected an integer",
                               path=where) from None
        if size < 0:
            raise FMUError(f"{where}: modelDescription.xml: array {variable.name!r}: dimension {size} is negative",
                           path=where)
        shape.append(size)
    return tuple(shape)


def dimension_holders(variable: ScalarVariable, md: ModelDescription) -> list[tuple[int, ScalarVariable]]:
    """(axis, variable) of each dimension of ``variable`` given by a structural parameter or constant."""
    by_vr = {int(v.valueReference): v for v in md.modelVariables if getattr(v, "alias", None) is None}
    return [(axis, by_vr[int(d.valueReference)]) for axis, d in enumerate(variable.dimensions)
            if d.start is None and d.valueReference is not None and int(d.valueReference) in by_vr]


def start_values(variable: ScalarVariable, size: int, where: str) -> list[str | None]:
    """The ``start`` of each element of an array variable (row-major), None for each when it has none.

    FMI 3.0 writes an array's start values as one space-separated list; a
    single value is taken for every element.

    Raises
    ------
    FMUError
        A start list whose length is neither 1 nor the element count.
    """
    raw = variable.start
    if raw is None or str(raw).strip() == "":
        return [None] * size
    if variable.type == "String":
        return [str(raw)] * size  # fmpy keeps the first <Start value=...> only
    parts = str(raw).split()
    if len(parts) == 1:
        return parts * size
    if len(parts) != size:
        raise FMUError(f"{where}: modelDescription.xml: array {variable.name!r}: start has {len(parts)} values; "
                       f"expected {size} (its shape) or 1", path=where)
    return parts


def arrays_among(names: Iterable[str]) -> dict[str, tuple[int, ...]]:
    """The arrays whose elements are among ``names``, with their shapes (the largest index on each axis)."""
    out: dict[str, tuple[int, ...]] = {}
    for name in names:
        parsed = parse_element(name)
        if parsed is None:
            continue
        base, index = parsed
        seen = out.get(base)
        if seen is None:
            out[base] = index
        elif len(seen) == len(index):
            out[base] = tuple(max(a, b) for a, b in zip(seen, index))
    return out


def shape_text(shape: Sequence[int]) -> str:
    """``"3x3"`` for ``(3, 3)``, ``"3"`` for ``(3,)``."""
    return "x".join(str(n) for n in shape)


def bad_element_reason(name: str, arrays: dict[str, tuple[int, ...]]) -> str | None:
    """Why ``name`` is not an element of an exposed array (``u[4]`` of a 3-array), None when it names none."""
    parsed = parse_element(name)
    base = parsed[0] if parsed is not None else name
    shape = arrays.get(base)
    if shape is None:
        return None
    first, last = element_name(base, [1] * len(shape)), element_name(base, shape)
    span = f"elements {first} .. {last}"
    if parsed is None:
        return f"{base!r} is an array of shape {shape_text(shape)} ({span}); name an element"
    index = parsed[1]
    if len(index) != len(shape):
        return (f"{base!r} is an array of shape {shape_text(shape)} ({span}): {name!r} has {len(index)} "
                f"index(es), expected {len(shape)}")
    return f"{base!r} is an array of shape {shape_text(shape)} ({span}): {name!r} is outside it"


def expand(base: str, value: Any, names: list[str], shape: tuple[int, ...], where: str) -> dict[str, Any]:
    """A whole-array value (nested lists or an ndarray of ``shape``, or flat row-major) by element name.

    Raises
    ------
    FMUError
        A value of another size.
    """
    arr = np.asarray(value)
    if arr.shape != tuple(shape) and arr.size != len(names):
        raise FMUError(f"{where}: {base!r} is an array of shape {shape_text(shape)}; got a value of shape "
                       f"{arr.shape}")
    return dict(zip(names, arr.reshape(-1).tolist()))


def dimension_problem(variable: ScalarVariable, shape: tuple[int, ...], holders: list[tuple[int, ScalarVariable]],
                      actual: list[int]) -> str | None:
    """What is wrong when the structural parameters read from the FMU (``actual``) differ from ``shape``."""
    wrong = [f"{holder.name} = {value} (expected {shape[axis]})" for (axis, holder), value in zip(holders, actual)
             if int(value) != shape[axis]]
    if not wrong:
        return None
    return (f"array {variable.name!r}: the FMU reports its dimension(s) {', '.join(wrong)} after instantiation, "
            f"not the start value(s) of the model description; only dimensions fixed at their start are supported")


def complete_arrays(names: Iterable[str]) -> dict[str, tuple[tuple[int, ...], list[str]]]:
    """The arrays all of whose elements are among ``names``: base name -> (shape, element names, row-major).

    How a whole array is addressed by its name (``set("A", matrix)``) where
    only its elements are variables.
    """
    present = set(names)
    out = {}
    for base, shape in arrays_among(present).items():
        elements = element_names(base, shape)
        if base not in present and all(e in present for e in elements):
            out[base] = (shape, elements)
    return out
