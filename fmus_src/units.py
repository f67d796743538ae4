"""Units: SI inside the physics, machinist units at the edge.

A small registry of the units this project uses. Each unit is a factor to its
SI unit and a dimension signature, so that connections between components can
be checked (same dimension) and converted (factor only, no offsets).

Machine parameter files put the unit in the key name (``screw_lead_mm``,
``rapid_feed_mm_per_min``); :func:`split_unit_suffix` reads it back.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


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
_register("A/(m/s)", 1.0, "I.T/L", "A_per_m_per_s")
_register("A/m", 1.0, "I/L", "A_per_m")
_register("m3/s", 1.0, "L3/T", "m3_per_s")
_register("mm3/min", 1e-9 / 60.0, "L3/T", "mm3_per_min")
_register("KRW", 1.0, "KRW", "KRW")
_register("KRW/s", 1.0, "KRW/T", "KRW_per_s")


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
    "F": {"kg": 1, "m": 1, "s": -2}, "P": {"kg": 1, "m": 2, "s": -3}, "KRW": {},
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
