"""The brain: the five modules of Fig. 1 wired into one tick and one reward pipeline."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from core.brain.catalog import Behaviour, Catalog
from core.brain.memory import (
    DEFAULT_REACTION_S,
    LongTermMemory,
    ReactionWindow,
    ShortTermMemory,
    credit_seen,
)
from core.brain.motor import Motor, cruise_scale
from core.brain.network import BehaviourNetwork
from core.brain.perception import Perception
from core.brain.propagation import KnowledgePropagation, KpConfig, Propagated
from core.brain.selection import COMMANDED, Decision, How, SelectionConfig, Selector
from core.brain.sensors import compile_detector
from core.events import AssociationDemoted, AssociationPromoted, Credit
from core.sim.robot import RobotConfig
from core.sim.types import MotorCommand


@dataclass(frozen=True, slots=True)
class LearningConfig:
    """Parameters of the memory module.

    Attributes:
        enabled: whether rewards update LTM and the behaviour network.
        eta: Eq. (1)'s learning rate.
        insert_threshold: a pair whose reliability reaches this joins the behaviour network
            (and a learned pair that falls below it leaves).
        stm_capacity: STM's bound in records.
        clear_stm_each_episode: forget STM when an episode starts, so a success is never
            credited to the previous episode's records.
        learnable_sensors: logical sensors whose stimuli are explored (epsilon-greedy).
    """

    enabled: bool = False
    eta: float = 0.1
    insert_threshold: float = 0.5
    stm_capacity: int = 1000
    clear_stm_each_episode: bool = True
    learnable_sensors: tuple[str, ...] = ("signal", "camera_obstacle")

    def __post_init__(self) -> None:
        if not 0.0 < self.insert_threshold <= 1.0:
            raise ValueError("insert_threshold must be in (0, 1]")


@dataclass(frozen=True, slots=True)
class BrainConfig:
    """Selection and learning parameters."""

    selection: SelectionConfig = field(default_factory=SelectionConfig)
    learning: LearningConfig = field(default_factory=LearningConfig)
    kp: KpConfig = field(default_factory=KpConfig)


@dataclass(frozen=True, slots=True)
class RewardOutcome:
    """What a reward did: the credited STM records and the network changes."""

    credits: tuple[Credit, ...]
    changes: tuple[AssociationPromoted | AssociationDemoted, ...]
    propagated: tuple[Propagated, ...] = ()
    window: tuple[int, int] | None = None
    """The first and last tick a reward with a seen tick could credit (None: the paper's
    rule, every record before the boundary)."""


class Brain:
    """Sensor (logical) -> perception -> selection -> motor, with STM/LTM learning."""

    def __init__(
        self,
        catalog: Catalog,
        network: BehaviourNetwork,
        config: BrainConfig,
        robot: RobotConfig,
        rng: np.random.Generator,
        dt_s: float = 0.1,
    ) -> None:
        self.catalog = catalog
        self.network = network
        self.config = config
        self.detect = compile_detector(catalog)
        self.perception = Perception(catalog)
        learnable = frozenset(
            s.id for s in catalog.stimuli if s.sensor in config.learning.learnable_sensors
        )
        self.learnable = learnable
        """The stimuli whose responses are explored and may be learned into the network."""
        self.selector = Selector(
            catalog, network, self.perception, config.selection, learnable, rng
        )
        self.motor = Motor(
            catalog,
            robot.align_gain,
            robot.max_turn_rad_s,
            dt_s,
            cruise_scale(catalog, robot, config.selection.default_behaviour),
        )
        self.stm = ShortTermMemory(config.learning.stm_capacity)
        self.window = ReactionWindow.of_seconds(*DEFAULT_REACTION_S, 1.0 / dt_s)
        """The reaction window of rewards with a seen tick (a run sets its own)."""
        self.ended = ShortTermMemory(1)
        """The ended episode's last records, kept at a reset for the rewards pressed at
        its end (`credit_seen`), until the window has passed."""
        self.ended_tick = -1
        """The ended episode's last tick (-1: none kept)."""
        self._tick = 0
        self.ltm = LongTermMemory(config.learning.eta)
        self.kp = (
            KnowledgePropagation(catalog, network, config.kp, dt_s, self._add_behaviour)
            if config.kp.enabled
            else None
        )
        self._priority = self.selector.priority
        self._filter = any(w <= 0.0 for w in self.perception.strength)
        self._last = Decision(-1, -1, 0.0, How.DEFAULT)
        self._running_priority = -1

    @property
    def rng(self) -> np.random.Generator:
        """The brain's random generator (exploration)."""
        return self.selector.rng

    @property
    def last(self) -> Decision:
        """The decision of the latest tick."""
        return self._last

    def reset_episode(self, last_tick: int | None = None) -> None:
        """A new episode: nothing runs; STM is forgotten if so configured.

        Forgotten, the records a reward seen at the ended episode's last tick
        (`last_tick`, default the last tick stepped) would credit are kept aside in
        `ended` for the trainer's rewards pressed as the episode ended.
        """
        self.motor.stop()
        self.selector.reset()
        self._last = Decision(-1, -1, 0.0, How.DEFAULT)
        self._running_priority = -1
        if self.config.learning.clear_stm_each_episode:
            self.ended_tick = self._tick if last_tick is None else last_tick
            self.ended = self.kept(self.ended_tick)
            self.stm.clear()
        if self.kp is not None:
            self.kp.reset_episode()

    def kept(self, last_tick: int) -> ShortTermMemory:
        """STM's records a reward seen at `last_tick` could credit (paused: to that tick)."""
        first, last = last_tick - self.window.hi_ticks, last_tick
        kept = ShortTermMemory(self.window.hi_ticks + 1)
        for r in self.stm:
            if first <= r[0] <= last:
                kept.push(r)
        return kept

    def answer(self, stimulus: int) -> int:
        """The behaviour the network releases for `stimulus` perceived alone (-1: none).

        What the robot has learned (or was given) for a stimulus, read without running it:
        the competition among the stimulus's own associations over the threshold, with no
        exploration.
        """
        decision = self.selector.released([stimulus])
        released = decision.how is How.RELEASED and decision.stimulus == stimulus
        return decision.behaviour if released else -1

    def _add_behaviour(self, behaviour: Behaviour) -> Behaviour:
        """Make a synthesised behaviour part of the catalogue and runnable."""
        self.catalog = self.catalog.with_behaviour(behaviour)
        added = self.catalog.behaviours[-1]
        self.motor.add_behaviour(added)
        return added

    def stimuli(self, channels: list[float]) -> list[int]:
        """The active stimuli for a channel vector (sensor and perception modules)."""
        active = self.detect(channels)
        if self._filter:
            active = self.perception.filter(active)
        return active

    def step(
        self, tick: int, channels: list[float], command: int = -1
    ) -> tuple[list[int], MotorCommand]:
        """One tick of Fig. 6: sense, perceive, match, select, motor, record to STM.

        `command`, when >= 0 and no primitive is running, is the behaviour an external
        learner chose; it is recorded against the most salient stimulus.
        Returns the active stimuli and the wheel command; the decision is `last`.
        """
        active = self.detect(channels)
        if self._filter:
            active = self.perception.filter(active)
        motor = self.motor
        last = self._last
        if command >= 0 and not motor.busy:
            decision = Decision(command, self.selector.focus(active), 0.0, How.COMMANDED, COMMANDED)
            self._start(decision, channels)
        elif motor.busy:
            top = max((self._priority[s] for s in active), default=-1)
            decision = last
            if top > self._running_priority:
                d = self.selector.select(active, last.behaviour)
                if (
                    d.how is not How.DEFAULT  # keeping moving never interrupts a response
                    and d.stimulus >= 0
                    and self._priority[d.stimulus] > self._running_priority
                ):
                    decision = d
            if decision is last:
                decision = Decision(
                    last.behaviour, last.stimulus, last.value, How.CONTINUED, last.origin
                )
            else:
                self._start(decision, channels)
        else:
            decision = self.selector.select(active, last.behaviour)
            self._start(decision, channels)
        self._last = decision
        wheels = motor.command(channels)
        if self.kp is not None:
            self.kp.percept(tick, active, decision)
        if decision.stimulus >= 0:
            self.stm.push((tick, decision.stimulus, decision.behaviour))
        self._tick = tick
        return active, wheels

    def _start(self, decision: Decision, channels: list[float]) -> None:
        self.motor.start(decision.behaviour, channels)
        s = decision.stimulus
        self._running_priority = self._priority[s] if s >= 0 else -1

    def reward(
        self,
        reward_tick: int,
        value: float,
        tick_seen: int | None = None,
        window: tuple[int, int] | None = None,
        records: Sequence[tuple[int, int, int]] | None = None,
    ) -> RewardOutcome:
        """Fig. 3 part 2: pop STM, update LTM by Eq. (1), insert strong pairs in the network.

        The reward arrives at the boundary before tick `reward_tick`. Without `tick_seen`
        it credits the STM records of earlier ticks, each at
        ``d_k = reward_tick - record tick`` (the paper's rule). With it, a person's
        reward credits the reaction window before the tick they saw (`credit_seen`;
        `window`, its first and last tick, as the reward arrived: by default the brain's
        `window` before `tick_seen`): from STM, or from the ended episode's last records
        when the seen tick lies in that episode and the reward comes at most the window's
        `hi_ticks` after its end (later, from nothing), or from `records`, a stored
        episode's (feedback on its replay).
        """
        memory = self.stm
        if tick_seen is None:
            window = None
        else:
            window = window or self.window.span(tick_seen)
            if records is None:
                memory = self._seen_memory(tick_seen, reward_tick)
            else:
                memory = ShortTermMemory(max(1, len(records)))
                for r in records:
                    memory.push(r)
        if not self.config.learning.enabled:
            memory.pop_before(reward_tick if window is None else window[1] + 1)
            if self.kp is not None:
                self.kp.reset_episode()
            return RewardOutcome((), (), (), window)
        if window is None:
            credits = self.ltm.apply(memory.pop_before(reward_tick), reward_tick, value)
        else:
            credits = credit_seen(memory, self.ltm, value, window)
        if value < 0.0 and credits and credits[0].d_k == 1 and memory is self.stm:
            self.selector.retry(credits[0].stimulus)
        threshold = self.config.learning.insert_threshold
        learnable = self.learnable
        changes: list[AssociationPromoted | AssociationDemoted] = []
        for s, b in dict.fromkeys((c.stimulus, c.behaviour) for c in credits):
            if s not in learnable:
                continue  # LTM keeps its reliability; only learnable stimuli are promoted
            v = self.ltm.reliability(s, b)
            old = self.network.get(s, b)
            if v >= threshold:
                if self.network.learn(s, b, v, "learned") and old is None:
                    changes.append(AssociationPromoted(s, b, v, "learned"))
            elif old is not None and old.source == "learned" and not old.locked:
                self.network.remove(s, b)
                changes.append(AssociationDemoted(s, b, v))
        propagated: list[Propagated] = []
        if self.kp is not None:
            propagated, promoted = self.kp.reward(value)
            changes.extend(promoted)
        return RewardOutcome(tuple(credits), tuple(changes), tuple(propagated), window)

    def _seen_memory(self, tick_seen: int, reward_tick: int) -> ShortTermMemory:
        """The records a reward seen at `tick_seen`, arriving before `reward_tick`, credits."""
        if tick_seen > self.ended_tick:
            return self.stm
        if reward_tick - 1 - self.ended_tick > self.window.hi_ticks:
            self.ended = ShortTermMemory(1)  # the window has passed: the records go
        return self.ended

    def episode_failed(self) -> RewardOutcome:
        """An episode failed: KP's RLTM is punished by `KpConfig.failure_penalty`.

        Nothing happens with no KP module, learning off or no penalty (the default): then
        a failure teaches nothing, as the paper's delayed reward has it. LTM and STM are
        left alone; the punishment is KP's own (`KnowledgePropagation.punish`).
        """
        kp = self.kp
        if kp is None or not self.config.learning.enabled or kp.config.failure_penalty <= 0.0:
            return RewardOutcome((), ())
        propagated, changes = kp.punish(kp.config.failure_penalty)
        return RewardOutcome((), tuple(changes), tuple(propagated))
