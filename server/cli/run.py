"""`srlab db`, `srlab run` and `srlab runs`: the engine and its storage from the shell."""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
import time
from collections.abc import Sequence
from contextlib import nullcontext
from typing import IO, Any

from rich import box
from rich.console import Console
from rich.live import Live
from rich.table import Table

from core.engine import RunEngine
from core.errors import StorageError
from core.events import EpisodeEnded, Outcome
from core.ports import Mode, RunStatus, StoredRun
from server.cli.common import print_table
from server.persistence import SqlAlchemyRunStore, database_url, make_engine, make_sessionmaker
from server.persistence.migrate import downgrade, upgrade
from server.persistence.seed import SeedReport
from server.runspec import run_spec


def db(args: argparse.Namespace, stdout: IO[str]) -> int:
    """`srlab db upgrade|downgrade`."""
    url = args.url or database_url()
    console = Console(file=stdout)
    if args.db_command == "upgrade":
        report = upgrade(url)
        console.print(f"database {_safe(url)} is at the newest schema")
        if report is not None:
            console.print(_seeded(report))
        return 0
    downgrade(url, args.revision)
    console.print(f"database {_safe(url)} is at revision {args.revision}")
    return 0


def _seeded(report: SeedReport) -> str:
    """What seeding did, as a sentence (not the report's repr)."""
    if not report.changed:
        return "the catalogue and the shipped networks were already seeded: nothing changed"
    return (
        f"seeded the catalogue and the shipped networks: {report.added} rows added, "
        f"{report.updated} updated"
    )


def _safe(url: str) -> str:
    """A URL with its password hidden."""
    from sqlalchemy.engine import make_url

    return make_url(url).render_as_string(hide_password=True)


def _store(url: str | None) -> tuple[SqlAlchemyRunStore, Any]:
    url = url or database_url()
    upgrade(url)  # cheap when already at head; a fresh machine needs no separate step
    engine = make_engine(url)
    return SqlAlchemyRunStore(make_sessionmaker(engine)), engine


def run(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """`srlab run`: a stored engine run, fast or realtime, until done or Ctrl-C."""
    store, db_engine = _store(args.url)
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
        return asyncio.run(_run(engine, args.quiet, stdout, stderr))
    finally:
        db_engine.dispose()


PROGRESS_EVERY_S = 5.0
"""Without a terminal, a progress line at least this often (and one per episode in
realtime mode), so a log or a pipe shows the run is alive."""


async def _run(engine: RunEngine, quiet: bool, stdout: IO[str], stderr: IO[str]) -> int:
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
    successes = engine.totals.successes
    ended = engine.totals.episodes

    def progress() -> str:
        # The live tick, not the stored totals: those move at episode ends only, which
        # in realtime mode can be minutes apart.
        return (
            f"episode {ended}{planned} done, {successes} successes, tick "
            f"{engine.sim.tick_count:,} ({engine.status.value})"
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
        while engine.status in (RunStatus.CREATED, RunStatus.RUNNING, RunStatus.PAUSED):
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
    console.print(
        f"run {engine.run_id} {status.value}: {t.episodes} episodes, {t.successes} successes,"
        f" {t.ticks:,} ticks"
    )
    if status is RunStatus.INTERRUPTED:
        console.print(f"resume it with: srlab run --resume {engine.run_id}")
    return 0


def runs(args: argparse.Namespace, stdout: IO[str]) -> int:
    """`srlab runs`: the stored runs with their status and success counts."""
    store, db_engine = _store(args.url)
    try:
        stored = store.list_runs()
    finally:
        db_engine.dispose()
    if args.json:
        stdout.write(json.dumps({"runs": [_run_dict(r) for r in stored]}) + "\n")
        return 0
    print_table(stdout, runs_table(stored, _safe(args.url or database_url())))
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
