"""Machine data the interpreter needs (:class:`InterpreterSettings`) and the units of a program's numbers.

Conventions
-----------
* Decimal point input (FANUC No. 3401#0): calculator type (DPI = 1, the default), ``X10`` is 10 mm; or
  ``decimal_input="increment"`` (DPI = 0), ``X10`` is 10 least input increments, 0.010 mm (:mod:`.decimal_input`).
* Program units: a length word times :data:`MM` (G21) or :data:`INCH` (G20) is metres, an S word times
  :data:`RPM` is rad/s; the writer and the optimiser use the same factors, so their numbers match the
  interpreter's bit for bit.
* Work-offset keys of :attr:`InterpreterSettings.work_offsets`: 54..59 for G54..G59,
  :func:`additional_offset_key` for G54.1 Pn, :func:`g154_offset_key` for Haas G154 Pn (the same keys),
  :data:`EXTERNAL_OFFSET` for the external offset (what G54.1, G154 and the external offset do: :mod:`.offsets`).
* Coordinate frames: the interpreter's positions (block end points, :attr:`InterpreterSettings.initial`, the NC
  kernel's outputs, recordings) are in the twin's *axis frame*. Machine coordinates (G53 positions, the G28/G30
  reference positions, the work offsets G54.. and the stroke limits, as on FANUC) are axis frame minus
  :attr:`InterpreterSettings.machine_zero`, the position of machine zero in the axis frame. A work offset not
  given is the default work zero ``-machine_zero``: its work coordinates are the axis frame. With
  ``machine_zero`` = 0 (the default) machine coordinates are the axis frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Sequence

from .blocks import Vec3
from .cycles import CycleMachine
from .decimal_input import DECIMAL_INPUTS
from .errors import NCParameterError
from .m_aliases import check_m_codes

#: One millimetre (G21 program unit), m.
MM = 1e-3
#: One inch (G20 program unit), m.
INCH = 25.4e-3
#: Tool length (H) and radius (D) offset registers of the twin's NC kernel (its component and ``cnctwin simulate``):
#: 200, as a Haas NGC's offset table and within a FANUC 0i-F's optional 400, so that a post writing H = T reaches
#: every tool of a large magazine.
TWIN_OFFSET_REGISTERS = 200
#: One revolution per minute (S word), rad/s.
RPM = 2.0 * math.pi / 60.0
#: Reference position (G28) of the default machine in its axis frame (m): ``machine_zero_*_mm`` +
#: ``reference_*_mm`` of models/machines/default.toml (380, 225, 300 mm; assumption, see there). The NC kernel's
#: default, with machine zero at the axis-frame origin (:attr:`InterpreterSettings.machine_zero` = 0), so that a
#: machine file without ``machine_zero_*_mm`` and ``reference_*_mm`` returns there as before.
DEFAULT_REFERENCE: Vec3 = (0.380, 0.225, 0.300)
#: Settings of the M6 Z retract (:func:`.machine_moves.tool_change_retract`): none, to the 1st (G28) or the 2nd
#: (G30 P2) reference position Z.
TOOL_CHANGE_RETRACTS = ("off", "G28", "G30")
#: Settings of the spindle at M6 (:func:`.auxiliary_functions.auxiliary_blocks`): "stop" (the tool-change macro
#: stops it, M19, the change waits for it at rest, and it stays stopped until M3/M4) or "keep" (it turns on
#: through the change).
TOOL_CHANGE_SPINDLES = ("stop", "keep")
#: Key of the external workpiece zero point offset in :attr:`InterpreterSettings.work_offsets` (FANUC "EXT",
#: ``G10 L2 P0``): added to every work coordinate system.
EXTERNAL_OFFSET = 0
#: Number of additional work coordinate systems G54.1 P1..P48 (FANUC 0i-MF/31i-B option).
N_ADDITIONAL_OFFSETS = 48
#: Number of Haas additional work offsets G154 P1..P99 (the same table: G154 Pn is G54.1 Pn for n <= 48).
N_HAAS_OFFSETS = 99


def additional_offset_key(n: int) -> int:
    """Key of G54.1 P``n`` in :attr:`InterpreterSettings.work_offsets`: ``1000 + n`` (1001..1048).

    Parameters
    ----------
    n : int
        Number of the additional work coordinate system, 1..48.
    """
    if not 1 <= n <= N_ADDITIONAL_OFFSETS:
        raise ValueError(f"G54.1 P{n}: expected P1..P{N_ADDITIONAL_OFFSETS}")
    return 1000 + n


def g154_offset_key(n: int) -> int:
    """Key of Haas G154 P``n`` in :attr:`InterpreterSettings.work_offsets`: ``1000 + n`` (1001..1099).

    One table with G54.1 Pn: ``g154_offset_key(n) == additional_offset_key(n)`` for n = 1..48, and G110..G129
    are G154 P1..P20.

    Parameters
    ----------
    n : int
        Number of the additional work offset, 1..99.
    """
    if not 1 <= n <= N_HAAS_OFFSETS:
        raise ValueError(f"G154 P{n}: expected P1..P{N_HAAS_OFFSETS}")
    return 1000 + n


@dataclass(frozen=True)
class InterpreterSettings:
    """Machine data the interpreter needs (SI).

    Attributes
    ----------
    initial : Vec3
        Tool position before the program (m, axis frame; without tool length).
    work_offsets : Mapping[int, Vec3]
        Work offset → (x, y, z) (m, machine coordinates of the work zero; the external offset a shift).
        Keys: 54..59 for G54..G59, :func:`additional_offset_key` ``(n)`` = 1000 + n
        for G54.1 Pn (n = 1..48) and :func:`g154_offset_key` ``(n)`` = 1000 + n for Haas G154 Pn (n = 1..99;
        G110..G129 = G154 P1..P20), :data:`EXTERNAL_OFFSET` = 0 for the external workpiece zero point offset,
        which is added to every work coordinate system. A missing work system is the default work zero
        ``-machine_zero`` (its work coordinates are the axis frame), a missing external offset zero.
        ``G10 L2``/``G10 L20`` in the program change a copy (these stay untouched).
    tool_lengths : Sequence[float]
        Tool length offsets (m) for H1..Hn (index 0 is H1). H0 is always zero. They are the geometry values
        of ``G10 L10``; the wear values (``G10 L11``) start at zero.
    tool_radii : Sequence[float]
        Tool radius offsets (m) for D1..Dn (index 0 is D1; FANUC's radius, geometry + wear). D0 is always zero.
        Geometry of ``G10 L12``; the wear (``G10 L13``) starts at zero.
        A nonzero one under G41/G42 gives the tool-centre path (:mod:`.radius_offset`).
    block_delete : bool
        Block delete switch: True skips blocks starting with ``/``.
    reference : Vec3
        G28 reference position (m, machine coordinates; FANUC No. 1240). Default: the default machine's.
    reference2, reference3, reference4 : Vec3 or None
        2nd/3rd/4th reference position of G30 P2/P3/P4 (m, machine coordinates; FANUC No. 1241-1243).
        None: the 1st reference position ``reference``.
    cycles : CycleMachine
        Return amount of G73 (No. 5114) and clearance of G83 (No. 5115).
    m_codes : Mapping[int, tuple[int, ...]]
        The machine builder's M codes: alias -> the standard M codes it stands for (:mod:`.m_aliases`, the
        machine file's ``[nck.m_codes]``). Default: none (the FANUC codes only). Checked at construction
        (:class:`.errors.NCParameterError`).
    decimal_input : {"calculator", "increment"}
        FANUC No. 3401#0 DPI: a number without a decimal point is in mm/inch (``"calculator"``, DPI = 1, the
        default) or in least input increments (``"increment"``, DPI = 0: ``X10`` = 0.010 mm); see
        :mod:`.decimal_input`.
    tool_change_retract : {"off", "G28", "G30"}
        M6 first moves Z at rapid to the 1st ("G28") or 2nd ("G30") reference position Z, as a VMC's tool-change
        macro does; "off" (default): M6 is the tool change time alone (:func:`.machine_moves.tool_change_retract`).
    tool_change_spindle : {"stop", "keep"}
        "stop" (default): M6 stops a turning spindle as M19 does, with the Z retract; the tool change starts when
        the axes are in position and the spindle is at rest, and the spindle stays stopped until M3/M4; "keep":
        the spindle turns on at its speed through the tool change (a macro that restarts it).
    machine_zero : Vec3
        Where machine zero sits in the axis frame (m): machine coordinates = axis frame - machine_zero. Default
        (0, 0, 0): machine coordinates are the axis frame. The default machine has its machine zero at the G28
        reference position, (380, 225, 300) mm, so that ``G53 Z0`` is the top of the Z travel.
    """

    initial: Vec3 = (0.0, 0.0, 0.0)
    work_offsets: Mapping[int, Vec3] = field(default_factory=dict)
    tool_lengths: Sequence[float] = ()
    tool_radii: Sequence[float] = ()
    block_delete: bool = False
    reference: Vec3 = DEFAULT_REFERENCE
    reference2: Vec3 | None = None
    reference3: Vec3 | None = None
    reference4: Vec3 | None = None
    cycles: CycleMachine = field(default_factory=CycleMachine)
    m_codes: Mapping[int, tuple[int, ...]] = field(default_factory=dict)
    decimal_input: str = "calculator"
    tool_change_retract: str = "off"
    tool_change_spindle: str = "stop"
    machine_zero: Vec3 = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "m_codes", check_m_codes(self.m_codes, "InterpreterSettings.m_codes"))
        if self.decimal_input not in DECIMAL_INPUTS:
            raise NCParameterError(f"InterpreterSettings.decimal_input must be one of {list(DECIMAL_INPUTS)}, "
                                   f"got {self.decimal_input!r}")
        if self.tool_change_retract not in TOOL_CHANGE_RETRACTS:
            raise NCParameterError(f"InterpreterSettings.tool_change_retract must be one of "
                                   f"{list(TOOL_CHANGE_RETRACTS)}, got {self.tool_change_retract!r}")
        if self.tool_change_spindle not in TOOL_CHANGE_SPINDLES:
            raise NCParameterError(f"InterpreterSettings.tool_change_spindle must be one of "
                                   f"{list(TOOL_CHANGE_SPINDLES)}, got {self.tool_change_spindle!r}")
        if len(self.machine_zero) != 3 or not all(math.isfinite(v) for v in self.machine_zero):
            raise NCParameterError(f"InterpreterSettings.machine_zero must be 3 finite numbers (m), "
                                   f"got {self.machine_zero!r}")

    def reference_position(self, n: int) -> Vec3:
        """The n-th reference position (n = 1..4, m, machine coordinates); an unset 2nd-4th is the 1st."""
        other = {2: self.reference2, 3: self.reference3, 4: self.reference4}.get(n)
        return self.reference if other is None else other

    def machine_to_axis(self, axis: int, value: float) -> float:
        """Axis-frame coordinate (m) of machine coordinate ``value`` (m) of axis 0, 1, 2 (X, Y, Z).

        With machine zero at the axis-frame origin the value itself (no rounding).
        """
        zero = self.machine_zero[axis]
        return value + zero if zero else value

    def axis_offset(self, key: int, offset: Vec3) -> Vec3:
        """Work offset ``key`` (m, machine coordinates) as a shift of the axis frame (m).

        A work system (G54.., G54.1 Pn) becomes ``offset + machine_zero``, so the default work zero
        ``-machine_zero`` is exactly 0; the external offset (:data:`EXTERNAL_OFFSET`) is a shift, the same in
        both frames.
        """
        if key == EXTERNAL_OFFSET:
            return offset
        return (self.machine_to_axis(0, offset[0]), self.machine_to_axis(1, offset[1]),
                self.machine_to_axis(2, offset[2]))
