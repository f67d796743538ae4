"""The engagement table the cutting diagnosis replays on: the program's, for one cutter only.

The diagnosis replays a recording (which has no tool channel) with the case's ``[tool]`` and fits effect terms
that depend on the teeth (runout, helix, edge force: :mod:`fmus_src.cutting.path_effects`), which the path
mode models for one cutter. A case whose tool table lists a cutter other than ``[tool]`` is therefore refused
here, although the optimiser's path mode takes such cases (each station with its own cutter).
"""
from __future__ import annotations

from fmus_src.cutting.table import EngagementTable

from ..case import Case
from ..twin import engagement_table
from .errors import DiagnosisError


def one_cutter_table(case: Case) -> EngagementTable:
    """:func:`orchestrator.twin.engagement_table` of ``case``, refused for several cutters.

    Raises
    ------
    DiagnosisError
        Naming the case file, when its ``[tools]`` lists a cutter other than ``[tool]``.
    """
    if case.several_tools():
        raise DiagnosisError(
            f"{case.source or case.folder}: [tools] lists cutters other than [tool]; the cutting diagnosis "
            "replays the recording with one cutter (a recording has no tool channel, and the effect terms it "
            "fits are modelled for one cutter): diagnose a program cut with [tool] only")
    return engagement_table(case)
