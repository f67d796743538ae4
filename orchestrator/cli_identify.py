"""``cnctwin identify`` and ``cnctwin experiment`` sub-commands.

The lead's :mod:`orchestrator.cli` calls :func:`add_parsers` with its
sub-parsers object; each command calls one documented function.
"""
from __future__ import annotations

import argparse
import json

from .cli import emit
from .errors import CncTwinError


def _cmd_identify(args: argparse.Namespace) -> int:
    from .identify import identify

    options: dict = {}
    if args.axes:
        if args.kind == "cutting":
            raise CncTwinError("--axes applies to friction and servo only")
        options["axes"] = list(args.axes)
    if args.machine:
        if args.kind != "servo":
            raise CncTwinError("--machine applies to servo only (friction and cutting use the case's)")
        options["machine"] = args.machine
    fit = identify(args.kind, args.cases, out=args.out, method=args.method, seed=args.seed, resume=args.resume,
                   **options)
    report = fit.report()
    report.pop("segments", None)
    emit(json.dumps(report, indent=2))
    for name, path in fit.files_.items():
        emit(f"wrote {name}: {path}")
    return 0


def _cmd_experiment(args: argparse.Namespace) -> int:
    from .experiments import write_experiment

    kwargs: dict = {"machine": args.machine}
    if args.axes:
        kwargs["axes"] = tuple(args.axes)
    if args.speeds:
        kwargs["speeds_mm_min"] = tuple(args.speeds)
    files = write_experiment(args.kind, args.out, **kwargs)
    for name, path in files.items():
        emit(f"wrote {name}: {path}")
    emit(f"run {files['program'].name} on the machine, save the log as recording.csv in {args.out}, then: "
          f"cnctwin identify {args.kind} {args.out} --out <result folder>")
    return 0


def add_parsers(subparsers: argparse._SubParsersAction) -> None:
    """Add ``identify`` and ``experiment`` to the ``cnctwin`` sub-command parsers."""
    p = subparsers.add_parser("identify",
                              help="fit friction, servo scale factors or cutting coefficients to recordings")
    p.add_argument("kind", choices=("friction", "servo", "cutting"))
    p.add_argument("cases", nargs="+", metavar="CASE_DIR", help="case folders with case.toml and recording.csv")
    p.add_argument("--out", required=True, help="result folder (machine.toml, report.json, plots, checkpoints/)")
    p.add_argument("--method", choices=("default", "paper-ga"), default="default",
                   help="optimiser: fast least squares (default) or the paper's genetic algorithm")
    p.add_argument("--seed", type=int, default=0, help="random seed of the genetic algorithm")
    p.add_argument("--axes", nargs="+", choices=("x", "y", "z"), help="axes to identify (default: all that move)")
    p.add_argument("--machine", help="servo only: machine file with the identified friction (default: the case's)")
    p.add_argument("--resume", action="store_true",
                   help="continue the killed job from its checkpoints in --out (same cases, method, seed, options)")
    p.set_defaults(func=_cmd_identify)

    p = subparsers.add_parser("experiment", help="write an identification program and case folder")
    p.add_argument("kind", choices=("friction", "servo", "cutting"))
    p.add_argument("--out", required=True, help="case folder to create")
    p.add_argument("--machine", default="default", help="machine set name or TOML file")
    p.add_argument("--axes", nargs="+", choices=("x", "y", "z"), help="axes to run (friction, servo)")
    p.add_argument("--speeds", nargs="+", type=float, help="speeds in mm/min (friction, servo)")
    p.set_defaults(func=_cmd_experiment)
