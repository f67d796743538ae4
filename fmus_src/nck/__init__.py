"""NC kernel: FANUC-dialect interpreter, program writer, look-ahead interpolator, acc/dec and spindle.

Public API
----------
interpret, InterpreterSettings, Program and the typed blocks
    G-code text → typed blocks (SI, machine coordinates).
additional_offset_key, EXTERNAL_OFFSET
    Keys of G54.1 Pn and of the external offset in ``InterpreterSettings.work_offsets``.
read_program
    Read a program file (UTF-8, BOM dropped) or raise GCodeError naming the file.
rewrite_program
    Re-emit a program with new F/S words on given lines, every other byte untouched.
NCKernel
    The batch-capable component (reference trajectories for the servo axes).
NCParams, plan_batch, plan_member, build_schedule
    The planner used by NCKernel, usable on its own.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy_exports import lazy_exports

#: Public name -> submodule that defines it, imported on first access (PEP 562): reading a machine
#: file needs only the tables of a few light submodules, not the planner and its numba kernels.
_LAZY = {
    **dict.fromkeys(("Arc", "Block", "Coolant", "Dwell", "Linear", "Program", "ProgramEnd", "ProgramStop", "Rapid",
                     "SpindleSpeed", "SpindleStop", "ToolChange"), ".blocks"),
    "NCKernel": ".component",
    "GCodeError": ".errors", "NCParameterError": ".errors",
    "interpret": ".interpreter",
    "NCParams": ".params",
    **dict.fromkeys(("BatchPlan", "MemberPlan", "build_schedule", "plan_batch", "plan_member"), ".planner"),
    **dict.fromkeys(("EXTERNAL_OFFSET", "InterpreterSettings", "additional_offset_key"), ".settings"),
    "read_program": ".source",
    "rewrite_program": ".writer",
}

__all__ = [
    "EXTERNAL_OFFSET", "additional_offset_key", "Arc", "BatchPlan", "Block", "Coolant", "Dwell", "GCodeError",
    "InterpreterSettings", "Linear", "MemberPlan",
    "NCKernel", "NCParameterError", "NCParams", "Program", "ProgramEnd", "ProgramStop", "Rapid", "SpindleSpeed",
    "SpindleStop", "ToolChange", "build_schedule", "interpret", "plan_batch", "plan_member", "read_program",
    "rewrite_program",
]


#: Imports a public name on first access (PEP 562); submodules import as usual.
__getattr__, __dir__ = lazy_exports(__name__, _LAZY, globals(), __all__)


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs
    from .blocks import (
        Arc, Block, Coolant, Dwell, Linear, Program, ProgramEnd, ProgramStop, Rapid, SpindleSpeed, SpindleStop,
        ToolChange,
    )
    from .component import NCKernel
    from .errors import GCodeError, NCParameterError
    from .interpreter import interpret
    from .params import NCParams
    from .planner import BatchPlan, MemberPlan, build_schedule, plan_batch, plan_member
    from .settings import EXTERNAL_OFFSET, InterpreterSettings, additional_offset_key
    from .source import read_program
    from .writer import rewrite_program
