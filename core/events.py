"""Domain events: what happened during a tick, in the past tense."""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum


class Outcome(StrEnum):
    """How an episode ended."""

    SUCCESS = "success"
    FAILURE = "failure"


class Cause(StrEnum):
    """Why an episode failed."""

    WALL_COLLISION = "wall_collision"
    OBSTACLE_COLLISION = "obstacle_collision"
    SIGNAL_VIOLATION = "signal_violation"
    TIMEOUT = "timeout"


@dataclass(frozen=True, slots=True)
class Credit:
    """What one STM record received from a reward."""

    tick: int
    stimulus: int
    behaviour: int
    d_k: int
    before: float
    after: float


@dataclass(frozen=True, slots=True)
class EpisodeEnded:
    """An episode finished."""

    episode: int
    outcome: Outcome
    cause: Cause | None
    ticks: int


@dataclass(frozen=True, slots=True)
class RewardApplied:
    """A reward popped STM into LTM (Eq. 1)."""

    tick: int
    episode: int
    value: float
    source: str
    note: str
    credits: tuple[Credit, ...]
    uid: str = ""
    """The reward's id from its arrival (`core.commands.InjectReward.uid`)."""
    tick_seen: int | None = None
    """The tick the trainer saw when they pressed (None: the paper's rule)."""
    window: tuple[int, int] | None = None
    """The first and last tick it could credit (`core.brain.memory.credit_seen`)."""


@dataclass(frozen=True, slots=True)
class AssociationPromoted:
    """An S-R pair's reliability passed the threshold: it joined the behaviour network."""

    stimulus: int
    behaviour: int
    reliability: float
    source: str


@dataclass(frozen=True, slots=True)
class AssociationDemoted:
    """A learned S-R pair's reliability fell below the threshold: it left the network."""

    stimulus: int
    behaviour: int
    reliability: float


@dataclass(frozen=True, slots=True)
class RewardDue:
    """A reward the simulation produced (task or reinforcement program), due at `tick`.

    Emitted instead of applied when the simulation defers rewards to the engine's reward
    task; `tick` is the boundary it applies at (it credits the STM records before it).
    """

    tick: int
    episode: int
    value: float
    source: str
    note: str


Event = EpisodeEnded | RewardApplied | RewardDue | AssociationPromoted | AssociationDemoted
