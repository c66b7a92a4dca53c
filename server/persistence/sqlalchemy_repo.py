"""`RunStore` on SQLAlchemy: every write is one transaction, committed when it returns."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from functools import partial
from typing import Any, TypeVar

from sqlalchemy import Engine, bindparam, delete, func, insert, select
from sqlalchemy import update as sql_update
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.orm import Session, sessionmaker
from sqlalchemy.sql import Executable

from core.errors import CatalogError, StorageError, UnknownNameError, UnknownRunError
from core.ports import (
    ACTIVE,
    BehaviourSpec,
    Checkpoint,
    CommandRecord,
    EpisodeRecord,
    LearningUpdate,
    Mode,
    NetworkPair,
    RewardCommit,
    RewardRecord,
    RunSpec,
    RunStatus,
    RunTotals,
)
from server.persistence.driver import DriverStatement, Sql, driver_transaction, drives
from server.persistence.grouping import GroupedWrites
from server.persistence.orm import (
    BehaviourRow,
    EpisodeRow,
    LtmRow,
    RewardRow,
    RltmRow,
    RunAssociationRow,
    RunCommandRow,
    RunRow,
    StimulusRow,
    motion_columns,
)
from server.persistence.run_reads import SqlAlchemyRunReads
from server.persistence.run_rows import json_values, reward_values, session_sql

_FINAL = frozenset({RunStatus.FINISHED, RunStatus.STOPPED, RunStatus.INTERRUPTED, RunStatus.FAILED})
_Pair = tuple[str, str]
_Row = TypeVar("_Row", LtmRow, RltmRow)


_END_RUN = (
    sql_update(RunRow)
    .where(RunRow.id == bindparam("rid"))
    .values(
        checkpoint_episode=bindparam("checkpoint_episode"),
        checkpoint_tick=bindparam("checkpoint_tick"),
        checkpoint=bindparam("checkpoint"),
        episodes_done=bindparam("episodes_done"),
        successes=bindparam("successes"),
        ticks=bindparam("ticks"),
    )
)
_INSERT_EPISODE = insert(EpisodeRow)


def _upsert(dialect: str, table: Any) -> Any:
    """INSERT for the dialect, with ON CONFLICT support."""
    module = postgresql if dialect == "postgresql" else sqlite
    return module.insert(table)


# The hot path's statements are built once: building one costs more than running it.
_INSERT_REWARD = insert(RewardRow).returning(RewardRow.id)
_INSERT_REWARDS_IN_ORDER = insert(RewardRow).returning(RewardRow.id, sort_by_parameter_order=True)
_MARK_APPLIED = (
    sql_update(RewardRow)
    .where(RewardRow.id == bindparam("b_id"), RewardRow.run_id == bindparam("b_run"))
    .values(applied=True, credited=bindparam("b_credited"))
)
_REWARD_OF_RUN = select(RewardRow.id).where(
    RewardRow.id == bindparam("b_id"), RewardRow.run_id == bindparam("b_run")
)
_STIMULUS_IDS = select(StimulusRow.name, StimulusRow.id)
_CATALOGUE_BEHAVIOUR_IDS = select(BehaviourRow.name, BehaviourRow.id).where(
    BehaviourRow.run_id.is_(None)
)
_RUN_BEHAVIOUR_IDS = select(BehaviourRow.name, BehaviourRow.id).where(
    BehaviourRow.run_id == bindparam("b_run")
)
_RUN_BEHAVIOUR = select(BehaviourRow.id).where(
    BehaviourRow.run_id == bindparam("b_run"), BehaviourRow.name == bindparam("b_name")
)
_MAX_POSITION = select(func.max(BehaviourRow.position))
_INSERT_BEHAVIOUR = insert(BehaviourRow).returning(BehaviourRow.id)
_UPDATE_BEHAVIOUR = sql_update(BehaviourRow).where(BehaviourRow.id == bindparam("b_id"))
_DELETE_PAIR = delete(RunAssociationRow).where(
    RunAssociationRow.run_id == bindparam("b_run"),
    RunAssociationRow.stimulus_id == bindparam("b_stimulus"),
    RunAssociationRow.behaviour_id == bindparam("b_behaviour"),
)
_EPISODES_BETWEEN = select(EpisodeRow.episode).where(
    EpisodeRow.run_id == bindparam("b_run"),
    EpisodeRow.episode >= bindparam("b_first"),
    EpisodeRow.episode <= bindparam("b_last"),
)
_INSERT_COMMAND = insert(RunCommandRow).returning(RunCommandRow.id)


class _Names:
    """Stimulus and behaviour names <-> ids within one transaction, for one run."""

    def __init__(self, store: SqlAlchemyRunStore, sql: Sql, run_id: int | None) -> None:
        self._store = store
        self._sql = sql
        self._run_id = run_id
        self._synth: dict[str, int] | None = None

    def stimulus(self, name: str) -> int:
        found = self._store._stimulus_ids(self._sql).get(name)
        if found is None:
            found = self._store._stimulus_ids(self._sql, refresh=True).get(name)
        if found is None:
            raise UnknownNameError(f"unknown stimulus {name!r}")
        return found

    def behaviour(self, name: str) -> int:
        found = self._store._behaviour_ids(self._sql).get(name)
        if found is not None:
            return found
        if self._synth is None:
            self._synth = dict(self._sql.rows(_RUN_BEHAVIOUR_IDS, {"b_run": self._run_id}))
        found = self._synth.get(name)
        if found is None:
            found = self._store._behaviour_ids(self._sql, refresh=True).get(name)
        if found is None:
            raise UnknownNameError(f"unknown behaviour {name!r}")
        return found

    def pair(self, key: _Pair) -> tuple[int, int]:
        return self.stimulus(key[0]), self.behaviour(key[1])

    def added(self, name: str, behaviour_id: int) -> None:
        if self._synth is not None:
            self._synth[name] = behaviour_id


GroupedWrite = tuple[str, Callable[[Sql], Any]]
"""A write `GroupedWrites` may run with others': what it is (for errors), and the write."""


class SqlAlchemyRunStore(SqlAlchemyRunReads):
    """Runs, their learning, episodes and reward log in a SQL database.

    Stimuli and behaviours are rows (seeded by `server.persistence.seed`); the ports speak
    names, so this maps names to ids, caching the catalogue's and looking a run's
    synthesised behaviours up per transaction. Database failures come out as
    `StorageError` after the transaction is rolled back, so nothing committed before is
    touched and nothing half-written remains. On a SQLite file, the writes run their
    statements straight on the driver (`server.persistence.driver`), unless ``driver`` is
    False (every write through a session, as `bench.engine --stores sessions` measures).
    Its reads are `SqlAlchemyRunReads`'s (`server.persistence.run_reads`).
    """

    def __init__(self, sessions: Callable[[], Session], *, driver: bool = True) -> None:
        super().__init__(sessions)
        self._stimuli: dict[str, int] = {}
        self._behaviours: dict[str, int] = {}
        self._upserts: dict[tuple[str, str], Any] = {}
        kw: dict[str, Any] = sessions.kw if isinstance(sessions, sessionmaker) else {}
        bind = kw.get("bind")
        self._driver = bind if driver and isinstance(bind, Engine) and drives(bind) else None
        self._compiled: dict[tuple[int, tuple[str, ...]], tuple[Executable, DriverStatement]] = {}
        self._together: GroupedWrites[GroupedWrite, Any] = GroupedWrites(self._write_together)

    @contextmanager
    def _writing(self, what: str) -> Iterator[Sql]:
        """A write transaction, on SQLite's driver when the store has one (as `transaction`)."""
        if self._driver is not None:
            with driver_transaction(self._driver, what, self._compiled) as sql:
                yield sql
        else:
            with self._transaction(what, write=True) as s:
                yield session_sql(s)

    def _upsert_stmt(self, sql: Sql, table: Any, values: tuple[str, ...]) -> Any:
        """An INSERT ... ON CONFLICT DO UPDATE for executemany, built once per dialect."""
        dialect = sql.dialect.name
        key = (dialect, table.name)
        stmt = self._upserts.get(key)
        if stmt is None:
            base = _upsert(dialect, table)
            stmt = base.on_conflict_do_update(
                index_elements=["run_id", "stimulus_id", "behaviour_id"],
                set_={v: base.excluded[v] for v in values},
            )
            self._upserts[key] = stmt
        return stmt

    def _stimulus_ids(self, sql: Sql, *, refresh: bool = False) -> dict[str, int]:
        if refresh or not self._stimuli:
            self._stimuli = dict(sql.rows(_STIMULUS_IDS, {}))
        return self._stimuli

    def _behaviour_ids(self, sql: Sql, *, refresh: bool = False) -> dict[str, int]:
        if refresh or not self._behaviours:
            self._behaviours = dict(sql.rows(_CATALOGUE_BEHAVIOUR_IDS, {}))
        return self._behaviours

    def _apply(
        self, sql: Sql, run_id: int, change: LearningUpdate, names: _Names | None = None
    ) -> None:
        """Store what an update changed: synthesised behaviours first, then what names them."""
        names = names or _Names(self, sql, run_id)
        for spec in change.behaviours_added:
            self._add_behaviour(sql, run_id, spec, names)
        self._upsert_memory(sql, LtmRow, run_id, change.ltm, names)
        self._upsert_memory(sql, RltmRow, run_id, change.rltm, names)
        if change.network_upserts:
            rows = []
            for pair in change.network_upserts:
                st, be = names.pair((pair.stimulus, pair.behaviour))
                rows.append(
                    {
                        "run_id": run_id,
                        "stimulus_id": st,
                        "behaviour_id": be,
                        "strength": pair.strength,
                        "source": pair.source,
                        "locked": pair.locked,
                    }
                )
            stmt = self._upsert_stmt(
                sql, RunAssociationRow.__table__, ("strength", "source", "locked")
            )
            sql.many(stmt, rows)
        for removal in change.network_removals:
            st, be = names.pair(removal)
            sql.run(_DELETE_PAIR, {"b_run": run_id, "b_stimulus": st, "b_behaviour": be})

    def _add_behaviour(self, sql: Sql, run_id: int, spec: BehaviourSpec, names: _Names) -> None:
        stored = sql.first(_RUN_BEHAVIOUR, {"b_run": run_id, "b_name": spec.name})
        found = None if stored is None else int(stored[0])
        values = {**motion_columns(spec), "synthesized": True}
        if found is None:
            if spec.name in self._behaviour_ids(sql):
                raise CatalogError(f"behaviour {spec.name!r} exists in the catalogue")
            last = sql.first(_MAX_POSITION, {})
            position = ((last[0] if last else None) or 0) + 1
            row = sql.first(
                _INSERT_BEHAVIOUR,
                {"name": spec.name, "run_id": run_id, "position": position, **values},
            )
            assert row is not None
            found = int(row[0])
        else:
            sql.run(_UPDATE_BEHAVIOUR, {"b_id": found, **values})
        names.added(spec.name, found)

    def _upsert_memory(
        self,
        sql: Sql,
        table: type[_Row],
        run_id: int,
        values: Mapping[_Pair, float],
        names: _Names,
    ) -> None:
        """Insert or update reliabilities with one statement (ON CONFLICT DO UPDATE)."""
        if not values:
            return
        rows = []
        for key, reliability in values.items():
            st, be = names.pair(key)
            rows.append(
                {
                    "run_id": run_id,
                    "stimulus_id": st,
                    "behaviour_id": be,
                    "reliability": reliability,
                }
            )
        stmt = self._upsert_stmt(sql, table.__table__, ("reliability",))
        sql.many(stmt, rows)

    def create_run(self, spec: RunSpec, network: tuple[NetworkPair, ...]) -> int:
        """Store a new run (status created) with its starting network; returns its id."""
        params = json_values(spec.params)
        with self._transaction("creating a run", write=True) as s:
            row = RunRow(
                condition=spec.condition,
                seed=spec.seed,
                episodes=spec.episodes,
                mode=Mode(spec.mode).value,
                hz=spec.hz,
                network=spec.network,
                network_id=spec.network_id,
                params=params,
                world=spec.world,
                sensors=spec.sensors,
                status=RunStatus.CREATED.value,
            )
            s.add(row)
            s.flush()
            names = _Names(self, session_sql(s), row.id)
            seen: dict[tuple[int, int], RunAssociationRow] = {}
            for pair in network:
                key = names.pair((pair.stimulus, pair.behaviour))
                assoc = seen.get(key)
                if assoc is None:
                    assoc = RunAssociationRow(
                        run_id=row.id, stimulus_id=key[0], behaviour_id=key[1]
                    )
                    s.add(assoc)
                    seen[key] = assoc
                assoc.strength = pair.strength
                assoc.source = pair.source
                assoc.locked = pair.locked
            return row.id

    def set_status(self, run_id: int, status: RunStatus, error: str | None = None) -> None:
        """Change a run's status (and error message), stamping when it started and ended."""
        status = RunStatus(status)
        values: dict[str, Any] = {"status": status.value, "error": error}
        if status is RunStatus.RUNNING:
            values["started_at"] = func.coalesce(RunRow.started_at, func.now())
        if status in _FINAL:
            values["finished_at"] = func.now()
        with self._transaction(f"setting the status of run {run_id}", write=True) as s:
            row = self._run_row(s, run_id)
            for name, value in values.items():
                setattr(row, name, value)

    @staticmethod
    def _insert_reward(
        sql: Sql, run_id: int, reward: RewardRecord, applied: bool, credited: int
    ) -> int:
        row = sql.first(_INSERT_REWARD, reward_values(run_id, reward, applied, credited))
        assert row is not None
        return int(row[0])

    def log_reward(self, run_id: int, reward: RewardRecord) -> int:
        """Append a reward to the log, committed before returning its id."""
        what = f"logging a reward for run {run_id}"
        return int(self._together.write((what, partial(self._log_reward, run_id, reward))))

    def _log_reward(self, run_id: int, reward: RewardRecord, sql: Sql) -> int:
        self._require_run(sql, run_id)
        return self._insert_reward(sql, run_id, reward, False, 0)

    def _write_together(self, writes: Sequence[GroupedWrite]) -> list[Any]:
        """Run writes other threads asked for at once (`GroupedWrites`) in one transaction.

        A write that raises is answered its error alone: the transaction is rolled back
        and the others run again without it. An error of the transaction itself (storage
        failing) is every write's.
        """
        results: list[Any] = [None] * len(writes)
        pending = list(range(len(writes)))
        while pending:
            done: dict[int, Any] = {}
            failing: int | None = None
            try:
                what = writes[pending[0]][0]
                if len(pending) > 1:
                    what += f" with {len(pending) - 1} other write(s)"
                with self._writing(what) as sql:
                    for failing in pending:
                        done[failing] = writes[failing][1](sql)
                    failing = None
            except Exception as e:
                if failing is None:  # BEGIN or COMMIT: every write's
                    for i in pending:
                        results[i] = e
                    return results
                results[failing] = e
                pending.remove(failing)
                continue
            for i, value in done.items():
                results[i] = value
            break
        return results

    def apply_reward(
        self, run_id: int, reward_id: int, update: LearningUpdate, credited: int
    ) -> None:
        """In one transaction: mark a logged reward applied and store what it changed."""
        with self._writing(f"applying reward {reward_id} of run {run_id}") as sql:
            self._mark_all_applied(sql, run_id, [(reward_id, credited)])
            self._apply(sql, run_id, update)

    def record_reward(
        self, run_id: int, reward: RewardRecord, update: LearningUpdate, credited: int
    ) -> int:
        """In one transaction: log an already applied reward and store what it changed."""
        with self._writing(f"recording a reward for run {run_id}") as sql:
            self._require_run(sql, run_id)
            reward_id = self._insert_reward(sql, run_id, reward, True, credited)
            self._apply(sql, run_id, update)
            return reward_id

    def commit_rewards(self, run_id: int, rewards: Sequence[RewardCommit]) -> tuple[int, ...]:
        """In one transaction and in order: each reward applied or recorded, with its learning.

        The rewards' learning is merged into one update that leaves the tables as applying
        each in turn would (`LearningUpdate.merged`): one statement per table.
        """
        if not rewards:
            return ()
        what = f"committing {len(rewards)} reward(s) of run {run_id}"
        return tuple(self._together.write((what, partial(self._commit_rewards, run_id, rewards))))

    def _commit_rewards(
        self, run_id: int, rewards: Sequence[RewardCommit], sql: Sql
    ) -> tuple[int, ...]:
        new = [r.record for r in rewards if r.logged_id is None]
        if new:
            # A logged reward's UPDATE finds its run or says which is missing: only new
            # rewards need the run looked up (a trainer's commit saves a statement).
            self._require_run(sql, run_id)
        credited = [r.credited for r in rewards if r.logged_id is None]
        new_ids = iter(self._insert_rewards(sql, run_id, new, credited))
        logged = [(r.logged_id, r.credited) for r in rewards if r.logged_id is not None]
        self._mark_all_applied(sql, run_id, logged)
        ids = tuple(next(new_ids) if r.logged_id is None else r.logged_id for r in rewards)
        self._apply(sql, run_id, LearningUpdate.merged([r.update for r in rewards]))
        return ids

    @staticmethod
    def _insert_rewards(
        sql: Sql, run_id: int, records: Sequence[RewardRecord], credited: Sequence[int]
    ) -> list[int]:
        """Insert applied rewards; their ids in the records' order."""
        rows = [reward_values(run_id, r, True, c) for r, c in zip(records, credited, strict=True)]
        return [int(r[0]) for r in sql.returning(_INSERT_REWARDS_IN_ORDER, rows)]

    def _mark_all_applied(self, sql: Sql, run_id: int, logged: Sequence[tuple[int, int]]) -> None:
        """Mark logged rewards applied with their credit (`StorageError` for a missing one)."""
        if not logged:
            return
        changed = sql.many(
            _MARK_APPLIED, [{"b_id": i, "b_run": run_id, "b_credited": c} for i, c in logged]
        )
        if changed == len(logged):
            return
        for reward_id, _ in logged:  # the driver could not count, or one is missing
            if sql.first(_REWARD_OF_RUN, {"b_id": reward_id, "b_run": run_id}) is None:
                self._require_run(sql, run_id)
                raise StorageError(f"run {run_id} has no reward {reward_id}")

    def log_command(self, run_id: int, command: CommandRecord, update: LearningUpdate) -> int:
        """In one transaction: append a command to the log and store what it changed."""
        payload = json_values(command.payload)
        with self._writing(f"logging a command for run {run_id}") as sql:
            self._require_run(sql, run_id)
            self._apply(sql, run_id, update)
            row = sql.first(
                _INSERT_COMMAND,
                {"run_id": run_id, "tick": command.tick, "kind": command.kind, "payload": payload},
            )
            assert row is not None
            return int(row[0])

    def end_episode(
        self, run_id: int, episode: EpisodeRecord, checkpoint: Checkpoint, totals: RunTotals
    ) -> None:
        """In one transaction: store an episode, the checkpoint after it and the totals."""
        self.end_episodes(run_id, (episode,), checkpoint, totals)

    def end_episodes(
        self,
        run_id: int,
        episodes: Sequence[EpisodeRecord],
        checkpoint: Checkpoint,
        totals: RunTotals,
    ) -> None:
        """In one transaction: store episodes, the checkpoint after the last, the totals."""
        numbers = [e.episode for e in episodes]
        what = f"ending episodes {numbers} of run {run_id}"
        with self._writing(what) as sql:
            done = sql.run(
                _END_RUN,
                {
                    "rid": run_id,
                    "checkpoint_episode": checkpoint.episode,
                    "checkpoint_tick": checkpoint.tick,
                    "checkpoint": checkpoint.state,
                    "episodes_done": totals.episodes,
                    "successes": totals.successes,
                    "ticks": totals.ticks,
                },
            )
            if done != 1:
                raise UnknownRunError(f"no run {run_id}")
            stored: set[int] = set()
            if numbers:
                bounds = {"b_run": run_id, "b_first": min(numbers), "b_last": max(numbers)}
                stored = {row[0] for row in sql.rows(_EPISODES_BETWEEN, bounds)}
            taken = next((n for n in numbers if n in stored), None)
            duplicate = next((n for n in numbers if numbers.count(n) > 1), None)
            if taken is not None or duplicate is not None:
                n = taken if taken is not None else duplicate
                raise StorageError(f"run {run_id} has an episode {n} already")
            if episodes:
                sql.many(
                    _INSERT_EPISODE,
                    [
                        {
                            "run_id": run_id,
                            "episode": e.episode,
                            "outcome": e.outcome,
                            "cause": e.cause,
                            "ticks": e.ticks,
                            "start_tick": e.start_tick,
                            "rewards": e.rewards,
                            "trace": e.trace,
                        }
                        for e in episodes
                    ],
                )

    def interrupt_active(self) -> int:
        """Mark every run stored as running or paused interrupted (its process died)."""
        active = [s.value for s in ACTIVE]
        with self._transaction("marking runs interrupted", write=True) as s:
            result = s.execute(
                sql_update(RunRow)
                .where(RunRow.status.in_(active))
                .values(status=RunStatus.INTERRUPTED.value)
            )
            return int(getattr(result, "rowcount", 0) or 0)
