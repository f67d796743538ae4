"""``cnctwin bench``: thin CLI over :func:`orchestrator.bench.run_bench`.

Prints a table on stdout followed by the JSON (or writes the JSON to
``--json``); progress lines go to stderr. The lead's :mod:`orchestrator.cli` calls :func:`add_parsers`.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from .cli import emit


def _cmd_bench(args: argparse.Namespace) -> int:
    from .atomic import atomic_write_json
    from .bench import format_table, run_bench

    progress = None if args.silent else (lambda text: emit(f"... {text}", file=sys.stderr, flush=True))
    result = run_bench(quick=args.quick, progress=progress)
    emit(format_table(result))
    if args.json:
        atomic_write_json(Path(args.json), result)
        emit(f"\nwrote {args.json}")
    else:
        emit()
        emit(json.dumps(result, indent=2, default=float))
    return 0


def add_parsers(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``bench`` sub-command to ``cnctwin``."""
    p = subparsers.add_parser(
        "bench", help="measure real-time factors and per-step costs of the twin and its FMU paths")
    p.add_argument("--quick", action="store_true", help="short measurements (well under a minute; rough figures)")
    p.add_argument("--json", metavar="FILE", help="write the JSON result to FILE instead of printing it")
    p.add_argument("--silent", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=_cmd_bench)
