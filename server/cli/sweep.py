"""`srlab sweep`, and the `--backend local|ray` choice it shares with `srlab experiment`."""

from __future__ import annotations

import argparse
import os
import shlex
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import ExitStack, contextmanager, nullcontext
from pathlib import Path
from typing import IO, Any

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
)
from rich.table import Table

from core.conditions import CONDITIONS
from core.experiment import Backend, LocalBackend, TaskResult
from core.params import PARAMETERS
from core.setup import Setup
from core.sweep import point_label
from server.reports.base import fmt, setup_params


def add_setup_arguments(parser: argparse.ArgumentParser, *, signal: bool = True) -> None:
    """--world, --sensors and (unless `signal` is False) --signal: where a condition runs."""
    from core.brain.catalog import sensor_definitions
    from core.setup import SIGNAL_MODES
    from core.worlds import default_world, world_names

    parser.add_argument(
        "--world",
        choices=world_names(),
        default="",
        help=f"world preset (default {default_world()}; see `srlab world-check`)",
    )
    definitions = list(sensor_definitions())
    parser.add_argument(
        "--sensors",
        choices=definitions,
        default="",
        help=f"camera obstacle stimuli: {', '.join(definitions)} (default {definitions[0]}: "
        "the paper's Fig. 10)",
    )
    if signal:
        parser.add_argument(
            "--signal",
            choices=SIGNAL_MODES,
            default="learned",
            help="learned: as the condition has it (default); given: the signal's correct "
            "responses added, so success measures the obstacle alone",
        )


def setup_of(args: argparse.Namespace) -> Setup:
    """The setup the --world, --sensors and --signal arguments name, defaults named."""
    return Setup(args.world, args.sensors, getattr(args, "signal", "learned")).resolved()


def add_task_arguments(
    parser: argparse.ArgumentParser,
    positive_int: Callable[[str], Any],
    seed: Callable[[str], Any],
    out: Path,
) -> None:
    """What `experiment` and `sweep` share: seeds, episodes, jobs, backend, setup, --out."""
    parser.add_argument("--seeds", type=positive_int, default=20, help="seeds (default 20)")
    parser.add_argument("--seed-base", type=seed, default=0, help="first seed (default 0)")
    parser.add_argument(
        "--episodes", type=positive_int, default=50, help="episodes per seed (default 50)"
    )
    parser.add_argument(
        "--jobs",
        type=positive_int,
        default=os.cpu_count() or 1,
        help="local processes, or CPUs of a private Ray instance",
    )
    add_backend_arguments(parser)
    add_setup_arguments(parser)
    parser.add_argument("--out", type=Path, default=out, help="output folder")
    parser.add_argument("--quiet", action="store_true", help="no progress display")


def add_backend_arguments(parser: argparse.ArgumentParser) -> None:
    """--backend, --address and --ship-code."""
    parser.add_argument(
        "--backend",
        choices=["local", "ray"],
        default="local",
        help="local: --jobs processes on this machine (default); ray: Ray tasks, on a "
        "private local Ray instance with --jobs CPUs or on the cluster at --address "
        "(needs pip install 'srlab[ray]')",
    )
    parser.add_argument(
        "--address",
        help="the Ray cluster to use: auto (the one started here with `ray start`), "
        "HOST:PORT, or ray://HOST:10001 (default: RAY_ADDRESS, else a private instance)",
    )
    parser.add_argument(
        "--ship-code",
        action="store_true",
        help="upload this checkout's core package with the Ray job, so the workers need "
        "srlab's dependencies but not srlab itself",
    )


def check_backend_arguments(args: argparse.Namespace) -> None:
    """--address and --ship-code make sense only with --backend ray."""
    if args.backend != "ray" and (args.address is not None or args.ship_code):
        raise ValueError("--address and --ship-code need --backend ray")


@contextmanager
def open_backend(args: argparse.Namespace, err: Console) -> Iterator[tuple[Backend, str]]:
    """The backend the arguments choose, connected, and where it runs, for people."""
    check_backend_arguments(args)
    if args.backend == "local":
        yield LocalBackend(args.jobs), f"{args.jobs} local process{'es' * (args.jobs > 1)}"
        return
    from server.backends import RayBackend

    backend = RayBackend(args.address, args.jobs, args.ship_code)
    with ExitStack() as stack:
        with nullcontext() if args.quiet else err.status(f"connecting to {backend.where}"):
            stack.enter_context(backend)
        yield backend, backend.where


def progress_display(err: Console, title: str, total: int, quiet: bool) -> tuple[Progress, TaskID]:
    """The progress bar of a batch of tasks and its task id."""
    progress = Progress(
        TextColumn(f"[bold]{title}[/]"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[last]}"),
        TimeElapsedColumn(),
        console=err,
        transient=True,
        disable=quiet,
    )
    return progress, progress.add_task("tasks", total=total, last="")


def on_result_updater(progress: Progress, bar: TaskID) -> Callable[[TaskResult], None]:
    """A callback that advances the bar and names the task just done."""

    def on_result(r: TaskResult) -> None:
        mark = "ok" if r.ok else "[red]FAILED[/]"
        where = point_label(dict(r.task.params))
        progress.update(
            bar,
            advance=1,
            last=f"{r.task.condition}{' ' + where if where else ''} seed {r.task.seed} {mark}",
        )

    return on_result


def add_sweep_parser(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
    positive_int: Callable[[str], Any],
    seed: Callable[[str], Any],
) -> None:
    """The `sweep` command and its arguments; the number types are the CLI's own."""
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
        help=f"comma-separated, from: {', '.join(CONDITIONS)} (default: kp,qlambda)",
    )
    add_task_arguments(sweep, positive_int, seed, Path("results/sweep"))


def command_line(args: argparse.Namespace) -> str:
    """The command as typed (the arguments `main` was given), for the report."""
    argv = getattr(args, "argv", None)
    argv = sys.argv[1:] if argv is None else argv
    return "srlab " + shlex.join(argv) if argv else f"srlab {args.command}"


def sweep_command(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab sweep`."""
    from core.experiment import parse_conditions
    from core.sweep import Sweep, format_value, parse_grid, run_sweep, summarise_sweep
    from server.reports.sweep import write_sweep_report

    plan = Sweep(
        parse_grid(args.param),
        tuple(parse_conditions(args.conditions)),
        tuple(range(args.seed_base, args.seed_base + args.seeds)),
        args.episodes,
        setup_of(args),
    )
    check_backend_arguments(args)
    tasks = plan.tasks()
    err = Console(file=stderr, stderr=True)
    with open_backend(args, err) as (backend, where):
        progress, bar = progress_display(err, "sweep", len(tasks), args.quiet)
        started = time.perf_counter()
        with progress:
            results = run_sweep(plan, backend, on_result_updater(progress, bar))
        elapsed = time.perf_counter() - started
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
    failed = [r for r in results if not r.ok]
    for r in failed:
        first = (r.error or "").splitlines()[0]
        label = point_label(dict(r.task.params))
        err.print(
            f"[red]task {r.task.condition}{' ' + label if label else ''} seed {r.task.seed} "
            f"failed:[/] {first}"
        )
    return 1 if failed else 0
