"""The migrations build exactly the ORM's schema, on SQLite and PostgreSQL, and run both ways."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from alembic import command
from alembic.autogenerate import compare_metadata
from alembic.config import Config
from alembic.migration import MigrationContext
from alembic.script import ScriptDirectory
from conftest import fresh_postgres_database
from sqlalchemy import Engine, inspect, text

from core.engine.build import reaction_seconds
from core.ports import RewardRecord
from server.persistence import (
    Base,
    SqlAlchemyRunStore,
    alembic_config,
    downgrade,
    make_engine,
    make_sessionmaker,
    upgrade,
)
from server.persistence.migrate import ROOT
from server.persistence.studies import SqlAlchemyStudyRepository

TABLES = {
    "logical_sensors",
    "stimuli",
    "behaviours",
    "networks",
    "associations",
    "network_versions",
    "runs",
    "run_associations",
    "ltm",
    "rltm",
    "episodes",
    "rewards",
    "run_commands",
    "studies",
    "participants",
    "participant_identities",
    "questionnaire_answers",
}


def drift(url: str) -> list[Any]:
    """What autogenerate would change to make the database match the ORM (nothing, we hope)."""
    engine = make_engine(url)
    try:
        with engine.connect() as connection:
            context = MigrationContext.configure(
                connection, opts={"compare_type": True, "compare_server_default": True}
            )
            return list(compare_metadata(context, Base.metadata))
    finally:
        engine.dispose()


def tables(url: str) -> set[str]:
    engine = make_engine(url)
    try:
        return set(inspect(engine).get_table_names())
    finally:
        engine.dispose()


@pytest.fixture
def sqlite_url(tmp_path: Path) -> str:
    return f"sqlite:///{tmp_path / 'srlab.db'}"


def upgraded_from(url: str, revision: str, *statements: str) -> None:
    """The database made at `revision` with the rows `statements` insert, then upgraded."""
    command.upgrade(alembic_config(url), revision)
    with engine_of(url) as engine, engine.begin() as connection:
        for statement in statements:
            connection.execute(text(statement))
    upgrade(url, seed=False)


@contextmanager
def engine_of(url: str) -> Iterator[Engine]:
    """An engine on `url`, disposed after."""
    engine = make_engine(url)
    try:
        yield engine
    finally:
        engine.dispose()


def test_there_is_one_head() -> None:
    script = ScriptDirectory.from_config(alembic_config("sqlite://"))

    assert len(script.get_heads()) == 1


def test_upgrade_head_on_sqlite_matches_the_models(sqlite_url: str) -> None:
    upgrade(sqlite_url, seed=False)

    assert tables(sqlite_url) == TABLES | {"alembic_version"}
    assert drift(sqlite_url) == []


def test_downgrade_to_base_and_upgrade_again_on_sqlite(sqlite_url: str) -> None:
    first = upgrade(sqlite_url)

    downgrade(sqlite_url, "base")
    emptied = tables(sqlite_url)
    again = upgrade(sqlite_url)

    assert emptied == {"alembic_version"}
    assert first is not None and again is not None and again.added == first.added
    assert drift(sqlite_url) == []


def test_upgrade_twice_changes_nothing(sqlite_url: str) -> None:
    upgrade(sqlite_url)

    report = upgrade(sqlite_url)

    assert report is not None and not report.changed


def test_alembic_ini_takes_the_url_from_the_environment(
    sqlite_url: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SRLAB_DATABASE_URL", sqlite_url)
    config = Config(str(ROOT / "alembic.ini"))
    config.attributes["configure_logger"] = False

    command.upgrade(config, "head")

    assert drift(sqlite_url) == []


def test_upgrade_head_on_postgres_matches_the_models_and_round_trips(postgres_url: str) -> None:
    with fresh_postgres_database(postgres_url) as url:
        upgrade(url)
        assert tables(url) == TABLES | {"alembic_version"}
        assert drift(url) == []

        downgrade(url, "base")
        assert tables(url) == {"alembic_version"}

        upgrade(url)
        assert drift(url) == []


def test_runs_stored_before_0002_read_with_the_defaults_unnamed(sqlite_url: str) -> None:
    upgraded_from(
        sqlite_url,
        "0001",
        "INSERT INTO runs (condition, seed, mode, hz, params, status) "
        "VALUES ('kp', 3, 'fast', 10.0, '{}', 'stopped')",
    )
    with engine_of(sqlite_url) as engine:
        [run] = SqlAlchemyRunStore(make_sessionmaker(engine)).list_runs()
    assert (run.spec.condition, run.spec.world, run.spec.sensors) == ("kp", "", "")
    assert drift(sqlite_url) == []
    downgrade(sqlite_url, "0001")
    assert drift(sqlite_url) != []  # the two columns are gone again


def test_runs_stored_before_0003_keep_the_network_made_before_them(sqlite_url: str) -> None:
    upgraded_from(
        sqlite_url,
        "0002",
        "INSERT INTO networks (id, name, description, created_at, updated_at) VALUES "
        "(7, 'mine', '', '2026-01-01 00:00:00', '2026-01-01 00:00:00'), "
        "(8, 'later', '', '2026-06-01 00:00:00', '2026-06-01 00:00:00')",
        "INSERT INTO runs (condition, seed, mode, hz, params, status, network, "
        "created_at) VALUES "
        "('kp', 1, 'fast', 10.0, '{}', 'stopped', 'mine', '2026-02-01 00:00:00'), "
        "('kp', 2, 'fast', 10.0, '{}', 'stopped', 'later', '2026-02-01 00:00:00'), "
        "('kp', 3, 'fast', 10.0, '{}', 'stopped', 'gone', '2026-02-01 00:00:00'), "
        "('kp', 4, 'fast', 10.0, '{}', 'stopped', NULL, '2026-02-01 00:00:00')",
    )
    with engine_of(sqlite_url) as engine:
        store = SqlAlchemyRunStore(make_sessionmaker(engine))
        # 'later' was made after its run: an unrelated network that took the name.
        assert [r.spec.network_id for r in store.list_runs()] == [7, None, None, None]
        with engine.begin() as connection:
            connection.execute(text("DELETE FROM networks WHERE id = 7"))
        assert [r.spec.network_id for r in store.list_runs()] == [None] * 4
    assert drift(sqlite_url) == []


def test_rewards_logged_before_0004_read_with_no_uid(sqlite_url: str) -> None:
    upgraded_from(
        sqlite_url,
        "0003",
        "INSERT INTO runs (id, condition, seed, mode, hz, params, status, created_at) "
        "VALUES (1, 'kp', 1, 'fast', 10.0, '{}', 'stopped', '2026-02-01 00:00:00')",
        "INSERT INTO rewards (run_id, tick, episode, value, source, note, applied, "
        "credited, created_at) VALUES "
        "(1, 5, 0, 1.0, 'trainer', 'old', 1, 3, '2026-02-01 00:00:01')",
    )
    with engine_of(sqlite_url) as engine:
        store = SqlAlchemyRunStore(make_sessionmaker(engine))
        (old,) = store.rewards(1)
        assert (old.record.note, old.record.uid, old.credited) == ("old", "", 3)
        new = store.log_reward(1, RewardRecord(6, 0, -1.0, "trainer", "new", "abc123"))
        assert [r.record.uid for r in store.rewards(1)] == ["", "abc123"]
        assert new > old.id
    assert drift(sqlite_url) == []


def test_participants_stored_before_0006_have_no_answers_and_may_answer(sqlite_url: str) -> None:
    upgraded_from(
        sqlite_url,
        "0005",
        "INSERT INTO studies (id, name, conditions, assignment, budget_s, "
        "consent_text, consent_version, questionnaire, secret) VALUES "
        "(1, 'pilot', '[\"kp\"]', 'balanced', 60, 'ok', '1', '[\"How hard?\"]', 'x')",
        "INSERT INTO participants (id, study_id, pseudonym, token_hash, status) "
        "VALUES (1, 1, 'ab12', 'cd34', 'done')",
    )
    with engine_of(sqlite_url) as engine:
        studies = SqlAlchemyStudyRepository(make_sessionmaker(engine))
        assert studies.answers("pilot") == ()
        [given] = studies.answer(1, ["Hard."])
        assert (given.participant, given.question_no, given.question, given.answer) == (
            "ab12", 1, "How hard?", "Hard.",
        )  # fmt: skip
    assert drift(sqlite_url) == []
    command.downgrade(alembic_config(sqlite_url), "0005")  # the answers go, the rest stays
    assert "questionnaire_answers" not in tables(sqlite_url)
    assert "participants" in tables(sqlite_url)


def test_rewards_logged_before_0007_read_with_no_seen_tick(sqlite_url: str) -> None:
    upgraded_from(
        sqlite_url,
        "0006_questionnaire_answers",
        "INSERT INTO runs (id, condition, seed, mode, hz, params, status, created_at) "
        "VALUES (1, 'kp', 1, 'fast', 10.0, '{}', 'stopped', '2026-02-01 00:00:00')",
        "INSERT INTO rewards (run_id, tick, episode, value, source, note, uid, "
        "applied, credited, created_at) VALUES "
        "(1, 5, 0, 1.0, 'trainer', 'old', 'u', 1, 3, '2026-02-01 00:00:01')",
    )
    with engine_of(sqlite_url) as engine:
        store = SqlAlchemyRunStore(make_sessionmaker(engine))
        (old,) = store.rewards(1)
        assert (old.record.tick_seen, old.record.seen_episode, old.record.window) == (
            None,
            None,
            None,
        )
        seen = RewardRecord(9, 0, -1.0, "trainer", "new", "v", 7, 0, (-33, 5))
        store.log_reward(1, seen)
        assert [r.record for r in store.rewards(1)][1] == seen
        # The run stored without a window reads with TAMER's.
        assert reaction_seconds(store.load_run(1).spec) == (0.2, 4.0)
    assert drift(sqlite_url) == []
