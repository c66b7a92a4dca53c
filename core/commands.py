"""Commands: external inputs applied at a tick boundary, stamped with that tick."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class InjectReward:
    """A reward in [-1, 1] from a trainer, a reinforcement program or the task itself."""

    value: float
    note: str = ""
    source: str = "trainer"

    def __post_init__(self) -> None:
        if not -1.0 <= self.value <= 1.0:
            raise ValueError("a reward must be in [-1, 1]")
