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

__all__ = [
    "EXTERNAL_OFFSET", "additional_offset_key", "Arc", "BatchPlan", "Block", "Coolant", "Dwell", "GCodeError", "InterpreterSettings", "Linear", "MemberPlan",
    "NCKernel", "NCParameterError", "NCParams", "Program", "ProgramEnd", "ProgramStop", "Rapid", "SpindleSpeed",
    "SpindleStop", "ToolChange", "build_schedule", "interpret", "plan_batch", "plan_member", "read_program",
    "rewrite_program",
]
