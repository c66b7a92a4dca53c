"""What the engine needs from the outside: storage and event sinks, as Protocols.

`server/persistence` implements `RunStore` and `NetworkRepository` with SQLAlchemy;
`tests/fakes/` with memory.
Every method is synchronous and durable when it returns; the engine calls them from a
worker thread so the event loop never blocks on I/O.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from enum import StrEnum
from typing import Any, Protocol

from core.networks import (
    AssociationChange,
    ExpectedVersion,
    NetworkEdit,
    NetworkSnapshot,
    NetworkSummary,
    NetworkVersion,
    StoredNetwork,
)
from core.networks import NetworkPair as NetworkPair  # its home is core.networks


class RunStatus(StrEnum):
    """Where a run stands."""

    CREATED = "created"
    RUNNING = "running"
    PAUSED = "paused"
    FINISHED = "finished"
    STOPPED = "stopped"
    INTERRUPTED = "interrupted"
    FAILED = "failed"


ACTIVE = (RunStatus.RUNNING, RunStatus.PAUSED)
"""The statuses of a run that is going (its ticks run, or wait for a resume)."""
NOT_ENDED = (RunStatus.CREATED, *ACTIVE)
"""The statuses of a run that has not ended: going, or not started yet."""


class Mode(StrEnum):
    """How the engine's tick task is paced."""

    FAST = "fast"
    REALTIME = "realtime"


@dataclass(frozen=True, slots=True)
class RunSpec:
    """What a run is: everything needed to reproduce it with its command log.

    Attributes:
        condition: the condition's name (core.run.conditions).
        seed: the run's seed.
        episodes: how many episodes to run, or None to run until stopped.
        mode: fast or realtime.
        hz: the realtime tick rate.
        network: the knowledge set or stored network the run starts from (None: the
            condition's own).
        params: learning parameters that override the condition's (eta, epsilon, ...).
        world: the world preset it runs in (`core.sim.worlds`; "" for the default).
        sensors: the sensor definition its logical sensors use (`core.brain.catalog`;
            "" for the default). A stored run keeps both resolved (see `core.run.setup.Setup`),
            so a later change of the defaults never changes what an old run meant.
        network_id: the stored network's identity when `network` names one (None: a
            knowledge set, or the network was deleted since): live edits of that network
            reach the run by it, never by the name, which a later network may take.
    """

    condition: str
    seed: int
    episodes: int | None = None
    mode: Mode = Mode.FAST
    hz: float = 10.0
    network: str | None = None
    params: Mapping[str, Any] = field(default_factory=dict)
    world: str = ""
    sensors: str = ""
    network_id: int | None = None


@dataclass(frozen=True, slots=True)
class BehaviourSpec:
    """A behaviour a run synthesised (knowledge propagation), to store beside the catalogue."""

    name: str
    family: str
    speed_mps: float
    turn_dps: float
    ticks: int
    mode: str


@dataclass(frozen=True, slots=True)
class LearningUpdate:
    """What one reward (or edit) changed, by names: LTM, RLTM and the network.

    `ltm` and `rltm` hold the new reliability of every pair the reward touched;
    `network_upserts` and `network_removals` the run network's changes.
    """

    ltm: Mapping[tuple[str, str], float] = field(default_factory=dict)
    rltm: Mapping[tuple[str, str], float] = field(default_factory=dict)
    network_upserts: tuple[NetworkPair, ...] = ()
    network_removals: tuple[tuple[str, str], ...] = ()
    behaviours_added: tuple[BehaviourSpec, ...] = ()

    @classmethod
    def merged(cls, updates: Sequence[LearningUpdate]) -> LearningUpdate:
        """One update that leaves storage as applying `updates` in order would.

        The last value of each pair wins; a pair's last network change (an upsert, or a
        removal after its update's upserts, as `_apply`s do it) is the one kept. Storage
        commits a batch of rewards' learning with it, one statement per table.
        """
        if len(updates) == 1:
            return updates[0]
        ltm: dict[tuple[str, str], float] = {}
        rltm: dict[tuple[str, str], float] = {}
        network: dict[tuple[str, str], NetworkPair | None] = {}
        added: list[BehaviourSpec] = []
        for u in updates:
            ltm.update(u.ltm)
            rltm.update(u.rltm)
            for p in u.network_upserts:
                network[(p.stimulus, p.behaviour)] = p
            for key in u.network_removals:
                network[key] = None
            added.extend(u.behaviours_added)
        return cls(
            ltm,
            rltm,
            tuple(p for p in network.values() if p is not None),
            tuple(key for key, p in network.items() if p is None),
            tuple(added),
        )


@dataclass(frozen=True, slots=True)
class RewardRecord:
    """A reward as the log keeps it: stamped with the tick boundary it applies at."""

    tick: int
    episode: int
    value: float
    source: str
    note: str = ""
    uid: str = ""
    """The id the reward got on arrival (`core.commands.InjectReward.uid`)."""
    tick_seen: int | None = None
    """The tick the trainer saw when they pressed (None: the paper's rule)."""
    seen_episode: int | None = None
    """The episode of `tick_seen`."""
    window: tuple[int, int] | None = None
    """The first and last tick the reward could credit (`core.brain.memory.credit_seen`)."""
    records: tuple[tuple[int, int, int], ...] | None = None
    """A stored episode's records it credits (`core.commands.InjectReward.records`)."""


@dataclass(frozen=True, slots=True)
class RewardCommit:
    """A reward's learning, ready to commit.

    `logged_id` names a reward the log already holds (a trainer's, logged on arrival);
    None means it is logged now, already applied (the task's and a program's rewards).
    """

    record: RewardRecord
    update: LearningUpdate
    credited: int
    logged_id: int | None = None


@dataclass(frozen=True, slots=True)
class StoredReward:
    """A logged reward with its id and whether its learning was committed."""

    id: int
    record: RewardRecord
    applied: bool
    credited: int = 0
    at: datetime | None = None
    """When the log took it (UTC; the database's clock): the reward log's reads
    (`RunQueries.rewards_page`) give it, a run's reload (`StoredRun.rewards_after`) need not."""


@dataclass(frozen=True, slots=True)
class CommandRecord:
    """A state-changing command other than a reward (an association edit), stamped."""

    tick: int
    kind: str
    payload: Mapping[str, Any]


@dataclass(frozen=True, slots=True)
class StoredCommand:
    """A logged command with its id."""

    id: int
    record: CommandRecord


@dataclass(frozen=True, slots=True)
class EpisodeRecord:
    """An episode's summary and its compressed trace (for replay)."""

    episode: int
    outcome: str
    cause: str | None
    ticks: int
    start_tick: int
    rewards: int
    trace: bytes


@dataclass(frozen=True, slots=True)
class Checkpoint:
    """The run's state at an episode boundary: resuming replays the log from here.

    `state` is the engine's own opaque, compressed serialisation of the brain (LTM, RLTM,
    network, synthesised behaviours, STM, random generator).
    """

    episode: int
    tick: int
    state: bytes


@dataclass(frozen=True, slots=True)
class RunTotals:
    """Counters kept on the run's row."""

    episodes: int
    successes: int
    ticks: int

    def __reduce__(self) -> tuple[type[RunTotals], tuple[int, int, int]]:
        # Pickled as a tuple of its fields (each tick sent to the service carries one).
        return RunTotals, (self.episodes, self.successes, self.ticks)


@dataclass(frozen=True, slots=True)
class StoredRun:
    """A run as stored: its spec, status, last checkpoint and the log after it."""

    id: int
    spec: RunSpec
    status: RunStatus
    totals: RunTotals
    checkpoint: Checkpoint | None
    rewards_after: tuple[StoredReward, ...]
    """Rewards stamped after the checkpoint's tick, in log order (applied or not)."""
    commands_after: tuple[StoredCommand, ...]
    """Commands stamped after the checkpoint's tick, in log order."""
    error: str | None = None


class RunStore(Protocol):
    """Durable storage of runs, their learning, episodes and the reward log."""

    def create_run(self, spec: RunSpec, network: tuple[NetworkPair, ...]) -> int:
        """Store a new run (status created) with its starting network; returns its id."""
        ...

    def load_run(self, run_id: int) -> StoredRun:
        """A stored run; raises `UnknownRunError` when there is none."""
        ...

    def set_status(self, run_id: int, status: RunStatus, error: str | None = None) -> None:
        """Change a run's status (and error message)."""
        ...

    def log_reward(self, run_id: int, reward: RewardRecord) -> int:
        """Append a reward to the log, committed before returning its id."""
        ...

    def apply_reward(
        self, run_id: int, reward_id: int, update: LearningUpdate, credited: int
    ) -> None:
        """In one transaction: mark a logged reward applied and store what it changed."""
        ...

    def record_reward(
        self, run_id: int, reward: RewardRecord, update: LearningUpdate, credited: int
    ) -> int:
        """In one transaction: log a reward already applied and store what it changed.

        For the task's and a program's rewards, which nobody waits to acknowledge.
        Returns the reward's id.
        """
        ...

    def commit_rewards(self, run_id: int, rewards: Sequence[RewardCommit]) -> tuple[int, ...]:
        """In one transaction and in order: `apply_reward` or `record_reward` for each.

        Returns the rewards' ids. A writer that fell behind commits what queued up at once.
        """
        ...

    def log_command(self, run_id: int, command: CommandRecord, update: LearningUpdate) -> int:
        """In one transaction: append a command to the log and store what it changed."""
        ...

    def end_episode(
        self, run_id: int, episode: EpisodeRecord, checkpoint: Checkpoint, totals: RunTotals
    ) -> None:
        """In one transaction: store an episode, the checkpoint after it and the totals."""
        ...

    def end_episodes(
        self,
        run_id: int,
        episodes: Sequence[EpisodeRecord],
        checkpoint: Checkpoint,
        totals: RunTotals,
    ) -> None:
        """`end_episode` for several episodes at once (a writer that fell behind)."""
        ...


class RunQueries(RunStore, Protocol):
    """A `RunStore` with the reads the service answers from: each reads only what it returns.

    Pages are in id (or episode number) order with the total count beside them; an unknown
    run raises `UnknownRunError`.
    """

    def ltm(self, run_id: int) -> dict[tuple[str, str], float]:
        """The run's LTM reliabilities by (stimulus, behaviour)."""
        ...

    def rltm(self, run_id: int) -> dict[tuple[str, str], float]:
        """The run's RLTM (KP) reliabilities by (stimulus, behaviour)."""
        ...

    def network(self, run_id: int) -> tuple[NetworkPair, ...]:
        """The run's behaviour network as stored."""
        ...

    def behaviours(self, run_id: int) -> tuple[BehaviourSpec, ...]:
        """The behaviours the run synthesised (KP), in the order they were added."""
        ...

    def list_runs(self) -> list[StoredRun]:
        """Every run, by id."""
        ...

    def run_summary(self, run_id: int) -> StoredRun:
        """A run's spec, status and totals, without its checkpoint or log."""
        ...

    def run_summaries(self, offset: int = 0, limit: int = 100) -> tuple[list[StoredRun], int]:
        """A page of runs by id, as `run_summary`, and how many runs are stored."""
        ...

    def rewards_page(
        self, run_id: int, offset: int = 0, limit: int = 100
    ) -> tuple[list[StoredReward], int]:
        """A page of the run's reward log in log order, with times, and the log's length."""
        ...

    def episode(self, run_id: int, episode: int) -> EpisodeRecord | None:
        """One episode with its trace, None if the run has no such episode."""
        ...

    def episode_summaries(self, run_id: int) -> list[EpisodeRecord]:
        """The run's episodes by number, without their traces."""
        ...

    def episode_summaries_page(
        self, run_id: int, offset: int = 0, limit: int = 100
    ) -> tuple[list[EpisodeRecord], int]:
        """A page of the run's episodes without traces, and how many it has."""
        ...

    def interrupt_active(self) -> int:
        """Mark every run stored as running or paused interrupted (its process died)."""
        ...


class NetworkRepository(Protocol):
    """Stored networks (the S-R editor's subject), their associations and edit history.

    Each method is one transaction that applies `core.networks`' rules. Unknown networks,
    versions and addressed pairs raise `UnknownNameError`; invalid input raises `ValueError`
    or `CatalogError`; conflicts (a taken name, a built-in network, an existing pair) raise
    `NetworkConflictError`, a locked association changed without `force`
    `LockedAssociationError`, and a write whose `expected` is no longer current
    `StaleVersionError`. A write that changes nothing makes no version.
    """

    def summaries(self) -> tuple[NetworkSummary, ...]:
        """Every network without its associations: built-in ones first, then by name."""
        ...

    def get(self, name: str) -> StoredNetwork:
        """A network with its associations, in catalogue order."""
        ...

    def pairs(self, name: str) -> tuple[NetworkPair, ...]:
        """A network's associations in the order they were stored (a run's start)."""
        ...

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
        ...

    def delete(self, name: str, *, expected: ExpectedVersion | None = None) -> None:
        """Delete an editable network and its history."""
        ...

    def add_association(
        self,
        name: str,
        pair: NetworkPair,
        *,
        note: str = "",
        expected: ExpectedVersion | None = None,
    ) -> NetworkEdit:
        """Add an association the network lacks."""
        ...

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
        ...

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
        ...

    def versions(self, name: str) -> tuple[NetworkVersion, ...]:
        """A network's edit history, oldest first."""
        ...

    def versions_page(
        self, name: str, offset: int = 0, limit: int = 100
    ) -> tuple[tuple[NetworkVersion, ...], int]:
        """A page of `versions`, and how many versions the history holds."""
        ...

    def snapshot(self, name: str, version: int) -> NetworkSnapshot:
        """The network as it was at `version`."""
        ...

    def diff(self, name: str, from_version: int, to_version: int) -> tuple[AssociationChange, ...]:
        """What changed between two versions of a network (either order)."""
        ...

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
        ...

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
        ...
