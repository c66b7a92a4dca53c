"""Commands: external inputs applied at a tick boundary, stamped with that tick."""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass
from enum import StrEnum


class RewardSource(StrEnum):
    """Who gave a reward. A `str`: it is stored, logged and sent as its value."""

    TRAINER = "trainer"
    """A person (or a client speaking for one): an external reward, kept in the log."""
    PROGRAM = "program"
    """The reinforcement program: produced again when a run is replayed."""
    TASK = "task"
    """The task itself (a lap completed): produced again when a run is replayed."""


INTERNAL_SOURCES = frozenset({RewardSource.PROGRAM, RewardSource.TASK})
"""The sources a run produces itself, so a replay produces them again."""


@dataclass(frozen=True, slots=True)
class InjectReward:
    """A reward in [-1, 1] from a trainer, a reinforcement program or the task itself."""

    value: float
    _: KW_ONLY
    note: str = ""
    source: RewardSource = RewardSource.TRAINER
    uid: str = ""
    """The reward's own id from its arrival on: kept in the log, its event and the console
    ("": the engine gives it one)."""
    tick_seen: int | None = None
    """The tick the trainer was looking at when they pressed: the reward credits the
    reaction window before it (`core.brain.memory.credit_seen`). None: the paper's rule,
    every STM record before the boundary (the task's, the program's, and clients that send
    none)."""
    seen_episode: int | None = None
    """The episode `tick_seen` belongs to (None: the one it lies in, the run's current or
    the one that just ended)."""
    window: tuple[int, int] | None = None
    """The first and last tick it credits, set as it arrives (None: the run's window
    before `tick_seen`)."""
    records: tuple[tuple[int, int, int], ...] | None = None
    """A stored episode's records it credits, (tick, stimulus id, behaviour id) from the
    episode's trace, carried so a replay credits the same (None: the run's memory)."""

    def __post_init__(self) -> None:
        if not -1.0 <= self.value <= 1.0:
            raise ValueError("a reward must be in [-1, 1]")


@dataclass(frozen=True, slots=True)
class EditAssociation:
    """Set (or, with `strength` None, remove) an association of a running robot's network.

    The S-R editor's live edit: applied at the next tick boundary and logged, so the run
    stays replayable from its seed and command log.
    """

    stimulus: str
    behaviour: str
    strength: float | None
    source: str = "dp"
    locked: bool = False

    def __post_init__(self) -> None:
        if self.strength is not None and not 0.0 <= self.strength <= 1.0:
            raise ValueError("an association's strength must be in [0, 1]")
