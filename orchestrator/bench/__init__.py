"""``cnctwin bench``: how fast the twin runs, and what each layer (master, FMU calls, components) costs.

* :func:`run_bench` / :class:`BenchSettings` / :func:`format_table` — the whole measurement, one process.
* :mod:`.fused` — the fused reference (servo + drives + simple cutting load in one numba loop).
* :mod:`.cfmu` — the C-FMU fixture (four first-order lags in a ring).
* :mod:`.systems` — the native lag ring, the pythonfmu servo system, the plain fmpy loop.
"""
from .core import TARGETS, BenchSettings, format_table, machine_info, run_bench

__all__ = ["TARGETS", "BenchSettings", "format_table", "machine_info", "run_bench"]
