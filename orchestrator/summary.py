"""Figures of merit of a run: cycle time, per-line times and loads, following error, cost."""
from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from typing import Any

import numpy as np

from .cost import CostModel, ToolLife, production_cost, tool_use_json
from .recording import Recording

AXES = ("x", "y", "z")


def _sample_weights(t: np.ndarray) -> np.ndarray:
    """Time each sample stands for (forward difference; the last sample gets none), s."""
    w = np.zeros_like(t)
    w[:-1] = np.diff(t)
    return w


def line_table(recording: Recording) -> list[dict[str, Any]]:
    """Per source line: time spent executing it and, with cutting, max and mean load.

    Returns
    -------
    list of dict
        ``{"line", "time_s"[, "max_load_N", "mean_load_N"]}`` in order of first execution.
    """
    t = recording.t
    lines = recording["line"]
    weights = _sample_weights(t)
    load = recording["fc_peak_N"] if "fc_peak_N" in recording else (recording["fc_N"] if "fc_N" in recording else None)
    mean_source = recording["fc_N"] if "fc_N" in recording else None
    valid = np.isfinite(lines)
    order, first = np.unique(lines[valid], return_index=True)
    rows = []
    for line in order[np.argsort(first)]:
        mask = lines == line
        row: dict[str, Any] = {"line": int(line), "time_s": float(weights[mask].sum())}
        if load is not None and mean_source is not None:
            w = weights[mask]
            row["max_load_N"] = float(np.nanmax(load[mask]))
            row["mean_load_N"] = float(np.sum(mean_source[mask] * w) / w.sum()) if w.sum() > 0 else float(mean_source[mask][0])
        rows.append(row)
    return rows


def following_error_stats(recording: Recording) -> tuple[dict[str, float], dict[str, float]]:
    """RMS and max absolute following error per axis, µm."""
    rms, peak = {}, {}
    for a in AXES:
        if f"{a}_ref_mm" in recording and f"{a}_mm" in recording:
            e = recording.following_error_um(a)
            e = e[np.isfinite(e)]
            rms[a] = float(np.sqrt(np.mean(e**2))) if e.size else math.nan
            peak[a] = float(np.max(np.abs(e))) if e.size else math.nan
    return rms, peak


def summarize(
    recording: Recording,
    cycle_time_s: float,
    cost_model: CostModel | None = None,
    tool_diameter_mm: float | ToolLife = 6.0,
    tools: Mapping[int, ToolLife] | None = None,
) -> dict[str, Any]:
    """Summary of a single-member run, as written to ``summary.json``.

    Parameters
    ----------
    recording : Recording
        The twin's recording (spec channels).
    cycle_time_s : float
        Time from program start to program end, s.
    cost_model : CostModel, optional
        When given, ``cost_KRW`` (Eq. 19–22) is included.
    tool_diameter_mm : float or ToolLife
        The cutter of every tool ``tools`` does not list (the case's ``[tool]``): its diameter for the cutting
        speed in Taylor's equation, mm, or its :class:`~orchestrator.cost.ToolLife`.
    tools : mapping int -> ToolLife, optional
        The case's tool table (``[tools.T<n>]``). The tool wear goes, sample by sample, to the tool in the
        spindle (the recording's ``tool`` channel; without it, one tool).
    """
    summary: dict[str, Any] = {
        "success": bool(recording.success),
        "message": recording.message,
        "cycle_time_s": float(cycle_time_s),
    }
    rms, peak = following_error_stats(recording)
    if rms:
        summary["rms_following_error_um"] = rms
        summary["max_following_error_um"] = peak
    load_channel = "fc_peak_N" if "fc_peak_N" in recording else ("fc_N" if "fc_N" in recording else None)
    if load_channel:
        summary["max_cutting_load_N"] = float(np.nanmax(recording[load_channel]))
    if cost_model is not None and "spindle_rpm" in recording:
        in_spindle = recording["tool"] if "tool" in recording else None
        cost = production_cost(recording.t, recording["spindle_rpm"], tool_diameter_mm, cost_model, cycle_time_s,
                               in_spindle, tools)
        summary["cost_KRW"] = cost.total_KRW
        summary["cost"] = {
            "tool_KRW": cost.tool_KRW,
            "machining_KRW": cost.machining_KRW,
            "tool_life_used": cost.tool_life_used,
            "tools": tool_use_json(cost),
        }
    summary["lines"] = line_table(recording)
    return summary


def tool_notes(changes: list[tuple[int, int]], cutting: bool, diameter_mm: float, flutes: int,
               listed: Collection[int] = ()) -> tuple[list[dict[str, int]], list[str]]:
    """The program's tool changes, and what the twin assumes about them.

    Parameters
    ----------
    changes : list of (int, int)
        ``(line, tool)`` of every M6, in execution order.
    cutting : bool
        Whether the run computes a cutting load (the case has a ``[stock]``).
    diameter_mm, flutes : float, int
        The case's ``[tool]`` (mm, teeth): the cutter of every tool the tool table does not list.
    listed : collection of int
        The tool numbers of the case's tool table (``[tools.T<n>]``), each cut with its own cutter.

    Returns
    -------
    tool_changes : list of dict
        ``{"line": ..., "tool": ...}`` per M6.
    notes : list of str
        When the run cuts and the program puts a tool in the spindle that the tool table does not list
        (and it uses more than one tool, or the case has a tool table): that tool's cutting load is
        computed with ``[tool]`` (a drill after an end mill, unlisted, is modelled as the end mill). Empty
        otherwise (one tool and no table: ``[tool]`` is that tool).
    """
    table = [{"line": int(line), "tool": int(tool)} for line, tool in changes]
    tools = sorted({int(tool) for _, tool in changes})
    listed = {int(n) for n in listed}
    unlisted = [t for t in tools if t not in listed]
    notes = []
    if cutting and unlisted and (len(tools) > 1 or listed):
        first = next(line for line, tool in changes if int(tool) in unlisted and (listed or tool != changes[0][1]))
        cutter = f"[tool]: {diameter_mm:g} mm, {flutes} flutes"
        if listed:
            notes.append(
                f"the program uses {', '.join(f'T{t}' for t in unlisted)} (the first change to one at line {first}), "
                f"which the case's [tools] does not list ({', '.join(f'T{t}' for t in sorted(listed))}); their "
                f"cutting load is computed with {cutter}")
        else:
            notes.append(
                f"the program uses tools {', '.join(f'T{t}' for t in tools)} (the first change to another tool at "
                f"line {first}); the case has no tool table ([tools.T<n>]) and describes one tool ({cutter}), and "
                "the cutting load of every tool is computed with it")
    return table, notes
