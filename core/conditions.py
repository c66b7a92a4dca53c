"""The experimental conditions: which knowledge the robot starts with and how it learns."""

from __future__ import annotations

from dataclasses import dataclass

from core.brain.brain import BrainConfig, LearningConfig
from core.brain.selection import SelectionConfig
from core.errors import UnknownNameError


@dataclass(frozen=True, slots=True)
class Condition:
    """One condition of the paper's comparison.

    Attributes:
        name: its name on the command line.
        description: one line for people.
        network: the knowledge set the behaviour network starts from.
        learning: whether rewards update LTM and the network.
        epsilon: exploration rate of the learnable stimuli.
        success_reward: the delayed reward a successful lap gives (None: none).
        learnable_sensors: the logical sensors whose stimuli are explored and learned.
    """

    name: str
    description: str
    network: str
    learning: bool = False
    epsilon: float = 0.0
    success_reward: float | None = None
    learnable_sensors: tuple[str, ...] = ("signal", "camera_obstacle")

    def brain_config(self, eta: float = 0.1) -> BrainConfig:
        """The brain parameters of this condition."""
        return BrainConfig(
            selection=SelectionConfig(epsilon=self.epsilon if self.learning else 0.0),
            learning=LearningConfig(
                enabled=self.learning, eta=eta, learnable_sensors=self.learnable_sensors
            ),
        )


CONDITIONS: dict[str, Condition] = {
    c.name: c
    for c in (
        Condition(
            "innate",
            "Table I's innate knowledge only, no learning (the paper's Table II).",
            network="innate",
        ),
        Condition(
            "delayed",
            "Innate knowledge, learning from the delayed reward of a successful lap only.",
            network="innate",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
        ),
        Condition(
            "expert",
            "A hand-designed correct response to every stimulus, no learning.",
            network="expert",
        ),
    )
}


def get_condition(name: str) -> Condition:
    """The condition called `name`."""
    try:
        return CONDITIONS[name]
    except KeyError:
        known = ", ".join(CONDITIONS)
        raise UnknownNameError(f"unknown condition {name!r} (known: {known})") from None
