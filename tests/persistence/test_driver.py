"""Writes straight on SQLite's driver (`server.persistence.driver`): what SQLAlchemy would do."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest
from apphelpers import migrated_copy
from sqlalchemy import Engine, insert, select
from sqlalchemy.exc import IntegrityError, InvalidRequestError
from sqlalchemy.sql import Executable

from core.errors import StorageError
from core.ports import RewardRecord, RunSpec
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker
from server.persistence.db import DatabaseIdentityError, write_lock
from server.persistence.driver import ConnectionSql, DriverStatement, driver_transaction, drives
from server.persistence.orm import BehaviourRow, RewardRow, RunCommandRow

SPEC = RunSpec("kp", 1, 5)


def _run(engine: Engine) -> int:
    return SqlAlchemyRunStore(make_sessionmaker(engine)).create_run(SPEC, ())


def test_only_a_sqlite_file_is_written_through_the_driver(tmp_path: Path) -> None:
    assert drives(make_engine(migrated_copy(tmp_path / "a.db")))
    assert not drives(make_engine("sqlite://"))  # in memory: one shared connection


def test_values_are_stored_as_sqlalchemy_stores_them(sqlite_engine: Engine) -> None:
    """JSON, booleans, bytes and NULLs converted by their types, read back by the ORM."""
    run_id = _run(sqlite_engine)
    payload = {"stimulus": "Red", "strength": 0.5, "locked": True, "nested": [1, None]}
    with driver_transaction(sqlite_engine, "writing", {}) as sql:
        command = sql.first(
            insert(RunCommandRow).returning(RunCommandRow.id),
            {"run_id": run_id, "tick": 7, "kind": "edit", "payload": payload},
        )
        sql.many(
            insert(BehaviourRow),
            [
                {
                    "name": "drift-left",
                    "position": 99,
                    "family": "turn",
                    "speed_mps": 0.1,
                    "turn_dps": -30.0,
                    "ticks": 3,
                    "mode": "steer",
                    "synthesized": True,
                    "run_id": run_id,
                }
            ],
        )
    with sqlite_engine.connect() as c:
        read = ConnectionSql(c)
        assert read.first(select(RunCommandRow.payload), {}) == (payload,)
        stored = read.first(
            select(BehaviourRow.synthesized, BehaviourRow.turn_dps).where(
                BehaviourRow.name == "drift-left"
            ),
            {},
        )
        assert stored == (True, -30.0)
        assert command is not None
        assert read.first(select(RunCommandRow.id), {}) == command
    raw = sqlite3.connect(str(sqlite_engine.url.database))
    try:  # what SQLite holds is what a SQLAlchemy insert writes
        query = "SELECT synthesized, typeof(payload) FROM behaviours, run_commands WHERE name = ?"
        assert raw.execute(query, ("drift-left",)).fetchone() == (1, "text")
    finally:
        raw.close()


def test_a_statement_is_compiled_once_for_its_parameters(sqlite_engine: Engine) -> None:
    statement = insert(RewardRow)
    compiled = DriverStatement(statement, sqlite_engine.dialect, ("run_id", "tick"))
    assert compiled.sql.startswith("INSERT INTO rewards (run_id, tick")
    assert compiled.values({"run_id": 1, "tick": 2}) == (1, 2, "")  # note: its default
    cache: dict[tuple[int, tuple[str, ...]], tuple[Executable, DriverStatement]] = {}
    run_id = _run(sqlite_engine)
    row = {"run_id": run_id, "tick": 1, "episode": 0, "value": 1.0, "source": "task", "note": ""}
    for _ in range(3):
        with driver_transaction(sqlite_engine, "writing", cache) as sql:
            assert sql.many(statement, [row, row]) == 2  # rows changed, summed
    assert len(cache) == 1


def test_statements_the_driver_cannot_run_as_compiled_are_refused(sqlite_engine: Engine) -> None:
    expanding = select(RewardRow.id).where(RewardRow.id.in_([1, 2]))
    with pytest.raises(ValueError, match="expanding IN"):
        DriverStatement(expanding, sqlite_engine.dialect, ())
    compiled = DriverStatement(insert(RewardRow), sqlite_engine.dialect, ("run_id", "tick"))
    with pytest.raises(InvalidRequestError, match="tick"):
        compiled.values({"run_id": 1})  # a value missing is an error, never a NULL


def test_a_failure_rolls_back_the_whole_transaction_and_says_what_failed(
    sqlite_engine: Engine,
) -> None:
    run_id = _run(sqlite_engine)
    row = {"run_id": run_id, "tick": 1, "episode": 0, "value": 1.0, "source": "task", "note": ""}
    with (
        pytest.raises(StorageError, match="storage failed while logging things: FOREIGN KEY") as e,
        driver_transaction(sqlite_engine, "logging things", {}) as sql,
    ):
        sql.many(insert(RewardRow), [row])
        sql.many(insert(RewardRow), [{**row, "run_id": run_id + 1}])  # no such run
    assert isinstance(e.value.__cause__, IntegrityError)  # as a session's failure says
    with sqlite_engine.connect() as c:
        assert ConnectionSql(c).rows(select(RewardRow.id), {}) == []
    # The lock and the connection were given back: the next write goes through.
    with driver_transaction(sqlite_engine, "writing", {}) as sql:
        sql.many(insert(RewardRow), [row])
    lock = write_lock(sqlite_engine)
    lock.acquire("checking")  # not held: a StorageError after the busy timeout otherwise
    lock.release()


def test_a_replaced_database_file_is_refused_before_anything_is_written(
    sqlite_engine: Engine, tmp_path: Path
) -> None:
    run_id = _run(sqlite_engine)
    path = Path(str(sqlite_engine.url.database))
    path.rename(tmp_path / "moved.db")
    path.write_bytes((tmp_path / "moved.db").read_bytes())
    store = SqlAlchemyRunStore(make_sessionmaker(sqlite_engine))
    with pytest.raises(DatabaseIdentityError, match=r"logging a reward .* replaced"):
        store.log_reward(run_id, RewardRecord(1, 0, 1.0, "trainer", ""))
    sqlite_engine.dispose()  # no pooled connection left: a new one is refused too
    with pytest.raises(DatabaseIdentityError, match=r"storage failed while logging .* replaced"):
        store.log_reward(run_id, RewardRecord(1, 0, 1.0, "trainer", ""))
