"""`srlab export`: stored runs as files for analysis (docs/export.md)."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path
from typing import IO

from rich.console import Console
from rich.progress import TaskID

from server.cli.common import check_out_folder, counted, positive_int, progress_bar
from server.cli.db import open_store


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `export` command and its arguments."""
    p = sub.add_parser(
        "export",
        help="write stored runs' rewards, episodes and networks as files for analysis",
        description="Write each run's reward log and episodes (JSON Lines and CSV, the same "
        "rows), its learned network and a manifest (code version, run spec, counts) into "
        "DIR/run-ID/; with --minari also a Minari dataset of its episodes (the srlab[minari] "
        "extra). docs/export.md says what each file holds.",
    )
    p.add_argument("runs", nargs="+", type=positive_int, metavar="RUN", help="a stored run's id")
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="the folder to write")
    p.add_argument("--minari", action="store_true", help="also write a Minari dataset per run")
    p.add_argument(
        "--force",
        action="store_true",
        help="write into DIR even if it holds files (each run's folder is replaced)",
    )
    p.add_argument("--url", help="SQLAlchemy URL (default: SRLAB_DATABASE_URL)")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.set_defaults(handler=export)


def export(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """`srlab export RUN [RUN ...] --out DIR`: checked first, then written run by run."""
    from server.export import export_run
    from server.export.dataset import require_minari

    out: Path = args.out
    runs: list[int] = list(dict.fromkeys(args.runs))
    check_out_folder(out, args.force)
    if args.minari:
        require_minari()
    store, db_engine = open_store(args.url)
    try:
        for run_id in runs:
            store.run_summary(run_id)  # every run is known before anything is written
        console = Console(file=stdout)
        err = Console(file=stderr, stderr=True)
        progress, bar = progress_bar(err, "[bold]export[/]", len(runs), quiet=args.quiet)
        with progress:
            for run_id in runs:
                folder = out / f"run-{run_id}"
                if folder.exists():
                    shutil.rmtree(folder)
                episodes = progress.add_task(f"run {run_id}: episodes", total=None, visible=False)

                def tell(what: str, done: int, total: int, task: TaskID = episodes) -> None:
                    progress.update(task, completed=done, total=total, visible=True)

                done = export_run(store, run_id, folder, minari=args.minari, progress=tell)
                progress.remove_task(episodes)
                progress.advance(bar)
                extra = f", Minari dataset {done.minari}" if done.minari else ""
                console.print(
                    f"run {run_id}: {counted(done.rewards, 'reward')}, "
                    f"{counted(done.episodes, 'episode')}{extra} "
                    f"-> {folder}",
                    soft_wrap=True,
                )
    finally:
        db_engine.dispose()
    return 0
