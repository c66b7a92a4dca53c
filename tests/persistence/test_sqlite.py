"""SQLite specifics: PRAGMAs, storage failures surfacing as StorageError, seeding."""

from __future__ import annotations

import dataclasses
import shutil
import sqlite3
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from apphelpers import migrated_copy
from sqlalchemy import Engine, event, func, select, text, update
from sqlalchemy.exc import OperationalError
from sqlalchemy.orm import Session, sessionmaker

from core.brain.catalog import AssociationSpec, Catalog, KnowledgeSet
from core.errors import StorageError
from core.ports import LearningUpdate, NetworkPair, RewardRecord, RunSpec, RunStatus
from server.persistence import (
    SqlAlchemyRunStore,
    database_url,
    make_engine,
    make_sessionmaker,
    seed_catalog,
)
from server.persistence.db import DatabaseIdentityError, transaction
from server.persistence.orm import (
    AssociationRow,
    BehaviourRow,
    LogicalSensorRow,
    NetworkRow,
    NetworkVersionRow,
    RewardRow,
    RunRow,
    StimulusRow,
)

SPEC = RunSpec("dp", seed=1)
NETWORK = (NetworkPair("Red", "stop", 1.0, "dp"),)


def reward(tick: int) -> RewardRecord:
    return RewardRecord(tick, 0, 1.0, "human")


def test_every_connection_gets_the_pragmas(sqlite_engine: Engine) -> None:
    for _ in range(2):
        with sqlite_engine.connect() as c:
            c.invalidate()  # the next checkout opens a new connection
    with sqlite_engine.connect() as c:
        values = {
            p: c.exec_driver_sql(f"PRAGMA {p}").scalar()
            for p in ("journal_mode", "foreign_keys", "busy_timeout", "synchronous")
        }

    assert values == {
        "journal_mode": "wal",
        "foreign_keys": 1,
        "busy_timeout": 5000,
        "synchronous": 1,
    }


def test_make_engine_creates_the_folder_of_the_file(tmp_path: Path) -> None:
    path = tmp_path / "a" / "b" / "srlab.db"

    engine = make_engine(f"sqlite:///{path}")
    with engine.connect() as c:
        c.exec_driver_sql("CREATE TABLE t (x INTEGER)")
    engine.dispose()

    assert path.exists()


def test_make_engine_shares_one_in_memory_database_across_threads() -> None:
    engine = make_engine("sqlite://")
    with engine.begin() as c:
        c.exec_driver_sql("CREATE TABLE t (x INTEGER)")
        c.exec_driver_sql("INSERT INTO t VALUES (1)")
    seen: list[int] = []

    def read() -> None:
        with engine.connect() as c:
            seen.append(c.exec_driver_sql("SELECT x FROM t").scalar_one())

    thread = threading.Thread(target=read)
    thread.start()
    thread.join()
    engine.dispose()

    assert seen == [1]


def test_database_url_reads_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SRLAB_DATABASE_URL", raising=False)
    assert database_url() == "sqlite:///var/srlab.db"

    monkeypatch.setenv("SRLAB_DATABASE_URL", "postgresql+psycopg://u@h/db")
    assert database_url() == "postgresql+psycopg://u@h/db"


def test_deleting_a_run_cascades_to_what_it_owns(sqlite_engine: Engine) -> None:
    store = SqlAlchemyRunStore(make_sessionmaker(sqlite_engine))
    run_id = store.create_run(SPEC, NETWORK)
    store.apply_reward(
        run_id, store.log_reward(run_id, reward(1)), LearningUpdate(ltm={("Red", "stop"): 1.0}), 1
    )

    with sqlite_engine.begin() as c:
        c.execute(text("DELETE FROM runs WHERE id = :id"), {"id": run_id})
        left = [
            c.execute(text(f"SELECT count(*) FROM {t}")).scalar_one()
            for t in ("rewards", "ltm", "run_associations")
        ]

    assert left == [0, 0, 0]


class FailingCursor(sqlite3.Cursor):
    """A driver cursor whose COMMIT fails as a full disk makes it fail, once armed."""

    def execute(self, sql: str, parameters: Any = (), /) -> FailingCursor:
        if FailingConnection.armed and sql.strip().upper() == "COMMIT":
            raise sqlite3.OperationalError("database or disk is full")
        super().execute(sql, parameters)
        return self


class FailingConnection(sqlite3.Connection):
    """SQLite's driver with `FailingCursor`s and a commit that fails the same way."""

    armed = False

    def cursor(self, factory: Any = FailingCursor) -> Any:
        return super().cursor(factory)

    def commit(self) -> None:
        if FailingConnection.armed and self.in_transaction:
            raise sqlite3.OperationalError("database or disk is full")
        super().commit()


@pytest.fixture
def failing_sessions(tmp_path: Path, migrated_sqlite: Path) -> Iterator[sessionmaker[Session]]:
    """Sessions on an engine whose driver fails to commit while `FailingConnection.armed`."""
    FailingConnection.armed = False
    engine = make_engine(
        migrated_copy(tmp_path / "failing.db"), connect_args={"factory": FailingConnection}
    )
    yield make_sessionmaker(engine)
    FailingConnection.armed = False
    engine.dispose()


def test_a_failed_commit_raises_storage_error_and_loses_nothing_committed(
    failing_sessions: sessionmaker[Session],
) -> None:
    store = SqlAlchemyRunStore(failing_sessions)
    run_id = store.create_run(SPEC, NETWORK)
    kept = store.log_reward(run_id, reward(1))

    FailingConnection.armed = True
    with pytest.raises(StorageError, match="database or disk is full") as raised:
        store.log_reward(run_id, reward(2))
    with pytest.raises(StorageError, match="applying reward"):
        store.apply_reward(run_id, kept, LearningUpdate(ltm={("Red", "stop"): 0.9}), 1)
    FailingConnection.armed = False

    assert isinstance(raised.value.__cause__, OperationalError)
    fresh = SqlAlchemyRunStore(make_sessionmaker(make_engine(str(failing_sessions.kw["bind"].url))))
    assert [(r.id, r.applied) for r in fresh.rewards(run_id)] == [(kept, False)]
    assert fresh.ltm(run_id) == {}
    assert fresh.network(run_id) == NETWORK


def test_a_locked_database_raises_storage_error_and_recovers(sqlite_engine: Engine) -> None:
    path = sqlite_engine.url.database
    assert path is not None
    store = SqlAlchemyRunStore(make_sessionmaker(sqlite_engine))
    run_id = store.create_run(SPEC, NETWORK)
    kept = store.log_reward(run_id, reward(1))
    impatient = make_engine(sqlite_engine.url, busy_timeout_ms=50)
    blocked = SqlAlchemyRunStore(make_sessionmaker(impatient))
    holder = sqlite3.connect(path, isolation_level=None)
    try:
        holder.execute("BEGIN IMMEDIATE")
        holder.execute(
            "INSERT INTO logical_sensors (name, position, physical, processing, "
            "objective, level, priority, weight) "
            "VALUES ('held', 99, '[]', 'rules', 'x', 'low', 1, 1.0)"
        )
        assert blocked.load_run(run_id).id == run_id  # WAL: readers never wait
        with pytest.raises(StorageError, match="locked"):
            blocked.log_reward(run_id, reward(2))
        with pytest.raises(StorageError, match="locked"):
            blocked.apply_reward(run_id, kept, LearningUpdate(ltm={("Red", "stop"): 0.5}), 1)
        holder.execute("ROLLBACK")
    finally:
        holder.close()

    after = blocked.log_reward(run_id, reward(3))
    impatient.dispose()
    assert [(r.id, r.applied) for r in store.rewards(run_id)] == [(kept, False), (after, False)]
    assert store.ltm(run_id) == {}


def test_writes_take_the_write_lock_at_begin_and_reads_do_not(sqlite_engine: Engine) -> None:
    store = SqlAlchemyRunStore(make_sessionmaker(sqlite_engine))
    run_id = store.create_run(SPEC, NETWORK)
    begins: list[str] = []

    def record(statement: str) -> None:
        if statement.startswith("BEGIN"):
            begins.append(statement)

    def trace(connection: sqlite3.Connection, *_: Any) -> None:
        connection.set_trace_callback(record)  # what SQLite itself is asked to run

    event.listen(sqlite_engine, "checkout", trace)
    try:
        store.log_reward(run_id, reward(1))
        store.load_run(run_id)
    finally:
        event.remove(sqlite_engine, "checkout", trace)

    assert begins == ["BEGIN IMMEDIATE", "BEGIN"]


def test_set_status_stamps_when_a_run_started_and_ended(sqlite_engine: Engine) -> None:
    store = SqlAlchemyRunStore(make_sessionmaker(sqlite_engine))
    run_id = store.create_run(SPEC, NETWORK)

    def stamps() -> tuple[bool, bool]:
        with Session(sqlite_engine) as s:
            run = s.get_one(RunRow, run_id)
            return run.started_at is not None, run.finished_at is not None

    created = stamps()
    store.set_status(run_id, RunStatus.RUNNING)
    running = stamps()
    store.set_status(run_id, RunStatus.FINISHED)

    assert (created, running, stamps()) == ((False, False), (True, False), (True, True))


def test_writers_on_two_engines_interleave_without_failing(sqlite_engine: Engine) -> None:
    store = SqlAlchemyRunStore(make_sessionmaker(sqlite_engine))
    run_ids = [store.create_run(SPEC, NETWORK) for _ in range(2)]
    errors: list[BaseException] = []

    def write(run_id: int) -> None:
        engine = make_engine(sqlite_engine.url)
        mine = SqlAlchemyRunStore(make_sessionmaker(engine))
        try:
            for tick in range(40):
                rid = mine.log_reward(run_id, reward(tick))
                mine.apply_reward(run_id, rid, LearningUpdate(ltm={("Red", "stop"): tick / 40}), 1)
        except BaseException as e:  # collected and asserted below
            errors.append(e)
        finally:
            engine.dispose()

    threads = [threading.Thread(target=write, args=(r,)) for r in run_ids]
    for t in threads:
        t.start()
    for t in threads:
        t.join()

    assert errors == []
    for run_id in run_ids:
        assert [r.applied for r in store.rewards(run_id)] == [True] * 40
        assert store.ltm(run_id) == {("Red", "stop"): 39 / 40}


def test_a_committed_write_is_visible_from_another_engine(sqlite_engine: Engine) -> None:
    store = SqlAlchemyRunStore(make_sessionmaker(sqlite_engine))
    run_id = store.create_run(SPEC, NETWORK)
    reward_id = store.log_reward(run_id, reward(1))

    other = make_engine(sqlite_engine.url)
    with other.connect() as c:
        row = c.execute(select(RewardRow.id, RewardRow.run_id)).one()
    other.dispose()

    assert tuple(row) == (reward_id, run_id)


def counts(engine: Engine) -> dict[str, int]:
    with Session(engine) as s:
        return {
            "sensors": s.scalar(select(func.count()).select_from(LogicalSensorRow)) or 0,
            "stimuli": s.scalar(select(func.count()).select_from(StimulusRow)) or 0,
            "behaviours": s.scalar(select(func.count()).select_from(BehaviourRow)) or 0,
            "associations": s.scalar(select(func.count()).select_from(AssociationRow)) or 0,
            "versions": s.scalar(select(func.count()).select_from(NetworkVersionRow)) or 0,
        }


def test_seeding_stores_the_catalogue(sqlite_engine: Engine, catalog: Catalog) -> None:
    with Session(sqlite_engine) as s:
        networks = {n.name: (n.builtin, n.version) for n in s.scalars(select(NetworkRow))}
        dp = s.scalars(select(NetworkRow).where(NetworkRow.name == "dp")).one()
        dp_pairs = s.scalar(
            select(func.count())
            .select_from(AssociationRow)
            .where(AssociationRow.network_id == dp.id)
        )

    assert counts(sqlite_engine) == {
        "sensors": len(catalog.sensors),
        "stimuli": len(catalog.stimuli),
        "behaviours": len(catalog.behaviours),
        "associations": sum(len(k.associations) for k in catalog.knowledge.values()),
        "versions": len(catalog.knowledge),
    }
    assert networks == dict.fromkeys(catalog.knowledge, (True, 1))
    assert dp_pairs == len(catalog.knowledge_set("dp").associations)


def test_seeding_again_changes_nothing(sqlite_engine: Engine) -> None:
    before = counts(sqlite_engine)

    report = seed_catalog(make_sessionmaker(sqlite_engine))

    assert not report.changed
    assert counts(sqlite_engine) == before


def changed_knowledge(catalog: Catalog) -> Catalog:
    """The catalogue with one more association in every knowledge set."""
    extra = AssociationSpec("Collision", "leftturn15", 0.5, "designed")
    assert all(
        (a.stimulus, a.behaviour) != ("Collision", "leftturn15")
        for ks in catalog.knowledge.values()
        for a in ks.associations
    )
    knowledge = {
        name: KnowledgeSet(ks.name, ks.description, (*ks.associations, extra))
        for name, ks in catalog.knowledge.items()
    }
    return dataclasses.replace(catalog, knowledge=knowledge)


def test_seeding_refreshes_an_unedited_network_but_never_an_edited_one(
    sqlite_engine: Engine, catalog: Catalog
) -> None:
    sessions = make_sessionmaker(sqlite_engine)
    with sessions.begin() as s:
        s.execute(update(NetworkRow).where(NetworkRow.name == "dp").values(version=2))
        dp = s.scalars(select(NetworkRow).where(NetworkRow.name == "dp")).one()
        s.execute(
            update(AssociationRow).where(AssociationRow.network_id == dp.id).values(strength=0.25)
        )
    edited = counts(sqlite_engine)["associations"]

    report = seed_catalog(sessions, changed_knowledge(catalog))

    with Session(sqlite_engine) as s:
        strengths = {
            n.name: sorted(
                {
                    a.strength
                    for a in s.scalars(
                        select(AssociationRow).where(AssociationRow.network_id == n.id)
                    )
                }
            )
            for n in s.scalars(select(NetworkRow))
        }
    unedited = len(catalog.knowledge) - 1  # every shipped network but dp
    assert report.updated == unedited
    assert counts(sqlite_engine)["associations"] == edited + unedited
    assert strengths["dp"] == [0.25]
    assert 0.5 in strengths["innate"]
    assert not seed_catalog(sessions, changed_knowledge(catalog)).changed


def _table(engine: Engine) -> sessionmaker[Session]:
    sessions = make_sessionmaker(engine)
    with transaction(sessions, "creating a table", write=True) as s:
        s.execute(text("CREATE TABLE t (x INTEGER)"))
    return sessions


def _execute(sessions: sessionmaker[Session], what: str, sql: str, *, write: bool) -> None:
    with transaction(sessions, what, write=write) as s:
        s.execute(text(sql))


def test_a_deleted_file_fails_every_transaction_and_is_not_recreated(tmp_path: Path) -> None:
    path = tmp_path / "srlab.db"
    engine = make_engine(f"sqlite:///{path}")
    sessions = _table(engine)
    path.unlink()
    for write in (True, False):
        with pytest.raises(DatabaseIdentityError, match=f"while inserting: .*{path}.*deleted"):
            _execute(sessions, "inserting", "INSERT INTO t VALUES (1)", write=write)
    engine.dispose()  # a new pooled connection would have made an empty file
    with pytest.raises(DatabaseIdentityError, match="deleted"):
        _execute(sessions, "reading", "SELECT 1", write=False)
    assert not path.exists()
    engine.dispose()


def test_a_replaced_file_fails_every_transaction(tmp_path: Path) -> None:
    path = tmp_path / "srlab.db"
    engine = make_engine(f"sqlite:///{path}")
    sessions = _table(engine)
    other = tmp_path / "other.db"
    with sqlite3.connect(other) as c:
        c.execute("CREATE TABLE t (x INTEGER)")
    other.replace(path)
    with pytest.raises(DatabaseIdentityError, match="replaced by another file"):
        _execute(sessions, "inserting", "INSERT INTO t VALUES (1)", write=True)
    engine.dispose()
    with sqlite3.connect(path) as c:
        assert c.execute("SELECT count(*) FROM t").fetchone() == (0,)  # nothing went there


def test_a_truncated_wal_index_is_a_storage_error_not_sigbus(tmp_path: Path) -> None:
    # In a child: the truncated index stays mapped, and closing the connection would fault.
    script = f"""
import os, sys
from sqlalchemy import text
from server.persistence.db import DatabaseIdentityError, make_engine, make_sessionmaker, transaction
sessions = make_sessionmaker(make_engine("sqlite:///{tmp_path / "srlab.db"}"))
with transaction(sessions, "creating", write=True) as s:
    s.execute(text("CREATE TABLE t (x INTEGER)"))
os.truncate("{tmp_path / "srlab.db-shm"}", 0)
try:
    with transaction(sessions, "inserting", write=True) as s:
        s.execute(text("INSERT INTO t VALUES (1)"))
except DatabaseIdentityError as e:
    sys.stdout.write(str(e))
    sys.stdout.flush()
    os._exit(0)
os._exit(3)
"""
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 0, done.stderr
    assert "WAL index" in done.stdout and "truncated to 0 bytes" in done.stdout


def test_this_process_writers_wait_for_each_other_not_on_sqlite(
    migrated_sqlite: Path, tmp_path: Path
) -> None:
    """A writer of this process waits on the process's write lock, never polling SQLite.

    The lock held by one thread's write transaction makes another's wait here (and fail
    with this message past the timeout); reads never wait; once released, writes go on.
    """
    shutil.copyfile(migrated_sqlite, tmp_path / "srlab.db")
    engine = make_engine(f"sqlite:///{tmp_path / 'srlab.db'}", busy_timeout_ms=200)
    store = SqlAlchemyRunStore(make_sessionmaker(engine))
    run_id = store.create_run(SPEC, NETWORK)
    sessions = make_sessionmaker(engine)
    begins: list[str] = []

    def record(_c: Any, _cursor: Any, statement: str, *_: Any) -> None:
        if statement.startswith("BEGIN"):
            begins.append(statement)

    event.listen(engine, "before_cursor_execute", record)
    holding, release = threading.Event(), threading.Event()

    def hold() -> None:
        with transaction(sessions, "holding the lock", write=True):
            holding.set()
            release.wait(30)

    holder = threading.Thread(target=hold)
    holder.start()
    try:
        assert holding.wait(30)
        with pytest.raises(StorageError, match="another writer of this process"):
            store.log_reward(run_id, reward(1))
        assert begins == ["BEGIN IMMEDIATE"]  # the waiting writer never asked SQLite
        assert store.load_run(run_id).id == run_id
    finally:
        release.set()
        holder.join(30)
    kept = store.log_reward(run_id, reward(2))
    assert [r.id for r in store.rewards(run_id)] == [kept]
    engine.dispose()
