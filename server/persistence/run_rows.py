"""A run's rows as the ports' values: reward and command log rows, a run's summary."""

from __future__ import annotations

import json
from collections.abc import Mapping
from datetime import datetime
from typing import Any

from sqlalchemy import ColumnElement, Row, Select, select
from sqlalchemy.orm import Session

from core.ports import (
    CommandRecord,
    RewardRecord,
    RunSpec,
    RunStatus,
    RunTotals,
    StoredCommand,
    StoredReward,
    StoredRun,
)
from server.persistence.driver import ConnectionSql
from server.persistence.network_rows import utc
from server.persistence.orm import RewardRow, RunCommandRow, RunRow
from server.services.runspec import run_spec


def session_sql(session: Session) -> ConnectionSql:
    """`Sql` on a session's connection (inside its transaction)."""
    return ConnectionSql(session.connection())


def json_values(value: Mapping[str, Any]) -> dict[str, Any]:
    """`value` as JSON will give it back (tuples become lists); TypeError if it cannot."""
    out: dict[str, Any] = json.loads(json.dumps(value, allow_nan=False))
    return out


def reward_values(run_id: int, r: RewardRecord, applied: bool, credited: int) -> dict[str, Any]:
    """A reward log row's column values."""
    return {
        "run_id": run_id,
        "tick": r.tick,
        "episode": r.episode,
        "value": r.value,
        "source": r.source,
        "note": r.note,
        "uid": r.uid,
        "tick_seen": r.tick_seen,
        "seen_episode": r.seen_episode,
        "window_first": None if r.window is None else r.window[0],
        "window_last": None if r.window is None else r.window[1],
        "records": None if r.records is None else [list(x) for x in r.records],
        "applied": applied,
        "credited": credited,
    }


def summary(run: RunRow) -> StoredRun:
    """A run's spec, status and totals, without its checkpoint or log."""
    return StoredRun(
        id=run.id,
        spec=_spec(run),
        status=RunStatus(run.status),
        totals=RunTotals(run.episodes_done, run.successes, run.ticks),
        checkpoint=None,
        rewards_after=(),
        commands_after=(),
        error=run.error,
    )


def _spec(run: RunRow) -> RunSpec:
    return run_spec(
        condition=run.condition,
        seed=run.seed,
        episodes=run.episodes,
        mode=run.mode,
        hz=run.hz,
        network=run.network,
        network_id=run.network_id,
        params=run.params,
        world=run.world,
        sensors=run.sensors,
    )


RewardColumns = tuple[
    int, int, int, float, str, str, str, int | None, int | None, int | None, int | None,
    list[list[int]] | None, bool, int,
]  # fmt: skip
"""`select_rewards`'s columns."""


def select_rewards(*where: ColumnElement[bool]) -> Select[*RewardColumns]:
    """Reward log rows in log order, as plain columns.

    Not ORM objects: their identity map, change tracking and the unused `created_at`
    (parsed from SQLite's text) cost more than the rows' values.
    """
    r = RewardRow
    columns = (
        r.id, r.tick, r.episode, r.value, r.source, r.note, r.uid, r.tick_seen, r.seen_episode,
        r.window_first, r.window_last, r.records, r.applied, r.credited,
    )  # fmt: skip
    return select(*columns).where(*where).order_by(r.id)


def stored_reward(row: Row[*RewardColumns], at: datetime | None = None) -> StoredReward:
    """A reward log row of `select_rewards` as the ports' value."""
    id_, tick, episode, value, source, note, uid, seen, seen_episode, first, last = row[:11]
    window = None if first is None or last is None else (first, last)
    stored = None if row[11] is None else tuple((t, s, b) for t, s, b in row[11])
    record = RewardRecord(
        tick, episode, value, source, note, uid, seen, seen_episode, window, stored
    )
    return StoredReward(id_, record, row[12], row[13], at)


def select_reward_log(*where: ColumnElement[bool]) -> Select[*RewardColumns, datetime]:
    """`select_rewards` with each reward's time (`created_at`): the reward log's reads."""
    return select_rewards(*where).add_columns(RewardRow.created_at)


def logged_reward(row: Row[*RewardColumns, datetime]) -> StoredReward:
    """A reward log row of `select_reward_log` as the ports' value, with its time."""
    return stored_reward(row, utc(row[14]))  # type: ignore[arg-type]


def select_commands(*where: ColumnElement[bool]) -> Select[int, int, str, dict[str, Any]]:
    """Command log rows in log order, as plain columns (as `_rewards`)."""
    c = RunCommandRow
    return select(c.id, c.tick, c.kind, c.payload).where(*where).order_by(c.id)


def stored_command(row: Row[int, int, str, dict[str, Any]]) -> StoredCommand:
    """A command log row of `select_commands` as the ports' value."""
    id_, tick, kind, payload = row
    return StoredCommand(id_, CommandRecord(tick, kind, dict(payload)))
