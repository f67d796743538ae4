"""cnctwin orchestrator: co-simulation master, system description, recordings, CLI.

Every capability is a Python call first and a ``cnctwin`` command second::

    from orchestrator import simulate
    result = simulate(case="models/examples/paper_part", out="out/paper_part")
"""
from __future__ import annotations

from fmus_src.component import Component, ComponentError, Variable

from .errors import CncTwinError, SimulationError, SystemDescriptionError
from .machine import Machine, MachineFileError, load_machine
from .master import Master, MasterSettings, Probe, RunResult, simulate_system
from .recording import Recording, RecordingError
from .simulate import SimulationResult, simulate
from .system import Connection, System

__all__ = [
    "CncTwinError", "Component", "ComponentError", "Connection", "Machine", "MachineFileError", "Master",
    "MasterSettings", "Probe", "Recording", "RecordingError", "RunResult", "SimulationError", "System",
    "SimulationResult", "SystemDescriptionError", "Variable", "load_machine", "simulate", "simulate_system",
]
