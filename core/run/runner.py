"""Headless runs: a condition for a number of episodes, as fast as the CPU allows."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field

from core.brain.brain import BrainConfig
from core.brain.catalog import Catalog
from core.events import Cause, EpisodeEnded, Outcome, RewardApplied
from core.run.conditions import Condition
from core.run.simulation import Simulation, Snapshot
from core.sim.world import WorldConfig


@dataclass(frozen=True, slots=True)
class EpisodeSummary:
    """One episode's result."""

    episode: int
    outcome: Outcome
    cause: Cause | None
    ticks: int
    rewards: int


@dataclass(frozen=True, slots=True)
class RunSummary:
    """A run's results: its episodes, total ticks and final LTM."""

    condition: str
    seed: int
    episodes: tuple[EpisodeSummary, ...]
    ticks: int
    ltm: dict[tuple[int, int], float]
    ticks_by_origin: dict[str, int] = field(default_factory=dict)
    """Ticks by what made their behaviour run: an association's source (innate, designed,
    dp, learned, kp, expert), explored, default or commanded."""

    @property
    def successes(self) -> int:
        """Episodes that ended in success."""
        return sum(e.outcome is Outcome.SUCCESS for e in self.episodes)

    @property
    def success_rate(self) -> float:
        """Successes per episode."""
        return self.successes / len(self.episodes) if self.episodes else 0.0

    def failures(self) -> dict[str, int]:
        """Failed episodes by cause, every cause listed."""
        counts = Counter(e.cause.value for e in self.episodes if e.cause is not None)
        return {c.value: counts.get(c.value, 0) for c in Cause}


def run(
    condition: Condition,
    seed: int,
    episodes: int,
    *,
    world_config: WorldConfig | None = None,
    catalog: Catalog | None = None,
    brain_config: BrainConfig | None = None,
    on_episode: Callable[[EpisodeSummary], None] | None = None,
    on_tick: Callable[[Snapshot], None] | None = None,
    simulation: Simulation | None = None,
) -> RunSummary:
    """Run `episodes` episodes of a condition from `seed` and summarise them.

    Pass `simulation` to run a prepared one (and read its brain afterwards).
    """
    if episodes < 1:
        raise ValueError("episodes must be >= 1")
    sim = simulation or Simulation(
        condition, seed, world_config=world_config, catalog=catalog, brain_config=brain_config
    )
    results: list[EpisodeSummary] = []
    tick = sim.tick
    for _ in range(episodes):
        snap = sim.reset()
        if on_tick is not None:
            on_tick(snap)
        rewards = 0
        while True:
            result = tick()
            if on_tick is not None:
                on_tick(result.snapshot)
            if result.events:
                ended = None
                for e in result.events:
                    if isinstance(e, RewardApplied):
                        rewards += 1
                    elif isinstance(e, EpisodeEnded):
                        ended = e
                if ended is not None:
                    summary = EpisodeSummary(
                        ended.episode, ended.outcome, ended.cause, ended.ticks, rewards
                    )
                    results.append(summary)
                    if on_episode is not None:
                        on_episode(summary)
                    break
    return RunSummary(
        condition.name,
        seed,
        tuple(results),
        sim.tick_count,
        sim.brain.ltm.as_dict(),
        dict(sim.ticks_by_origin),
    )
