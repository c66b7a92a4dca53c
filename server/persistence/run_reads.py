"""The run store's reads: a run, its memories, network, logs and episodes, whole or a page."""

from __future__ import annotations

from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import replace
from typing import TypeVar

from sqlalchemy import bindparam, func, select
from sqlalchemy.orm import Session, aliased

from core.errors import UnknownRunError
from core.ports import (
    BehaviourSpec,
    Checkpoint,
    EpisodeRecord,
    NetworkPair,
    StoredCommand,
    StoredReward,
    StoredRun,
)
from server.persistence.db import transaction
from server.persistence.driver import Sql
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
)
from server.persistence.run_rows import (
    logged_reward,
    select_commands,
    select_reward_log,
    select_rewards,
    session_sql,
    stored_command,
    stored_reward,
    summary,
)

_Pair = tuple[str, str]
_Row = TypeVar("_Row", LtmRow, RltmRow)
_RUN_EXISTS = select(RunRow.id).where(RunRow.id == bindparam("b_run"))
"""Built once, as the writes' statements: building one costs more than running it."""


class SqlAlchemyRunReads:
    """What `SqlAlchemyRunStore` reads: each read is one read-only transaction.

    Database failures come out as `StorageError` after the transaction is rolled back.
    """

    def __init__(self, sessions: Callable[[], Session]) -> None:
        self._sessions = sessions

    def _transaction(self, what: str, *, write: bool) -> AbstractContextManager[Session]:
        return transaction(self._sessions, what, write=write)

    @staticmethod
    def _run_row(session: Session, run_id: int) -> RunRow:
        row = session.get(RunRow, run_id)
        if row is None:
            raise UnknownRunError(f"no run {run_id}")
        return row

    @staticmethod
    def _require_run(sql: Sql, run_id: int) -> None:
        if sql.first(_RUN_EXISTS, {"b_run": run_id}) is None:
            raise UnknownRunError(f"no run {run_id}")

    def load_run(self, run_id: int) -> StoredRun:
        """A stored run; raises `UnknownRunError` when there is none."""
        with self._transaction(f"loading run {run_id}", write=False) as s:
            return self._stored(s, self._run_row(s, run_id))

    def _stored(self, s: Session, run: RunRow) -> StoredRun:
        checkpoint = None
        after = -1
        if run.checkpoint_tick is not None:
            assert run.checkpoint_episode is not None and run.checkpoint is not None
            after = run.checkpoint_tick
            checkpoint = Checkpoint(run.checkpoint_episode, after, bytes(run.checkpoint))
        rewards = s.execute(select_rewards(RewardRow.run_id == run.id, RewardRow.tick > after))
        commands = s.execute(
            select_commands(RunCommandRow.run_id == run.id, RunCommandRow.tick > after)
        )
        return replace(
            summary(run),
            checkpoint=checkpoint,
            rewards_after=tuple(stored_reward(r) for r in rewards),
            commands_after=tuple(stored_command(c) for c in commands),
        )

    def _pairs(self, s: Session, table: type[_Row], run_id: int) -> dict[_Pair, float]:
        self._require_run(session_sql(s), run_id)
        query = (
            select(StimulusRow.name, BehaviourRow.name, table.reliability)
            .join(StimulusRow, StimulusRow.id == table.stimulus_id)
            .join(BehaviourRow, BehaviourRow.id == table.behaviour_id)
            .where(table.run_id == run_id)
        )
        return {(st, be): r for st, be, r in s.execute(query)}

    def ltm(self, run_id: int) -> dict[_Pair, float]:
        """The run's LTM reliabilities by (stimulus, behaviour)."""
        with self._transaction(f"reading the LTM of run {run_id}", write=False) as s:
            return self._pairs(s, LtmRow, run_id)

    def rltm(self, run_id: int) -> dict[_Pair, float]:
        """The run's RLTM reliabilities by (stimulus, behaviour)."""
        with self._transaction(f"reading the RLTM of run {run_id}", write=False) as s:
            return self._pairs(s, RltmRow, run_id)

    def network(self, run_id: int) -> tuple[NetworkPair, ...]:
        """The run's live behaviour network, in insertion order."""
        with self._transaction(f"reading the network of run {run_id}", write=False) as s:
            self._require_run(session_sql(s), run_id)
            a = aliased(RunAssociationRow)
            query = (
                select(StimulusRow.name, BehaviourRow.name, a.strength, a.source, a.locked)
                .join(StimulusRow, StimulusRow.id == a.stimulus_id)
                .join(BehaviourRow, BehaviourRow.id == a.behaviour_id)
                .where(a.run_id == run_id)
                .order_by(a.id)
            )
            return tuple(NetworkPair(*row) for row in s.execute(query).all())

    def behaviours(self, run_id: int) -> tuple[BehaviourSpec, ...]:
        """The behaviours the run synthesised, in the order they were added."""
        with self._transaction(f"reading the behaviours of run {run_id}", write=False) as s:
            self._require_run(session_sql(s), run_id)
            rows = s.scalars(
                select(BehaviourRow).where(BehaviourRow.run_id == run_id).order_by(BehaviourRow.id)
            )
            return tuple(
                BehaviourSpec(b.name, b.family, b.speed_mps, b.turn_dps, b.ticks, b.mode)
                for b in rows
            )

    def rewards(self, run_id: int) -> list[StoredReward]:
        """The run's whole reward log, in log order."""
        with self._transaction(f"reading the rewards of run {run_id}", write=False) as s:
            self._require_run(session_sql(s), run_id)
            return [stored_reward(r) for r in s.execute(select_rewards(RewardRow.run_id == run_id))]

    def rewards_page(
        self, run_id: int, offset: int = 0, limit: int = 100
    ) -> tuple[list[StoredReward], int]:
        """A page of the run's reward log in log order, with times, and the log's length."""
        with self._transaction(f"reading the rewards of run {run_id}", write=False) as s:
            self._require_run(session_sql(s), run_id)
            total = s.scalar(
                select(func.count()).select_from(RewardRow).where(RewardRow.run_id == run_id)
            )
            log = select_reward_log(RewardRow.run_id == run_id).offset(offset).limit(limit)
            return [logged_reward(r) for r in s.execute(log)], int(total or 0)

    def commands(self, run_id: int) -> list[StoredCommand]:
        """The run's whole command log, in log order."""
        with self._transaction(f"reading the commands of run {run_id}", write=False) as s:
            self._require_run(session_sql(s), run_id)
            return [
                stored_command(c)
                for c in s.execute(select_commands(RunCommandRow.run_id == run_id))
            ]

    def episodes(self, run_id: int) -> list[EpisodeRecord]:
        """The run's episodes, by episode number."""
        with self._transaction(f"reading the episodes of run {run_id}", write=False) as s:
            self._require_run(session_sql(s), run_id)
            rows = s.scalars(
                select(EpisodeRow).where(EpisodeRow.run_id == run_id).order_by(EpisodeRow.episode)
            )
            return [
                EpisodeRecord(
                    e.episode, e.outcome, e.cause, e.ticks, e.start_tick, e.rewards, bytes(e.trace)
                )
                for e in rows
            ]

    def episode(self, run_id: int, episode: int) -> EpisodeRecord | None:
        """One episode of a run with its trace, None if it has no such episode."""
        with self._transaction(f"reading episode {episode} of run {run_id}", write=False) as s:
            self._require_run(session_sql(s), run_id)
            e = s.scalars(
                select(EpisodeRow).where(EpisodeRow.run_id == run_id, EpisodeRow.episode == episode)
            ).first()
            if e is None:
                return None
            return EpisodeRecord(
                e.episode, e.outcome, e.cause, e.ticks, e.start_tick, e.rewards, bytes(e.trace)
            )

    def episode_summaries(self, run_id: int) -> list[EpisodeRecord]:
        """The run's episodes by number, without their traces (`trace` is empty)."""
        with self._transaction(f"reading the episodes of run {run_id}", write=False) as s:
            self._require_run(session_sql(s), run_id)
            e = EpisodeRow
            rows = s.execute(
                select(e.episode, e.outcome, e.cause, e.ticks, e.start_tick, e.rewards)
                .where(e.run_id == run_id)
                .order_by(e.episode)
            )
            return [EpisodeRecord(*row, trace=b"") for row in rows]

    def list_runs(self) -> list[StoredRun]:
        """Every run, by id."""
        with self._transaction("listing runs", write=False) as s:
            return [self._stored(s, r) for r in s.scalars(select(RunRow).order_by(RunRow.id))]

    def episode_summaries_page(
        self, run_id: int, offset: int = 0, limit: int = 100
    ) -> tuple[list[EpisodeRecord], int]:
        """A page of the run's episodes by number, without traces, and how many it has.

        It reads the page's rows only (by the episodes' primary key): never a trace.
        """
        with self._transaction(f"reading the episodes of run {run_id}", write=False) as s:
            self._require_run(session_sql(s), run_id)
            e = EpisodeRow
            total = s.scalar(select(func.count()).select_from(e).where(e.run_id == run_id))
            rows = s.execute(
                select(e.episode, e.outcome, e.cause, e.ticks, e.start_tick, e.rewards)
                .where(e.run_id == run_id)
                .order_by(e.episode)
                .offset(offset)
                .limit(limit)
            )
            return [EpisodeRecord(*row, trace=b"") for row in rows], int(total or 0)

    def run_summary(self, run_id: int) -> StoredRun:
        """A run's spec, status and totals, without its checkpoint or log (`UnknownRunError`)."""
        with self._transaction(f"reading run {run_id}", write=False) as s:
            return summary(self._run_row(s, run_id))

    def run_summaries(self, offset: int = 0, limit: int = 100) -> tuple[list[StoredRun], int]:
        """A page of runs by id, as `run_summary`, and how many runs are stored."""
        with self._transaction("listing runs", write=False) as s:
            total = s.scalar(select(func.count()).select_from(RunRow))
            rows = s.scalars(select(RunRow).order_by(RunRow.id).offset(offset).limit(limit))
            return [summary(r) for r in rows], int(total or 0)
