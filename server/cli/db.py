"""`srlab db`: migrate and seed the database; and the run store the run commands open.

Storage (SQLAlchemy, Alembic) is imported when a command uses it, so the commands that
never touch the database start without it.
"""

from __future__ import annotations

import argparse
from typing import IO, TYPE_CHECKING, Any

from rich.console import Console

if TYPE_CHECKING:
    from server.persistence import SeedReport, SqlAlchemyRunStore


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """The `db` command, its actions and their arguments."""
    db_parser = sub.add_parser("db", help="the database: migrate and seed it")
    db_sub = db_parser.add_subparsers(dest="db_command", required=True, metavar="ACTION")
    up = db_sub.add_parser(
        "upgrade",
        help="create or migrate the database to the newest schema and seed the catalogue",
        description="Create or migrate the database (SRLAB_DATABASE_URL, default "
        "sqlite:///var/srlab.db) to the newest schema, then seed stimuli, behaviours, "
        "logical sensors and the innate, dp, kp and expert networks.",
    )
    up.add_argument("--url", help="SQLAlchemy URL (default: SRLAB_DATABASE_URL)")
    down = db_sub.add_parser("downgrade", help="migrate the database down to a revision")
    down.add_argument("revision", help="an Alembic revision, or 'base' to empty it")
    down.add_argument("--url", help="SQLAlchemy URL (default: SRLAB_DATABASE_URL)")
    db_parser.set_defaults(handler=db)


def db(args: argparse.Namespace, stdout: IO[str], stderr: IO[str]) -> int:
    """`srlab db upgrade|downgrade`."""
    from server.persistence import database_url, downgrade, upgrade

    url = args.url or database_url()
    console = Console(file=stdout)
    if args.db_command == "upgrade":
        report = upgrade(url)
        console.print(f"database {safe_url(url)} is at the newest schema")
        if report is not None:
            console.print(_seeded(report))
        return 0
    downgrade(url, args.revision)
    console.print(f"database {safe_url(url)} is at revision {args.revision}")
    return 0


def _seeded(report: SeedReport) -> str:
    """What seeding did, as a sentence (not the report's repr)."""
    if not report.changed:
        return "the catalogue and the shipped networks were already seeded: nothing changed"
    return (
        f"seeded the catalogue and the shipped networks: {report.added} rows added, "
        f"{report.updated} updated"
    )


def safe_url(url: str) -> str:
    """A URL with its password hidden."""
    from sqlalchemy.engine import make_url

    return make_url(url).render_as_string(hide_password=True)


def open_store(url: str | None) -> tuple[SqlAlchemyRunStore, Any]:
    """The run store at `url` (default: SRLAB_DATABASE_URL), migrated, and its engine."""
    from server.persistence import (
        SqlAlchemyRunStore,
        database_url,
        make_engine,
        make_sessionmaker,
        upgrade,
    )

    url = url or database_url()
    upgrade(url)  # cheap when already at head; a fresh machine needs no separate step
    engine = make_engine(url)
    return SqlAlchemyRunStore(make_sessionmaker(engine)), engine
