"""``cnctwin optimize``: feed and spindle speed per G-code line (thin layer over :func:`orchestrator.optimize.optimize`).

The lead wires it into ``cnctwin`` with ``add_parsers(subparsers)``; it also
runs on its own: ``python -m orchestrator.cli_optimize PROGRAM --case ... --out DIR``.
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Sequence
from .cli import emit



def _pair(text: str) -> tuple[float, float]:
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH (two numbers), got {text!r}") from None
    return lo, hi


def _cmd_optimize(args: argparse.Namespace) -> int:
    from .optimize import OptimizeSettings, optimize

    settings = OptimizeSettings(
        objective=args.objective, method=args.method, load_limit_N=args.load_limit_N, feed_range=args.feed_range,
        spindle_range=args.spindle_range, pop=args.pop, gens=args.gens, seed=args.seed, workers=args.workers,
        dask=args.dask, resume=args.resume, penalty_weight=args.penalty_weight, fitness_limit=args.fitness_limit,
        step=args.step * 1e-3, max_cycle_factor=args.max_cycle_factor, check_front=not args.no_front_check,
        tidy=not args.no_tidy, push=not args.no_push,
        feed_step=args.feed_step, spindle_step=args.spindle_step, feed_step_in_per_min=args.feed_step_in_per_min,
        feed_step_mm_per_rev=args.feed_step_mm_per_rev, feed_step_in_per_rev=args.feed_step_in_per_rev,
    )
    result = optimize(program=args.program, case=args.case, settings=settings, out=args.out, machine=args.machine)
    keys = ("cycle_time_s", "cost_KRW", "max_cutting_load_N")
    summary = {"before": {k: result.before[k] for k in keys}, "after": {k: result.after[k] for k in keys},
               "evaluations": result.evaluations}
    if result.front:
        summary["front_points"] = len(result.front)
        if "zmap_feasible" in result.front[0]:
            summary["front_over_limit_in_zmap"] = sum(not p["zmap_feasible"] for p in result.front)
    emit(json.dumps(summary, indent=2))
    for name, path in result.files.items():
        emit(f"wrote {name}: {path}")
    return 0


def add_parsers(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``optimize`` sub-command to ``cnctwin``'s sub-parsers."""
    p = subparsers.add_parser("optimize", help="optimise feed and spindle speed per G-code line (pymoo)")
    p.add_argument("program", nargs="?", help="G-code file (overrides the case's program)")
    p.add_argument("--case", required=True, help="case folder or case.toml with a [stock]")
    p.add_argument("--machine", help="machine parameter set overriding the case's")
    p.add_argument("--objective", choices=("time", "cost", "pareto"), default="time",
                   help="machining time (Eq. 17), production cost (Eq. 18-22) or both (NSGA-II front)")
    p.add_argument("--method", choices=("default", "paper"), default="default",
                   help="default: load limit as a constraint; paper: GA with the penalty of Eq. 17/18")
    p.add_argument("--load-limit-N", dest="load_limit_N", type=float, default=60.0, help="cutting load limit, N")
    p.add_argument("--feed-range", type=_pair, default=(100.0, 500.0), help="LOW,HIGH in mm/min (default 100,500)")
    p.add_argument("--spindle-range", type=_pair, default=(1000.0, 8000.0), help="LOW,HIGH in rpm (default 1000,8000)")
    p.add_argument("--feed-step", type=float, default=10.0, help="feed grid a machinist writes, mm/min (default 10)")
    p.add_argument("--feed-step-in-per-min", type=float, default=0.1,
                   help="feed grid of a program cutting under G20, in/min (default 0.1)")
    p.add_argument("--feed-step-mm-per-rev", type=float, default=0.001,
                   help="grid of the F words written on G95 (feed per revolution) lines, mm/rev (default 0.001)")
    p.add_argument("--feed-step-in-per-rev", type=float, default=0.0001,
                   help="the same under G20, in/rev (default 0.0001)")
    p.add_argument("--spindle-step", type=float, default=50.0, help="spindle grid, rpm (default 50)")
    p.add_argument("--pop", type=int, default=20, help="population size (default 20)")
    p.add_argument("--gens", type=int, default=10, help="generations (default 10, as the paper)")
    p.add_argument("--seed", type=int, default=1, help="random seed")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--workers", type=int, default=1, help="worker processes (population split in batched chunks)")
    group.add_argument("--dask", metavar="ADDRESS", help="Dask scheduler address, e.g. tcp://host:8786")
    p.add_argument("--resume", action="store_true", help="continue from the newest checkpoint in --out")
    p.add_argument("--penalty-weight", type=float, default=1.0, help="w of Eq. 17/18 (paper method), objective unit per N")
    p.add_argument("--fitness-limit", type=float, default=None, help="paper method: stop when the best fitness reaches it")
    p.add_argument("--max-cycle-factor", type=float, default=1.5,
                   help="stop simulating individuals slower than this multiple of the original cycle (default 1.5)")
    p.add_argument("--step", type=float, default=1.0, help="communication step, ms (default 1)")
    p.add_argument("--no-front-check", action="store_true",
                   help="pareto: do not re-simulate the front points other than the knee on the Z-map model")
    p.add_argument("--no-tidy", action="store_true",
                   help="time/cost: keep the search's best as it is (no post-pass copying feeds between lines "
                        "that cut alike where that costs nothing)")
    p.add_argument("--no-push", action="store_true",
                   help="time/cost: no post-pass raising feeds toward the load limit by the chip-load rule")
    p.add_argument("--out", required=True, help="output folder (optimized.nc, report.json, report.png, checkpoints/)")
    p.set_defaults(func=_cmd_optimize)


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``optimize`` alone (same behaviour as ``cnctwin optimize``)."""
    from .cli import main as cnctwin_main

    return cnctwin_main(["optimize", *(sys.argv[1:] if argv is None else argv)])


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
