"""Engines and sessions: SQLite tuned for a single durable writer, any other SQLAlchemy URL."""

from __future__ import annotations

import os
import threading
import urllib.parse
import weakref
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any

from sqlalchemy import Engine, create_engine, event, text
from sqlalchemy import exc as sa_exc
from sqlalchemy.engine import URL, Connection, make_url
from sqlalchemy.orm import Session, sessionmaker
from sqlalchemy.pool import StaticPool

from core.errors import StorageError
from core.text import UNSTORABLE, check_storable

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


WAL_INDEX_MIN_BYTES = 32768
"""A WAL index (-shm) in use is at least one 32 KiB region: SQLite never shrinks it."""


class DatabaseIdentityError(StorageError):
    """The SQLite file the service opened is gone, or another file took its place."""


class SqliteFileGuard:
    """Keeps a SQLite engine on the file it first opened, by the file's device and inode.

    A connection holds its file open, so after the file is deleted (or replaced by a
    rename) it would go on reading and committing to a file no one can open again: acks for
    writes that a restart loses. `check` compares the path's identity with the pinned one;
    the engine calls it before every transaction and before every new connection, and new
    connections open the file read-write without creating it (an empty file in its place
    would fail later with "no such table").

    The WAL index (-shm) is memory-mapped: if it is truncated, SQLite's next access to the
    mapping raises SIGBUS, which SQLite cannot turn into an error. `check` refuses a
    transaction while the index is shorter than SQLite ever leaves it, so the common fault
    (the file truncated, or replaced by an empty one) is a `StorageError` instead of a
    dead process; a truncation in the microseconds between the check and the access still
    kills the process (`srlab serve` logs it with faulthandler).
    """

    def __init__(self, path: Path) -> None:
        self.path = path.resolve()
        self.shm = self.path.with_name(self.path.name + "-shm")
        self.identity: tuple[int, int] | None = None
        self._lock = threading.RLock()  # a nested write in one thread waits on SQLite, as before

    def pin(self) -> None:
        """Remember the file's identity, the first time a connection opened it."""
        with self._lock:
            if self.identity is None:
                st = self.path.stat()
                self.identity = (st.st_dev, st.st_ino)

    def check(self) -> None:
        """`DatabaseIdentityError` if the pinned file is gone or replaced, or its index cut."""
        if self.identity is None:
            return
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            raise DatabaseIdentityError(
                f"the database file {self.path} was deleted while the service had it open: "
                "nothing more is stored (restore the file and restart the service)"
            ) from None
        if (st.st_dev, st.st_ino) != self.identity:
            raise DatabaseIdentityError(
                f"the database file {self.path} was replaced by another file (device, inode "
                f"{self.identity} became {(st.st_dev, st.st_ino)}) while the service had it "
                "open: nothing more is stored (restart the service to use the new file)"
            )
        try:
            shm = os.stat(self.shm).st_size
        except FileNotFoundError:
            return  # no connection has the index open: SQLite makes a new one
        if shm < WAL_INDEX_MIN_BYTES:
            raise DatabaseIdentityError(
                f"the WAL index {self.shm} was truncated to {shm} bytes while the service "
                "had it mapped: nothing more is stored (restart the service)"
            )

    def read_write_uri(self) -> str:
        """The file as a SQLite URI that opens it read-write and never creates it."""
        return f"file:{urllib.parse.quote(str(self.path))}?mode=rw"


_GUARDS: weakref.WeakKeyDictionary[Engine, SqliteFileGuard] = weakref.WeakKeyDictionary()


def sqlite_guard(engine: Engine) -> SqliteFileGuard | None:
    """The file guard of an engine `make_engine` made for a SQLite file, else None."""
    return _GUARDS.get(engine)


_WRITERS: weakref.WeakKeyDictionary[Engine, _WriteLock] = weakref.WeakKeyDictionary()


class _WriteLock:
    """One writer at a time among this process's connections to one SQLite database.

    SQLite has one write lock per database. Without this, every thread that wants it polls
    SQLite's busy handler, which sleeps up to 100 ms between tries: under 32 realtime runs'
    writers and the requests' edits, waiters kept missing the lock until the busy timeout
    failed them ("database is locked") while the lock was free most of the time. Waiting
    here instead wakes the next writer as soon as the lock is released; SQLite's own busy
    timeout is left for other processes (a migration, the CLI).
    """

    def __init__(self, timeout_s: float) -> None:
        self._lock = threading.RLock()  # a nested write in one thread waits on SQLite, as before
        self.timeout_s = timeout_s

    def acquire(self, what: str) -> None:
        if not self._lock.acquire(timeout=self.timeout_s):
            raise StorageError(
                f"storage failed while {what}: database is locked (another writer of this "
                f"process held it for over {self.timeout_s:g} s)"
            )

    def release(self) -> None:
        self._lock.release()


def refuse_unstorable(parameters: Any) -> None:
    """`ValueError` for a statement's text value no supported database stores.

    The one check every statement's parameters pass (`make_engine`'s engines, and the
    driver's statements in `server.persistence.driver`), so a text SQLite would take and
    PostgreSQL refuse (NUL), or neither can encode (a lone surrogate), is refused the same
    way on both before anything is written: as bad input, not as failing storage.
    """
    if isinstance(parameters, dict):
        parameters = tuple(parameters.values())
    if not isinstance(parameters, tuple | list):
        return
    for value in parameters:
        if isinstance(value, str):
            if UNSTORABLE.search(value) is not None:
                check_storable(value, "a value to store")
        elif isinstance(value, dict | tuple | list):  # executemany's rows
            refuse_unstorable(value)


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
        engine = create_engine(url, pool_pre_ping=True, **kwargs)
        event.listen(engine, "before_cursor_execute", _refuse_unstorable)
        return engine
    path = _sqlite_file(url)
    if path is None:
        kwargs.setdefault("poolclass", StaticPool)
        kwargs.setdefault("connect_args", {"check_same_thread": False})
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
    engine = create_engine(url, **kwargs)
    event.listen(engine, "before_cursor_execute", _refuse_unstorable)
    guard = SqliteFileGuard(path) if path is not None else None
    if guard is not None:
        _GUARDS[engine] = guard
    _WRITERS[engine] = _WriteLock(busy_timeout_ms / 1000)
    pragmas = (
        "PRAGMA journal_mode=WAL",
        f"PRAGMA foreign_keys={'ON' if foreign_keys else 'OFF'}",
        f"PRAGMA busy_timeout={int(busy_timeout_ms)}",
        "PRAGMA synchronous=NORMAL",
    )

    @event.listens_for(engine, "do_connect")
    def _on_do_connect(
        _dialect: Any, _record: Any, cargs: list[Any], cparams: dict[str, Any]
    ) -> None:
        if guard is not None and guard.identity is not None:
            guard.check()
            # Once the file is pinned, a new pooled connection never creates one.
            cargs[:1] = [guard.read_write_uri()]
            cparams["uri"] = True

    @event.listens_for(engine, "connect")
    def _on_connect(dbapi_connection: Any, _record: Any) -> None:
        dbapi_connection.isolation_level = None
        cursor = dbapi_connection.cursor()
        try:
            for pragma in pragmas:
                cursor.execute(pragma)
        finally:
            cursor.close()
        if guard is not None:
            guard.pin()

    @event.listens_for(engine, "begin")
    def _on_begin(connection: Connection) -> None:
        if guard is not None:
            guard.check()
        immediate = connection.get_execution_options().get(IMMEDIATE, False)
        connection.exec_driver_sql("BEGIN IMMEDIATE" if immediate else "BEGIN")

    return engine


def _refuse_unstorable(
    _connection: Any, _cursor: Any, _statement: str, parameters: Any, *_: Any
) -> None:
    refuse_unstorable(parameters)


def make_sessionmaker(engine: Engine) -> sessionmaker[Session]:
    """Sessions on `engine` whose objects stay readable after commit."""
    return sessionmaker(engine, expire_on_commit=False)


_DB_ERRORS = (sa_exc.DBAPIError, sa_exc.TimeoutError)


def _writer(session: Session) -> _WriteLock | None:
    bind = session.get_bind()
    return _WRITERS.get(bind if isinstance(bind, Engine) else bind.engine)


def write_lock(engine: Engine) -> _WriteLock:
    """The one-writer lock of a SQLite engine `make_engine` made."""
    return _WRITERS[engine]


def storage_error(what: str, e: Exception) -> StorageError:
    """A database failure as srlab reports it: what failed, and the database's message.

    A `DatabaseIdentityError` stays one, so that callers can tell a lost file apart.
    """
    detail = str(getattr(e, "orig", None) or e).strip().splitlines()[0]
    kind = DatabaseIdentityError if isinstance(e, DatabaseIdentityError) else StorageError
    return kind(f"storage failed while {what}: {detail}")


@contextmanager
def transaction(sessions: Callable[[], Session], what: str, *, write: bool) -> Iterator[Session]:
    """A session whose work is committed at the end or rolled back on any error.

    Writers take SQLite's write lock at BEGIN (see `make_engine`). Database failures come
    out as `StorageError` naming `what`, after the rollback, so nothing half-written stays.
    """
    session = sessions()
    writer = _writer(session) if write else None
    if writer is not None:
        try:
            writer.acquire(what)
        except StorageError:
            session.close()
            raise
    try:
        if write:
            session.connection(execution_options={IMMEDIATE: True})
        yield session
        session.commit()
    except DatabaseIdentityError as e:
        with suppress(*_DB_ERRORS, DatabaseIdentityError):
            session.rollback()
        raise storage_error(what, e) from e
    except _DB_ERRORS as e:
        with suppress(*_DB_ERRORS):
            session.rollback()
        raise storage_error(what, e) from e
    except BaseException:
        session.rollback()
        raise
    finally:
        session.close()
        if writer is not None:
            writer.release()


class DatabaseCheck:
    """What /api/health asks of the database: a read, and the dialect's name."""

    def __init__(self, engine: Engine) -> None:
        self.engine = engine
        self._sessions = make_sessionmaker(engine)

    def check(self) -> str:
        """Read one row in a transaction (the SQLite file's identity checked); the dialect."""
        with transaction(self._sessions, "checking the database", write=False) as s:
            s.execute(text("select 1"))
        return self.engine.dialect.name
