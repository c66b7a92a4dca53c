"""The synchronous simulation: a world and a brain, stepped one tick at a time."""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from core.brain.brain import Brain, BrainConfig, RewardOutcome
from core.brain.catalog import Catalog, load_catalog
from core.brain.network import BehaviourNetwork
from core.brain.selection import How
from core.commands import InjectReward, RewardSource
from core.errors import SimulationStateError
from core.events import Cause, EpisodeEnded, Event, Outcome, RewardApplied, RewardDue
from core.run.conditions import Condition
from core.run.setup import condition_network
from core.run.trainer import ReinforcementProgram, Teacher, load_trainer
from core.sim.channels import Channel
from core.sim.corridor_world import CorridorWorld
from core.sim.types import SensorFrame
from core.sim.world import LampColor, World, WorldConfig, make_world
from core.sim.worlds import load_world

_PROGRESS = int(Channel.PROGRESS_M)


@dataclass(frozen=True, slots=True)
class TickInputs:
    """What reaches the robot from outside at a tick boundary."""

    rewards: tuple[InjectReward, ...] = ()
    behaviour: int = -1
    """A behaviour chosen by an external learner for this tick (-1: the brain chooses)."""


NO_INPUTS = TickInputs()


class Snapshot(NamedTuple):
    """The state after a tick: what the robot sensed and did, and where the episode stands."""

    episode: int
    tick: int
    episode_tick: int
    x: float
    y: float
    heading_rad: float
    stimuli: tuple[int, ...]
    behaviour: int
    how: How
    lamp: LampColor
    progress_m: float
    outcome: Outcome | None = None
    cause: Cause | None = None
    origin: str = "default"
    """What made the behaviour run: its association's source, explored, default or
    commanded (`core.brain.selection.ORIGINS`)."""
    released_by: int = -1
    """The stimulus the behaviour answers (-1: none)."""

    @property
    def done(self) -> bool:
        """Whether the episode has ended."""
        return self.outcome is not None


class TickResult(NamedTuple):
    """A tick's new snapshot and the events it produced."""

    snapshot: Snapshot
    events: tuple[Event, ...] = ()


class Simulation:
    """The world and the brain, with episodes, the referee and the delayed reward.

    `reset()` starts the next episode; `tick()` advances one tick. Everything random comes
    from `seed` (the obstacle and the lamp per episode, sonar noise, exploration), so the
    same seed and the same rewards give the same trajectory and LTM, bit for bit.
    """

    def __init__(
        self,
        condition: Condition,
        seed: int,
        *,
        world: World | None = None,
        world_config: WorldConfig | None = None,
        catalog: Catalog | None = None,
        network: BehaviourNetwork | None = None,
        brain_config: BrainConfig | None = None,
        end_on_failure: bool = True,
        defer_rewards: bool = False,
    ) -> None:
        self.condition = condition
        self.seed = seed
        self.catalog = catalog or load_catalog()
        self.world = world or make_world(world_config or load_world().config)
        if network is None:
            network = condition_network(self.catalog, condition)
        brain_rng = np.random.default_rng(np.random.SeedSequence([seed, 0, 3]))
        self.brain = Brain(
            self.catalog,
            network,
            brain_config or condition.brain_config(),
            self.world.config.robot,
            brain_rng,
            self.world.config.dt_s,
        )
        self.trainer: ReinforcementProgram | None = (
            load_trainer(self.catalog, condition.trainer) if condition.trainer else None
        )
        self.teacher: Teacher | None = (
            Teacher(self.trainer, condition.teacher, seed, self.world.config.dt_s)
            if self.trainer is not None
            else None
        )
        self._pending: list[InjectReward] = []
        self._in_flight: list[tuple[int, int, InjectReward]] = []
        """The teacher's rewards on their way, a heap by (due boundary, order judged)."""
        self._judged = 0
        self.end_on_failure = end_on_failure
        self.defer_rewards = defer_rewards
        self.episode = -1
        self.tick_count = 0
        self._episode_tick = 0
        self._lap = self.world.geometry.lap_length_m
        self._max_ticks = self.world.config.max_ticks
        self._progress = 0.0
        self._last_p = 0.0
        self._cause: Cause | None = None
        self._done = True
        self._snapshot: Snapshot | None = None
        self._channels: list[float] = []
        self._latest: Callable[[], SensorFrame] | None = getattr(self.world, "latest", None)
        """A world whose readings arrive by themselves (a robot, `server.robots.ros2`): each tick
        reads them afresh right before the brain decides, so the command answers the newest."""
        self.ticks_by_origin: dict[str, int] = {}
        """Ticks run so far by what made their behaviour run (see `Snapshot.origin`)."""
        self.stimulus_ticks = [0] * len(self.catalog.stimuli)
        """Ticks each stimulus was active, by stimulus id."""
        self.encounters = [0] * len(self.catalog.stimuli)
        """Times each stimulus became active (an encounter), by stimulus id."""
        self._was_active: frozenset[int] = frozenset()
        self.met_this_episode: set[int] = set()
        """The stimuli active at some tick of the current episode."""

    @property
    def snapshot(self) -> Snapshot:
        """The latest snapshot."""
        if self._snapshot is None:
            raise SimulationStateError("call reset() before reading the snapshot")
        return self._snapshot

    def reset(self) -> Snapshot:
        """Start the next episode and return its first snapshot."""
        self.episode += 1
        frame = self.world.reset(self.seed, self.episode)
        self.brain.reset_episode(self.tick_count)
        self._episode_tick = 0
        self._progress = 0.0
        self._last_p = float(frame.channels[_PROGRESS])
        self._cause = None
        self._done = False
        self._pending.clear()
        self._in_flight.clear()
        self._was_active = frozenset()
        self.met_this_episode = set()
        self._channels = frame.channels.tolist()
        self._snapshot = Snapshot(
            self.episode,
            self.tick_count,
            0,
            frame.x,
            frame.y,
            frame.heading_rad,
            (),
            -1,
            How.DEFAULT,
            frame.lamp,
            0.0,
        )
        return self._snapshot

    def sonar_m(self) -> tuple[float, ...]:
        """The sonars' readings of the last tick (or reset), in metres, sonar 0 first."""
        return tuple(self._channels[Channel.SONAR_0 : Channel.SONAR_7 + 1])

    def obstacle_centers(self) -> tuple[tuple[float, float], ...]:
        """Where every obstacle is at the last tick (or reset), the first placed first."""
        world = self.world
        if isinstance(world, CorridorWorld):
            return tuple(world.obstacle_centers())
        center = world.layout.obstacle_center
        return () if center is None else (center,)

    def upcoming_stimuli(self) -> list[int]:
        """The stimuli the next tick will act on (sensed at the end of the last one)."""
        return self.brain.stimuli(self._channels)

    def reward(
        self, value: float, *, source: RewardSource = RewardSource.TRAINER, note: str = ""
    ) -> RewardApplied:
        """Apply a reward now, between ticks: it credits every STM record so far."""
        reward = InjectReward(value, note=note, source=source)
        return self.apply_reward(reward, self.tick_count + 1)[0]

    def apply_reward(
        self, r: InjectReward, tick: int, episode: int | None = None
    ) -> tuple[RewardApplied, RewardOutcome]:
        """Apply a reward stamped with the boundary before `tick` (see `Brain.reward`)."""
        outcome = self.brain.reward(tick, r.value, r.tick_seen, r.window, r.records)
        event = RewardApplied(
            tick,
            self.episode if episode is None else episode,
            r.value,
            r.source,
            r.note,
            outcome.credits,
            r.uid,
            r.tick_seen,
            outcome.window,
        )
        return event, outcome

    def tick(self, inputs: TickInputs = NO_INPUTS) -> TickResult:
        """Advance one tick: rewards at the boundary, then sense to act, step, referee."""
        if self._done:
            raise SimulationStateError("the episode is over: call reset() first")
        events: list[Event] = []
        if self._pending:
            self._apply_rewards(self._pending, events)
            self._pending = []
        if inputs.rewards:
            self._apply_rewards(inputs.rewards, events)
        self.tick_count += 1
        self._episode_tick += 1
        brain = self.brain
        if self._latest is not None:
            self._channels = self._latest().channels.tolist()
        active, command = brain.step(self.tick_count, self._channels, inputs.behaviour)
        was = self._was_active
        counts, met = self.stimulus_ticks, self.encounters
        for s in active:
            counts[s] += 1
            if s not in was:
                met[s] += 1
                self.met_this_episode.add(s)
        self._was_active = frozenset(active)
        if self.teacher is not None:
            judged = self.teacher.judge(brain.last, self.tick_count, self.episode)
            if judged is not None:
                r = InjectReward(judged.value, note=judged.note, source=RewardSource.PROGRAM)
                heapq.heappush(self._in_flight, (judged.due, self._judged, r))
                self._judged += 1
        if self._in_flight:
            self._arrive(self.tick_count + 1, events)
        self.world.apply(command)
        frame = self.world.step()
        channels = frame.channels.tolist()
        self._channels = channels
        p = channels[_PROGRESS]
        ds = p - self._last_p
        half = self._lap / 2
        if ds < -half:
            ds += self._lap
        elif ds > half:
            ds -= self._lap
        self._progress += ds
        self._last_p = p

        if self._cause is None:
            if frame.collision == "wall":
                self._cause = Cause.WALL_COLLISION
            elif frame.collision == "obstacle":
                self._cause = Cause.OBSTACLE_COLLISION
            elif frame.violation:
                self._cause = Cause.SIGNAL_VIOLATION
        outcome: Outcome | None = None
        cause = self._cause
        if cause is not None and self.end_on_failure:
            outcome = Outcome.FAILURE
        elif self._progress >= self._lap:
            outcome = Outcome.SUCCESS if cause is None else Outcome.FAILURE
        elif self._episode_tick >= self._max_ticks:
            outcome = Outcome.FAILURE
            cause = cause or Cause.TIMEOUT
        decision = brain.last
        by_origin = self.ticks_by_origin
        by_origin[decision.origin] = by_origin.get(decision.origin, 0) + 1
        snap = Snapshot(
            self.episode,
            self.tick_count,
            self._episode_tick,
            frame.x,
            frame.y,
            frame.heading_rad,
            tuple(active),
            decision.behaviour,
            decision.how,
            frame.lamp,
            self._progress,
            outcome,
            cause,
            decision.origin,
            decision.stimulus,
        )
        self._snapshot = snap
        if outcome is not None:
            self._done = True
            if self._in_flight:
                # Rewards still on their way arrive as the episode ends: the robot stands
                # still from here, and STM keeps the episode's records until the next one.
                self._arrive(None, events)
            if self._pending:
                self._apply_rewards(self._pending, events)
                self._pending = []
            if outcome is Outcome.FAILURE:
                events.extend(brain.episode_failed().changes)
            events.append(EpisodeEnded(self.episode, outcome, cause, self._episode_tick))
            reward = self.condition.success_reward
            if outcome is Outcome.SUCCESS and reward is not None:
                self._apply_rewards(
                    [InjectReward(reward, note="lap completed", source=RewardSource.TASK)], events
                )
        return TickResult(snap, tuple(events))

    def _arrive(self, boundary: int | None, events: list[Event]) -> None:
        """The teacher's rewards due by `boundary` (None: all) arrive at the next boundary.

        Each credits the STM records before the boundary it arrives at, not the tick it
        judged: a late reward credits what the robot did since as well.
        """
        flight = self._in_flight
        while flight and (boundary is None or flight[0][0] <= boundary):
            r = heapq.heappop(flight)[2]
            if self.defer_rewards:
                # Due at the next boundary: the engine's reward task applies it there.
                due = RewardDue(self.tick_count + 1, self.episode, r.value, r.source, r.note)
                events.append(due)
            else:
                self._pending.append(r)

    def _apply_rewards(self, rewards: Iterable[InjectReward], events: list[Event]) -> None:
        stamp = self.tick_count + 1
        for r in rewards:
            if self.defer_rewards:
                events.append(RewardDue(stamp, self.episode, r.value, r.source, r.note))
                continue
            event, applied = self.apply_reward(r, stamp)
            events.append(event)
            events.extend(applied.changes)
