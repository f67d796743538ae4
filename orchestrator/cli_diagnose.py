"""``cnctwin diagnose`` sub-command.

The lead's :mod:`orchestrator.cli` calls :func:`add_parsers` with its
sub-parsers object; the command calls :func:`orchestrator.diagnose.diagnose`.
"""
from __future__ import annotations

import argparse
import sys
from .cli import emit


def _cmd_diagnose(args: argparse.Namespace) -> int:
    from .diagnose import diagnose

    def progress(message: str) -> None:
        if not args.quiet:
            emit(f"diagnose: {message}", file=sys.stderr)

    result = diagnose(args.case, holdout=args.holdout, machine=args.machine, axes=args.axes,
                      vertical=tuple(args.vertical), refit_scales=not args.no_scales, progress=progress,
                      cutting=False if args.no_cutting else None, drives=not args.no_drives)
    files = result.write(args.out, plots=not args.no_plots)
    found = ", ".join(f"{e['effect']} ({e.get('axis', 'cutting')})" for e in result.effects) \
        or "no effect above the noise"
    emit(f"effects: {found}")
    if result.unexplained:
        emit("unexplained: " + ", ".join(",".join(u["channels"]) for u in result.unexplained))
    for channel, before in result.rms_before.items():
        emit(f"rms {channel}: {before:g} -> {result.rms_after[channel]:g}")
    for name, path in files.items():
        emit(f"wrote {name}: {path}")
    return 0


def add_parsers(subparsers: argparse._SubParsersAction) -> None:
    """Add ``diagnose`` to the ``cnctwin`` sub-command parsers."""
    p = subparsers.add_parser(
        "diagnose", help="locate where a recording disagrees with the twin, name and refit the missing physics")
    p.add_argument("case", metavar="CASE_DIR", help="case folder with case.toml, program and recording")
    p.add_argument("--holdout", metavar="CASE_DIR", help="a second case, only re-simulated (RMS before/after)")
    p.add_argument("--out", required=True, help="result folder (diagnosis.json, machine.toml, report.md, plots)")
    p.add_argument("--machine", help="parameter set to start from (default: the case's)")
    p.add_argument("--axes", nargs="+", choices=("x", "y", "z"), help="axes to diagnose (default: all that move)")
    p.add_argument("--vertical", nargs="*", default=["z"], choices=("x", "y", "z"),
                   help="axes carrying a weight (gravity candidates; default z)")
    p.add_argument("--no-scales", action="store_true", help="do not refit the scale factors Spp, Svp, Svi")
    p.add_argument("--no-drives", action="store_true",
                   help="diagnose only the cutting process (forces, spindle speed), not the feed drives")
    p.add_argument("--no-cutting", action="store_true",
                   help="diagnose only the feed drives, even when the recording has forces")
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    p.set_defaults(func=_cmd_diagnose)
