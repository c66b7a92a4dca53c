"""Engines and sessions: SQLite tuned for a single durable writer, any other SQLAlchemy URL."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

from sqlalchemy import Engine, create_engine, event
from sqlalchemy import exc as sa_exc
from sqlalchemy.engine import URL, Connection, make_url
from sqlalchemy.orm import Session, sessionmaker
from sqlalchemy.pool import StaticPool

from core.errors import StorageError

DEFAULT_DATABASE_URL = "sqlite:///var/srlab.db"
IMMEDIATE = "srlab_begin_immediate"
"""Execution option asking SQLite for a write lock at BEGIN (see `make_engine`)."""


def database_url() -> str:
    """The database URL: ``SRLAB_DATABASE_URL``, else a SQLite file under ``./var``."""
    return os.environ.get("SRLAB_DATABASE_URL") or DEFAULT_DATABASE_URL


def parse_database_url(url: str | URL) -> URL:
    """The URL, checked: a `ValueError` that says what is wrong, and never the password.

    Catches a string that is no URL, an unknown database or driver name, and a driver
    that is not installed, before anything connects.
    """
    try:
        parsed = make_url(url)
    except sa_exc.ArgumentError:
        raise ValueError(
            "the database URL (SRLAB_DATABASE_URL or --url) is not a SQLAlchemy URL: "
            "expected dialect[+driver]://user:password@host[:port]/database or "
            "sqlite:///path/to/file.db"
        ) from None
    shown = parsed.render_as_string(hide_password=True)
    try:
        parsed.get_dialect().import_dbapi()
    except sa_exc.NoSuchModuleError:
        raise ValueError(
            f"database URL {shown!r}: SQLAlchemy has no dialect or driver "
            f"{parsed.drivername!r} (e.g. sqlite, postgresql+psycopg)"
        ) from None
    except ImportError as e:
        raise ValueError(
            f"database URL {shown!r}: its driver is not installed ({e.name or e})"
        ) from None
    return parsed


def _sqlite_file(url: URL) -> Path | None:
    """The file of a SQLite URL, or None for an in-memory database."""
    database = url.database
    if not database or database == ":memory:" or database.startswith("file:"):
        return None
    return Path(database)


def make_engine(
    url: str | URL,
    *,
    busy_timeout_ms: int = 5000,
    foreign_keys: bool = True,
    **kwargs: Any,
) -> Engine:
    """An engine for `url`; for SQLite, every connection gets srlab's PRAGMAs.

    SQLite runs in WAL mode with ``synchronous=NORMAL`` (durable across a process crash,
    fast enough to commit every reward), foreign keys on and a busy timeout. The driver's
    own transaction handling is turned off so that BEGIN is ours: a transaction opened
    with the `IMMEDIATE` execution option takes the write lock at once, so a writer never
    fails half-way when another connection committed since its first read. Migrations
    pass ``foreign_keys=False`` because batch table rebuilds would otherwise cascade.

    On PostgreSQL the same timeout is the sessions' ``lock_timeout``: a write that waits
    longer for a lock fails (the run ends with a storage error) instead of hanging with
    every request that waits for it.
    """
    url = parse_database_url(url)
    if url.get_backend_name() == "postgresql":
        kwargs.setdefault("connect_args", {"options": f"-c lock_timeout={int(busy_timeout_ms)}"})
    if url.get_backend_name() != "sqlite":
        return create_engine(url, pool_pre_ping=True, **kwargs)
    path = _sqlite_file(url)
    if path is None:
        kwargs.setdefault("poolclass", StaticPool)
        kwargs.setdefault("connect_args", {"check_same_thread": False})
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(url, **kwargs)
    pragmas = (
        "PRAGMA journal_mode=WAL",
        f"PRAGMA foreign_keys={'ON' if foreign_keys else 'OFF'}",
        f"PRAGMA busy_timeout={int(busy_timeout_ms)}",
        "PRAGMA synchronous=NORMAL",
    )

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, _record: Any) -> None:
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        try:
            for pragma in pragmas:
                cursor.execute(pragma)
        finally:
            cursor.close()

    @event.listens_for(engine, "begin")
    def _on_begin(connection: Connection) -> None:
        immediate = connection.get_execution_options().get(IMMEDIATE, False)
        connection.exec_driver_sql("BEGIN IMMEDIATE" if immediate else "BEGIN")

    return engine


def make_sessionmaker(engine: Engine) -> sessionmaker[Session]:
    """Sessions on `engine` whose objects stay readable after commit."""
    return sessionmaker(engine, expire_on_commit=False)


_DB_ERRORS = (sa_exc.DBAPIError, sa_exc.TimeoutError)


@contextmanager
def transaction(sessions: Callable[[], Session], what: str, *, write: bool) -> Iterator[Session]:
    """A session whose work is committed at the end or rolled back on any error.

    Writers take SQLite's write lock at BEGIN (see `make_engine`). Database failures come
    out as `StorageError` naming `what`, after the rollback, so nothing half-written stays.
    """
    session = sessions()
    try:
        if write:
            session.connection(execution_options={IMMEDIATE: True})
        yield session
        session.commit()
    except _DB_ERRORS as e:
        with suppress(*_DB_ERRORS):
            session.rollback()
        detail = str(getattr(e, "orig", None) or e).strip().splitlines()[0]
        raise StorageError(f"storage failed while {what}: {detail}") from e
    except BaseException:
        session.rollback()
        raise
    finally:
        session.close()
