"""`srlab phase`: a phase diagram over world parameters, and its report."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import IO

from rich.console import Console
from rich.table import Table

from core.run.conditions import CONDITIONS
from server.cli.common import (
    add_task_arguments,
    command_line,
    print_table,
    report_failures,
    run_batch,
    setup_of,
)
from server.reports.base import setup_params

DEFAULT_CONDITIONS = "kp,sonar,rp,qlambda-hybrid,dp"


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `phase` command and its arguments."""
    from core.sim.worlds import WORLD_PARAMETERS

    names = "; ".join(
        f"{p.name} ({p.unit}, {p.parameter.bounds}): {p.parameter.description}"
        for p in WORLD_PARAMETERS.values()
    )
    phase = sub.add_parser(
        "phase",
        help="where a comparison holds: conditions x seeds on a star of world parameters",
        description="Vary each declared world parameter alone around the base world "
        "(--world), run reflexes (the sonar reflexes alone) and every condition on each "
        "point on the same seeds, and plot each difference (the first condition minus each "
        "other, paired by seed) against the success of reflexes there. Writes "
        "summary.json, summary.md (the command, the declared grid, a table per parameter), "
        f"runs.jsonl, phase.png and phase_by_parameter.png to --out. Parameters: {names}.",
    )
    phase.add_argument(
        "--grid",
        type=Path,
        metavar="FILE",
        help="a TOML file declaring the grid: NAME = [V1, V2, ...] per world parameter",
    )
    phase.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=V1,V2,...",
        help="a world parameter and its values (repeat for more; with or instead of --grid)",
    )
    phase.add_argument(
        "--conditions",
        default=DEFAULT_CONDITIONS,
        help=f"comma-separated, from: {', '.join(CONDITIONS)}; the first is compared with "
        f"each other (default: {DEFAULT_CONDITIONS})",
    )
    phase.add_argument(
        "--untuned",
        action="store_true",
        help="run every condition with its default parameters, not the tuned ones",
    )
    add_task_arguments(phase, Path("results/phase"))
    phase.set_defaults(handler=phase_command)


def phase_command(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab phase`."""
    from core.lab.experiment import parse_conditions
    from core.lab.phase import Phase, load_grid, merge_axes, parse_axes, run_phase, summarise_phase
    from core.lab.stats import Estimate, pct
    from core.params import ParameterError, tuned_params
    from server.reports.base import diff
    from server.reports.phase import write_phase_report

    if args.grid is None and not args.param:
        raise ParameterError("declare the grid: --grid FILE or --param NAME=V1,V2,...")
    axes = merge_axes(
        load_grid(args.grid) if args.grid is not None else (),
        parse_axes(args.param) if args.param else (),
    )
    plan = Phase(
        axes,
        tuple(parse_conditions(args.conditions)),
        tuple(range(args.seed_base, args.seed_base + args.seeds)),
        args.episodes,
        setup_of(args),
        tuned=not args.untuned,
    )
    tasks = plan.tasks()
    err = Console(file=stderr, stderr=True)
    results, elapsed, where = run_batch(
        args, err, "phase", len(tasks), lambda backend, on: run_phase(plan, backend, on)
    )
    summary = summarise_phase(plan, results)
    params = {
        "command": command_line(args),
        "grid_file": str(args.grid) if args.grid is not None else None,
        "conditions": list(plan.all_conditions),
        "seeds": len(plan.seeds),
        "seed_base": args.seed_base,
        "episodes": plan.episodes,
        **setup_params(plan.setup),
        "points": len(plan.points()),
        "tasks": len(tasks),
        "tuned": {
            c: dict(tuned_params(c)) for c in plan.all_conditions if plan.tuned and tuned_params(c)
        },
        "backend": args.backend,
        "jobs": args.jobs,
        "where": where,
        "elapsed_s": elapsed,
        "ticks": sum(r.ticks for r in results),
    }
    paths = write_phase_report(args.out, plan, results, summary, params)

    table = Table(
        title=f"srlab phase: {len(plan.points())} points x {len(plan.seeds)} seeds x "
        f"{plan.episodes} episodes around world {plan.setup.world_name}"
    )
    names = list(summary["regions"])
    for col in ("point", "reflexes' success", *names):
        table.add_column(col, justify="left" if col == "point" else "right")
    for p in summary["points"]:
        s = p["conditions"]["reflexes"]["success_rate"]
        table.add_row(
            p["label"],
            pct(Estimate.of(s)) if s else "failed",
            *(diff(p["differences"][n]) for n in names),
        )
    console = print_table(stdout, table)
    ticks = params["ticks"]
    rate = f" ({ticks / elapsed:,.0f} ticks/s)" if elapsed > 0 else ""
    console.print(f"{len(tasks)} tasks, {ticks:,} ticks in {elapsed:.1f} s on {where}{rate}")
    for p in paths:
        console.print(f"wrote {p}")
    return report_failures(err, results, params=True)
