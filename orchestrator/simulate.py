"""``simulate``: run a G-code program on the twin and write recording, summary and overview."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from fmus_src.cutting.tool_table import N_TOOL_TABLE
from fmus_src.nck.blocks import ToolChange

from .atomic import atomic_write_json
from .case import Case, CaseError, case_for_program, load_case, missing_file
from .cost import CostModel, ToolLife, case_tool_lives
from .master import Master, MasterSettings
from .plots import overview_png
from .recording import Recording
from .summary import summarize, tool_notes
from .twin import TwinOptions, build_twin


@dataclass
class SimulationResult:
    """Outcome of :func:`simulate`.

    Attributes
    ----------
    recording : Recording
        Spec channels (``t_s``, ``line``, ``x_ref_mm`` … ``fc_N``).
    summary : dict
        What ``summary.json`` holds (cycle time, per-line times and loads,
        following error, cost).
    success : bool
        The program reached its end.
    message : str
        Why the run ended; a failed run's message starts with ``program:line:``,
        the program line executing when it failed (:func:`failure_message`).
    files : dict[str, Path]
        Files written (when ``out`` was given).
    """

    recording: Recording
    summary: dict[str, Any]
    success: bool
    message: str
    files: dict[str, Path] = field(default_factory=dict)

    def to_pandas(self):  # -> pandas.DataFrame
        """The recording as a pandas DataFrame."""
        return self.recording.to_pandas()


def failure_message(message: str, recording: Recording, program: str | Path) -> str:
    """``message`` of a failed run prefixed ``program:line:`` with the line executing when it failed.

    Parameters
    ----------
    message : str
        The master's message (e.g. ``"simulation failed at t = ... s: cutting: ..."``).
    recording : Recording
        The recording up to the failure; its last sample with a source line
        (``line`` > 0, spec ``recording.md``) names the line.
    program : str or Path
        The program file, as the user gave it.

    Returns
    -------
    str
        ``"<program>:<line>: <message>"``, or ``message`` unchanged when no line is known.
    """
    if "line" not in recording or len(recording) == 0:
        return message
    lines = np.asarray(recording["line"], dtype=np.float64).reshape(len(recording), -1)[:, 0]
    known = np.flatnonzero(np.isfinite(lines) & (lines > 0))
    if known.size == 0:
        return message
    return f"{program}:{int(lines[known[-1]])}: {message}"


def resolve_case(
    program: str | Path | None = None,
    case: str | Path | Case | None = None,
    machine: str | Path | None = None,
) -> Case:
    """The case to run: a case file/folder, a bare program (air cut), or both (program overrides)."""
    if isinstance(case, Case):
        resolved = case
    elif case is not None:
        resolved = load_case(case, machine_override=machine)
    elif program is not None:
        resolved = case_for_program(program, machine or "default")
    else:
        raise CaseError("give a program, a case, or both")
    if program is not None:
        resolved.program = Path(program)
    if not resolved.program.is_file():
        problem = missing_file(resolved, "program") if program is None else None
        raise CaseError(problem or f"{resolved.program}: program file not found")
    return resolved


def simulate(
    program: str | Path | None = None,
    case: str | Path | Case | None = None,
    machine: str | Path | None = None,
    out: str | Path | None = None,
    options: TwinOptions | None = None,
    time_limit_s: float = 3600.0,
    progress: Callable[[float, float], None] | None = None,
    plot: bool = True,
) -> SimulationResult:
    """Run a program on the default twin.

    Parameters
    ----------
    program : str or Path, optional
        G-code file; overrides the case's ``program``. Without a case the
        program runs as an air cut on ``machine`` (default: ``"default"``).
    case : str, Path or Case, optional
        Case folder or ``case.toml`` (stock, tool, machine).
    machine : str or Path, optional
        Machine set name or file; overrides the case's.
    out : str or Path, optional
        Folder for ``recording.csv``, ``summary.json`` and ``overview.png``.
    options : TwinOptions, optional
        Communication step, start position, cutting on/off.
    time_limit_s : float
        Simulated-time limit, s.
    progress : callable, optional
        ``progress(t, t_expected)``.
    plot : bool
        Write ``overview.png``.

    Returns
    -------
    SimulationResult
        ``success`` is False (with the recording so far) when the run failed.

    Examples
    --------
    >>> from orchestrator import simulate
    >>> result = simulate(case="models/examples/paper_part")  # doctest: +SKIP
    >>> result.summary["cycle_time_s"]                        # doctest: +SKIP
    """
    resolved = resolve_case(program, case, machine)
    twin = build_twin(resolved, batch=1, options=options)
    settings = MasterSettings(
        step=twin.options.step, time_limit=time_limit_s, stop_when=twin.stop_when, limits=twin.limits or {}
    )
    run = Master(twin.system, settings, twin.probes, progress=progress).run()
    recording = run.recording
    message = run.message
    if not run.success:  # name the program line executing at the failure (file:line, as parse errors)
        message = failure_message(message, recording, resolved.program)
        recording.message = message
    stop = run.stopped_at[0] if run.stopped_at.size else math.nan
    cycle_time = float(stop - settings.t0) if math.isfinite(stop) else float(run.t_end - settings.t0)
    cost_model = CostModel.from_machine(resolved.machine)
    summary = summarize(recording, cycle_time, cost_model, *case_tool_lives(cost_model, resolved))
    summary["program"] = str(resolved.program)
    summary["machine"] = resolved.machine.name
    changes = [(b.line, b.tool) for b in twin.nck.program_.blocks if isinstance(b, ToolChange)]
    summary["tool_changes"], notes = tool_notes(changes, twin.cutting is not None, resolved.tool.diameter_mm,
                                                resolved.tool.flutes, resolved.tools)
    if notes:
        summary["notes"] = notes
    result = SimulationResult(recording, summary, run.success, message)
    if out is not None:
        out = Path(out)
        result.files["recording"] = recording.write_csv(out / "recording.csv")
        result.files["summary"] = atomic_write_json(out / "summary.json", summary)
        if plot and len(recording) > 1:
            result.files["overview"] = overview_png(recording, out / "overview.png", title=resolved.program.name)
    return result


def _table_tool_lives(values: dict[str, Any], model: CostModel) -> dict[int, ToolLife]:
    """The cutting component's tool table (``tool_<i>_number``, ``tool_<i>_diameter`` in m) as tool lives with
    ``model``'s price and Taylor constants (an SSP file holds no cost keys), by tool number."""
    tools = {}
    for i in range(1, N_TOOL_TABLE + 1):
        number, diameter = values.get(f"tool_{i}_number"), values.get(f"tool_{i}_diameter")
        if number is not None and diameter is not None and int(number[0]) > 0:
            tools[int(number[0])] = model.tool(float(diameter[0]) * 1e3)
    return tools


def simulate_system_file(
    system_file: str | Path,
    out: str | Path | None = None,
    native: bool = True,
    time_limit_s: float | None = None,
    progress: Callable[[float, float], None] | None = None,
    plot: bool = True,
) -> SimulationResult:
    """Run a system described by an SSP 1.0 ``.ssd`` file.

    Parameters
    ----------
    system_file : str or Path
        The ``.ssd``; parameter values come from the ``.ssv`` files it binds.
    out : str or Path, optional
        Folder for ``recording.csv``, ``summary.json`` and ``overview.png``.
    native : bool
        Run elements that name a native implementation natively (fast); with
        False every element is loaded from its FMU (build them first with
        ``cnctwin build-fmus``).
    time_limit_s : float, optional
        Overrides the DefaultExperiment's stop time.

    Returns
    -------
    SimulationResult
        The twin's channels when the system has the twin's components,
        otherwise every output as ``component.variable``.
    """
    from .master import Probe
    from .ssp import build_system, read_ssd
    from .twin import twin_probes

    system, settings = build_system(read_ssd(system_file), native=native)
    if time_limit_s is not None:
        settings.time_limit = float(time_limit_s)
    probes = twin_probes(system) or [
        Probe(f"{name}.{var}", f"{name}.{var}")
        for name, comp in system.components.items()
        for var in comp.names("output")
        if comp.variable(var).type != "String"
    ]
    run = Master(system, settings, probes, progress=progress).run()
    recording = run.recording
    stop = run.stopped_at[0] if run.stopped_at.size else math.nan
    cycle_time = float(stop - settings.t0) if math.isfinite(stop) else float(run.t_end - settings.t0)
    if "line" in recording:
        model = CostModel()
        diameter_mm, tools = 6.0, {}
        if "cutting" in system.components:
            values = system.components["cutting"].values
            diameter_mm = float(values["tool_diameter"][0]) * 1e3
            tools = _table_tool_lives(values, model)
        summary = summarize(recording, cycle_time, model, diameter_mm, tools)
    else:
        summary = {"success": run.success, "message": run.message, "cycle_time_s": cycle_time}
    summary["system"] = str(system_file)
    result = SimulationResult(recording, summary, run.success, run.message)
    if out is not None:
        out = Path(out)
        result.files["recording"] = recording.write_csv(out / "recording.csv")
        result.files["summary"] = atomic_write_json(out / "summary.json", summary)
        if plot and "line" in recording and len(recording) > 1:
            result.files["overview"] = overview_png(recording, out / "overview.png", title=Path(system_file).name)
    return result
