"""`srlab simulate`: one condition headless for some episodes, its outcomes summarised."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import IO, Any

from rich.console import Console
from rich.table import Table

from core.brain.catalog import Catalog
from core.brain.selection import Strategy
from core.events import Outcome
from core.run.runner import EpisodeSummary, RunSummary, run
from core.run.simulation import Snapshot
from server.cli.common import (
    CONDITION_METAVAR,
    OTHER_CONDITIONS,
    UsageError,
    add_setup_arguments,
    non_negative_int,
    positive_int,
    print_table,
    progress_bar,
    setup_of,
)
from server.cli.conditions import (
    add_network_arguments,
    engine_condition_or_file,
    with_conditions,
)
from server.reports.base import setup_params


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `simulate` command and its arguments."""
    sim = sub.add_parser(
        "simulate",
        help="run a condition headless for some episodes and summarise the outcomes",
        description="Run a condition headless and summarise successes and failures.",
    )
    sim.add_argument(
        "--condition",
        required=True,
        type=engine_condition_or_file,
        metavar=CONDITION_METAVAR[:-1] + ",FILE}",
        help="which knowledge and learning the robot has: a built-in condition (the "
        f"baselines, {', '.join(OTHER_CONDITIONS)}, run in srlab experiment), or a condition "
        "file (.toml, docs/conditions.md) holding one, or FILE.toml:NAME for one of several",
    )
    sim.add_argument("--episodes", type=positive_int, default=50, help="episodes (default 50)")
    sim.add_argument("--seed", type=non_negative_int, default=0, help="random seed (default 0)")
    sim.add_argument(
        "--strategy",
        choices=[s.value for s in Strategy],
        default=None,
        help="behaviour selection strategy (default: the condition's, competition)",
    )
    sim.add_argument("--json", action="store_true", help="print one JSON object, nothing else")
    sim.add_argument(
        "--trace",
        type=Path,
        metavar="FILE",
        help="write every tick (pose, stimuli, behaviour) as JSON lines to FILE",
    )
    sim.add_argument("--quiet", action="store_true", help="no progress bar (it goes to stderr)")
    add_setup_arguments(sim)
    add_network_arguments(sim)
    sim.set_defaults(handler=simulate)


class _TraceWriter:
    """Writes one JSON line per tick with names instead of ids."""

    def __init__(self, out: IO[str], catalog: Catalog) -> None:
        self._out = out
        self._stimuli = [s.name for s in catalog.stimuli]
        self._behaviours = [b.name for b in catalog.behaviours]

    def __call__(self, s: Snapshot) -> None:
        row: dict[str, Any] = {
            "episode": s.episode,
            "tick": s.tick,
            "episode_tick": s.episode_tick,
            "x": round(s.x, 4),
            "y": round(s.y, 4),
            "heading_rad": round(s.heading_rad, 4),
            "stimuli": [self._stimuli[i] for i in s.stimuli],
            "behaviour": self._behaviours[s.behaviour] if s.behaviour >= 0 else None,
            "how": s.how.value,
            "released_by": self._stimuli[s.released_by] if s.released_by >= 0 else None,
            "source": s.origin,
            "lamp": s.lamp.name.lower(),
            "progress_m": round(s.progress_m, 3),
        }
        if s.outcome is not None:
            row["outcome"] = s.outcome.value
            row["cause"] = s.cause.value if s.cause else None
        self._out.write(json.dumps(row) + "\n")


def summary_dict(result: RunSummary) -> dict[str, Any]:
    """The `--json` form of a run's summary."""
    return {
        "condition": result.condition,
        "seed": result.seed,
        "episodes": len(result.episodes),
        "successes": result.successes,
        "success_rate": result.success_rate,
        "failures": result.failures(),
        "ticks": result.ticks,
        "ticks_by_source": dict(
            sorted(result.ticks_by_origin.items(), key=lambda kv: (-kv[1], kv[0]))
        ),
    }


def simulate(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """Run `srlab simulate`."""
    setup, names = with_conditions(setup_of(args), [args.condition], args.network, args.url)
    if len(names) != 1:
        raise UsageError(
            f"--condition {args.condition} holds conditions {', '.join(names)}: name one as "
            f"{args.condition}:NAME"
        )
    condition = setup.condition(setup.lookup(names[0]))
    if condition.agent != "brain":
        raise ValueError(
            f"condition {condition.name!r} is not the paper's architecture: run it with "
            "`srlab experiment --conditions " + condition.name + "`"
        )
    catalog = setup.catalog()
    brain_config = None
    if args.strategy is not None:
        from dataclasses import replace

        base = condition.brain_config()
        brain_config = replace(
            base, selection=replace(base.selection, strategy=Strategy(args.strategy))
        )
    progress, task = progress_bar(
        Console(file=stderr, stderr=True),
        f"[bold]{condition.name}[/] seed {args.seed}",
        args.episodes,
        quiet=args.quiet,
        status="{task.fields[ok]} ok",
        ok=0,
    )
    successes = 0

    def on_episode(e: EpisodeSummary) -> None:
        nonlocal successes
        successes += e.outcome is Outcome.SUCCESS
        progress.update(task, advance=1, ok=successes)

    trace_file = None
    try:
        if args.trace is not None:
            trace_file = args.trace.open("w", encoding="utf-8")
        started = time.perf_counter()
        with progress:
            result = run(
                condition,
                args.seed,
                args.episodes,
                world_config=setup.world_config(),
                catalog=catalog,
                brain_config=brain_config,
                on_episode=on_episode,
                on_tick=_TraceWriter(trace_file, catalog) if trace_file else None,
            )
        elapsed = time.perf_counter() - started
    finally:
        if trace_file is not None:
            trace_file.close()

    if args.json:
        stdout.write(json.dumps({**summary_dict(result), **setup_params(setup)}) + "\n")
        return 0
    title = (
        f"srlab simulate: {condition.name}, seed {args.seed}, world {setup.world_name}, "
        f"sensors {setup.sensors_name}, signal {setup.signal}"
    )
    table = Table(title=title, show_header=False)
    table.add_column("what")
    table.add_column("value", justify="right")
    table.add_row("episodes", str(len(result.episodes)))
    table.add_row("successes", str(result.successes))
    table.add_row("success rate", f"{result.success_rate:.1%}")
    for cause, count in result.failures().items():
        table.add_row(f"  {cause.replace('_', ' ')}", str(count))
    table.add_row("ticks", f"{result.ticks:,}")
    for origin, n in sorted(result.ticks_by_origin.items(), key=lambda kv: -kv[1]):
        table.add_row(f"  run by {origin}", f"{n:,} ({n / max(result.ticks, 1):.1%})")
    table.add_row("ticks/s", f"{result.ticks / elapsed:,.0f}" if elapsed > 0 else "-")
    console = print_table(stdout, table)
    if args.trace is not None:
        console.print(f"trace written to {args.trace}")
    return 0
