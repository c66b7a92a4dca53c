"""`InMemoryRunStore`: the run store in memory, for the core's and the API's tests."""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from typing import Any, Protocol

import numpy as np

from core.brain.catalog import Catalog
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
    RunQueries,
    RunSpec,
    RunStatus,
    RunTotals,
    StoredCommand,
    StoredReward,
    StoredRun,
)
from core.text import check_storable

FloatArray = np.ndarray[Any, np.dtype[np.float64]]


def _as_json(value: Mapping[str, Any]) -> dict[str, Any]:
    """`value` as a JSON column gives it back (tuples become lists), as the SQL store does."""
    out: dict[str, Any] = json.loads(json.dumps(value, allow_nan=False))
    return out


@dataclass(slots=True)
class _MemoryRun:
    """One run's rows in `InMemoryRunStore`."""

    spec: RunSpec
    status: RunStatus = RunStatus.CREATED
    error: str | None = None
    totals: RunTotals = field(default_factory=lambda: RunTotals(0, 0, 0))
    checkpoint: Checkpoint | None = None
    network: dict[tuple[str, str], NetworkPair] = field(default_factory=dict)
    ltm: dict[tuple[str, str], float] = field(default_factory=dict)
    rltm: dict[tuple[str, str], float] = field(default_factory=dict)
    behaviours: dict[str, BehaviourSpec] = field(default_factory=dict)
    rewards: dict[int, StoredReward] = field(default_factory=dict)
    commands: dict[int, StoredCommand] = field(default_factory=dict)
    episodes: dict[int, EpisodeRecord] = field(default_factory=dict)


class InMemoryRunStore:
    """A `RunStore` in memory, with the read helpers of `SqlAlchemyRunStore`.

    It behaves as the SQL store does (the shared contract suite in `tests/persistence` holds
    both to it): ids increase across runs, every write is all or nothing, an unknown run
    raises `UnknownRunError`. Given a catalogue it also rejects stimulus and behaviour names
    it does not know (beside the run's synthesised behaviours), as the SQL store must.
    """

    def __init__(self, catalog: Catalog | None = None) -> None:
        self._runs: dict[int, _MemoryRun] = {}
        self._stimuli = None if catalog is None else {s.name for s in catalog.stimuli}
        self._behaviours = None if catalog is None else {b.name for b in catalog.behaviours}
        self._next_run = 1
        self._next_reward = 1
        self._next_command = 1

    def _run(self, run_id: int) -> _MemoryRun:
        try:
            return self._runs[run_id]
        except KeyError:
            raise UnknownRunError(f"no run {run_id}") from None

    def _check_names(self, run: _MemoryRun, pairs: Iterable[tuple[str, str]]) -> None:
        for stimulus, behaviour in pairs:
            if self._stimuli is not None and stimulus not in self._stimuli:
                raise UnknownNameError(f"unknown stimulus {stimulus!r}")
            if (
                self._behaviours is not None
                and behaviour not in self._behaviours
                and behaviour not in run.behaviours
            ):
                raise UnknownNameError(f"unknown behaviour {behaviour!r}")

    def _apply(self, run: _MemoryRun, update: LearningUpdate) -> None:
        """Store what an update changed; checks everything before changing anything."""
        self._check(run, update)
        run.behaviours.update({b.name: b for b in update.behaviours_added})
        run.ltm.update(update.ltm)
        run.rltm.update(update.rltm)
        for pair in update.network_upserts:
            run.network[(pair.stimulus, pair.behaviour)] = pair
        for key in update.network_removals:
            run.network.pop(key, None)

    def _check(self, run: _MemoryRun, update: LearningUpdate) -> _MemoryRun:
        """Raise what storing `update` would; else `run` as it would be after (a trial)."""
        added = {b.name: b for b in update.behaviours_added}
        for name in added:
            if self._behaviours is not None and name in self._behaviours:
                raise CatalogError(f"behaviour {name!r} exists in the catalogue")
        trial = replace(run, behaviours={**run.behaviours, **added})
        self._check_names(
            trial,
            [
                *update.ltm,
                *update.rltm,
                *((p.stimulus, p.behaviour) for p in update.network_upserts),
                *update.network_removals,
            ],
        )
        return trial

    def _stored(self, run_id: int, run: _MemoryRun) -> StoredRun:
        after = -1 if run.checkpoint is None else run.checkpoint.tick
        return StoredRun(
            id=run_id,
            spec=run.spec,
            status=run.status,
            totals=run.totals,
            checkpoint=run.checkpoint,
            rewards_after=tuple(r for r in run.rewards.values() if r.record.tick > after),
            commands_after=tuple(c for c in run.commands.values() if c.record.tick > after),
            error=run.error,
        )

    def create_run(self, spec: RunSpec, network: tuple[NetworkPair, ...]) -> int:
        """Store a new run (status created) with its starting network; returns its id."""
        run = _MemoryRun(spec=replace(spec, mode=Mode(spec.mode), params=_as_json(spec.params)))
        self._check_names(run, ((p.stimulus, p.behaviour) for p in network))
        run.network = {(p.stimulus, p.behaviour): p for p in network}
        run_id = self._next_run
        self._next_run += 1
        self._runs[run_id] = run
        return run_id

    def load_run(self, run_id: int) -> StoredRun:
        """A stored run; raises `UnknownRunError` when there is none."""
        return self._stored(run_id, self._run(run_id))

    def set_status(self, run_id: int, status: RunStatus, error: str | None = None) -> None:
        """Change a run's status (and error message)."""
        run = self._run(run_id)
        if error is not None:
            check_storable(error, "a run's error")
        run.status = status
        run.error = error

    def log_reward(self, run_id: int, reward: RewardRecord) -> int:
        """Append a reward to the log; returns its id."""
        run = self._run(run_id)
        check_storable(reward.note, "a reward's note")
        reward_id = self._next_reward
        self._next_reward += 1
        at = datetime.now(UTC)  # as the database's clock stamps a logged row
        run.rewards[reward_id] = StoredReward(reward_id, reward, applied=False, at=at)
        return reward_id

    def apply_reward(
        self, run_id: int, reward_id: int, update: LearningUpdate, credited: int
    ) -> None:
        """Mark a logged reward applied and store what it changed."""
        run = self._run(run_id)
        if reward_id not in run.rewards:
            raise StorageError(f"run {run_id} has no reward {reward_id}")
        self._apply(run, update)
        run.rewards[reward_id] = replace(run.rewards[reward_id], applied=True, credited=credited)

    def record_reward(
        self, run_id: int, reward: RewardRecord, update: LearningUpdate, credited: int
    ) -> int:
        """Log an already applied reward and store what it changed, all or nothing."""
        run = self._run(run_id)
        check_storable(reward.note, "a reward's note")
        self._apply(run, update)
        reward_id = self.log_reward(run_id, reward)
        run.rewards[reward_id] = replace(run.rewards[reward_id], applied=True, credited=credited)
        return reward_id

    def commit_rewards(self, run_id: int, rewards: Sequence[RewardCommit]) -> tuple[int, ...]:
        """`apply_reward` or `record_reward` for each, in order, all or nothing."""
        trial = self._run(run_id)
        for r in rewards:  # everything is checked before anything changes
            if r.logged_id is not None and r.logged_id not in trial.rewards:
                raise StorageError(f"run {run_id} has no reward {r.logged_id}")
            check_storable(r.record.note, "a reward's note")
            trial = self._check(trial, r.update)
        ids = []
        for r in rewards:
            if r.logged_id is None:
                ids.append(self.record_reward(run_id, r.record, r.update, r.credited))
            else:
                self.apply_reward(run_id, r.logged_id, r.update, r.credited)
                ids.append(r.logged_id)
        return tuple(ids)

    def log_command(self, run_id: int, command: CommandRecord, update: LearningUpdate) -> int:
        """Append a command to the log and store what it changed; returns its id."""
        run = self._run(run_id)
        stored = CommandRecord(command.tick, command.kind, _as_json(command.payload))
        self._apply(run, update)
        command_id = self._next_command
        self._next_command += 1
        run.commands[command_id] = StoredCommand(command_id, stored)
        return command_id

    def end_episode(
        self, run_id: int, episode: EpisodeRecord, checkpoint: Checkpoint, totals: RunTotals
    ) -> None:
        """Store an episode, the checkpoint after it and the totals."""
        self.end_episodes(run_id, (episode,), checkpoint, totals)

    def end_episodes(
        self,
        run_id: int,
        episodes: Sequence[EpisodeRecord],
        checkpoint: Checkpoint,
        totals: RunTotals,
    ) -> None:
        """Store episodes, the checkpoint after the last and the totals, all or nothing."""
        run = self._run(run_id)
        numbers = [e.episode for e in episodes]
        for n in numbers:
            if n in run.episodes or numbers.count(n) > 1:
                raise StorageError(f"run {run_id} has an episode {n} already")
        for e in episodes:
            run.episodes[e.episode] = e
        run.checkpoint = checkpoint
        run.totals = totals

    def ltm(self, run_id: int) -> dict[tuple[str, str], float]:
        """The run's LTM reliabilities by (stimulus, behaviour)."""
        return dict(self._run(run_id).ltm)

    def rltm(self, run_id: int) -> dict[tuple[str, str], float]:
        """The run's RLTM reliabilities by (stimulus, behaviour)."""
        return dict(self._run(run_id).rltm)

    def network(self, run_id: int) -> tuple[NetworkPair, ...]:
        """The run's live behaviour network, in insertion order."""
        return tuple(self._run(run_id).network.values())

    def behaviours(self, run_id: int) -> tuple[BehaviourSpec, ...]:
        """The behaviours the run synthesised, in the order they were added."""
        return tuple(self._run(run_id).behaviours.values())

    def rewards(self, run_id: int) -> list[StoredReward]:
        """The run's whole reward log, in log order."""
        return list(self._run(run_id).rewards.values())

    def commands(self, run_id: int) -> list[StoredCommand]:
        """The run's whole command log, in log order."""
        return list(self._run(run_id).commands.values())

    def episodes(self, run_id: int) -> list[EpisodeRecord]:
        """The run's episodes, by episode number."""
        return sorted(self._run(run_id).episodes.values(), key=lambda e: e.episode)

    def list_runs(self) -> list[StoredRun]:
        """Every run, by id."""
        return [self._stored(i, r) for i, r in sorted(self._runs.items())]

    # --- the service's reads (`core.ports.RunQueries`) ------------------------------

    def _summary(self, run_id: int, run: _MemoryRun) -> StoredRun:
        return replace(
            self._stored(run_id, run), checkpoint=None, rewards_after=(), commands_after=()
        )

    def run_summary(self, run_id: int) -> StoredRun:
        """A run's spec, status and totals, without its checkpoint or log."""
        return self._summary(run_id, self._run(run_id))

    def run_summaries(self, offset: int = 0, limit: int = 100) -> tuple[list[StoredRun], int]:
        """A page of runs by id, as `run_summary`, and how many runs are stored."""
        ids = sorted(self._runs)
        page = ids[offset : offset + limit]
        return [self._summary(i, self._runs[i]) for i in page], len(ids)

    def rewards_page(
        self, run_id: int, offset: int = 0, limit: int = 100
    ) -> tuple[list[StoredReward], int]:
        """A page of the run's reward log in log order, and the log's length."""
        log = self.rewards(run_id)
        return log[offset : offset + limit], len(log)

    def episode(self, run_id: int, episode: int) -> EpisodeRecord | None:
        """One episode with its trace, None if the run has no such episode."""
        return self._run(run_id).episodes.get(episode)

    def episode_summaries(self, run_id: int) -> list[EpisodeRecord]:
        """The run's episodes by number, without their traces."""
        return [replace(e, trace=b"") for e in self.episodes(run_id)]

    def episode_summaries_page(
        self, run_id: int, offset: int = 0, limit: int = 100
    ) -> tuple[list[EpisodeRecord], int]:
        """A page of the run's episodes without traces, and how many it has."""
        summaries = self.episode_summaries(run_id)
        return summaries[offset : offset + limit], len(summaries)

    def interrupt_active(self) -> int:
        """Mark every run stored as running or paused interrupted (its process died)."""
        active = [r for r in self._runs.values() if r.status in ACTIVE]
        for run in active:
            run.status = RunStatus.INTERRUPTED
        return len(active)


class InspectableRunStore(RunQueries, Protocol):
    """The service's store (`RunQueries`) with the whole logs, which only tests read."""

    def rewards(self, run_id: int) -> list[StoredReward]: ...
    def commands(self, run_id: int) -> list[StoredCommand]: ...
    def episodes(self, run_id: int) -> list[EpisodeRecord]: ...
