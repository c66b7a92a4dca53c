"""`srlab run` and `srlab runs`: a condition on the engine, stored, and the stored runs."""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import time
from collections.abc import Sequence
from contextlib import nullcontext
from typing import IO, TYPE_CHECKING, Any

from rich import box
from rich.console import Console
from rich.live import Live
from rich.table import Table

from core.brain.catalog import sensor_definitions
from core.errors import StorageError
from core.events import EpisodeEnded, Outcome
from core.ports import NOT_ENDED, Mode, RunQueries, RunStatus, RunTotals, StoredRun
from core.run.setup import default_sensors
from core.sim.worlds import default_world, world_names
from server.cli.common import (
    CONDITION_METAVAR,
    OTHER_CONDITIONS,
    UsageError,
    engine_condition,
    non_negative_int,
    positive_int,
    print_table,
    rate,
    unit,
)
from server.cli.db import open_store, safe_url
from server.runtime.tuning import configure_process, freeze_heap
from server.services.runspec import run_spec

if TYPE_CHECKING:
    from core.engine import RunEngine


def add_run_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `run` command and its arguments."""
    runp = sub.add_parser(
        "run",
        help="run a condition on the engine, stored in the database",
        description="Run a condition on the asyncio engine (a tick task and a reward "
        "task), storing its LTM, RLTM, network, episodes and rewards. Ctrl-C or SIGTERM "
        "stops it cleanly (status interrupted); --resume continues it. A run is stored at "
        "each episode's end: stopped in the middle of an episode, it resumes from that "
        "episode's start and runs it again, to the same end as if it had not stopped.",
    )
    runp.add_argument(
        "--condition",
        type=engine_condition,
        metavar=CONDITION_METAVAR,
        help="which condition (the engine runs the paper's architecture; the baselines, "
        f"{', '.join(OTHER_CONDITIONS)}, run in srlab experiment)",
    )
    runp.add_argument("--seed", type=non_negative_int, default=0, help="random seed (default 0)")
    runp.add_argument(
        "--episodes", type=positive_int, help="episodes to run (default: until stopped)"
    )
    runp.add_argument("--mode", choices=["fast", "realtime"], default="fast")
    runp.add_argument("--hz", type=rate, default=10.0, help="realtime tick rate (default 10)")
    runp.add_argument("--network", help="start from this knowledge set instead")
    runp.add_argument(
        "--world", choices=world_names(), help=f"world preset (default {default_world()})"
    )
    runp.add_argument(
        "--sensors",
        choices=list(sensor_definitions()),
        help=f"sensor definition (default {default_sensors()})",
    )
    runp.add_argument("--eta", type=unit, help="Eq. (1)'s learning rate")
    runp.add_argument("--epsilon", type=unit, help="exploration rate")
    runp.add_argument("--resume", type=positive_int, metavar="RUN", help="resume a stored run")
    runp.add_argument("--url", help="SQLAlchemy URL (default: SRLAB_DATABASE_URL)")
    runp.add_argument("--quiet", action="store_true", help="no progress display")
    runp.set_defaults(handler=run_command)


def run_command(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """`srlab run` from the command line: the process tuned for an engine, then `run`."""
    configure_process()
    if args.resume is None and args.condition is None:
        raise UsageError("run needs --condition (or --resume RUN)")
    return run(args, stdout, stderr)


def run(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """`srlab run`: a stored engine run, fast or realtime, until done or Ctrl-C."""
    from core.engine import RunEngine

    store, db_engine = open_store(args.url)
    try:
        if args.resume is not None:
            engine = RunEngine.restore(args.resume, store)
        else:
            params: dict[str, float] = {}
            if args.eta is not None:
                params["eta"] = args.eta
            if args.epsilon is not None:
                params["epsilon"] = args.epsilon
            spec = run_spec(
                condition=args.condition,
                seed=args.seed,
                episodes=args.episodes,
                mode=args.mode,
                hz=args.hz,
                network=args.network,
                params=params,
                # The parser may not offer these yet: the defaults then.
                world=getattr(args, "world", None),
                sensors=getattr(args, "sensors", None),
            )
            engine = RunEngine.create(spec, store)
        freeze_heap()  # set up: what it built is never scanned again
        resumed = args.resume is not None
        return asyncio.run(_run(engine, store, args.quiet, stdout, stderr, resumed=resumed))
    finally:
        db_engine.dispose()


PROGRESS_EVERY_S = 5.0
"""Without a terminal, a progress line at least this often (and one per episode in
realtime mode), so a log or a pipe shows the run is alive."""


async def _run(
    engine: RunEngine,
    store: RunQueries,
    quiet: bool,
    stdout: IO[str],
    stderr: IO[str],
    *,
    resumed: bool = False,
) -> int:
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, engine.interrupt)
    console = Console(file=stdout)
    # Progress lines are whole lines in a log or a pipe, not wrapped at Rich's 80 columns.
    err = Console(file=stderr, stderr=True, soft_wrap=True)
    spec = engine.spec
    sub = engine.subscribe(maxsize=1024)
    what = (
        f"run {engine.run_id}: {spec.condition}, seed {spec.seed}, world {spec.world or '-'},"
        f" sensors {spec.sensors or '-'}, {spec.mode.value}"
    )
    if spec.mode is Mode.REALTIME:
        what += f" at {spec.hz:g} Hz"
    planned = f"/{spec.episodes}" if spec.episodes else ""
    start = engine.totals
    successes = start.successes
    ended = start.episodes
    if resumed:
        what += f", resumed from {_episode_end(start)}"

    def progress() -> str:
        # The live tick, not the stored totals: those move at episode ends only, which
        # in realtime mode can be minutes apart.
        return (
            f"{ended}{planned} episodes ended, {successes} successes, tick "
            f"{engine.totals.ticks:,} ({engine.status.value})"
        )

    def take(events: list[object]) -> bool:
        """Count the episodes that ended; whether any did."""
        nonlocal successes, ended
        before = ended
        for event in events:
            if isinstance(event, EpisodeEnded):
                ended += 1
                successes += event.outcome is Outcome.SUCCESS
        return ended > before

    async def watch(live: Live | None) -> None:
        last_line = time.monotonic()
        while engine.status in NOT_ENDED:
            await asyncio.sleep(0.25)
            episode_ended = take(sub.drain())
            if live is not None:
                live.update(f"{what} | {progress()}")
                continue
            now = time.monotonic()
            realtime_episode = episode_ended and spec.mode is Mode.REALTIME
            if realtime_episode or now - last_line >= PROGRESS_EVERY_S:
                err.print(progress(), highlight=False)
                last_line = now

    if not quiet:
        err.print(
            f"{what} (Ctrl-C stops it; srlab run --resume {engine.run_id} goes on)",
            highlight=False,
        )
    try:
        if quiet:
            status = await engine.run()
        else:
            live_display = (
                Live(f"{what} | {progress()}", console=err, refresh_per_second=4, transient=True)
                if err.is_terminal
                else nullcontext(None)
            )
            with live_display as live:
                watcher = asyncio.create_task(watch(live))
                try:
                    status = await engine.run()
                finally:
                    watcher.cancel()
            # The episodes that ended since the watcher's last look (it may not have woken).
            if take(sub.drain()) and spec.mode is Mode.REALTIME:
                err.print(progress(), highlight=False)
    except StorageError as e:
        err.print(f"[red]run {engine.run_id} failed:[/] {e}")
        return 1
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)
    t = engine.totals
    if status is RunStatus.INTERRUPTED:
        # What `srlab runs` shows and --resume goes on from: the run as stored.
        kept = store.run_summary(engine.run_id).totals
        for line in interrupted(engine.run_id, t, kept, planned):
            console.print(line, highlight=False, soft_wrap=True)
        return 0
    console.print(
        f"run {engine.run_id} {status.value}: {t.episodes} episodes, {t.successes} successes,"
        f" {t.ticks:,} ticks"
    )
    return 0


def _episode_end(kept: RunTotals) -> str:
    """Where a run stored at `kept` goes on from, for people."""
    if not kept.episodes:
        return f"its start (tick {kept.ticks:,})"
    return f"the end of episode {kept.episodes} (tick {kept.ticks:,})"


def interrupted(run_id: int, live: RunTotals, kept: RunTotals, planned: str) -> list[str]:
    """What an interrupted run kept and how it resumes, as lines for people.

    A run is stored at each episode's end (its checkpoint), and resuming replays from
    there: the ticks of the episode under way run again, to the same end as if it had not
    stopped (the same seed, and the rewards given in it replayed at their ticks).
    """
    episodes = f"{kept.episodes} episode{'s' * (kept.episodes != 1)}"
    stored = f"{episodes}, {kept.successes} success{'es' * (kept.successes != 1)}"
    if live.ticks == kept.ticks:
        lines = [f"run {run_id} interrupted at tick {live.ticks:,}; all of it is stored: {stored}"]
    else:
        episode = kept.episodes + 1
        lines = [
            f"run {run_id} interrupted at tick {live.ticks:,}, in episode {episode}{planned}; "
            f"stored: {stored}, to {_episode_end(kept)}",
            f"--resume runs episode {episode} again from its start "
            f"({live.ticks - kept.ticks:,} ticks), to the same end as if it had not stopped",
        ]
    return [*lines, f"resume it with: srlab run --resume {run_id}"]


def add_runs_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `runs` command and its arguments."""
    runs_parser = sub.add_parser("runs", help="list the stored runs")
    runs_parser.add_argument("--json", action="store_true", help="print one JSON object")
    runs_parser.add_argument("--url", help="SQLAlchemy URL (default: SRLAB_DATABASE_URL)")
    runs_parser.set_defaults(handler=runs)


def runs(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """`srlab runs`: the stored runs with their status and success counts."""
    from server.persistence import database_url

    store, db_engine = open_store(args.url)
    try:
        stored = store.list_runs()
    finally:
        db_engine.dispose()
    if args.json:
        stdout.write(json.dumps({"runs": [_run_dict(r) for r in stored]}) + "\n")
        return 0
    console = print_table(stdout, runs_table(stored, safe_url(args.url or database_url())))
    if any(r.status is RunStatus.INTERRUPTED for r in stored):
        console.print(
            "An interrupted run is stored to the end of its last episode (the ticks shown); "
            "--resume runs the episode it stopped in again from its start.",
            highlight=False,
            soft_wrap=True,
        )
    return 0


STATUS_WIDTH = max(len(s.value) for s in RunStatus)


def runs_table(stored: Sequence[StoredRun], where: str) -> Table:
    """The runs as a table that fits 80 columns with every status whole.

    World and sensors share a column that may wrap, the counts have short headings, the
    columns are one space apart, and the status, ids and counts never wrap (at 80 columns
    Rich cut "interrupted" before).
    """
    table = Table(
        title=f"runs in {where}",
        box=box.SIMPLE_HEAD,
        show_edge=False,
        padding=(0, 0),  # the box's separator alone: one space between columns
    )
    table.add_column("id", justify="right", no_wrap=True)
    table.add_column("condition", overflow="fold")
    table.add_column("seed", justify="right", no_wrap=True)
    table.add_column("world/sensors", overflow="fold")
    table.add_column("mode", no_wrap=True)
    table.add_column("status", no_wrap=True, min_width=STATUS_WIDTH)
    table.add_column("episodes", justify="right", no_wrap=True)
    table.add_column("ok", justify="right", no_wrap=True)
    table.add_column("ticks", justify="right", no_wrap=True)
    for r in stored:
        planned = f"/{r.spec.episodes}" if r.spec.episodes else ""
        # "-": stored before runs kept their world and sensors (the defaults then).
        setup = f"{r.spec.world or '-'}/{r.spec.sensors or '-'}"
        table.add_row(
            str(r.id),
            r.spec.condition,
            str(r.spec.seed),
            setup,
            r.spec.mode.value,
            r.status.value,
            f"{r.totals.episodes}{planned}",
            str(r.totals.successes),
            f"{r.totals.ticks:,}",
        )
    return table


def _run_dict(r: StoredRun) -> dict[str, Any]:
    return {
        "id": r.id,
        "condition": r.spec.condition,
        "seed": r.spec.seed,
        "world": r.spec.world,
        "sensors": r.spec.sensors,
        "mode": r.spec.mode.value,
        "hz": r.spec.hz,
        "episodes_planned": r.spec.episodes,
        "status": r.status.value,
        "episodes": r.totals.episodes,
        "successes": r.totals.successes,
        "ticks": r.totals.ticks,
        "error": r.error,
    }
