"""The reference run: the original program on the twin, once, to find the cutting lines."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fmus_src.nck.blocks import Arc, Linear
from fmus_src.nck.writer import inch_lines

from ..case import Case
from ..twin import TwinOptions, build_twin, cutting_effect_parameters, engagement_table
from .context import ProblemContext, Ranges, check_context, classify_lines
from .evaluate import Evaluation, figures, run_twin
from .errors import OptimizeError
from .tapping import check_tapping_spindle

#: Default threshold of a cutting line: removed volume in the reference run, mm3.
MIN_REMOVED_MM3 = 0.1
#: Default cycle-time cut-off of an evaluation, as a multiple of the original cycle time.
MAX_CYCLE_FACTOR = 1.5
#: What the path-mode cutting load reports when a member leaves the engagement table's path.
OFF_PATH = "farther than path_tolerance"


@dataclass
class Reference:
    """The problem found from the reference run, and that run's figures.

    Attributes
    ----------
    context : ProblemContext
        Cutting lines, S-word lines, pins, original values.
    evaluation : Evaluation
        Figures of the original program (B = 1).
    recording : Recording
        The full recording of the reference run (for plots).
    """

    context: ProblemContext
    evaluation: Evaluation
    recording: object


def removed_volume_by_line(recording) -> dict[int, float]:
    """Removed volume per executing line, mm3 (integral of the MRR channel)."""
    t = np.asarray(recording.t, float)
    lines = np.asarray(recording["line"], float).ravel()
    mrr = np.asarray(recording["mrr_mm3_per_min"], float).ravel() / 60.0  # mm3/s, step mean over (t-h, t]
    dt = np.zeros_like(t)
    dt[1:] = np.diff(t)  # the step mean recorded at t covers the step ending at t
    out: dict[int, float] = {}
    # attribute a step's removal to the line executing at the start of that step
    prev = np.concatenate([[lines[0]], lines[:-1]])
    for line in np.unique(prev[np.isfinite(prev)]):
        mask = prev == line
        out[int(line)] = float(np.sum(mrr[mask] * dt[mask]))
    return out


def _per_revolution_lines(blocks, lines: set[int], file: str) -> frozenset[int]:
    """The given feed lines that run under G95 (feed per revolution); a line run in both modes is refused.

    Raises
    ------
    OptimizeError
        Naming the file and the line whose runs are in G94 and in G95 (a subprogram called in both modes).
    """
    modes: dict[int, set[bool]] = {}
    for b in blocks:
        if isinstance(b, (Linear, Arc)) and b.line in lines:
            modes.setdefault(b.line, set()).add(b.feed_per_rev > 0.0)
    mixed = sorted(line for line, m in modes.items() if len(m) > 1)
    if mixed:
        raise OptimizeError(f"{file}:{mixed[0]}: the line runs in feed per minute (G94) and in feed per "
                            "revolution (G95); expected one feed mode in every run of a line whose F the "
                            "optimiser writes (call the subprogram in one mode)")
    return frozenset(line for line, m in modes.items() if m == {True})


def member_off_path(cache: dict) -> str:
    """The first reason in an evaluation cache (``{genes: Evaluation}``) that a member lost the path-mode
    cutting load's path (:data:`OFF_PATH`), naming the line; ``""`` when none did."""
    for ev in cache.values():
        for reason in ev.reason:
            if OFF_PATH in reason:
                return reason
    return ""


#: Effect terms (component parameters) that depend on the teeth: the path mode models them for one cutter
#: (``PathCuttingLoad`` refuses them with a table of several cutters).
TOOTH_EFFECTS = ("runout_eccentricity", "helix_angle", "edge_force_tangential", "edge_force_radial",
                 "tool_stiffness", "chatter_frequency")


def path_mode_limit(case: Case) -> str:
    """Why the path mode cannot search ``case`` from the start, or ``""``.

    Parameters
    ----------
    case : Case
        The case to optimise.

    Returns
    -------
    str
        The note for ``report.json`` when the case's tool table lists cutters other than ``[tool]`` and the
        machine file's ``[cutting.effects]`` turns on an effect term that depends on the teeth
        (:data:`TOOTH_EFFECTS`); ``""`` otherwise.
    """
    if not case.several_tools():
        return ""
    on = sorted(k for k, v in cutting_effect_parameters(case.machine).items() if k in TOOTH_EFFECTS and v != 0)
    if not on:
        return ""
    return (f"the case's tool table ([tools]) lists cutters other than [tool] and the machine file's "
            f"[cutting.effects] turns on {', '.join(on)}, which the path-mode cutting load models for one cutter: "
            "the search ran on the Z-map cutting model (slower)")


def search_on_zmap(ctx: ProblemContext, reason: str) -> None:
    """Move the search of ``ctx`` to the Z-map cutting model because a member of the search lost the path
    mode's path while the original followed it (``reason``: that member's failure, naming the line); the
    note goes to ``report.json``."""
    ctx.engagement = None
    ctx.search_model_note = (f"a member of the search loses the path-mode cutting load's path although the "
                             f"original program follows it ({reason.removeprefix('simulation failed: ')}): the "
                             "search ran on the Z-map cutting model (slower)")


def build_reference(case: Case, program_text: str | None = None, ranges: Ranges | None = None,
                    load_limit_N: float = 60.0, min_removed_mm3: float = MIN_REMOVED_MM3, step: float = 1e-3,
                    time_limit_s: float = 3600.0, max_cycle_factor: float = MAX_CYCLE_FACTOR,
                    cutting_mode: str = "path") -> Reference:
    """Run the original program once and build the optimisation problem.

    Parameters
    ----------
    case : Case
        Case with a stock (an air cut has no cutting line).
    program_text : str, optional
        Program text; default: ``case.program`` read from disk.
    ranges : Ranges, optional
        Search ranges and grid.
    load_limit_N : float
        Cutting load limit, N.
    min_removed_mm3 : float
        A feed line removing at least this volume is a cutting line, mm3.
    step : float
        Communication step, s.
    time_limit_s : float
        Simulated-time limit of the reference run, s.
    max_cycle_factor : float
        Evaluations stop at this multiple of the original cycle time (slower
        individuals are marked failed; see :mod:`.evaluate`).
    cutting_mode : {"path", "zmap"}
        ``"path"`` (default): the engagement along the program's path is
        computed once and reused by every evaluation of the search (several
        times faster; largest loads within 0.1 N of the Z-map model's on the
        bundled parts, which :func:`~.run.optimize` uses for its final
        re-simulation). ``"zmap"``: every individual removes material from its
        own stock. When the path mode fails on the original program itself
        (the tool leaves the table's path, e.g. a reversal on one line inside
        material that the servo turns back from short of its end; the pecks
        of G83, which turn back in air at R, are followed), the Z-map mode is
        used: ``context.engagement`` is then None and
        ``context.search_model_note`` says why, naming the line. A case whose tool table
        (``[tools.T<n>]``) lists cutters other than ``[tool]`` is searched in the path mode too: the table
        is built with the cutter of each path point (:func:`~orchestrator.twin.engagement_table`); only
        with an effect term that depends on the teeth on (:func:`path_mode_limit`) it is searched on the
        Z-map mode, with a note.
    """
    from ..simulate import failure_message  # names the line executing at a failure, as cnctwin simulate does

    if case.stock is None:
        raise OptimizeError(f"{case.source or case.program}: the case has no [stock]; nothing is cut, nothing to optimise")
    if not load_limit_N > 0:
        raise OptimizeError(f"load limit must be positive, got {load_limit_N!r} N")
    text = program_text if program_text is not None else case.program.read_text(encoding="utf-8")
    ranges = ranges or Ranges()
    # the engagement along the path is the same for every individual (only F and S change): compute it once
    limit = path_mode_limit(case) if cutting_mode == "path" else ""  # what the path mode cannot carry
    engagement = (engagement_table(case, TwinOptions(step=step), program_text=text)
                  if cutting_mode == "path" and not limit else None)
    probe = ProblemContext(case, text, np.zeros(0, int), np.zeros(0, int), {}, np.zeros(0), np.zeros(0), ranges,
                           float(load_limit_N), {}, step, time_limit_s, engagement=engagement)
    run = run_twin(probe, None, None, 1, channels=None)
    search_model_note = limit
    if not run.success and engagement is not None and OFF_PATH in run.message:
        # the path mode lost the tool on its own reference path (e.g. a reversal on one line inside material that
        # the servo does not reach): every evaluation removes material from its own Z-map instead
        lost = failure_message(run.message, run.recording, case.program)
        search_model_note = (f"the path-mode cutting load loses the tool on the original program ({lost}): the "
                             "search ran on the Z-map cutting model (slower)")
        engagement = None
        probe.engagement = None
        run = run_twin(probe, None, None, 1, channels=None)
    if not run.success:
        where = failure_message("", run.recording, case.program)
        raise OptimizeError(f"{where or f'{case.program}: '}the original program fails on the twin: {run.message}")
    # the twin has planned the program: reuse its interpretation

    twin = build_twin(case, batch=1, options=TwinOptions(step=step), program_text=text)
    twin.nck.setup(0.0)
    blocks = twin.nck.blocks_
    removed = removed_volume_by_line(run.recording)
    lines, s_lines, pins, f0, s0 = classify_lines(blocks, removed, min_removed_mm3, twin.nck.program_)
    check_tapping_spindle(twin.nck.program_, s_lines, str(case.program))  # tapping: F tied to S
    per_rev = _per_revolution_lines(blocks, set(lines) | set(pins), str(case.program))  # F words in mm/rev
    inch = frozenset(inch_lines(text, list(lines) + list(pins), file=str(case.program)))  # F words in in/min
    ctx = ProblemContext(case, text, np.asarray(lines, int), np.asarray(s_lines, int), pins, np.asarray(f0, float),
                         np.asarray(s0, float), ranges, float(load_limit_N), removed, step, time_limit_s,
                         engagement=engagement, inch_lines=inch, per_rev_lines=per_rev, program=twin.nck.program_,
                         search_model_note=search_model_note)
    check_context(ctx)
    evaluation = figures(ctx, run, 1)
    if not max_cycle_factor > 1.0:
        raise OptimizeError(f"max_cycle_factor must exceed 1, got {max_cycle_factor!r}")
    ctx.original_load_N = np.nan_to_num(evaluation.line_max_load_N[0], nan=0.0)
    ctx.time_limit_s = min(time_limit_s, float(np.ceil(max_cycle_factor * evaluation.cycle_time_s[0])))
    return Reference(ctx, evaluation, run.recording)
