"""Units: SI inside the physics, machinist units at the edge.

A small registry of the units this project uses. Each unit is a factor to its
SI unit and a dimension signature, so that connections between components can
be checked (same dimension) and converted (factor only, no offsets).

Units this registry does not know can still be converted when their source
defines them against the SI base units, as FMI 2.0/3.0 ``<UnitDefinitions>``
and SSP ``<ssc:Units>`` do (:class:`UnitDefinition`: value_SI = factor ×
value + offset, e.g. ``degC``: factor 1, offset 273.15). :func:`conversion`
returns the affine map between two units, from this registry first and from
such definitions otherwise. A variable that declares no unit at all is
*undeclared* (``None``), which is not the dimensionless ``"1"``.

Machine parameter files put the unit in the key name (``screw_lead_mm``,
``rapid_feed_mm_per_min``); :func:`split_unit_suffix` reads it back.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping


class UnitError(ValueError):
    """Unknown unit, or units of different dimension joined together."""


@dataclass(frozen=True)
class Unit:
    """A unit as a factor to SI and a dimension.

    Attributes
    ----------
    symbol : str
        Symbol as written in variable declarations (``"mm/min"``).
    factor : float
        Value in SI = value in this unit × ``factor``.
    dimension : str
        Dimension signature (e.g. ``"L/T"``); units are compatible when equal.
    """

    symbol: str
    factor: float
    dimension: str


_UNITS: dict[str, Unit] = {}


def _register(symbol: str, factor: float, dimension: str, *suffixes: str) -> None:
    _UNITS[symbol] = Unit(symbol, factor, dimension)
    for suffix in suffixes:
        _SUFFIXES[suffix] = symbol


_SUFFIXES: dict[str, str] = {}

_TWO_PI = 2.0 * math.pi
# symbol, factor to SI, dimension, key suffixes used in machine files
_register("1", 1.0, "1", "")
_register("%", 0.01, "1", "percent")
_register("m", 1.0, "L", "m")
_register("mm", 1e-3, "L", "mm")
_register("um", 1e-6, "L", "um")
_register("s", 1.0, "T", "s")
_register("ms", 1e-3, "T", "ms")
_register("min", 60.0, "T", "min")
_register("um/m", 1e-6, "1", "um_per_m")
_register("1/s", 1.0, "1/T", "per_s")
_register("Hz", 1.0, "1/T", "Hz")
_register("m/s", 1.0, "L/T", "m_per_s")
_register("um/min", 1e-6 / 60.0, "L/T", "um_per_min")
_register("mm/s", 1e-3, "L/T", "mm_per_s")
_register("mm/min", 1e-3 / 60.0, "L/T", "mm_per_min")
_register("m/s2", 1.0, "L/T2", "m_per_s2")
_register("mm/s2", 1e-3, "L/T2", "mm_per_s2")
_register("m/s3", 1.0, "L/T3", "m_per_s3")
_register("mm/s3", 1e-3, "L/T3", "mm_per_s3")
_register("rad", 1.0, "A", "rad")
_register("deg", math.pi / 180.0, "A", "deg")
_register("rad/s", 1.0, "A/T", "rad_per_s")
_register("rpm", _TWO_PI / 60.0, "A/T", "rpm")
_register("rad/s2", 1.0, "A/T2", "rad_per_s2")
_register("rpm/s", _TWO_PI / 60.0, "A/T2", "rpm_per_s")
_register("rad/(s.N.m)", 1.0, "A/T.F.L", "rad_per_s_per_Nm")
_register("rpm/N.m", _TWO_PI / 60.0, "A/T.F.L", "rpm_per_Nm")
_register("%/min", 0.01 / 60.0, "1/T", "percent_per_min")
_register("kg", 1.0, "M", "kg")
_register("kg.m2", 1.0, "M.L2", "kg_m2")
_register("N", 1.0, "F", "N")
_register("N/m", 1.0, "F/L", "N_per_m")
_register("N/um", 1e6, "F/L", "N_per_um")
_register("N/mm", 1e3, "F/L", "N_per_mm")
_register("N.s/m", 1.0, "F.T/L", "Ns_per_m")
_register("N/m2", 1.0, "F/L2", "N_per_m2")
_register("N/mm2", 1e6, "F/L2", "N_per_mm2")
_register("N.m", 1.0, "F.L", "Nm")
_register("N.m/A", 1.0, "F.L/I", "Nm_per_A")
_register("W", 1.0, "P", "W")
_register("kW", 1e3, "P", "kW")
_register("A", 1.0, "I", "A")
_register("V", 1.0, "P/I", "V")
_register("K", 1.0, "K", "K")
_register("A/(m/s)", 1.0, "I.T/L", "A_per_m_per_s")
_register("A/m", 1.0, "I/L", "A_per_m")
_register("m3/s", 1.0, "L3/T", "m3_per_s")
_register("mm3/min", 1e-9 / 60.0, "L3/T", "mm3_per_min")
_register("KRW", 1.0, "KRW", "KRW")
_register("KRW/s", 1.0, "KRW/T", "KRW_per_s")


#: SI base units of FMI 2.0/3.0 ``<BaseUnit>`` and SSP ``<ssc:BaseUnit>``, in the schema's order.
BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


@dataclass(frozen=True)
class UnitDefinition:
    """How a unit maps to SI: value_SI = ``factor`` × value + ``offset``.

    The form of an FMI ``<Unit name=...><BaseUnit .../></Unit>`` and of an SSP
    ``<ssc:Unit>``: e.g. ``kN`` is ``kg·m·s⁻²`` with factor 1000, ``degC`` is
    ``K`` with offset 273.15.

    Attributes
    ----------
    name : str
        Unit symbol (``"kN"``).
    exponents : tuple of (str, int)
        Non-zero exponents of the SI base units (:data:`BASE_UNITS`), in that
        order (``(("kg", 1), ("m", 1), ("s", -2))``).
    factor : float
        Scale to SI (1000 for ``kN``).
    offset : float
        Offset to SI, in SI units (273.15 for ``degC``; 0 for almost every unit).
    source : str
        Where it was defined (the FMU or SSP file), for messages; ``""`` for
        this module's own table.
    """

    name: str
    exponents: tuple[tuple[str, int], ...] = ()
    factor: float = 1.0
    offset: float = 0.0
    source: str = ""

    @classmethod
    def from_base(cls, name: str, base: Mapping[str, float], factor: float = 1.0, offset: float = 0.0,
                  source: str = "") -> "UnitDefinition":
        """A definition from base-unit exponents by name (``{"kg": 1, "m": 1, "s": -2}``).

        Raises
        ------
        UnitError
            An exponent of a base unit not in :data:`BASE_UNITS`, or a factor that is not finite and non-zero.
        """
        unknown = sorted(set(base) - set(BASE_UNITS))
        if unknown:
            raise UnitError(f"unit {name!r}{_at(source)}: unknown base unit(s) {unknown}; expected {list(BASE_UNITS)}")
        if not (math.isfinite(factor) and factor != 0.0 and math.isfinite(offset)):
            raise UnitError(f"unit {name!r}{_at(source)}: factor {factor!r} and offset {offset!r} must be finite "
                            "and the factor non-zero")
        exps = tuple((b, int(base[b])) for b in BASE_UNITS if int(base.get(b, 0)) != 0)
        return cls(name, exps, float(factor), float(offset), source)

    @property
    def signature(self) -> str:
        """The exponents as text (``"kg m s-2"``; ``"1"`` when dimensionless)."""
        return " ".join(b if e == 1 else f"{b}{e}" for b, e in self.exponents) or "1"

    def same_as(self, other: "UnitDefinition") -> bool:
        """Same exponents, factor and offset (to 1e-12 relative): the same unit, whatever its name."""
        return (self.exponents == other.exponents and math.isclose(self.factor, other.factor, rel_tol=1e-12)
                and math.isclose(self.offset, other.offset, rel_tol=1e-12, abs_tol=1e-12))


def _at(source: str) -> str:
    return f" (defined in {source})" if source else ""


def unit(symbol: str) -> Unit:
    """Look up a unit by symbol.

    Raises
    ------
    UnitError
        If the symbol is not registered.
    """
    try:
        return _UNITS[symbol]
    except KeyError:
        raise UnitError(f"unknown unit {symbol!r}; known units: {sorted(_UNITS)}") from None


def conversion_factor(source: str, target: str) -> float:
    """Factor ``k`` such that value_in_target = k × value_in_source.

    Raises
    ------
    UnitError
        If the units are unknown or of different dimension.
    """
    a, b = unit(source), unit(target)
    if a.dimension != b.dimension:
        raise UnitError(f"cannot connect {source!r} ({a.dimension}) to {target!r} ({b.dimension})")
    return a.factor / b.factor


def split_unit_suffix(key: str) -> tuple[str, str]:
    """Split a machine-file key into its name and unit symbol.

    The longest registered suffix wins: ``"rapid_feed_mm_per_min"`` →
    ``("rapid_feed", "mm/min")``; a key without a known suffix is
    dimensionless: ``"lookahead_blocks"`` → ``("lookahead_blocks", "1")``.
    """
    best = ""
    for suffix in _SUFFIXES:
        if suffix and key.endswith("_" + suffix) and len(suffix) > len(best):
            best = suffix
    if not best:
        return key, "1"
    return key[: -len(best) - 1], _SUFFIXES[best]


def to_si(value: float, symbol: str) -> float:
    """Convert ``value`` given in ``symbol`` to SI."""
    return value * unit(symbol).factor


def si_symbol(symbol: str) -> str:
    """The SI symbol of the dimension of ``symbol`` (the registered unit with factor 1)."""
    dim = unit(symbol).dimension
    for u in _UNITS.values():
        if u.dimension == dim and u.factor == 1.0:
            return u.symbol
    raise UnitError(f"no SI unit registered for dimension {dim!r}")


_PRIMITIVE_DIMENSIONS: dict[str, dict[str, int]] = {
    "L": {"m": 1}, "T": {"s": 1}, "M": {"kg": 1}, "I": {"A": 1}, "A": {"rad": 1},
    "F": {"kg": 1, "m": 1, "s": -2}, "P": {"kg": 1, "m": 2, "s": -3}, "K": {"K": 1}, "KRW": {},
}


def base_exponents(symbol: str) -> dict[str, int]:
    """SI base-unit exponents of a unit's dimension (``"N.s/m"`` → ``{"kg": 1, "s": -1}``).

    Used to write ``<ssc:BaseUnit>`` elements of SSP files. Currency (KRW)
    has no SI base unit and maps to no exponents.
    """
    dim = unit(symbol).dimension
    out: dict[str, int] = {}
    numerator, _, denominator = dim.partition("/")
    for part, sign in ((numerator, 1), (denominator, -1)):
        for token in filter(None, part.split(".")):
            if token == "1":
                continue
            name = token.rstrip("0123456789")
            power = int(token[len(name):] or 1)
            for base, exp in _PRIMITIVE_DIMENSIONS[name].items():
                out[base] = out.get(base, 0) + sign * power * exp
    return {k: v for k, v in out.items() if v}


def known(symbol: str | None) -> bool:
    """Whether ``symbol`` is in this module's table."""
    return symbol in _UNITS


def definition(symbol: str) -> UnitDefinition | None:
    """This table's unit ``symbol`` as a :class:`UnitDefinition`; None when unknown or without SI form (currency).

    Angles count in ``rad`` as FMI's ``<BaseUnit rad=...>`` does (``"rpm"`` is
    ``rad s-1`` with factor 2π/60).
    """
    if symbol not in _UNITS or _UNITS[symbol].dimension.startswith("KRW"):
        return None
    return UnitDefinition.from_base(symbol, base_exponents(symbol), _UNITS[symbol].factor)


def conversion(
    source: str,
    target: str,
    source_definition: UnitDefinition | None = None,
    target_definition: UnitDefinition | None = None,
) -> tuple[float, float]:
    """Affine map ``(factor, offset)`` with value_in_target = factor × value_in_source + offset.

    A unit of this module's table is taken from the table; any other from its
    definition (an FMU's ``<UnitDefinitions>``, an SSP's ``<ssc:Units>``):
    value_SI = factor × value + offset on each side, so ``degC`` → ``K`` is
    ``(1, 273.15)`` and ``kN`` → ``N`` is ``(1000, 0)``. Two table units convert
    exactly as :func:`conversion_factor` (offset 0). The same symbol on both
    sides is ``(1, 0)`` unless both sides define it, differently.

    Parameters
    ----------
    source, target : str
        Unit symbols (both declared: an undeclared unit is the caller's case).
    source_definition, target_definition : UnitDefinition, optional
        Definitions that came with each side's variable.

    Raises
    ------
    UnitError
        A unit neither in the table nor defined, or units of different base-unit exponents.
    """
    if source == target and (source in _UNITS or source_definition is None or target_definition is None
                             or source_definition.same_as(target_definition)):
        return 1.0, 0.0
    if source in _UNITS and target in _UNITS:
        return conversion_factor(source, target), 0.0
    sides = []
    for symbol, given in ((source, source_definition), (target, target_definition)):
        resolved = definition(symbol) if symbol in _UNITS else given
        if resolved is None:
            raise UnitError(
                f"cannot convert {source!r} to {target!r}: unknown unit {symbol!r}, neither in cnctwin's table "
                "(fmus_src.units) nor defined by its source (no <Unit> with a <BaseUnit> in the FMU's "
                "<UnitDefinitions> or the SSP's <ssc:Units>)")
        sides.append(resolved)
    a, b = sides
    if a.exponents != b.exponents:
        raise UnitError(f"cannot connect {source!r} ({a.signature}{_at(a.source)}) to {target!r} "
                        f"({b.signature}{_at(b.source)}): different SI base units")
    return a.factor / b.factor, (a.offset - b.offset) / b.factor


def disagreement(given: UnitDefinition) -> str | None:
    """How a definition of a symbol this table knows differs from the table's (None: it agrees).

    Exponents of ``rad`` are not compared (many tools leave angles out of
    ``<BaseUnit>``, as SI does); factor and offset are.
    """
    ours = definition(given.name)
    if ours is None:
        return None
    strip = lambda d: tuple(x for x in d.exponents if x[0] != "rad")  # noqa: E731
    if strip(ours) == strip(given) and math.isclose(ours.factor, given.factor, rel_tol=1e-9) \
            and given.offset == 0.0:
        return None
    return (f"{given.name!r} is defined as {given.factor!r} {given.signature} + {given.offset!r}{_at(given.source)}, "
            f"cnctwin's table has {ours.factor!r} {ours.signature}; the table is used")
