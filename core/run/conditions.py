"""The experimental conditions: which knowledge the robot starts with and how it learns."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

from core.brain.brain import BrainConfig, LearningConfig
from core.brain.propagation import KpConfig
from core.brain.selection import SelectionConfig
from core.errors import UnknownNameError
from core.run.trainer import PERFECT, Imperfections


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
        trainer: the reinforcement program that rewards responses at once (None: none).
        teacher: how the program's judgements are given (`core.run.trainer.Imperfections`): the
            perfect teacher, at once and always right, unless set (the teacher_*
            parameters, `srlab experiment --teacher`).
        kp: whether knowledge propagation runs.
        agent: ``brain`` (the paper's architecture), ``qlambda`` (the tabular baseline), or
            ``dqn`` / ``ppo`` (stable-baselines3's, the ``srlab[baselines]`` extra).
        extra_networks: knowledge sets added on top of `network` (the signal's responses
            when they are given, see `core.run.setup.Setup`).
        hybrid: for an outside learner (``agent`` other than ``brain``): it may defer to the
            built-in behaviour, starts by deferring, and explores per encounter, so the
            designed reflexes it starts from are kept until it has learned better.
        interactive: meant for a person giving rewards at the keyboard (the runs API):
            not one of the experiments' conditions, so never tuned or compared.
        kp_failure_penalty: with `kp`, the punishment a failed episode gives KP's RLTM
            (`core.brain.propagation.KpConfig.failure_penalty`; 0: none).
        epsilon_half_life: for Q(lambda), episodes over which `epsilon` halves
            (`core.learners.qlambda.epsilon_at`; 0: it stays constant).
    """

    name: str
    description: str
    network: str
    learning: bool = False
    epsilon: float = 0.0
    success_reward: float | None = None
    learnable_sensors: tuple[str, ...] = ("signal", "camera_obstacle")
    trainer: str | None = None
    teacher: Imperfections = PERFECT
    kp: bool = False
    agent: str = "brain"
    extra_networks: tuple[str, ...] = ()
    hybrid: bool = False
    interactive: bool = False
    kp_failure_penalty: float = 0.0
    epsilon_half_life: float = 0.0

    def brain_config(self, eta: float = 0.1, synthesize: bool = False) -> BrainConfig:
        """The brain parameters of this condition."""
        return BrainConfig(
            selection=SelectionConfig(epsilon=self.epsilon if self.learning else 0.0),
            learning=LearningConfig(
                enabled=self.learning, eta=eta, learnable_sensors=self.learnable_sensors
            ),
            kp=KpConfig(
                enabled=self.kp,
                eta=eta,
                synthesize=synthesize,
                failure_penalty=self.kp_failure_penalty,
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
            "dp",
            "Direct programming: signal and six camera obstacle responses programmed and "
            "locked; R-L, R-M and R-R learned from the delayed reward.",
            network="dp",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
        ),
        Condition(
            "dp-rare",
            "Direct programming split as the paper split it: signal and the six left- and "
            "middle-lane camera obstacle responses programmed and locked; R-L, R-M and R-R "
            "learned from the delayed reward.",
            network="dp-rare",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
        ),
        Condition(
            "rp",
            "A reinforcement program rewards signal and camera obstacle responses at once "
            "(+1 acceptable, -1 not), plus the delayed reward.",
            network="innate",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
            trainer="rp",
        ),
        Condition(
            "trainer",
            "For a person at the keyboard: rp's start and learning, but no reinforcement "
            "program; the only rewards are the person's and the delayed one of a lap.",
            network="innate",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
            interactive=True,
        ),
        Condition(
            "kp",
            "Position and sonar S-R designed (Fig. 13); camera obstacle responses learned "
            "by knowledge propagation, the signal's from the delayed reward.",
            network="kp",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
            kp=True,
        ),
        Condition(
            "kp-punished",
            "The kp condition whose RLTM is also punished when an episode fails (a reward of "
            "-1 to what KP taught and would teach), so a wrong copy can be unlearned.",
            network="kp",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
            kp=True,
            kp_failure_penalty=1.0,
        ),
        Condition(
            "sonar",
            "The kp condition with propagation off (its ablation): the same design, camera "
            "and signal responses learned from the delayed reward alone.",
            network="kp",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
        ),
        Condition(
            "qlambda",
            "Tabular Watkins Q(lambda) on the same stimuli, behaviours and delayed reward, "
            "starting from the KP condition's design.",
            network="kp",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
            agent="qlambda",
        ),
        Condition(
            "qlambda-hybrid",
            "The designed reflexes kept (kp's design) and Q(lambda) learning only what no "
            "low-level sensor covers: it may defer to the built-in behaviour, starts by "
            "deferring, and explores per encounter.",
            network="kp",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
            agent="qlambda",
            hybrid=True,
        ),
        Condition(
            "qlambda-decay",
            "qlambda whose exploration decays: it starts at 0.2 and halves every "
            "epsilon_half_life episodes, so it stops exploring as KP does once confident.",
            network="kp",
            learning=True,
            epsilon=0.2,
            success_reward=1.0,
            agent="qlambda",
            epsilon_half_life=50.0,
        ),
        Condition(
            "qlambda-hybrid-decay",
            "qlambda-hybrid whose exploration decays as qlambda-decay's.",
            network="kp",
            learning=True,
            epsilon=0.2,
            success_reward=1.0,
            agent="qlambda",
            hybrid=True,
            epsilon_half_life=50.0,
        ),
        Condition(
            "dqn",
            "stable-baselines3's DQN on srlab/AmigoTrack-v0 (the srlab[baselines] extra): "
            "kp's design kept, DQN answering what it leaves open, free to defer to it, from "
            "the same delayed reward.",
            network="kp",
            learning=True,
            epsilon=0.1,
            success_reward=1.0,
            agent="dqn",
            hybrid=True,
        ),
        Condition(
            "ppo",
            "stable-baselines3's PPO on srlab/AmigoTrack-v0 (the srlab[baselines] extra), "
            "as dqn: kp's design kept, free to defer to it, the same delayed reward.",
            network="kp",
            learning=True,
            success_reward=1.0,
            agent="ppo",
            hybrid=True,
        ),
        Condition(
            "expert",
            "A hand-designed correct response to every stimulus, no learning.",
            network="expert",
        ),
        Condition(
            "reflexes",
            "The kp condition's design (lane keeping and sonar obstacle responses) alone, "
            "no learning: what the low-level reflexes do by themselves.",
            network="kp",
        ),
        Condition(
            "unaware",
            "Table I plus lane keeping, no obstacle knowledge at all, no learning.",
            network="position",
        ),
    )
}


Start = Literal["", "table1", "design"]
"""What a condition's robot starts from: its own start (""), Table I, or kp's design."""
STARTS: tuple[Start, ...] = ("table1", "design")
START_SETS: dict[str, str] = {"table1": "innate", "design": "kp"}
"""The knowledge set of each start: Table I, or kp's design (Table I, lane keeping, sonar)."""
PROGRAMMED_ON_TABLE_I = ("dp", "dp-rare")
"""Knowledge sets that program responses on top of Table I (the S-R editor's)."""


def with_start(condition: Condition, start: Start) -> Condition:
    """`condition` with its robot starting from `start` instead of its own knowledge.

    A condition starting from Table I or kp's design starts from the other when told; a
    DP condition keeps its programmed responses and puts them on top of the start. A
    condition whose knowledge is neither (the expert's, `unaware`'s) has no start to change.
    """
    if not start:
        return condition
    if start not in START_SETS:
        raise UnknownNameError(f"unknown start {start!r} (known: {', '.join(START_SETS)})")
    base = START_SETS[start]
    if condition.network in START_SETS.values():
        return replace(condition, network=base)
    if condition.network in PROGRAMMED_ON_TABLE_I:
        if base == START_SETS["table1"]:
            return condition
        extra = (condition.network, *condition.extra_networks)
        return replace(condition, network=base, extra_networks=extra)
    raise UnknownNameError(
        f"condition {condition.name!r} starts from {condition.network!r}, which a start "
        f"does not replace (a start replaces Table I and kp's design)"
    )


DEEP_AGENTS = ("dqn", "ppo")
"""The agents of the deep baselines (`core.learners.baselines`), which need the optional extra."""


def get_condition(name: str) -> Condition:
    """The condition called `name`."""
    try:
        return CONDITIONS[name]
    except KeyError:
        known = ", ".join(CONDITIONS)
        raise UnknownNameError(f"unknown condition {name!r} (known: {known})") from None
