"""``cnctwin build-fmus`` and ``cnctwin check-fmu``: thin CLI over :mod:`orchestrator.fmu`.

The lead's :mod:`orchestrator.cli` calls :func:`add_parsers`; errors the user
can cause are :class:`~orchestrator.errors.CncTwinError` and are reported by
``cli.main`` (exit status 2). ``check-fmu`` exits 1 when the FMU is not OK.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from .errors import CncTwinError
from .cli import emit


def _parse_mapping(items: list[str]) -> dict[str, str]:
    mapping = {}
    for item in items:
        ours, sep, theirs = item.partition("=")
        if not sep or not ours or not theirs:
            raise CncTwinError(f"--map {item!r}: expected OUR_NAME=THEIR_NAME")
        mapping[ours] = theirs
    return mapping


def _parse_values(items: list[str]) -> dict[str, object]:
    values: dict[str, object] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise CncTwinError(f"--set {item!r}: expected NAME=VALUE")
        try:
            values[name] = float(text)
        except ValueError:
            values[name] = text
    return values


def _cmd_build_fmus(args: argparse.Namespace) -> int:
    from .fmu import build_fmus

    for path in build_fmus(out_dir=Path(args.out), machine=args.machine):
        emit(f"built {path}")
    return 0


def _cmd_check_fmu(args: argparse.Namespace) -> int:
    from .fmu import check_fmu

    report = check_fmu(args.path, role=args.role, mapping=_parse_mapping(args.map),
                       parameters=_parse_values(args.set))
    emit(report.to_text())
    return 0 if report.ok else 1


def add_parsers(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``build-fmus`` and ``check-fmu`` sub-commands to ``cnctwin``."""
    from .fmu.paths import DEFAULT_OUT_DIR
    from .fmu.roles import ROLES

    p = subparsers.add_parser("build-fmus", help="export every component as an FMI 2.0 co-simulation FMU")
    p.add_argument("--out", default=str(DEFAULT_OUT_DIR), help=f"output folder (default {DEFAULT_OUT_DIR})")
    p.add_argument("--machine", default="default", help="machine parameter set name or TOML file (default 'default')")
    p.set_defaults(func=_cmd_build_fmus)

    p = subparsers.add_parser("check-fmu", help="validate an FMU, run it briefly, check it fits a role of the twin")
    p.add_argument("path", help="the .fmu file")
    p.add_argument("--role", choices=sorted(ROLES), help="component role it should stand in for")
    p.add_argument("--map", action="append", default=[], metavar="OUR=THEIRS",
                   help="variable name mapping for the role check (repeatable)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="parameter for the smoke run, e.g. program_file=part.nc (repeatable)")
    p.set_defaults(func=_cmd_check_fmu)
