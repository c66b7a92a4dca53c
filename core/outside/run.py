"""srlab's brain on an outside world: one seed of a condition, trained then held out.

Each tick the adapter's channels go to `Brain.step` (logical sensors, perception,
releasers, selection, motor, STM, KP's RSTM); the running behaviour's `action` (or the
brain's wheel command) goes to the environment. A successful episode gives the condition's
delayed reward; a failed one `Brain.episode_failed`. Held out, the learned network is
frozen (learning, exploration and KP off) and run on episodes never trained on.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, replace

import numpy as np

from core.brain.brain import Brain, BrainConfig
from core.brain.network import BehaviourNetwork
from core.brain.propagation import KpConfig
from core.brain.selection import DEFAULT_DESIRES
from core.outside.world import OutsideEnv, OutsideWorld
from core.run.conditions import Condition
from core.run.setup import network_specs
from core.sim.robot import RobotConfig

HELD_OUT_OFFSET = 500_000
"""Held-out episodes' environment seeds start here past the training ones'."""


def episode_seed(seed: int, episode: int, held_out: bool = False) -> int:
    """The environment's seed for an episode: the same for every condition (paired by seed)."""
    return seed * 1000 + episode + (HELD_OUT_OFFSET if held_out else 0)


@dataclass(frozen=True, slots=True)
class Episode:
    """One episode: how it ended, its length in ticks and the environment's own return."""

    outcome: str
    ticks: int
    ret: float

    @property
    def success(self) -> bool:
        """Whether the episode succeeded."""
        return self.outcome == "success"


@dataclass(frozen=True, slots=True)
class SeedRun:
    """A condition on one seed: its training and held-out episodes and what ran.

    Attributes:
        condition: the condition's name.
        seed: the seed.
        episodes: the training episodes.
        held_out: the held-out episodes (learning frozen).
        origins: training ticks by the origin of the decision (innate, designed, kp,
            learned, explored, default...).
        answers: per high-level stimulus, the behaviour its network releases at the end
            ("" for none).
        onsets: training ticks where a low-level stimulus of an objective a high-level
            sensor shares became active (a reflex's onset).
        leads: for each onset the high-level sensor saw coming (a stimulus of the same
            objective active within KP's window before it), how many ticks before the
            onset that sighting began.
    """

    condition: str
    seed: int
    episodes: tuple[Episode, ...]
    held_out: tuple[Episode, ...]
    origins: dict[str, int]
    answers: dict[str, str]
    onsets: int = 0
    leads: tuple[int, ...] = ()


class Lead:
    """Counts reflex onsets and how long before each the high-level sensor saw it coming."""

    def __init__(self, world: OutsideWorld, window: int) -> None:
        stimuli = world.catalog.stimuli
        shared = {s.objective for s in stimuli if s.level == "high"}
        self.high = frozenset(s.id for s in stimuli if s.level == "high")
        self.low = frozenset(s.id for s in stimuli if s.level == "low" and s.objective in shared)
        self.window = window
        self.onsets = 0
        self.leads: list[int] = []
        self.reset()

    def reset(self) -> None:
        """A new episode: nothing seen."""
        self._low_before = False
        self._high_start = -1
        self._high_last = -(10**9)

    def see(self, tick: int, active: list[int]) -> None:
        """One tick's active stimuli."""
        high = any(s in self.high for s in active)
        low = any(s in self.low for s in active)
        if high:
            if self._high_last < tick - 1:
                self._high_start = tick
            self._high_last = tick
        if low and not self._low_before:
            self.onsets += 1
            if self._high_start >= 0 and tick - self._high_last <= self.window:
                self.leads.append(tick - self._high_start)
        self._low_before = low


def brain_for(world: OutsideWorld, condition: Condition, seed: int) -> Brain:
    """A brain for `condition` on `world`, its exploration seeded by `seed`."""
    catalog = world.catalog
    base = condition.brain_config()
    desires = {**DEFAULT_DESIRES, **world.desires}
    config = replace(
        base,
        selection=replace(
            base.selection, default_behaviour=world.default_behaviour, desires=desires
        ),
    )
    network = BehaviourNetwork.from_specs(catalog, network_specs(catalog, condition))
    rng = np.random.default_rng(np.random.SeedSequence([seed, 40]))
    return Brain(catalog, network, config, _robot(world), rng, world.dt_s)


def _robot(world: OutsideWorld) -> RobotConfig:
    """A robot whose cruise is the default behaviour's speed (the motor scales nothing)."""
    behaviours = world.catalog.behaviours
    cruise = world.catalog.behaviour(world.default_behaviour).speed_mps
    return RobotConfig(
        cruise_speed_mps=cruise, max_speed_mps=max(max(b.speed_mps for b in behaviours), cruise)
    )


def frozen(world: OutsideWorld, brain: Brain) -> Brain:
    """A copy of `brain`'s knowledge with learning, exploration and KP off."""
    cfg = brain.config
    config = BrainConfig(
        selection=replace(cfg.selection, epsilon=0.0),
        learning=replace(cfg.learning, enabled=False),
        kp=KpConfig(enabled=False),
    )
    rng = np.random.default_rng(0)
    return Brain(brain.catalog, brain.network.copy(), config, _robot(world), rng, world.dt_s)


def run_episode(
    world: OutsideWorld,
    env: OutsideEnv,
    brain: Brain,
    env_seed: int,
    tick: int,
    success_reward: float | None,
    origins: Counter[str] | None = None,
    lead: Lead | None = None,
) -> tuple[Episode, int]:
    """One episode from `env_seed`, ticks counted on from `tick`; the episode and next tick."""
    actions = world.actions
    channels = env.reset(env_seed)
    brain.reset_episode()
    if lead is not None:
        lead.reset()
    ret = 0.0
    start = tick
    while True:
        active, wheels = brain.step(tick, channels)
        if origins is not None:
            origins[brain.last.origin] += 1
        if lead is not None:
            lead.see(tick, active)
        step = env.step(actions[brain.motor.running], wheels)
        tick += 1
        ret += step.reward
        if step.outcome is not None:
            break
        channels = step.channels
    if step.outcome == "success":
        if success_reward is not None:
            brain.reward(tick, success_reward)
    else:
        brain.episode_failed()
    return Episode(step.outcome, tick - start, ret), tick


def run_seed(
    world: OutsideWorld,
    condition: Condition,
    seed: int,
    episodes: int | None = None,
    held_out: int | None = None,
) -> SeedRun:
    """`condition` on `world` for one seed: trained for `episodes`, then held out."""
    brain = brain_for(world, condition, seed)
    env = world.make()
    origins: Counter[str] = Counter()
    lead = Lead(world, brain.config.kp.window_ticks)
    try:
        tick = 0
        trained: list[Episode] = []
        for e in range(world.episodes if episodes is None else episodes):
            ep, tick = run_episode(
                world,
                env,
                brain,
                episode_seed(seed, e),
                tick,
                condition.success_reward,
                origins,
                lead,
            )
            trained.append(ep)
        still = frozen(world, brain)
        tested: list[Episode] = []
        tick = 0
        for e in range(world.held_out if held_out is None else held_out):
            ep, tick = run_episode(world, env, still, episode_seed(seed, e, True), tick, None)
            tested.append(ep)
    finally:
        env.close()
    names = [b.name for b in brain.catalog.behaviours]
    answers = {
        s.name: (names[b] if (b := brain.answer(s.id)) >= 0 else "")
        for s in brain.catalog.stimuli
        if s.level == "high"
    }
    return SeedRun(
        condition.name, seed, tuple(trained), tuple(tested), dict(origins), answers,
        lead.onsets, tuple(lead.leads),
    )  # fmt: skip
