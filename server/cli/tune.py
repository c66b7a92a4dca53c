"""`srlab tune` and `srlab qlambda-sweep`: the learners' parameters, on seeds of their own."""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import IO

from rich.console import Console
from rich.table import Table

from server.cli.common import (
    add_batch_arguments,
    add_setup_arguments,
    command_line,
    non_negative_int,
    open_backend,
    positive_int,
    print_table,
    progress_bar,
    setup_of,
    task_progress,
)


def add_tune_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `tune` command and its arguments."""
    tn = sub.add_parser(
        "tune",
        help="tune every learner with the same budget on seeds the experiments never use",
        description="Run each learning condition's 27-point grid (core/lab/tune.py) on the "
        "tuning seeds, print every point best first, and with --write keep each learner's "
        "best in core/data/tuned.toml, which srlab experiment then runs with.",
    )
    tn.add_argument(
        "--conditions",
        default="delayed,dp,rp,kp,sonar,qlambda,qlambda-hybrid",
        help="comma-separated learners (default: every one with a grid)",
    )
    add_batch_arguments(tn, seeds=5, seed_base=1000, kind="tuning ")
    add_setup_arguments(tn)
    tn.add_argument("--write", action="store_true", help="write core/data/tuned.toml")
    tn.add_argument("--out", type=Path, help="also write tuning.md and tuning.json here")
    tn.add_argument("--quiet", action="store_true", help="no progress display")
    tn.set_defaults(handler=tune)


def tune(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab tune`."""
    from core.brain.catalog import data_dir
    from core.lab import tune as tuning
    from core.lab.experiment import parse_conditions

    conditions = parse_conditions(args.conditions)
    if args.seed_base < tuning.TUNING_SEED_BASE:
        raise ValueError(
            f"--seed-base {args.seed_base}: tuning seeds start at {tuning.TUNING_SEED_BASE}, "
            "so the experiments' seeds are never tuned on"
        )
    seeds = list(range(args.seed_base, args.seed_base + args.seeds))
    setup = setup_of(args)
    plan = tuning.plan(conditions, seeds, args.episodes, setup)
    total = sum(len(s.tasks()) for s in plan.values())
    err = Console(file=stderr, stderr=True)
    started = time.perf_counter()
    with open_backend(args, err) as (backend, where):
        progress, on_result = task_progress(err, "tune", total, args.quiet)
        with progress:
            rows = tuning.tune(conditions, seeds, args.episodes, setup, backend, on_result)
    elapsed = time.perf_counter() - started
    command = command_line(args)
    for c, points in rows.items():
        names = [n for n, _ in tuning.GRIDS[c]]
        table = Table(title=f"{c}: {len(points)} points, {len(seeds)} seeds x {args.episodes} "
                      f"episodes, best first")  # fmt: skip
        for n in (*names, "success"):
            table.add_column(n, justify="right")
        for p in points[:5]:
            table.add_row(*(f"{p.point[n]:g}" for n in names), f"{p.success:.1%}")
        print_table(stdout, table)
    best = {c: points[0] for c, points in rows.items()}
    out = stdout
    out.write(f"{total} tasks in {elapsed:.1f} s on {where}\n")
    for c, p in best.items():
        out.write(f"best for {c}: {tuning.describe(p.point)} ({p.success:.1%})\n")
    if args.write:
        path = data_dir() / "tuned.toml"
        previous = path.read_text() if path.is_file() else ""
        path.write_text(tuning.tuned_toml(best, command, setup, previous))
        out.write(f"wrote {path}\n")
    if args.out is not None:
        from server.reports.tuning import write_tuning

        write_tuning(args.out, rows, command=command, seeds=seeds, episodes=args.episodes,
                     elapsed_s=elapsed, setup=setup)  # fmt: skip
        out.write(f"wrote {args.out / 'tuning.md'} and tuning.json\n")
    return 0


def add_qlambda_sweep_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `qlambda-sweep` command and its arguments."""
    sweep = sub.add_parser(
        "qlambda-sweep",
        help="tune Q(lambda)'s hyper-parameters on seeds the experiments do not use",
        description="Grid over alpha x lambda x epsilon; prints mean success over the last "
        "episodes per setting, best first.",
    )
    sweep.add_argument("--seeds", type=positive_int, default=5)
    sweep.add_argument("--seed-base", type=non_negative_int, default=1000)
    sweep.add_argument("--episodes", type=positive_int, default=300)
    sweep.add_argument("--alphas", default="0.1,0.3,0.5")
    sweep.add_argument("--lambdas", default="0.5,0.9")
    sweep.add_argument("--epsilons", default="0.05,0.1,0.2")
    sweep.add_argument("--jobs", type=positive_int, default=os.cpu_count() or 1)
    sweep.add_argument("--json", action="store_true", help="print one JSON object")
    sweep.set_defaults(handler=qlambda_sweep)


def _floats(text: str, name: str) -> list[float]:
    try:
        values = [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"--{name} takes comma-separated numbers, got {text!r}") from None
    if not values or any(not 0.0 <= v <= 1.0 for v in values):
        raise ValueError(f"--{name} values must be in [0, 1], got {text!r}")
    return values


def qlambda_sweep(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab qlambda-sweep`."""
    from core.learners.qlambda import QLambdaConfig, sweep

    grid = [
        QLambdaConfig(alpha=a, lam=lam, epsilon=e)
        for a in _floats(args.alphas, "alphas")
        for lam in _floats(args.lambdas, "lambdas")
        for e in _floats(args.epsilons, "epsilons")
    ]
    seeds = list(range(args.seed_base, args.seed_base + args.seeds))
    err = Console(file=stderr, stderr=True)
    progress, bar = progress_bar(err, "[bold]Q(lambda) sweep[/]", len(grid) * len(seeds))
    with progress:
        rows = sweep(grid, seeds, args.episodes, args.jobs, lambda: progress.advance(bar))
    if args.json:
        stdout.write(json.dumps({"seeds": seeds, "episodes": args.episodes, "rows": rows}) + "\n")
        return 0
    table = Table(title=f"Q(lambda) sweep: seeds {seeds[0]}..{seeds[-1]}, {args.episodes} episodes")
    for col in ("alpha", "lambda", "epsilon", "success, last 50", "success, all"):
        table.add_column(col, justify="right")
    for r in rows:
        table.add_row(
            f"{r['alpha']:g}",
            f"{r['lambda']:g}",
            f"{r['epsilon']:g}",
            f"{r['success_last50']:.1%}",
            f"{r['success_all']:.1%}",
        )
    Console(file=stdout).print(table)
    return 0
