"""``cnctwin`` command line: a thin layer over the Python API.

Every sub-command calls one documented function of :mod:`orchestrator`;
errors the user can cause are printed as one line naming the file, line and
what was expected, with a non-zero exit status and no traceback.
"""
from __future__ import annotations

import argparse
import json
import sys
from importlib import metadata
from typing import Sequence

from .errors import CncTwinError


def emit(*parts: object, file=None, end: str = "\n", flush: bool = False) -> None:
    """The one place the command line writes text (stdout unless ``file`` says otherwise).

    Library modules never print; the ``cli_*`` modules report through this.
    """
    print(*parts, file=file if file is not None else sys.stdout, end=end, flush=flush)


class _ProgressBar:
    """A one-line progress bar on stderr (only when stderr is a terminal)."""

    def __init__(self, label: str) -> None:
        self.label = label
        self.enabled = sys.stderr.isatty()

    def __call__(self, t: float, total: float) -> None:
        if not self.enabled:
            return
        frac = min(1.0, t / total) if total > 0 else 0.0
        bar = "#" * int(30 * frac)
        sys.stderr.write(f"\r{self.label} [{bar:<30}] t = {t:7.2f} s")
        sys.stderr.flush()

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")


def _cmd_simulate(args: argparse.Namespace) -> int:
    from .simulate import simulate, simulate_system_file
    from .twin import TwinOptions

    bar = _ProgressBar("simulate")
    if args.system:
        result = simulate_system_file(
            args.system, out=args.out, native=not args.fmu, time_limit_s=args.time_limit, progress=bar
        )
    else:
        options = TwinOptions(step=args.step * 1e-3, cutting_mode=args.cutting_mode)
        result = simulate(
            program=args.program, case=args.case, machine=args.machine, out=args.out,
            options=options, time_limit_s=args.time_limit or 3600.0, progress=bar,
        )
    bar.close()
    s = result.summary
    keys = ["cycle_time_s", "max_cutting_load_N", "cost_KRW", "rms_following_error_um", "notes"]
    emit(json.dumps({k: s[k] for k in keys if k in s}, indent=2))
    for name, path in result.files.items():
        emit(f"wrote {name}: {path}")
    if not result.success:
        emit(f"cnctwin: error: {result.message}", file=sys.stderr)
        return 1
    return 0


def _cmd_export_ssp(args: argparse.Namespace) -> int:
    from .simulate import resolve_case
    from .twin import write_twin_ssp

    ssd, ssv = write_twin_ssp(resolve_case(args.program, args.case, args.machine), args.ssd)
    emit(f"wrote {ssd}\nwrote {ssv}")
    return 0


def installed_version() -> str:
    """cnctwin's version as installed (``pyproject.toml``), or ``"unknown"`` when run from an uninstalled tree."""
    try:
        return metadata.version("cnctwin")
    except metadata.PackageNotFoundError:
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``cnctwin``."""
    parser = argparse.ArgumentParser(prog="cnctwin", description="Digital twin of a CNC machining center.")
    parser.add_argument("--version", action="version", version=f"cnctwin {installed_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("simulate", help="run a G-code program on the twin")
    p.add_argument("program", nargs="?", help="G-code file (overrides the case's program)")
    p.add_argument("--case", help="case folder or case.toml (stock, tool, machine)")
    p.add_argument("--machine", help="machine parameter set name or TOML file (default: the case's, else 'default')")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--step", type=float, default=1.0, help="communication step, ms (default 1)")
    p.add_argument("--time-limit", type=float, default=None, help="simulated-time limit, s (default 3600)")
    p.add_argument("--cutting-mode", choices=("zmap", "path"), default="zmap",
                   help="zmap: exact material removal on a Z-map (default); path: engagement along the "
                        "program's path computed once (faster; the axes must stay within 0.5 mm of the path)")
    p.add_argument("--system", help="run an SSP 1.0 system file (.ssd) instead of the default twin")
    p.add_argument("--fmu", action="store_true", help="with --system: load every element from its FMU")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("export-ssp", help="write the twin of a case as SSP 1.0 (.ssd + .ssv)")
    p.add_argument("--case", help="case folder or case.toml (default: air cut of --program)")
    p.add_argument("--program", help="G-code file (overrides the case's program)")
    p.add_argument("--machine", help="machine parameter set name or TOML file")
    p.add_argument("--ssd", required=True, help="system structure file to write (.ssd); the .ssv goes beside it")
    p.set_defaults(func=_cmd_export_ssp)

    from .cli_fmu import add_parsers as add_fmu_parsers

    add_fmu_parsers(sub)
    from .cli_bench import add_parsers as add_bench_parsers

    add_bench_parsers(sub)
    from .cli_identify import add_parsers as add_identify_parsers

    add_identify_parsers(sub)
    from .cli_diagnose import add_parsers as add_diagnose_parsers

    add_diagnose_parsers(sub)
    from .cli_optimize import add_parsers as add_optimize_parsers

    add_optimize_parsers(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``cnctwin`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command == "simulate" and args.program is None and args.case is None and args.system is None:
        parser.error("simulate needs a PROGRAM, a --case, or both (or --system FILE.ssd)")
    if args.command == "export-ssp" and args.program is None and args.case is None:
        parser.error("export-ssp needs a --case or a --program")
    try:
        return int(args.func(args))
    except CncTwinError as exc:
        emit(f"cnctwin: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        emit(f"cnctwin: error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
