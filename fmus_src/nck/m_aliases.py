"""Machine builders' M codes: aliases of the standard M codes, from the machine file's ``[nck.m_codes]``.

Each machine builder adds its own M codes to the FANUC set: M13/M14 (spindle CW/CCW and coolant on, Makino,
Okuma, Doosan), M48/M49 (feed/spindle override enable/cancel), M88/M89 (through-spindle coolant on/off, Haas).
Their numbers differ between builders, so the machine file maps them to the standard codes they stand for.

Conventions
-----------
* An alias ``code -> means`` is an M code of the builder and the standard M codes it stands for, in order
  (``13 -> (3, 8)``: M13 runs as M3 and M8 on its block). An empty ``means`` has no effect on the twin: M48/M49
  switch the override knobs on and off, and the twin runs at 100 % override.
* ``means`` may hold only :data:`ALIAS_TARGETS`: the spindle codes M3 M4 M5 M19, the coolant codes M7 M8 M9
  and the rigid-tapping code M29 (its number is a machine parameter, FANUC No. 5210, so a builder may use
  another; not together with a spindle code, as M29 alone in its block). Never the program-flow codes M0 M1
  M2 M30 M97 M98 M99 nor the tool change M6: stops, ends, calls and tool changes stay explicit in the program.
* At most one code of each kind in ``means`` (M3 with M4, or M7 with M8, is refused: the twin's coolant is on
  or off), no code twice.
* A standard code (:data:`.codes.M_GROUP`) cannot be redefined; an alias is 0..99999999 (8 digits, FANUC).
* As the NC kernel's String parameter ``m_codes`` (an FMU parameter): ``"13=3,8;14=4,8;48=;49=;88=8;89=9"``
  (:func:`format_m_codes`, :func:`parse_m_codes`).
"""
from __future__ import annotations

from typing import Mapping, Sequence

from .codes import M_GROUP
from .errors import NCParameterError

#: Standard M codes an alias may stand for (see the module docstring for why these).
ALIAS_TARGETS = (3, 4, 5, 7, 8, 9, 19, 29)
#: Largest alias code (FANUC M codes have at most 8 digits).
MAX_ALIAS_CODE = 99_999_999
#: Aliases of ``models/machines/default.toml`` ``[nck.m_codes]`` (assumptions, see there): the default of the
#: NC kernel's ``m_codes`` parameter.
DEFAULT_M_CODES: dict[int, tuple[int, ...]] = {13: (3, 8), 14: (4, 8), 48: (), 49: (), 88: (8,), 89: (9,)}

#: M-code aliases: builder's code -> the standard codes it stands for.
MCodeAliases = Mapping[int, tuple[int, ...]]


def alias_problem(code: int, means: Sequence[int]) -> str | None:
    """What is wrong with the alias ``M<code> -> means``, or None when it is valid.

    Parameters
    ----------
    code : int
        The builder's M code.
    means : sequence of int
        The standard M codes it stands for, in order (may be empty).
    """
    if isinstance(code, bool) or not isinstance(code, int) or not 0 <= code <= MAX_ALIAS_CODE:
        return f"M code {code!r} is not an integer in 0..{MAX_ALIAS_CODE}"
    if code in M_GROUP:
        return f"M{code} is a standard M code of the NC kernel and cannot be redefined"
    allowed = " ".join(f"M{c}" for c in ALIAS_TARGETS)
    kinds: dict[str, int] = {}
    for m in means:
        if isinstance(m, bool) or not isinstance(m, int):
            return f"M{code} means {list(means)!r}: {m!r} is not an M code number"
        if m not in ALIAS_TARGETS:
            why = (" (program stops, ends, calls and tool changes stay explicit in the program)"
                   if m in M_GROUP else "")
            return f"M{code} means M{m}, which an alias cannot stand for{why}; allowed: {allowed}"
        kind = M_GROUP[m]
        if kind in kinds:
            return f"M{code} means M{kinds[kind]} and M{m}, two {kind} codes; at most one of each kind"
        kinds[kind] = m
    if "rigid tapping" in kinds and "spindle" in kinds:
        return f"M{code} means M29 with M{kinds['spindle']}: M29 stands alone (it stops the spindle itself)"
    return None


def check_m_codes(m_codes: Mapping[int, Sequence[int]], where: str) -> dict[int, tuple[int, ...]]:
    """Validated copy of an alias table.

    Parameters
    ----------
    m_codes : mapping int -> sequence of int
        Builder's M code -> standard codes.
    where : str
        Names the table in the error message (e.g. ``"nck.m_codes"``).

    Raises
    ------
    NCParameterError
        An alias :func:`alias_problem` refuses.
    """
    out: dict[int, tuple[int, ...]] = {}
    for code, means in m_codes.items():
        problem = alias_problem(code, list(means))
        if problem is not None:
            raise NCParameterError(f"{where}: {problem}")
        out[code] = tuple(means)
    return out


def format_m_codes(m_codes: MCodeAliases) -> str:
    """The String-parameter form of an alias table: ``"13=3,8;48="`` (sorted by code)."""
    return ";".join(f"{code}=" + ",".join(str(m) for m in m_codes[code]) for code in sorted(m_codes))


def parse_m_codes(text: str, where: str) -> dict[int, tuple[int, ...]]:
    """Read the String-parameter form (:func:`format_m_codes`) of an alias table and validate it.

    Parameters
    ----------
    text : str
        ``"<code>=<m>,<m>;<code>=;..."``; empty or blank: no aliases.
    where : str
        Names the parameter in messages (``"nck.m_codes"``).

    Raises
    ------
    NCParameterError
        A malformed entry, a code given twice, or an alias :func:`alias_problem` refuses.
    """
    out: dict[int, tuple[int, ...]] = {}
    for entry in (e.strip() for e in text.split(";")):
        if not entry:
            continue
        code_text, eq, means_text = entry.partition("=")
        parts = [p.strip() for p in means_text.split(",")] if means_text.strip() else []
        if not eq or not code_text.strip().isdigit() or not all(p.isdigit() for p in parts):
            raise NCParameterError(f"{where}: entry {entry!r} is not <M code>=<standard M codes, comma separated>; "
                                   "expected e.g. '13=3,8;48='")
        code = int(code_text)
        if code in out:
            raise NCParameterError(f"{where}: M{code} is given twice")
        out[code] = tuple(int(p) for p in parts)
    return check_m_codes(out, where)

