"""What the commands share: argument types and groups, the backend, progress, tables."""

from __future__ import annotations

import argparse
import math
import os
import shlex
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import ExitStack, contextmanager, nullcontext
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

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

from core.params import point_label
from core.run.conditions import CONDITIONS
from core.run.setup import Setup
from core.sim.worlds import WorldSettings
from server.reports.base import first_line

if TYPE_CHECKING:
    from core.lab.cells import Cell
    from core.lab.experiment import Backend, TaskResult
    from core.lab.probe import ProbeResult

Handler = Callable[[argparse.Namespace, IO[str], IO[str]], int]
"""What a command runs: its arguments, stdout and stderr in; the exit code out."""


class UsageError(Exception):
    """Arguments that parse but do not go together: `main` answers as argparse does."""


def counted(n: int, noun: str) -> str:
    """`n` and `noun`, plural unless `n` is 1: "1 run", "2 runs", "0 runs"."""
    return f"{n:,} {noun}" if n == 1 else f"{n:,} {noun}s"


def number(
    cast: Callable[[str], float], low: float, high: float, closed_low: bool, what: str
) -> Callable[[str], Any]:
    """An argparse type: a number of `cast`'s kind within bounds, with a clear message."""
    kind = "whole number" if cast is int else "number"

    def parse(text: str) -> Any:
        try:
            value = cast(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a {kind}") from None
        if value > high or value < low or (value == low and not closed_low):
            raise argparse.ArgumentTypeError(f"must be {what}, got {value}")
        return value

    return parse


positive_int = number(int, 1, math.inf, True, "at least 1")
non_negative_int = number(int, 0, math.inf, True, "0 or more")
"""Seeds, and counts that may be none."""
unit = number(float, 0.0, 1.0, True, "in [0, 1]")
rate = number(float, 0.0, 1000.0, False, "in (0, 1000]")


ENGINE_CONDITIONS = sorted(n for n, c in CONDITIONS.items() if c.agent == "brain")
"""The conditions `srlab run` and `srlab simulate` accept: the paper's architecture."""
OTHER_CONDITIONS = sorted(set(CONDITIONS) - set(ENGINE_CONDITIONS))
"""The baselines (Q(lambda), DQN, PPO...): `srlab experiment` runs them."""
CONDITION_METAVAR = "{" + ",".join(ENGINE_CONDITIONS) + "}"


def engine_condition(text: str) -> str:
    """An argparse type: a condition of the paper's architecture, else where to run it."""
    if text in ENGINE_CONDITIONS:
        return text
    if text in OTHER_CONDITIONS:
        raise argparse.ArgumentTypeError(
            f"{text!r} is a baseline, not run by the engine (the paper's architecture): "
            "run it with "
            f"`srlab experiment --conditions {text}`"
        )
    raise argparse.ArgumentTypeError(
        f"invalid choice: {text!r} (choose from {', '.join(ENGINE_CONDITIONS)})"
    )


def world_type(text: str) -> str:
    """An argparse type: `--world`'s preset name, or a world file's path (made absolute).

    A world file is loaded here, so that a bad one is the command's one error line.
    """
    from core.errors import CoreError
    from core.sim.worlds import load_world, world_names

    if not text or text in world_names():  # "" is the default preset
        return text
    if text.endswith(".toml"):
        path = str(Path(text).resolve())
        try:
            load_world(path)
        except CoreError as e:
            raise argparse.ArgumentTypeError(str(e)) from None
        return path
    raise argparse.ArgumentTypeError(
        f"invalid choice: {text!r} (choose from {', '.join(world_names())}, "
        "or a world file FILE.toml)"
    )


def perception_type(text: str) -> WorldSettings:
    """An argparse type: `--perception`'s world settings (`core.sim.worlds.parse_perception`)."""
    from core.errors import CoreError
    from core.sim.worlds import parse_perception

    try:
        return parse_perception(text)
    except CoreError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_setup_arguments(
    parser: argparse.ArgumentParser, *, signal: bool = True, start: bool = False
) -> None:
    """--world, --sensors, --signal (unless `signal` is False) and, with `start`, --start."""
    from core.brain.catalog import sensor_definitions
    from core.run.setup import SIGNAL_MODES
    from core.sim.worlds import default_world, perception_parameters, world_names

    parser.add_argument(
        "--world",
        type=world_type,
        default="",
        metavar="NAME|FILE.toml",
        help=f"world preset ({', '.join(world_names())}; default {default_world()}; see "
        "`srlab world list`) or a world file's path (docs/worlds.md)",
    )
    parser.add_argument(
        "--perception",
        type=perception_type,
        default="exact",
        metavar="{exact,noisy,NAME=VALUE,...}",
        help="exact: stimuli from the true pose and obstacle (default); noisy: from a camera "
        "with 10 cm range and 3 degree bearing errors missing one detection in five, and "
        "odometry drifting 3 cm after 1 m (docs/results/noisy-perception/); or its settings "
        f"one by one, after a preset or alone ({', '.join(perception_parameters())}: "
        "noisy,camera_miss_rate=0.5)",
    )
    definitions = sensor_definitions()  # default first, each with its description
    described = "; ".join(f"{n}: {d.rstrip('.')}" for n, d in definitions.items())
    parser.add_argument(
        "--sensors",
        choices=list(definitions),
        default="",
        help=f"camera obstacle stimuli (default {next(iter(definitions))}). {described}",
    )
    if signal:
        parser.add_argument(
            "--signal",
            choices=SIGNAL_MODES,
            default="learned",
            help="learned: as the condition has it (default); given: the signal's correct "
            "responses added, so success measures the obstacle alone",
        )
    if start:
        from core.run.conditions import STARTS

        parser.add_argument(
            "--start",
            choices=STARTS,
            default="",
            help="what every condition's robot starts from (default: its own knowledge): "
            "table1, Table I's innate knowledge; design, kp's (Table I, lane keeping and the "
            "sonar's obstacle responses); a DP condition keeps its programmed responses on top",
        )


def setup_of(args: argparse.Namespace) -> Setup:
    """The setup the --world, --sensors and --signal arguments name, defaults named."""
    return Setup(
        args.world,
        args.sensors,
        getattr(args, "signal", "learned"),
        getattr(args, "perception", ()),
        start=getattr(args, "start", ""),
    ).resolved()


def add_batch_arguments(
    parser: argparse.ArgumentParser,
    *,
    seeds: int = 20,
    seed_base: int = 0,
    kind: str = "",
    jobs_help: str | None = None,
) -> None:
    """A batch of tasks and where it runs: --seeds, --seed-base, --episodes, --jobs, backend.

    `kind` names the seeds in the help ("tuning " for tuning seeds).
    """
    parser.add_argument(
        "--seeds", type=positive_int, default=seeds, help=f"{kind}seeds (default {seeds})"
    )
    parser.add_argument(
        "--seed-base",
        type=non_negative_int,
        default=seed_base,
        help=f"first {kind}seed (default {seed_base})",
    )
    parser.add_argument(
        "--episodes", type=positive_int, default=50, help="episodes per seed (default 50)"
    )
    parser.add_argument("--jobs", type=positive_int, default=os.cpu_count() or 1, help=jobs_help)
    add_backend_arguments(parser)


def add_task_arguments(parser: argparse.ArgumentParser, out: Path) -> None:
    """What `experiment` and `sweep` share: seeds, episodes, jobs, backend, setup, --out."""
    add_batch_arguments(parser, jobs_help="local processes, or CPUs of a private Ray instance")
    add_setup_arguments(parser, start=True)
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
        from core.lab.experiment import LocalBackend

        yield LocalBackend(args.jobs), f"{args.jobs} local process{'es' * (args.jobs > 1)}"
        return
    from server.backends.ray import RayBackend

    backend = RayBackend(args.address, args.jobs, args.ship_code)
    with ExitStack() as stack:
        with nullcontext() if args.quiet else err.status(f"connecting to {backend.where}"):
            stack.enter_context(backend)
        yield backend, backend.where


def progress_bar(
    err: Console, label: str, total: int, *, quiet: bool = False, status: str = "", **fields: Any
) -> tuple[Progress, TaskID]:
    """A transient progress bar on stderr, and its task.

    Its columns: `label` (Rich markup), the bar, done of `total`, `status` (a column that
    shows the task's `fields`, if given) and the time taken.
    """
    columns = [TextColumn(label), BarColumn(), MofNCompleteColumn()]
    if status:
        columns.append(TextColumn(status))
    progress = Progress(*columns, TimeElapsedColumn(), console=err, transient=True, disable=quiet)
    return progress, progress.add_task("tasks", total=total, **fields)


def task_label(r: TaskResult) -> str:
    """A task as people name it: ``kp seed 3``, or ``kp eta=0.1 seed 3`` with parameters.

    World settings (a phase diagram's point) follow the parameters.
    """
    where = point_label({**dict(r.task.params), **dict(r.task.setup.world_settings)})
    return f"{r.task.condition}{' ' + where if where else ''} seed {r.task.seed}"


def task_progress(
    err: Console, title: str, total: int, quiet: bool
) -> tuple[Progress, Callable[[TaskResult], None]]:
    """The progress bar of a batch of tasks, and a callback that advances it per result.

    The bar names the task just done and whether it failed.
    """
    progress, bar = progress_bar(
        err, f"[bold]{title}[/]", total, quiet=quiet, status="{task.fields[last]}", last=""
    )

    def on_result(r: TaskResult) -> None:
        mark = "ok" if r.ok else "[red]FAILED[/]"
        progress.update(bar, advance=1, last=f"{task_label(r)} {mark}")

    return progress, on_result


def run_batch(
    args: argparse.Namespace,
    err: Console,
    title: str,
    total: int,
    run: Callable[[Backend, Callable[[TaskResult], None]], list[TaskResult]],
) -> tuple[list[TaskResult], float, str]:
    """`run` a batch of `total` tasks on the backend the arguments choose, with a progress bar.

    Returns the results, the seconds they took and where they ran, for people.
    """
    with open_backend(args, err) as (backend, where):
        progress, on_result = task_progress(err, title, total, args.quiet)
        started = time.perf_counter()
        with progress:
            results = run(backend, on_result)
        elapsed = time.perf_counter() - started
    return results, elapsed, where


def report_failures(err: Console, results: Sequence[TaskResult], *, params: bool) -> int:
    """Say which tasks failed and why (their error's first line); the exit code: 1 if any.

    With `params`, each task is named with the parameters it set (a sweep's point).
    """
    failed = [r for r in results if not r.ok]
    for r in failed:
        name = task_label(r) if params else f"{r.task.condition} seed {r.task.seed}"
        err.print(f"[red]task {name} failed:[/] {first_line(r.error)}")
    return 1 if failed else 0


def command_line(args: argparse.Namespace) -> str:
    """The command as typed (the arguments `main` was given), for the report."""
    argv = getattr(args, "argv", None)
    argv = sys.argv[1:] if argv is None else argv
    return "srlab " + shlex.join(argv) if argv else f"srlab {args.command}"


def check_out_folder(out: Path, force: bool) -> None:
    """An export's --out: a folder, empty unless --force (`UsageError` otherwise)."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} is a file, not a folder")
    if out.is_dir() and any(out.iterdir()) and not force:
        raise UsageError(f"--out {out} is not empty: choose another folder, or add --force")


def print_table(out: IO[str], table: Table) -> Console:
    """Print `table` to `out`; returns the console used, for what follows it.

    A pipe or a file has no width of its own, and Rich's 80 columns would cut words in
    half: there the console is as wide as the table needs.
    """
    console = Console(file=out)
    wide = console.measure(table, options=console.options.update_width(1000)).maximum
    if not console.is_terminal and wide > console.width:
        console = Console(file=out, width=wide)
    console.print(table)
    return console


def add_study_arguments(parser: argparse.ArgumentParser) -> None:
    """What a study adds to its batch: --eval-episodes (10 by default) and --untuned."""
    parser.add_argument(
        "--eval-episodes",
        type=non_negative_int,
        default=10,
        metavar="N",
        help="after training, N episodes of frozen evaluation on held-out seeds, and N of "
        "the camera-only transfer test (default 10)",
    )
    parser.add_argument(
        "--untuned",
        action="store_true",
        help="run every condition with its default parameters, not the tuned ones "
        "(core/data/tuned.toml, written by srlab tune)",
    )


def run_cells(
    args: argparse.Namespace, err: Console, title: str, cells: Sequence[Cell]
) -> tuple[list[TaskResult], dict[str, Any]]:
    """Run a study's cells on the arguments' seeds, with a progress bar titled `title`.

    Returns the results and the parameters every study's report starts with: the command,
    the seeds and episodes, the tasks, where they ran and how long they took.
    """
    from core.lab.cells import run_study, study_tasks

    seeds = list(range(args.seed_base, args.seed_base + args.seeds))
    tasks = study_tasks(cells, seeds, args.episodes, args.eval_episodes)
    with open_backend(args, err) as (backend, where):
        progress, on_result = task_progress(err, title, len(tasks), args.quiet)
        started = time.perf_counter()
        with progress:
            results = run_study(cells, seeds, args.episodes, args.eval_episodes, backend, on_result)
        elapsed = time.perf_counter() - started
    return results, {
        "command": command_line(args),
        "seeds": len(seeds),
        "seed_base": args.seed_base,
        "episodes": args.episodes,
        "eval_episodes": args.eval_episodes,
        "tasks": len(tasks),
        "jobs": args.jobs,
        "backend": args.backend,
        "where": where,
        "elapsed_s": elapsed,
        "ticks": sum(r.ticks for r in results),
    }


def add_reference_study_arguments(
    parser: argparse.ArgumentParser, conditions: str, out: Path, conditions_help: str = ""
) -> None:
    """What a study of conditions against a reference takes besides its own arguments.

    --conditions (default `conditions`; `conditions_help` adds to its help), --reference,
    the batch, the setup, --out (default `out`), --quiet, --eval-episodes, --untuned and
    --no-probe.
    """
    parser.add_argument(
        "--conditions",
        default=conditions,
        help=f"the conditions, comma-separated (default {conditions}){conditions_help}",
    )
    parser.add_argument(
        "--reference",
        default="kp",
        help="the condition the others are compared with (default kp)",
    )
    add_batch_arguments(parser, jobs_help="local processes, or CPUs of a private Ray instance")
    add_setup_arguments(parser)
    parser.add_argument("--out", type=Path, default=out, help="output folder")
    parser.add_argument("--quiet", action="store_true", help="no progress display")
    add_study_arguments(parser)
    parser.add_argument(
        "--no-probe",
        action="store_true",
        help="do not judge what was learned with the placement probe (srlab probe)",
    )


def judge_learned(args: argparse.Namespace, err: Console, setup: Setup) -> ProbeResult | None:
    """The placement probe of `setup` (`srlab probe`, cached), or None with --no-probe."""
    if args.no_probe:
        return None
    from server.services.probe_cache import cached_probe

    status = err.status("judging what was learned (srlab probe)")
    with status if not args.quiet else nullcontext():
        probed, _ = cached_probe(setup)
    return probed


def finish_study(
    stdout: IO[str],
    err: Console,
    table: Table,
    params: dict[str, Any],
    paths: Sequence[Path],
    results: Sequence[TaskResult],
    *,
    with_params: bool = False,
) -> int:
    """Print a study's table, what it ran and the files it wrote; the exit code.

    1 if a task failed (each named, with its parameters when `with_params`), else 0.
    """
    console = print_table(stdout, table)
    console.print(
        f"{params['tasks']} tasks, {params['ticks']:,} ticks in {params['elapsed_s']:.1f} s on "
        f"{params['where']}"
    )
    for path in paths:
        console.print(f"wrote {path}")
    return report_failures(err, results, params=with_params)
