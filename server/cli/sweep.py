"""`srlab sweep`: a grid of learning parameters x conditions x seeds, and its report."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import IO

from rich.console import Console
from rich.table import Table

from core.params import PARAMETERS
from core.run.conditions import CONDITIONS
from server.cli.common import (
    add_task_arguments,
    command_line,
    report_failures,
    run_batch,
    setup_of,
)
from server.cli.conditions import add_network_arguments, with_conditions
from server.reports.base import fmt, setup_params


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `sweep` command and its arguments."""
    names = "; ".join(f"{p.name} {p.bounds} ({p.scope})" for p in PARAMETERS.values())
    sweep = sub.add_parser(
        "sweep",
        help="run a grid of learning parameters x conditions x seeds and write a report",
        description="Run every combination of the --param values for every condition and "
        "seed (locally or on Ray), then write summary.json, summary.md, runs.jsonl, "
        "learning_curves.png and a param_NAME.png per parameter to --out. Parameters: "
        f"{names}.",
    )
    sweep.add_argument(
        "--param",
        action="append",
        required=True,
        metavar="NAME=V1,V2,...",
        help="a parameter and its values; repeat for a grid (e.g. --param eta=0.05,0.1 "
        "--param epsilon=0.05,0.1)",
    )
    sweep.add_argument(
        "--conditions",
        default="kp,qlambda",
        help=f"comma-separated, from: {', '.join(CONDITIONS)}, or condition files (.toml, "
        "docs/conditions.md; FILE.toml:NAME for one of a file's) (default: kp,qlambda)",
    )
    add_task_arguments(sweep, Path("results/sweep"))
    add_network_arguments(sweep)
    sweep.set_defaults(handler=sweep_command)


def sweep_command(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab sweep`."""
    from core.lab.experiment import parse_conditions
    from core.lab.sweep import Sweep, parse_grid, run_sweep, summarise_sweep
    from core.params import format_value
    from server.reports.sweep import write_sweep_report

    setup, named = with_conditions(
        setup_of(args), args.conditions.split(","), args.network, args.url
    )
    plan = Sweep(
        parse_grid(args.param),
        tuple(parse_conditions(",".join(named), setup)),
        tuple(range(args.seed_base, args.seed_base + args.seeds)),
        args.episodes,
        setup,
    )
    tasks = plan.tasks()
    err = Console(file=stderr, stderr=True)
    results, elapsed, where = run_batch(
        args, err, "sweep", len(tasks), lambda backend, on: run_sweep(plan, backend, on)
    )
    summary = summarise_sweep(plan, results)
    params = {
        "command": command_line(args),
        "conditions": list(plan.conditions),
        "seeds": len(plan.seeds),
        "seed_base": args.seed_base,
        "episodes": plan.episodes,
        "points": len(plan.points()),
        **setup_params(plan.setup),
        "tasks": len(tasks),
        "backend": args.backend,
        "address": args.address,
        "jobs": args.jobs,
        "where": where,
        "elapsed_s": elapsed,
        "ticks": sum(r.ticks for r in results),
    }
    paths = write_sweep_report(args.out, plan, results, summary, params)

    console = Console(file=stdout)
    for name, values in plan.axes:
        entry = summary["by_parameter"][name]
        table = Table(title=f"{name} (other parameters averaged)")
        table.add_column(name, justify="right")
        conds = list(entry["conditions"])
        for c in conds:
            table.add_column(f"{c} success", justify="right")
            table.add_column(f"{c} last 10", justify="right")
        for i, v in enumerate(values):
            cells = [format_value(v)]
            for c in conds:
                row = entry["conditions"][c][i]
                cells += [
                    fmt(row["success_rate"], pct=True),
                    fmt(row["success_last10"], pct=True),
                ]
            table.add_row(*cells)
        console.print(table)
        if entry["ignored_by"]:
            console.print(f"  ({', '.join(entry['ignored_by'])} does not use {name})")
    ticks = params["ticks"]
    rate = f" ({ticks / elapsed:,.0f} ticks/s)" if elapsed > 0 else ""
    console.print(f"{len(tasks)} tasks, {ticks:,} ticks in {elapsed:.1f} s on {where}{rate}")
    for p in paths:
        console.print(f"wrote {p}")
    return report_failures(err, results, params=True)
