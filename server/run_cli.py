"""`srlab db`, `srlab run` and `srlab runs`: the engine and its storage from the shell."""

from __future__ import annotations

import argparse
import asyncio
import json
import signal
from typing import IO, Any

from rich.console import Console
from rich.live import Live
from rich.table import Table

from core.engine import Engine
from core.errors import StorageError
from core.events import EpisodeEnded
from core.ports import Mode, RunSpec, RunStatus, StoredRun
from server.persistence import SqlAlchemyRunStore, database_url, make_engine, make_sessionmaker
from server.persistence.migrate import downgrade, upgrade
from server.tables import print_table


def db(args: argparse.Namespace, stdout: IO[str]) -> int:
    """`srlab db upgrade|downgrade`."""
    url = args.url or database_url()
    console = Console(file=stdout)
    if args.db_command == "upgrade":
        report = upgrade(url)
        console.print(f"database {_safe(url)} is at the newest schema")
        if report is not None:
            console.print(f"seeded: {report}")
        return 0
    downgrade(url, args.revision)
    console.print(f"database {_safe(url)} is at revision {args.revision}")
    return 0


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
            engine = Engine.restore(args.resume, store)
        else:
            params: dict[str, float] = {}
            if args.eta is not None:
                params["eta"] = args.eta
            if args.epsilon is not None:
                params["epsilon"] = args.epsilon
            spec = RunSpec(
                condition=args.condition,
                seed=args.seed,
                episodes=args.episodes,
                mode=Mode(args.mode),
                hz=args.hz,
                network=args.network,
                params=params,
                # The parser may not offer these yet: the defaults then.
                world=getattr(args, "world", None) or "",
                sensors=getattr(args, "sensors", None) or "",
            )
            engine = Engine.create(spec, store)
        return asyncio.run(_run(engine, args.quiet, stdout, stderr))
    finally:
        db_engine.dispose()


async def _run(engine: Engine, quiet: bool, stdout: IO[str], stderr: IO[str]) -> int:
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, engine.interrupt)
    console = Console(file=stdout)
    err = Console(file=stderr, stderr=True)
    spec = engine.spec
    sub = engine.subscribe(maxsize=1024)
    what = (
        f"run {engine.run_id}: {spec.condition}, seed {spec.seed}, world {spec.world or '-'},"
        f" sensors {spec.sensors or '-'}, {spec.mode.value}"
    )
    if spec.mode is Mode.REALTIME:
        what += f" at {spec.hz:g} Hz"

    def status_line() -> str:
        t = engine.totals
        planned = f"/{spec.episodes}" if spec.episodes else ""
        return (
            f"{what} | episode {t.episodes}{planned} | {t.successes} ok | tick {t.ticks:,}"
            f" | {engine.status.value}"
        )

    async def watch(live: Live | None) -> None:
        while engine.status in (RunStatus.CREATED, RunStatus.RUNNING, RunStatus.PAUSED):
            try:
                event = await asyncio.wait_for(sub.get(), timeout=0.25)
            except TimeoutError:
                event = None
            if live is not None and (event is None or isinstance(event, EpisodeEnded)):
                live.update(status_line())

    try:
        if quiet:
            status = await engine.run()
        else:
            with Live(status_line(), console=err, refresh_per_second=4, transient=True) as live:
                watcher = asyncio.create_task(watch(live))
                try:
                    status = await engine.run()
                finally:
                    watcher.cancel()
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
    table = Table(title=f"runs in {_safe(args.url or database_url())}")
    columns = (
        "id", "condition", "seed", "world", "sensors", "mode", "status", "episodes",
        "successes", "ticks",
    )  # fmt: skip
    for col in columns:
        table.add_column(col, justify="right" if col in ("id", "seed", "ticks") else "left")
    for r in stored:
        planned = f"/{r.spec.episodes}" if r.spec.episodes else ""
        table.add_row(
            str(r.id),
            r.spec.condition,
            str(r.spec.seed),
            r.spec.world or "-",  # "-": stored before runs kept it (the default then)
            r.spec.sensors or "-",
            r.spec.mode.value,
            r.status.value,
            f"{r.totals.episodes}{planned}",
            str(r.totals.successes),
            f"{r.totals.ticks:,}",
        )
    print_table(stdout, table)
    return 0


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
