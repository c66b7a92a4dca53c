"""Test doubles: a scripted world that plays back sensor frames without pymunk."""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from typing import Any, Protocol

import numpy as np

from core import networks as rules
from core.brain.catalog import Catalog
from core.engine.pacing import Wake
from core.errors import CatalogError, StorageError, UnknownNameError, UnknownRunError
from core.networks import (
    AssociationChange,
    ExpectedVersion,
    Network,
    NetworkEdit,
    NetworkSnapshot,
    NetworkSummary,
    NetworkVersion,
    Revision,
    StoredNetwork,
    UnknownVersionError,
    Vocabulary,
    changes_between,
    fingerprint_of,
)
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
from core.sim.channels import Channel
from core.sim.track import TrackGeometry
from core.sim.world import (
    CollisionKind,
    EpisodeLayout,
    LampColor,
    MotorCommand,
    SensorFrame,
    WorldConfig,
)
from core.text import check_storable

FloatArray = np.ndarray[Any, np.dtype[np.float64]]

UNSEEN = 99.0

NEUTRAL: Mapping[Channel, float] = {
    **{Channel(i): 3.0 for i in range(8)},
    **{Channel(8 + i): 0.0 for i in range(8)},
    Channel.LATERAL_OFFSET_M: 0.0,
    Channel.HEADING_ERROR_RAD: 0.0,
    Channel.VERTEX_AHEAD_M: 3.6,
    Channel.CORNER_PENDING: 0.0,
    Channel.OBSTACLE_VISIBLE: 0.0,
    Channel.OBSTACLE_DISTANCE_M: UNSEEN,
    Channel.OBSTACLE_LATERAL_M: UNSEEN,
    Channel.LAMP_COLOR: 0.0,
    Channel.STOPLINE_AHEAD_M: UNSEEN,
    Channel.BUMPER: 0.0,
    Channel.LEG: 0.0,
    Channel.PROGRESS_M: 1.2,
    Channel.FRONT_TO_STOPLINE_M: UNSEEN,
    Channel.OBSTACLE_OFFSET_M: UNSEEN,
    Channel.HEADING_RAD: 0.0,
    Channel.OBSTACLE_IMAGE_X: UNSEEN,
}
"""Channels of a robot on the corridor's centre line of leg 0 with nothing in sight."""


def channel_vector(overrides: Mapping[Channel, float] | None = None) -> FloatArray:
    """A full channel vector: `NEUTRAL` with some channels replaced."""
    v = np.zeros(len(Channel), dtype=np.float64)
    for c, x in NEUTRAL.items():
        v[c] = x
    for c, x in (overrides or {}).items():
        v[c] = x
    return v


def channel_list(overrides: Mapping[Channel, float] | None = None) -> list[float]:
    """`channel_vector` as the plain list the brain reads."""
    out: list[float] = channel_vector(overrides).tolist()
    return out


@dataclass(frozen=True, slots=True)
class ScriptedStep:
    """What the world reports after one step: channel overrides and the referee's view."""

    channels: Mapping[Channel, float] = field(default_factory=dict)
    collision: CollisionKind | None = None
    violation: bool = False
    lamp: LampColor = LampColor.NONE


Script = Sequence[ScriptedStep] | Callable[[int], Sequence[ScriptedStep]]
"""Steps of every episode, or a function from the episode's number to its steps."""


class ScriptedWorld:
    """A `World` that plays back scripted sensor frames, step by step.

    Each `reset` restarts the script (or asks it for the episode's steps); once the steps run
    out the last one repeats. Resets and the motor commands the brain applies are recorded.
    """

    def __init__(
        self,
        script: Script = (),
        config: WorldConfig | None = None,
        initial: Mapping[Channel, float] | None = None,
    ) -> None:
        self.config = config or WorldConfig()
        self.geometry = TrackGeometry.build(self.config.track)
        self._script = script
        self._initial = dict(initial or {})
        self._steps: Sequence[ScriptedStep] = ()
        self._at = 0
        self._tick = 0
        self.resets: list[tuple[int, int]] = []
        self.commands: list[MotorCommand] = []
        self._layout = EpisodeLayout(None, -1, ((LampColor.GREEN, 1),))

    @property
    def layout(self) -> EpisodeLayout:
        """No obstacle and an always-green lamp: the script says what the robot sees."""
        return self._layout

    def reset(self, seed: int, episode: int) -> SensorFrame:
        """Restart the script for `episode`; the first frame is `initial` over `NEUTRAL`."""
        self.resets.append((seed, episode))
        script = self._script
        self._steps = script(episode) if callable(script) else script
        self._at = 0
        self._tick = 0
        return self._frame(ScriptedStep(self._initial))

    def apply(self, command: MotorCommand) -> None:
        """Record the command; it does not move anything."""
        self.commands.append(command)

    def step(self) -> SensorFrame:
        """The next scripted frame (the last one again once the script is over)."""
        self._tick += 1
        steps = self._steps
        step = steps[min(self._at, len(steps) - 1)] if steps else ScriptedStep()
        self._at += 1
        return self._frame(step)

    def _frame(self, step: ScriptedStep) -> SensorFrame:
        channels = channel_vector(step.channels)
        x, y, _ = self.geometry.start_pose
        return SensorFrame(
            self._tick,
            x,
            y,
            float(channels[Channel.HEADING_RAD]),
            channels,
            step.lamp,
            step.collision,
            step.violation,
        )


def lap_steps(
    geometry: TrackGeometry, step_m: float, extra: Mapping[int, ScriptedStep] | None = None
) -> list[ScriptedStep]:
    """Steps whose progress channel advances `step_m` a step from the start round one lap.

    `extra` replaces the step at some indices (their progress is kept).
    """
    lap = geometry.lap_length_m
    n = int(np.ceil(lap / step_m)) + 1
    steps = []
    for i in range(n):
        p = (geometry.start_progress_m + (i + 1) * step_m) % lap
        base = (extra or {}).get(i, ScriptedStep())
        channels = {**base.channels, Channel.PROGRESS_M: p}
        steps.append(ScriptedStep(channels, base.collision, base.violation, base.lamp))
    return steps


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
        run.rewards[reward_id] = StoredReward(reward_id, reward, applied=False)
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


class ManualPacer:
    """A realtime engine's clock that moves only when the test says (`Pacer`).

    A sleep ends when the clock is advanced past its end or when the engine's wake event
    is set, never by itself: a test of waking up cannot pass by waiting long enough.
    """

    def __init__(self, start: float = 0.0) -> None:
        self.time = start
        self._sleepers: list[tuple[float, asyncio.Event]] = []
        self._changed = asyncio.Event()

    def now(self) -> float:
        return self.time

    @property
    def sleeping(self) -> int:
        """How many sleeps are going on."""
        return len(self._sleepers)

    async def sleep(self, seconds: float, wake: Wake) -> None:
        if wake.is_set() or seconds <= 0:
            return
        entry = (self.time + seconds, asyncio.Event())
        self._sleepers.append(entry)
        self._changed.set()
        waits = [asyncio.ensure_future(wake.wait()), asyncio.ensure_future(entry[1].wait())]
        try:
            await asyncio.wait(waits, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for w in waits:
                w.cancel()
            self._sleepers.remove(entry)
            self._changed.set()

    def advance(self, seconds: float) -> None:
        """Move the clock on, ending the sleeps that are over."""
        self.time += seconds
        for until, done in self._sleepers:
            if until <= self.time + 1e-12:
                done.set()

    async def until(self, check: Callable[[], bool]) -> None:
        """Wait (without moving the clock) until `check()` holds after a sleep began or ended."""
        while not check():
            self._changed.clear()
            await self._changed.wait()


SEEDED_NOTE = "seeded from the catalogue"
"""The note of a built-in network's first version (as `server.persistence.seed` writes it)."""


@dataclass(frozen=True, slots=True)
class _MemoryVersion:
    """One entry of a network's history in `InMemoryNetworkRepository`."""

    version: int
    created_at: datetime
    note: str
    description: str
    state: Mapping[tuple[str, str], NetworkPair]
    """The associations by key, sorted (as the SQL store's snapshot keeps them)."""


@dataclass(slots=True)
class _MemoryNetwork:
    """One network's rows in `InMemoryNetworkRepository`."""

    id: int
    name: str
    description: str
    builtin: bool
    version: int
    created_at: datetime
    updated_at: datetime
    rows: dict[tuple[str, str], NetworkPair]
    """The associations in the order they were stored (a change keeps a pair's place)."""
    history: dict[int, _MemoryVersion] = field(default_factory=dict)

    def record(self, note: str, at: datetime) -> None:
        state = {k: self.rows[k] for k in sorted(self.rows)}
        self.history[self.version] = _MemoryVersion(self.version, at, note, self.description, state)


class InMemoryNetworkRepository:
    """A `NetworkRepository` in memory, seeded with the catalogue's knowledge sets (built in).

    Like the SQL store it loads a `core.networks.Network`, asks it for a `Revision` and
    stores that; the shared contract suite in `tests/persistence` holds both to the same
    answers. Every write is all or nothing (the domain decides before anything changes),
    ids are never reused and times come from `clock` (UTC now by default).
    """

    def __init__(self, catalog: Catalog, clock: Callable[[], datetime] | None = None) -> None:
        self._vocabulary = Vocabulary.of(catalog)
        self._clock = clock or (lambda: datetime.now(UTC))
        self._networks: dict[str, _MemoryNetwork] = {}
        self._next_id = 1
        self._lock = threading.RLock()
        now = self._clock()
        for ks in catalog.knowledge.values():
            rows = {
                (a.stimulus, a.behaviour): NetworkPair(
                    a.stimulus, a.behaviour, a.strength, a.source, a.locked
                )
                for a in ks.associations
            }
            stored = self._add(ks.name, ks.description, rows, now, builtin=True)
            stored.record(SEEDED_NOTE, now)

    def _add(
        self,
        name: str,
        description: str,
        rows: dict[tuple[str, str], NetworkPair],
        at: datetime,
        *,
        builtin: bool = False,
    ) -> _MemoryNetwork:
        stored = _MemoryNetwork(self._next_id, name, description, builtin, 1, at, at, rows)
        self._next_id += 1
        self._networks[name] = stored
        return stored

    def _get(self, name: str) -> _MemoryNetwork:
        try:
            return self._networks[name]
        except KeyError:
            raise UnknownNameError(f"unknown network {name!r}") from None

    def _find(self, name: str) -> Network | None:
        stored = self._networks.get(name)
        return None if stored is None else self._aggregate(stored)

    @staticmethod
    def _fingerprint(n: _MemoryNetwork) -> str:
        return fingerprint_of(n.id, n.created_at, n.version, n.description, n.rows.values())

    def _aggregate(self, n: _MemoryNetwork) -> Network:
        pairs = tuple(n.rows.values())
        return Network(n.name, n.description, n.builtin, n.version, pairs, self._fingerprint(n))

    def _stored(self, n: _MemoryNetwork) -> StoredNetwork:
        return StoredNetwork(
            n.name,
            n.description,
            n.builtin,
            n.version,
            n.created_at,
            n.updated_at,
            self._vocabulary.order(n.rows.values()),
            n.id,
            self._fingerprint(n),
        )

    def _version(self, n: _MemoryNetwork, version: int) -> _MemoryVersion:
        try:
            return n.history[version]
        except KeyError:
            raise UnknownVersionError(
                f"network {n.name!r} has no version {version} (it is at version {n.version})"
            ) from None

    def _insert(self, revision: Revision) -> NetworkEdit:
        network, now = revision.network, self._clock()
        rows = {(c.stimulus, c.behaviour): c.after for c in revision.changes if c.after}
        stored = self._add(network.name, network.description, rows, now)
        stored.record(revision.note, now)
        return NetworkEdit(self._stored(stored), revision.changes, created=True)

    def _save(self, n: _MemoryNetwork, revision: Revision) -> NetworkEdit:
        if not revision.versioned:
            return NetworkEdit(self._stored(n), ())
        for c in revision.changes:
            key = (c.stimulus, c.behaviour)
            if c.after is None:
                del n.rows[key]
            else:
                n.rows[key] = c.after
        n.version = revision.network.version
        n.description = revision.network.description
        n.updated_at = self._clock()
        n.record(revision.note, n.updated_at)
        return NetworkEdit(self._stored(n), revision.changes)

    def summaries(self) -> tuple[NetworkSummary, ...]:
        """Every network without its associations: built-in ones first, then by name."""
        with self._lock:
            ordered = sorted(self._networks.values(), key=lambda n: (not n.builtin, n.name))
            return tuple(self._stored(n).summary for n in ordered)

    def get(self, name: str) -> StoredNetwork:
        """A network with its associations, in catalogue order."""
        with self._lock:
            return self._stored(self._get(name))

    def pairs(self, name: str) -> tuple[NetworkPair, ...]:
        """A network's associations in the order they were stored."""
        with self._lock:
            return tuple(self._get(name).rows.values())

    def create(
        self,
        name: str,
        *,
        description: str = "",
        base: str | None = "innate",
        associations: Iterable[NetworkPair] = (),
        note: str = "",
    ) -> StoredNetwork:
        """A new, editable network at version 1: `base` (None: empty) with `associations`."""
        with self._lock:
            revision = rules.create(
                name,
                self._find,
                self._vocabulary,
                description=description,
                base=base,
                associations=associations,
                note=note,
            )
            return self._insert(revision).network

    def delete(self, name: str, *, expected: ExpectedVersion | None = None) -> None:
        """Delete an editable network and its history."""
        with self._lock:
            self._aggregate(self._get(name)).check_writable("deleted", expected)
            del self._networks[name]

    def add_association(
        self,
        name: str,
        pair: NetworkPair,
        *,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Add an association the network lacks."""
        with self._lock:
            n = self._get(name)
            revision = self._aggregate(n).add(pair, self._vocabulary, note=note, expected=expected)
            return self._save(n, revision)

    def put_association(
        self,
        name: str,
        stimulus: str,
        behaviour: str,
        *,
        strength: float | None = None,
        source: str | None = None,
        locked: bool | None = None,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Set an association (insert or update); None keeps a value."""
        with self._lock:
            n = self._get(name)
            revision = self._aggregate(n).put(
                stimulus,
                behaviour,
                self._vocabulary,
                strength=strength,
                source=source,
                locked=locked,
                force=force,
                note=note,
                expected=expected,
            )
            return self._save(n, revision)

    def remove_association(
        self,
        name: str,
        stimulus: str,
        behaviour: str,
        *,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Remove an association."""
        with self._lock:
            n = self._get(name)
            revision = self._aggregate(n).remove(
                stimulus, behaviour, self._vocabulary, force=force, note=note, expected=expected
            )
            return self._save(n, revision)

    def versions(self, name: str) -> tuple[NetworkVersion, ...]:
        """A network's edit history, oldest first."""
        with self._lock:
            n = self._get(name)
            return tuple(
                NetworkVersion(v.version, v.created_at, v.note, len(v.state))
                for _, v in sorted(n.history.items())
            )

    def versions_page(
        self, name: str, offset: int = 0, limit: int = 100
    ) -> tuple[tuple[NetworkVersion, ...], int]:
        """A page of `versions`, and their number."""
        every = self.versions(name)
        return every[offset : offset + limit], len(every)

    def snapshot(self, name: str, version: int) -> NetworkSnapshot:
        """The network as it was at `version`."""
        with self._lock:
            n = self._get(name)
            v = self._version(n, version)
            pairs = self._vocabulary.order(v.state.values())
            return NetworkSnapshot(n.name, v.version, v.created_at, v.note, v.description, pairs)

    def diff(self, name: str, from_version: int, to_version: int) -> tuple[AssociationChange, ...]:
        """What changed between two versions of a network (either order)."""
        with self._lock:
            n = self._get(name)
            before = self._version(n, from_version).state
            return changes_between(before, self._version(n, to_version).state)

    def revert(
        self,
        name: str,
        version: int,
        *,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Make the network what it was at `version`, as a new version."""
        with self._lock:
            n = self._get(name)

            def history(v: int) -> NetworkSnapshot:
                found = self._version(n, v)
                pairs = tuple(found.state.values())
                return NetworkSnapshot(
                    n.name, v, found.created_at, found.note, found.description, pairs
                )

            revision = self._aggregate(n).revert(
                version, history, self._vocabulary, force=force, note=note, expected=expected
            )
            return self._save(n, revision)

    def import_network(
        self,
        name: str,
        associations: Iterable[NetworkPair],
        *,
        description: str = "",
        replace: bool = False,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Store an imported network: a new one, or with `replace` a new version of one."""
        with self._lock:
            n = self._networks.get(name)
            revision = rules.import_network(
                name,
                None if n is None else self._aggregate(n),
                associations,
                self._vocabulary,
                description=description,
                replace=replace,
                force=force,
                note=note,
                expected=expected,
            )
            return self._insert(revision) if n is None else self._save(n, revision)
