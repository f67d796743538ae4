"""The cutting load's tool table: the cutter of each tool number the program puts in the spindle.

A program with several tools (T words, M6) cuts with each tool's own cutter. The
table is held as FMI 2.0 scalar parameters in :data:`N_TOOL_TABLE` slots,
``tool_<i>_number`` (Integer, the T number; 0 = empty slot), ``tool_<i>_diameter``
(m) and ``tool_<i>_flutes`` (Integer). The cutting load's ``tool`` input (the NC
kernel's tool in the spindle) picks the slot of that number; a number the table does
not list (and tool 0, the spindle before the first M6) is cut with the component's
``tool_diameter`` and ``flutes``. With every slot empty the component is the one-tool
model it always was.

:class:`ToolTable` packs the slots of a batch into arrays (column 0 = the default
cutter), which the numpy component and the compiled kernel
(:func:`.zmap_numba.zmap_component_step`) read through :func:`slot_of` / :func:`slots`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from ..component import Variable
from ..jit import njit

#: Slots of the tool table (tools one program may use with their own cutters).
N_TOOL_TABLE = 32


def table_variables() -> tuple[Variable, ...]:
    """The slot parameters ``tool_<i>_number``, ``tool_<i>_diameter``, ``tool_<i>_flutes``, i = 1..N_TOOL_TABLE."""
    out: list[Variable] = []
    for i in range(1, N_TOOL_TABLE + 1):
        out.append(Variable(f"tool_{i}_number", "parameter", "1", 0,
                            f"tool table slot {i}: T number (0 = empty slot)", "Integer"))
        out.append(Variable(f"tool_{i}_diameter", "parameter", "m", 0.0,
                            f"tool table slot {i}: flat end mill diameter"))
        out.append(Variable(f"tool_{i}_flutes", "parameter", "1", 0, f"tool table slot {i}: number of teeth",
                            "Integer"))
    return tuple(out)


#: Names of the slot parameters.
TABLE_PARAMETERS = frozenset(v.name for v in table_variables())


@dataclass(frozen=True)
class ToolTable:
    """The tool table of a batch, packed: column 0 is the default cutter, columns 1.. the used slots.

    Attributes
    ----------
    number : ndarray of int64, shape (B, 1 + n)
        T number of each column (column 0: -1, never matched; an empty slot: 0).
    radius : ndarray, shape (B, 1 + n)
        Cutter radius, m.
    flutes : ndarray of int64, shape (B, 1 + n)
        Teeth.
    """

    number: np.ndarray
    radius: np.ndarray
    flutes: np.ndarray

    @classmethod
    def from_values(cls, values: Mapping[str, np.ndarray], batch: int, name: str, error: type[Exception]
                    ) -> ToolTable:
        """Pack and check the slot parameters of ``values`` (a component's), default from ``tool_diameter``/``flutes``.

        Raises ``error`` naming ``name``, the slot and the member for a negative number, a number listed twice,
        or a listed number without a positive finite diameter and at least one flute.
        """
        number = [np.full(batch, -1, dtype=np.int64)]
        radius = [np.broadcast_to(0.5 * np.asarray(values["tool_diameter"], dtype=np.float64), (batch,))]
        flutes = [np.broadcast_to(np.asarray(values["flutes"], dtype=np.int64), (batch,))]
        for i in range(1, N_TOOL_TABLE + 1):
            t = np.broadcast_to(np.asarray(values[f"tool_{i}_number"], dtype=np.int64), (batch,))
            if not np.any(t != 0):
                continue
            d = np.broadcast_to(np.asarray(values[f"tool_{i}_diameter"], dtype=np.float64), (batch,))
            z = np.broadcast_to(np.asarray(values[f"tool_{i}_flutes"], dtype=np.int64), (batch,))
            for m in range(batch):
                if t[m] < 0:
                    raise error(f"{name}.tool_{i}_number: member {m} has {int(t[m])}; expected a T number >= 1 "
                                "(0 = empty slot)")
                if t[m] > 0 and not (np.isfinite(d[m]) and d[m] > 0.0):
                    raise error(f"{name}.tool_{i}_diameter: member {m} has {float(d[m])!r} for T{int(t[m])}; "
                                "expected a positive length in m")
                if t[m] > 0 and z[m] < 1:
                    raise error(f"{name}.tool_{i}_flutes: member {m} has {int(z[m])} for T{int(t[m])}; "
                                "expected an integer >= 1")
                if t[m] > 0 and any(col[m] == t[m] for col in number[1:]):
                    raise error(f"{name}.tool_{i}_number: member {m} lists T{int(t[m])} in a second slot; "
                                "expected each tool number once")
            number.append(t)
            radius.append(0.5 * d)
            flutes.append(z)
        return cls(np.ascontiguousarray(np.stack(number, axis=1).astype(np.int64)),
                   np.ascontiguousarray(np.stack(radius, axis=1), dtype=np.float64),
                   np.ascontiguousarray(np.stack(flutes, axis=1), dtype=np.int64))

    @property
    def listed(self) -> bool:
        """Whether any slot is in use."""
        return self.number.shape[1] > 1

    def smallest_radius(self) -> np.ndarray:
        """Smallest radius of each member's cutters (default and listed), shape (B,), m."""
        return np.min(np.where(self.number != 0, self.radius, np.inf), axis=1)


@njit
def slot_of(number: np.ndarray, m: int, tool: float) -> int:
    """Column of tool ``tool`` in row ``m`` of a :attr:`ToolTable.number` (0, the default cutter, when unlisted)."""
    for k in range(1, number.shape[1]):
        if number[m, k] != 0 and number[m, k] == tool:
            return k
    return 0


def slots(table: ToolTable, tool: np.ndarray) -> np.ndarray:
    """Column of each member's tool in ``table`` (:func:`slot_of` for every member), shape (B,) int."""
    tool = np.asarray(tool, dtype=np.float64)
    match = (table.number == tool[:, None]) & (table.number != 0)
    match[:, 0] = False
    return np.where(match.any(axis=1), match.argmax(axis=1), 0).astype(np.int64)
