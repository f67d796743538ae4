"""Modal state of the interpreter: the modes, words and positions that carry from block to block.

Conventions
-----------
* Power-on modes: G0, G17, G21, G40, G49, G54, G64, G80, G90, G91.1, G94, G98; H0, D0.
* Positions (``machine``, the block end points) are in the axis frame; the work offsets are kept as shifts of
  the axis frame (machine coordinates + :attr:`.settings.InterpreterSettings.machine_zero`), so "machine" below
  means the axis frame, which is machine coordinates when ``machine_zero`` is 0.
* An offset change takes effect on the next move of the axis: the machine
  target of a programmed axis is programmed value + work offset (+ tool length
  on Z); axes not programmed do not move. A work-offset change shifts the
  programmed coordinates of the current position (as FANUC's absolute
  position display); a tool-length change is applied by the next Z move, also
  in G91 (as FANUC).
* The modal state is one for the main program and its subprograms (see :mod:`.call_stack`).
* The G52 local shift and the G92 shift (:mod:`.coordinate_shifts`) are added to every workpiece coordinate
  system (G54-G59, G54.1 Pn); they start at zero (power-on, after a reference return).
* The programmable transforms G51.1/G51/G68 and G16 (:mod:`.transforms`, :mod:`.polar`) sit between the
  programmed coordinates and the work offset: machine = transformed(programmed) + work offset (+ tool length
  on Z); all off at power-on.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

from .blocks import Vec3
from .cycles import LevelWord
from .settings import EXTERNAL_OFFSET, MM, InterpreterSettings
from .transforms import Transforms

if TYPE_CHECKING:
    from .corners import OpenCorner


class ModalState:
    """Modal state of the interpreter (SI: m, m/s or m/rev, rad/s, s).

    Parameters
    ----------
    settings : InterpreterSettings
        Initial position, work and tool offsets (copied: G10 changes the copies).
    """

    def __init__(self, settings: InterpreterSettings) -> None:
        self.motion = 0
        self.plane = "XY"
        self.scale = MM
        self.absolute = True
        self.work = 54
        self.work_code = 54.0  # the code that selected it: 54-59, 54.1 (also G54 Pn), 154 or 110-129 (#4014)
        self.tool_sign = 0  # +1 G43, -1 G44, 0 G49
        self.h = 0
        self.feed: float | None = None
        self.feed_line = 0
        self.speed = 0.0
        self.speed_line = 0
        self.direction = 0
        self.tool_selected: int | None = None
        self.machine = list(settings.initial)
        self.applied_tool = 0.0  # tool length contained in machine[2]
        self.settings = settings
        # G10 changes these copies: work offsets by key as shifts of the axis frame (a missing work system, the
        # default work zero -machine_zero, is 0: see .settings), tool offsets as (geometry, wear) per number
        self.offsets: dict[int, Vec3] = {int(k): settings.axis_offset(int(k), tuple(v))  # type: ignore[arg-type]
                                         for k, v in settings.work_offsets.items()}
        self.lengths = [[float(v), 0.0] for v in settings.tool_lengths]
        self.radii = [[float(v), 0.0] for v in settings.tool_radii]
        self.local_shift = [0.0, 0.0, 0.0]  # G52 local coordinate system origin (m), see .coordinate_shifts
        self.g92_shift = [0.0, 0.0, 0.0]  # G92 shift of every workpiece coordinate system (m)
        self.suspended_shifts: tuple[Vec3, Vec3] | None = None  # (G52, G92) suspended by G92.2 (G92.3 restores)
        self.corner: OpenCorner | None = None  # open ,C/,R corner of the previous block (see .corners)
        self.per_rev = False  # G95 (True) / G94
        self.feed_per_rev = False  # the modal F was given under G95 (m/rev) rather than G94 (m/s)
        off = self.work_offset()
        self.prog = [self.machine[a] - off[a] for a in range(3)]
        self.exact_stop = False  # G61 (True) / G64 or Mazak G61.1
        self.path_code = 64.0  # the path mode code in effect: 61, 61.1 (Mazak geometry compensation) or 64
        self.lookahead_limit = 0  # Haas G103 P<n>: blocks read ahead of the executing one, 0: no limit
        self.return_initial = True  # G98 (True) / G99
        self.cycle: int | None = None  # active canned cycle, None under G80
        self.cycle_initial = 0.0  # initial level (work Z, m)
        self.cycle_r: LevelWord | None = None  # R word as programmed (G90 level / G91 from the initial level)
        self.cycle_bottom: LevelWord | None = None  # Z word as programmed (G90 level / G91 from the R point)
        self.cycle_q: float | None = None  # peck depth (m)
        self.cycle_dwell = 0.0  # s
        self.rigid = 0  # rigid tapping: 0 off, 1 M29 given, 2 in a G84/G74 cycle (see .tapping)
        self.arc_centre_absolute = False  # G90.1 (True, I/J/K are work coordinates) / G91.1 (see .motion)
        self.comp = 40  # cutter compensation G40/G41/G42
        self.d = 0  # tool radius offset number (modal)
        self.comp_pending: str | None = None  # "start-up"/"cancel" until the next move block
        self.xf = Transforms()  # G51.1 mirror, G51 scaling, G68 rotation, G16 polar (see .transforms)

    def sync_prog(self, axes: Sequence[int]) -> None:
        """Programmed position of ``axes`` from the machine position (after a machine-coordinate move)."""
        off = self.work_offset()
        for i in axes:
            self.prog[i] = self.machine[i] - off[i] - (self.applied_tool if i == 2 else 0.0)
        self.xf.pending -= set(axes)  # the machine position is known in work coordinates again

    def work_offset(self) -> Vec3:
        """Active work offset + external offset + G52 local shift + G92 shift (m)."""
        base, loc, g92 = self.base_work_offset(), self.local_shift, self.g92_shift
        return (base[0] + loc[0] + g92[0], base[1] + loc[1] + g92[1], base[2] + loc[2] + g92[2])

    def base_work_offset(self) -> Vec3:
        """Active work offset + external offset (m, a shift of the axis frame), without the G52/G92 shifts."""
        zero = (0.0, 0.0, 0.0)
        own, ext = self.offsets.get(self.work, zero), self.offsets.get(EXTERNAL_OFFSET, zero)
        return (own[0] + ext[0], own[1] + ext[1], own[2] + ext[2])

    def shift_work(self) -> None:
        """Programmed coordinates of the current position after a work-offset change (as FANUC's display)."""
        off = self.work_offset()
        self.prog = [self.machine[a] - off[a] for a in range(3)]
        self.prog[2] -= self.applied_tool
        if self.xf.active:  # G10 changed the active offset under a transform: back through the transforms
            self.prog = self.xf.to_program(self.prog)
        else:
            self.xf.pending.clear()

    def tool_length(self) -> float:
        """Active tool length offset (m): +-(geometry + wear) of H under G43/G44, 0 under G49 or with H0."""
        if self.tool_sign == 0 or self.h == 0:
            return 0.0
        return self.tool_sign * sum(self.lengths[self.h - 1])

    def tool_radius(self) -> float:
        """Radius of the active tool radius offset D (m, geometry + wear; D0 = 0)."""
        return 0.0 if self.d == 0 else sum(self.radii[self.d - 1])
