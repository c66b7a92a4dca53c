"""Writes as plain statements: on SQLite straight through the driver, elsewhere through Core.

The run store's hot writes (a trainer's reward logged, a reward's learning committed,
episodes ended) are a few short statements each. Run through SQLAlchemy (a session, its
connection, the compiled-statement cache, result objects, events) such a transaction cost
0.3-0.4 ms of Python on a warm CPU and 1.2-1.5 ms on one woken from idle, as a realtime
run's writer always is; the same statements on the `sqlite3` cursor cost 0.05 and
0.25-0.5 ms (`bench.store`, docs/benchmarks.md). Every write of a realtime run waits for
that, and in fast mode it is Python time taken from the ticks.

So the store writes against `Sql`, a small interface with two implementations:

- `DriverSql`: a SQLite transaction on the driver's own connection (`driver_transaction`),
  each statement compiled once by SQLAlchemy (`DriverStatement`: the same Core
  statement, its text and its parameters' order and type conversions) and executed on
  the cursor. The engine's guarantees are kept: the process's one-writer lock, the file
  guard's check before BEGIN, BEGIN IMMEDIATE, and errors as `StorageError` (caused by
  SQLAlchemy's own exception for the driver's, as a session's would be).
- `ConnectionSql`: the statements on a SQLAlchemy connection (PostgreSQL, or a write that
  also needs the ORM).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager, suppress
from typing import Any, Protocol

from sqlalchemy import Engine
from sqlalchemy import exc as sa_exc
from sqlalchemy.engine import Connection, Dialect
from sqlalchemy.schema import ColumnDefault
from sqlalchemy.sql import ClauseElement, Executable
from sqlalchemy.sql.compiler import SQLCompiler

from server.persistence.db import (
    DatabaseIdentityError,
    refuse_unstorable,
    sqlite_guard,
    storage_error,
    write_lock,
)

Row = tuple[Any, ...]
Params = Mapping[str, Any]


class Sql(Protocol):
    """Core statements run inside one open transaction."""

    @property
    def dialect(self) -> Dialect:
        """The database's dialect."""
        ...

    def first(self, statement: Executable, params: Params) -> Row | None:
        """The first row the statement returns, or None."""
        ...

    def rows(self, statement: Executable, params: Params) -> list[Row]:
        """Every row the statement returns."""
        ...

    def run(self, statement: Executable, params: Params) -> int:
        """Run a statement that returns no rows; how many rows it changed."""
        ...

    def many(self, statement: Executable, params: Sequence[Params]) -> int | None:
        """Run a statement that returns no rows once for each parameter set.

        How many rows it changed in all, or None where the driver cannot tell.
        """
        ...

    def returning(self, statement: Executable, params: Sequence[Params]) -> list[Row]:
        """Run an INSERT ... RETURNING once for each parameter set; a row for each, in order.

        The statement is built with ``sort_by_parameter_order``, so that SQLAlchemy keeps
        the order when it batches the sets.
        """
        ...


class ConnectionSql:
    """`Sql` on a SQLAlchemy connection."""

    def __init__(self, connection: Connection) -> None:
        self.connection = connection

    @property
    def dialect(self) -> Dialect:
        """As `Sql.dialect`."""
        return self.connection.dialect

    def first(self, statement: Executable, params: Params) -> Row | None:
        """As `Sql.first`."""
        row = self.connection.execute(statement, dict(params)).first()
        return None if row is None else tuple(row)

    def rows(self, statement: Executable, params: Params) -> list[Row]:
        """As `Sql.rows`."""
        return [tuple(r) for r in self.connection.execute(statement, dict(params))]

    def run(self, statement: Executable, params: Params) -> int:
        """As `Sql.run`."""
        return self.connection.execute(statement, dict(params)).rowcount

    def many(self, statement: Executable, params: Sequence[Params]) -> int | None:
        """As `Sql.many`."""
        if not params:
            return 0
        if len(params) == 1:  # one execution: its count is always the driver's own
            return self.connection.execute(statement, dict(params[0])).rowcount
        done = self.connection.execute(statement, [dict(p) for p in params])
        return done.rowcount if self.dialect.supports_sane_multi_rowcount else None

    def returning(self, statement: Executable, params: Sequence[Params]) -> list[Row]:
        """As `Sql.returning`."""
        if not params:
            return []
        if len(params) == 1:
            return [tuple(self.connection.execute(statement, dict(params[0])).one())]
        return [tuple(r) for r in self.connection.execute(statement, [dict(p) for p in params])]


class DriverStatement:
    """A Core statement compiled once for a dialect with positional parameters.

    `values` turns named parameters into the driver's tuple as SQLAlchemy would: what is
    not given comes from the statement's own bound values or a column's constant default,
    and each type's conversion for the dialect is applied. A default computed at execution
    (a function; none of the store's) and an expanding IN are refused when compiled.
    """

    def __init__(self, statement: Executable, dialect: Dialect, keys: Sequence[str]) -> None:
        assert isinstance(statement, ClauseElement)
        compiled = statement.compile(dialect=dialect, column_keys=list(keys) or None)
        assert isinstance(compiled, SQLCompiler)
        if compiled.positiontup is None:
            raise ValueError(f"{dialect.name}'s driver takes named parameters")
        prefetch = [*compiled.insert_prefetch, *compiled.update_prefetch]
        self._defaults: dict[str, Any] = {}
        for column in prefetch:
            default = column.default
            if not isinstance(default, ColumnDefault) or not default.is_scalar:
                raise ValueError("the statement needs column defaults computed at execution")
            self._defaults[column.key] = default.arg
        self.sql = str(compiled)
        if "POSTCOMPILE" in self.sql:
            raise ValueError("the statement has an expanding IN, rendered only at execution")
        self._compiled = compiled
        self._order: list[tuple[str, Callable[[Any], Any] | None]] = [
            (name, compiled.binds[name].type.dialect_impl(dialect).bind_processor(dialect))
            for name in compiled.positiontup
        ]

    def values(self, params: Params) -> tuple[Any, ...]:
        """The driver's parameters for `params`."""
        given = self._compiled.construct_params({**self._defaults, **params})
        values = tuple(
            given[name] if convert is None else convert(given[name])
            for name, convert in self._order
        )
        refuse_unstorable(values)  # as every engine's statements are (`make_engine`)
        return values


class DriverSql:
    """`Sql` on a DB-API cursor inside `driver_transaction`, statements compiled once."""

    def __init__(
        self,
        cursor: sqlite3.Cursor,
        dialect: Dialect,
        cache: dict[tuple[int, tuple[str, ...]], tuple[Executable, DriverStatement]],
    ) -> None:
        self.cursor = cursor
        self._dialect = dialect
        self._cache = cache

    @property
    def dialect(self) -> Dialect:
        """As `Sql.dialect`."""
        return self._dialect

    def _compiled(self, statement: Executable, keys: Params) -> DriverStatement:
        key = (id(statement), tuple(keys))
        found = self._cache.get(key)
        # The statement is kept with its compiled form, so its id is never another's.
        if found is None or found[0] is not statement:
            found = (statement, DriverStatement(statement, self._dialect, tuple(keys)))
            self._cache[key] = found
        return found[1]

    def _execute(self, statement: Executable, params: Params) -> sqlite3.Cursor:
        compiled = self._compiled(statement, params)
        return self.cursor.execute(compiled.sql, compiled.values(params))

    def first(self, statement: Executable, params: Params) -> Row | None:
        """As `Sql.first`."""
        row: Row | None = self._execute(statement, params).fetchone()
        return row

    def rows(self, statement: Executable, params: Params) -> list[Row]:
        """As `Sql.rows`."""
        return self._execute(statement, params).fetchall()

    def run(self, statement: Executable, params: Params) -> int:
        """As `Sql.run`."""
        return self._execute(statement, params).rowcount

    def many(self, statement: Executable, params: Sequence[Params]) -> int | None:
        """As `Sql.many`."""
        if not params:
            return 0
        compiled = self._compiled(statement, params[0])
        # sqlite3's rowcount after executemany is the sum of the changes.
        return self.cursor.executemany(compiled.sql, [compiled.values(p) for p in params]).rowcount

    def returning(self, statement: Executable, params: Sequence[Params]) -> list[Row]:
        """As `Sql.returning`."""
        rows = []
        for p in params:  # one execution each: a few microseconds on the driver
            row = self._execute(statement, p).fetchone()
            assert row is not None, "an INSERT ... RETURNING returned no row"
            rows.append(tuple(row))
        return rows


def drives(engine: Engine) -> bool:
    """Whether `driver_transaction` can write on `engine`: a SQLite file `make_engine` made."""
    return engine.dialect.name == "sqlite" and sqlite_guard(engine) is not None


@contextmanager
def driver_transaction(
    engine: Engine,
    what: str,
    cache: dict[tuple[int, tuple[str, ...]], tuple[Executable, DriverStatement]],
) -> Iterator[DriverSql]:
    """A SQLite write transaction on a pooled driver connection, as `transaction` keeps one.

    The process's write lock first, then the file guard's check and BEGIN IMMEDIATE;
    committed at the end, rolled back on any error. The driver's errors come out as
    `StorageError` naming `what`, caused by SQLAlchemy's exception for them.
    """
    guard = sqlite_guard(engine)
    assert guard is not None, "driver transactions are for SQLite files (see `drives`)"
    writer = write_lock(engine)
    with ExitStack() as held:  # given back in reverse: the cursor, the connection, the lock
        writer.acquire(what)
        held.callback(writer.release)
        try:
            pooled = engine.raw_connection()  # a new one checks the file guard first
        except (DatabaseIdentityError, sa_exc.DBAPIError, sa_exc.TimeoutError) as e:
            raise storage_error(what, e) from e
        held.callback(pooled.close)
        cursor = pooled.cursor()
        assert isinstance(cursor, sqlite3.Cursor)
        held.callback(cursor.close)
        try:
            guard.check()
            cursor.execute("BEGIN IMMEDIATE")
            yield DriverSql(cursor, engine.dialect, cache)
            cursor.execute("COMMIT")
        except DatabaseIdentityError as e:
            _rollback(cursor)
            raise storage_error(what, e) from e
        except sqlite3.Error as e:
            _rollback(cursor)
            wrapped = sa_exc.DBAPIError.instance(
                None, None, e, sqlite3.Error, dialect=engine.dialect
            )
            raise storage_error(what, wrapped) from wrapped
        except BaseException:
            _rollback(cursor)
            raise


def _rollback(cursor: sqlite3.Cursor) -> None:
    with suppress(sqlite3.Error):
        if cursor.connection.in_transaction:
            cursor.execute("ROLLBACK")
