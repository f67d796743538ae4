"""Outputs of an optimisation: ``optimized.nc``, ``report.json``, ``report.png`` (atomic writes)."""
from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..atomic import atomic_write_bytes, atomic_write_json, atomic_write_text


def _pct(before: float | None, after: float | None) -> float | None:
    if before is None or after is None or before == 0:
        return None
    return 100.0 * (before - after) / before


def _clean(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(float(obj)) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, Path):
        return str(obj)
    return obj


def report_dict(result, ctx, settings) -> dict[str, Any]:
    """What ``report.json`` holds."""
    identity = settings.identity()
    return _clean({
        "program": str(ctx.case.program),
        "case": str(ctx.case.source or ctx.case.folder),
        "settings": {**identity, "gens": settings.gens, "workers": settings.workers,
                     "dask": None if settings.dask is None else str(settings.dask),
                     "check_front": bool(settings.check_front), "tidy": bool(settings.tidy),
                     "push": bool(settings.push)},
        "cutting_line_rule": f"feed move removing >= {settings.min_removed_mm3:g} mm3 in the reference run",
        "search_cutting_model": "path" if ctx.engagement is not None else "zmap",
        "tool_changes": result.tool_changes,
        "notes": result.notes,
        "removed_mm3_by_line": {str(k): v for k, v in sorted(ctx.removed_mm3.items())},
        "before": result.before,
        "after": result.after,
        "reduction_percent": {
            "cycle_time": _pct(result.before["cycle_time_s"], result.after["cycle_time_s"]),
            "cost": _pct(result.before["cost_KRW"], result.after["cost_KRW"]),
        },
        "X": result.X,
        "lines": result.lines,
        "history": result.history,
        "pareto_front": result.front,
        "push": result.push,
        "tidy": result.tidy,
        "evaluations": result.evaluations,
        "wall_time_s": result.wall_time_s,
    })


def _envelope(x: np.ndarray, n: int) -> np.ndarray:
    """Running maximum over ``n`` samples (the tooth-passing ripple hides the load level otherwise)."""
    if n <= 1 or x.size < n:
        return x
    from numpy.lib.stride_tricks import sliding_window_view

    padded = np.concatenate([np.full(n - 1, x[0]), x])
    return sliding_window_view(padded, n).max(axis=1)


def _plot_front(ax, front: list[dict[str, Any]]) -> None:
    """The front in the search's figures: filled markers pass the Z-map check, hollow ones exceed the limit."""
    t = np.array([p["cycle_time_s"] for p in front], float)
    c = np.array([p["cost_KRW"] for p in front], float)
    status = [p.get("zmap_feasible") for p in front]
    ax.plot(t, c, "-", color="tab:blue", lw=0.8)
    ok = np.array([v is not False for v in status])
    checked = any(v is not None for v in status)
    ax.plot(t[ok], c[ok], "o", color="tab:blue",
            label="feasible non-dominated" + (" (Z-map checked)" if checked else ""))
    if not ok.all():
        ax.plot(t[~ok], c[~ok], "o", mfc="none", mec="tab:red", mew=1.5, ms=8, label="over the limit in Z-map")


def report_png(result, path: Path, title: str = "", load_limit_N: float | None = None) -> Path:
    """Load and feed vs time before/after, convergence, and the Pareto front (when there is one).

    The load is the 20 ms running maximum of the per-step peak; rapid traverse is cut off the feed axis.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8))
    (ax_load, ax_feed), (ax_conv, ax_front) = axes
    for rec, label, color in ((result.recording_before, "before", "tab:gray"), (result.recording_after, "after", "tab:blue")):
        if rec is None:
            continue
        t = np.asarray(rec.t)
        if "fc_peak_N" in rec:
            n = max(1, int(round(0.02 / max(float(np.median(np.diff(t))), 1e-9)))) if t.size > 1 else 1
            ax_load.plot(t, _envelope(np.asarray(rec["fc_peak_N"], float).ravel(), n), color=color, lw=0.8,
                         label=label)
        if "feed_mm_per_min" in rec:
            ax_feed.plot(t, np.asarray(rec["feed_mm_per_min"]).ravel(), color=color, lw=0.8, label=f"feed {label}")
        if "spindle_rpm" in rec:
            ax_spin = ax_feed.twinx() if not hasattr(ax_feed, "_cnc_twin") else ax_feed._cnc_twin
            ax_feed._cnc_twin = ax_spin
            ax_spin.plot(t, np.asarray(rec["spindle_rpm"]).ravel(), color=color, lw=0.8, ls="--")
            ax_spin.set_ylabel("spindle speed (dashed), rpm")
    if load_limit_N is not None:
        ax_load.axhline(load_limit_N, color="tab:red", ls=":", label=f"limit {load_limit_N:g} N")
    feeds = [v for row in result.lines for v in (row["feed_before_mm_per_min"], row["feed_after_mm_per_min"])]
    if feeds:
        ax_feed.set_ylim(0.0, 1.3 * max(feeds))
    ax_load.set_xlabel("time, s")
    ax_load.set_ylabel("cutting load (20 ms max of step peaks), N")
    ax_load.legend(loc="upper right")
    ax_feed.set_xlabel("time, s")
    ax_feed.set_ylabel("path feed (rapids off scale), mm/min")
    ax_feed.legend(loc="upper left")
    gens = [h["generation"] for h in result.history]
    best = [h["best"] for h in result.history]
    if best and isinstance(next((b for b in best if b is not None), None), list):
        for j, name in enumerate(("cycle time, s", "cost, KRW")):
            ax_conv.plot(gens, [b[j] if b else np.nan for b in best], marker="o", label=f"best {name}")
    else:
        ax_conv.plot(gens, [b if b is not None else np.nan for b in best], marker="o", label="best feasible objective")
    ax_conv.set_xlabel("generation")
    ax_conv.set_ylabel("objective")
    ax_conv.legend()
    if result.front:
        _plot_front(ax_front, result.front)
    for d, label, marker in ((result.before, "original", "s"), (result.after, "optimised", "*")):
        if d.get("cycle_time_s") is not None:
            ax_front.plot(d["cycle_time_s"], d["cost_KRW"], marker, ms=10, label=label)
    ax_front.set_xlabel("cycle time, s")
    ax_front.set_ylabel("production cost, KRW")
    ax_front.legend()
    fig.suptitle(title)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    plt.close(fig)
    return atomic_write_bytes(Path(path), buf.getvalue())


def write_outputs(result, ctx, settings, out: Path) -> dict[str, Path]:
    """Write ``optimized.nc``, ``report.json`` and (``settings.plot``) ``report.png`` into ``out``."""
    out = Path(out)
    files = {"program": atomic_write_text(out / "optimized.nc", result.program_text)}
    files["report"] = atomic_write_json(out / "report.json", report_dict(result, ctx, settings))
    if settings.plot:
        files["plot"] = report_png(result, out / "report.png", title=f"{ctx.case.program.name}: "
                                   f"{settings.objective} ({settings.method})", load_limit_N=ctx.load_limit_N)
    return files
