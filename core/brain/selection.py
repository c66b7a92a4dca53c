"""The behaviour selection module: releasers, internal desires, competition, exploration."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import NamedTuple

import numpy as np

from core.brain.catalog import SOURCES, Catalog
from core.brain.network import BehaviourNetwork
from core.brain.perception import Perception


class Strategy(StrEnum):
    """How the behaviour to run is chosen among the released ones."""

    COMPETITION = "competition"
    """The paper's choice: behaviours over a threshold compete and the strongest wins; the
    incumbent gets a small self-excitation (hysteresis) against rivals of its own or a lower
    priority layer."""
    MAX = "max"
    """The maximum behaviour value wins, threshold or not."""
    PRIORITY = "priority"
    """Subsumption: the highest-priority layer with a released behaviour wins."""


class How(StrEnum):
    """Where a decision came from."""

    RELEASED = "released"
    DEFAULT = "default"
    EXPLORED = "explored"
    CONTINUED = "continued"
    COMMANDED = "commanded"
    """Chosen from outside the brain: an external learner (the Gymnasium environment)."""


_RETRY = -2

EXPLORED, DEFAULT, COMMANDED = "explored", "default", "commanded"
ORIGINS: tuple[str, ...] = (*SOURCES, EXPLORED, DEFAULT, COMMANDED)
"""What can make a behaviour run: an association's source (innate, dp, learned, kp, expert,
designed), exploration, the keep-moving default, or an external learner's command."""

DEFAULT_DESIRES: Mapping[str, float] = {
    "avoid_collision": 1.0,
    "avoid_wall": 1.0,
    "avoid_obstacle": 1.0,
    "obey_signal": 1.0,
    "follow_track": 0.4,
    "keep_moving": 0.3,
}
"""Internal desire per objective. The urgent objectives (collision, wall, obstacle, signal)
are at 1. Following the track is a background desire below the insertion threshold (0.5):
any response to an urgent stimulus confident enough to have joined the behaviour network
outbids the position layer, whose stimuli (Left, Middle, Right) are active on every tick.
Keeping moving, the default behaviour's desire, is below everything released."""


@dataclass(frozen=True, slots=True)
class SelectionConfig:
    """Parameters of behaviour selection.

    Attributes:
        strategy: competition (default), max or priority.
        threshold: a behaviour value must reach this to compete.
        hysteresis: bonus of the incumbent behaviour in a competition.
        epsilon: probability, per encounter with an active learnable stimulus that has no
            confident association, of trying a random behaviour for it. The trial lasts as
            long as the stimulus does, so a try is a whole response, not a one-tick twitch.
        confident: an association this strong stops exploration of its stimulus.
        default_behaviour: what the keep-moving desire runs when nothing is released.
        desires: internal desire level per objective; a releaser's value is the stimulus
            strength x association strength x the desire of the stimulus' objective.
    """

    strategy: Strategy = Strategy.COMPETITION
    threshold: float = 0.25
    hysteresis: float = 0.05
    epsilon: float = 0.0
    confident: float = 0.8
    default_behaviour: str = "goforward3"
    desires: Mapping[str, float] = field(default_factory=lambda: dict(DEFAULT_DESIRES))

    def __post_init__(self) -> None:
        if not 0.0 <= self.epsilon <= 1.0:
            raise ValueError("epsilon must be in [0, 1]")
        if not 0.0 <= self.threshold <= 1.0:
            raise ValueError("threshold must be in [0, 1]")


class Decision(NamedTuple):
    """The behaviour chosen for a tick and the stimulus credited with it (-1: none).

    `origin` says what made it run: the releasing association's source, ``explored``,
    ``default`` or ``commanded`` (see `ORIGINS`); a continued primitive keeps its origin.
    A default decision's stimulus is the open learnable stimulus it answers (or -1).
    """

    behaviour: int
    stimulus: int
    value: float
    how: How
    origin: str = DEFAULT


class Selector:
    """Releasers + desires + a selection strategy + epsilon-greedy exploration."""

    def __init__(
        self,
        catalog: Catalog,
        network: BehaviourNetwork,
        perception: Perception,
        config: SelectionConfig,
        learnable: frozenset[int],
        rng: np.random.Generator,
    ) -> None:
        self.network = network
        self.config = config
        self._strength = perception.strength
        desires = dict(DEFAULT_DESIRES)
        desires.update(config.desires)
        self._gain = tuple(
            s_strength * desires.get(s.objective, 1.0)
            for s, s_strength in zip(catalog.stimuli, perception.strength, strict=True)
        )
        self._priority = tuple(s.priority for s in catalog.stimuli)
        self._default = catalog.behaviour(config.default_behaviour).id
        self._default_value = desires.get("keep_moving", 0.3)
        self._n_behaviours = len(catalog.behaviours)
        self._learnable = learnable
        self._rng = rng
        self._random = rng.random
        self._trials: dict[int, int] = {}
        """Learnable stimuli met in the current encounter -> behaviour tried (-1: none)."""

    @property
    def rng(self) -> np.random.Generator:
        """The generator exploration draws from."""
        return self._rng

    @property
    def priority(self) -> tuple[int, ...]:
        """Priority layer of each stimulus."""
        return self._priority

    def values(self, active: list[int]) -> dict[int, tuple[float, int]]:
        """Each released behaviour's value and the stimulus releasing it most."""
        gain = self._gain
        out: dict[int, tuple[float, int]] = {}
        for s in active:
            g = gain[s]
            for a in self.network.releasers(s):
                v = g * a.strength
                cur = out.get(a.behaviour)
                if cur is None or v > cur[0]:
                    out[a.behaviour] = (v, s)
        return out

    def select(self, active: list[int], incumbent: int) -> Decision:
        """Choose this tick's behaviour from the active stimuli."""
        cfg = self.config
        values = self.values(active)
        decision = self._choose(values, active, incumbent)
        if cfg.epsilon > 0.0 and self._learnable:
            decision = self._explore(decision, active)
        return decision

    def _choose(
        self, values: dict[int, tuple[float, int]], active: list[int], incumbent: int
    ) -> Decision:
        cfg = self.config
        prio = self._priority
        best_b = -1
        best_key: tuple[float, ...] = ()
        if cfg.strategy is Strategy.PRIORITY:
            for b, (v, s) in values.items():
                key: tuple[float, ...] = (prio[s], v, -b)
                if v > 0.0 and key > best_key:
                    best_b, best_key = b, key
        else:
            threshold = cfg.threshold if cfg.strategy is Strategy.COMPETITION else 0.0
            for b, (v, s) in values.items():
                if v < threshold or v <= 0.0:
                    continue
                key = (v, prio[s], -b)
                if key > best_key:
                    best_b, best_key = b, key
            if (
                cfg.strategy is Strategy.COMPETITION
                and best_b >= 0
                and incumbent != best_b
                and incumbent in values
            ):
                # The incumbent's self-excitation keeps it against a slightly stronger rival
                # of its own or a lower layer, never against a higher layer's response.
                v_inc, s_inc = values[incumbent]
                v_best, s_best = values[best_b]
                if (
                    v_inc >= threshold
                    and v_inc + cfg.hysteresis >= v_best
                    and prio[s_inc] >= prio[s_best]
                ):
                    best_b = incumbent
        if best_b >= 0:
            v, s = values[best_b]
            association = self.network.get(s, best_b)
            assert association is not None
            return Decision(best_b, s, v, How.RELEASED, association.source)
        return Decision(self._default, self.open_default(active), self._default_value, How.DEFAULT)

    def open_default(self, active: list[int]) -> int:
        """The stimulus a default decision answers: the most salient learnable one, or -1.

        Nothing was released, so whatever runs is the robot's response to the new stimuli
        it perceives: the paper's "arbitrary behavior to respond to a new stimulus", recorded
        in STM. Stimuli that are not learnable (the position layer, active on every tick) are
        never credited with the keep-moving default, which no releaser of theirs chose.
        """
        prio = self._priority
        learnable = self._learnable
        target = -1
        for s in active:
            if s in learnable and (target < 0 or prio[s] > prio[target]):
                target = s
        return target

    def released(self, active: list[int]) -> Decision:
        """What the competition alone would release for `active`.

        No exploration and no incumbent; a default decision when nothing is released.
        """
        return self._choose(self.values(active), active, -1)

    def open_stimulus(self, active: list[int], learnable: frozenset[int]) -> int:
        """The most salient active stimulus of `learnable` that nothing answers, or -1.

        "Nothing answers" means no response of its own or a higher priority layer would be
        released (default behaviours do not count): it is the stimulus a learner must
        answer.
        """
        prio = self._priority
        target = -1
        for s in active:
            if s in learnable and (target < 0 or prio[s] > prio[target]):
                target = s
        if target < 0:
            return -1
        decision = self.released(active)
        if decision.how is How.RELEASED and prio[decision.stimulus] >= prio[target]:
            return -1
        return target

    def focus(self, active: list[int]) -> int:
        """The most salient active stimulus (highest priority, then lowest id), or -1."""
        prio = self._priority
        best = -1
        for s in active:
            if best < 0 or prio[s] > prio[best]:
                best = s
        return best

    def reset(self) -> None:
        """Forget the current encounters (a new episode)."""
        self._trials.clear()

    def retry(self, stimulus: int) -> None:
        """After a punishment: the next response to `stimulus` is a random try.

        Operant conditioning's trial and error: a "bad" from a trainer makes the robot try
        something else for the stimulus it is facing, instead of waiting for epsilon.
        """
        if stimulus in self._learnable and self.config.epsilon > 0.0:
            self._trials[stimulus] = _RETRY

    def _explore(self, decision: Decision, active: list[int]) -> Decision:
        trials = self._trials
        if trials:
            for s in [s for s in trials if s not in active]:
                del trials[s]
        learnable = self._learnable
        prio = self._priority
        confident = self.config.confident
        target = -1
        for s in active:
            if (
                s in learnable
                and self.network.strongest(s) < confident
                and (target < 0 or prio[s] > prio[target])
            ):
                target = s
        if target < 0:
            return decision
        if (
            decision.how is How.RELEASED
            and decision.stimulus != target
            and prio[decision.stimulus] >= prio[target]
        ):
            return decision  # never explore over another response of the same or a higher layer
        tried = trials.get(target)
        if tried is None or tried == _RETRY:
            if tried == _RETRY or self._random() < self.config.epsilon:
                tried = int(self._rng.integers(self._n_behaviours))
            else:
                tried = -1
            trials[target] = tried
        if tried < 0:
            return decision
        return Decision(tried, target, 0.0, How.EXPLORED, EXPLORED)
