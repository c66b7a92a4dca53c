"""Learning parameters a run, an experiment or a sweep may set, validated in one place.

The brain's conditions take the runs API's learning parameters (eta, epsilon, synthesize)
and a few more of the memory, selection and KP modules; the Q(lambda) baseline takes its
own; a condition with a reinforcement program takes its teacher's imperfections
(``teacher_mistake``..., `core.run.trainer.Imperfections`). Each parameter says which conditions
it applies to, so a sweep over `eta` runs the Q(lambda) condition once instead of once per
value.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from functools import cache
from typing import Any, Literal

from core.brain.brain import BrainConfig
from core.brain.catalog import data_dir
from core.errors import CatalogError, CoreError, UnknownNameError
from core.run.conditions import Condition, get_condition
from core.run.trainer import MAX_DELAY_CV, MAX_DELAY_S, Imperfections


@dataclass(frozen=True, slots=True)
class QLambdaConfig:
    """Hyper-parameters of Watkins Q(lambda).

    The defaults are the best of the sweep `srlab qlambda-sweep` runs (alpha x lambda x
    epsilon on seeds the experiments do not use); see the README.

    Attributes:
        alpha: step size.
        gamma: discount per decision.
        lam: trace decay (lambda).
        epsilon: exploration rate of the epsilon-greedy behaviour policy.
        prior: the knowledge set the robot keeps as built-in behaviour (the KP condition's
            design by default, so Q(lambda) and KP start from the same knowledge).
        defer: give the learner the environment's "defer" action (let the built-in
            behaviour answer), preferred while nothing is learned (see `defer_prior`).
        defer_prior: the initial value of "defer" in every state, above the 0 of every
            other action: the learner starts by doing what the robot already does, and
            overrides it only where it has learned better.
        per_encounter: draw exploration once per encounter (a stimulus becoming the open
            one), as the architecture does, and keep the choice while the same stimulus
            stays open; otherwise at every decision.
        epsilon_half_life: episodes over which the exploration rate halves
            (`epsilon_at`); 0 (the default) keeps it at `epsilon` for ever.
    """

    alpha: float = 0.3
    gamma: float = 0.99
    lam: float = 0.5
    epsilon: float = 0.1
    prior: str = "kp"
    defer: bool = False
    defer_prior: float = 1e-3
    per_encounter: bool = False
    epsilon_half_life: float = 0.0

    def __post_init__(self) -> None:
        for name in ("alpha", "gamma", "lam", "epsilon"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in [0, 1]")
        if not (math.isfinite(self.epsilon_half_life) and self.epsilon_half_life >= 0.0):
            raise ValueError("epsilon_half_life must be 0 or more")


ParamValue = float | int | bool
Params = tuple[tuple[str, ParamValue], ...]
"""Parameter settings as sorted (name, value) pairs: hashable, so tasks can be compared."""


def point_label(point: Mapping[str, ParamValue]) -> str:
    """``eta=0.1 epsilon=0.05``."""
    return " ".join(f"{n}={format_value(v)}" for n, v in point.items())


def format_value(v: ParamValue) -> str:
    """A parameter value as people write it."""
    if isinstance(v, bool):
        return "true" if v else "false"
    return f"{v:g}"


class ParameterError(CoreError):
    """A learning parameter's name or value is not acceptable."""


def _learns(c: Condition) -> bool:
    return c.agent == "brain" and c.learning


def _explores(c: Condition) -> bool:
    return c.learning and c.agent != "ppo"  # PPO explores by its stochastic policy


def _brain(c: Condition) -> bool:
    return c.agent == "brain"


def _kp(c: Condition) -> bool:
    return c.agent == "brain" and c.kp


def _taught(c: Condition) -> bool:
    return c.agent == "brain" and c.learning and c.trainer is not None


def _qlambda(c: Condition) -> bool:
    return c.agent == "qlambda"


def _td(c: Condition) -> bool:
    return c.agent in ("qlambda", "dqn", "ppo")


def _deep(c: Condition) -> bool:
    return c.agent in ("dqn", "ppo")


def _dqn(c: Condition) -> bool:
    return c.agent == "dqn"


def _ppo(c: Condition) -> bool:
    return c.agent == "ppo"


@dataclass(frozen=True, slots=True)
class Parameter:
    """One settable learning parameter.

    Attributes:
        name: its name on the command line and in reports.
        description: one line for people.
        kind: ``float``, ``int`` or ``bool``.
        low: the smallest value allowed (numbers only).
        high: the largest value allowed (numbers only).
        closed_low: whether `low` itself is allowed.
        applies: whether a condition uses the parameter.
        scope: the conditions it applies to, in words.
    """

    name: str
    description: str
    kind: Literal["float", "int", "bool"]
    low: float
    high: float
    closed_low: bool
    applies: Callable[[Condition], bool]
    scope: str

    def parse(self, text: str) -> ParamValue:
        """One value from its text, checked against the bounds."""
        t = text.strip()
        if self.kind == "bool":
            lowered = t.lower()
            if lowered in ("true", "yes", "1"):
                return True
            if lowered in ("false", "no", "0"):
                return False
            raise ParameterError(f"{self.name}: {text!r} is not true or false")
        try:
            value: float = int(t) if self.kind == "int" else float(t)
        except ValueError:
            kind = "whole number" if self.kind == "int" else "number"
            raise ParameterError(f"{self.name}: {text!r} is not a {kind}") from None
        return self.check(value)

    def check(self, value: ParamValue) -> ParamValue:
        """`value` if it is of the right kind and within bounds, else a ParameterError."""
        if self.kind == "bool":
            if not isinstance(value, bool):
                raise ParameterError(f"{self.name} must be true or false, got {value!r}")
            return value
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ParameterError(f"{self.name} must be a number, got {value!r}")
        if self.kind == "int" and value != int(value):
            raise ParameterError(f"{self.name} must be a whole number, got {value!r}")
        if (
            not math.isfinite(value)
            or value > self.high
            or value < self.low
            or (value == self.low and not self.closed_low)
        ):
            raise ParameterError(f"{self.name} must be in {self.bounds}, got {value!r}")
        return int(value) if self.kind == "int" else float(value)

    @property
    def bounds(self) -> str:
        """The allowed values, as text."""
        if self.kind == "bool":
            return "true or false"
        low = f"{self.low:g}" if self.kind == "float" else str(int(self.low))
        high = f"{self.high:g}" if self.kind == "float" else str(int(self.high))
        return f"{'[' if self.closed_low else '('}{low}, {high}]"


PARAMETERS: dict[str, Parameter] = {
    p.name: p
    for p in (
        Parameter(
            "eta",
            "Eq. (1)'s learning rate, of LTM and of KP's RLTM (default 0.1)",
            "float", 0.0, 1.0, True, _learns, "the brain's learning conditions",
        ),
        Parameter(
            "epsilon",
            "exploration rate (default 0.1)",
            "float", 0.0, 1.0, True, _explores, "every learning condition but ppo",
        ),
        Parameter(
            "threshold",
            "a behaviour value must reach this to compete in selection (default 0.25)",
            "float", 0.0, 1.0, True, _brain, "every condition but qlambda",
        ),
        Parameter(
            "insert_threshold",
            "a pair this reliable joins the behaviour network, in LTM and RLTM (default 0.5)",
            "float", 0.0, 1.0, False, _learns, "the brain's learning conditions",
        ),
        Parameter(
            "kp_window",
            "ticks after a camera stimulus in which sonar responses are propagated (default 20)",
            "int", 1.0, 1000.0, True, _kp, "kp",
        ),
        Parameter(
            "synthesize",
            "KP keeps a new behaviour instead of snapping to a primitive (default false)",
            "bool", 0.0, 1.0, True, _kp, "kp",
        ),
        Parameter(
            "kp_failure_penalty",
            "a failed episode punishes KP's RLTM by this reward's size (default 0: never)",
            "float", 0.0, 1.0, True, _kp, "kp",
        ),
        Parameter(
            "teacher_mistake",
            "probability a teacher's judgement has the wrong sign (default 0)",
            "float", 0.0, 1.0, True, _taught, "rp",
        ),
        Parameter(
            "teacher_skip",
            "probability a teacher gives no judgement (default 0)",
            "float", 0.0, 1.0, True, _taught, "rp",
        ),
        Parameter(
            "teacher_delay_s",
            "a teacher's mean reaction delay in seconds (default 0)",
            "float", 0.0, MAX_DELAY_S, True, _taught, "rp",
        ),
        Parameter(
            "teacher_delay_cv",
            "the spread of the delay, its coefficient of variation (default 0.7; 0: fixed)",
            "float", 0.0, MAX_DELAY_CV, True, _taught, "rp",
        ),
        Parameter(
            "teacher_bias",
            "probability a deserved penalty is given as a reward (default 0)",
            "float", 0.0, 1.0, True, _taught, "rp",
        ),
        Parameter(
            "teacher_fatigue",
            "share of a teacher's feedback rate lost per episode (default 0)",
            "float", 0.0, 1.0, True, _taught, "rp",
        ),
        Parameter(
            "alpha",
            "Q(lambda)'s step size (default 0.3)",
            "float", 0.0, 1.0, True, _qlambda, "qlambda",
        ),
        Parameter(
            "gamma",
            "discount per decision of Q(lambda), DQN and PPO (default 0.99)",
            "float", 0.0, 1.0, True, _td, "qlambda, dqn, ppo",
        ),
        Parameter(
            "lambda",
            "Q(lambda)'s trace decay (default 0.5)",
            "float", 0.0, 1.0, True, _qlambda, "qlambda",
        ),
        Parameter(
            "epsilon_half_life",
            "episodes over which Q(lambda)'s exploration rate halves (default 0: constant)",
            "float", 0.0, 1e6, True, _qlambda, "qlambda",
        ),
        Parameter(
            "learning_rate",
            "Adam's step size of DQN and PPO (default 5e-4)",
            "float", 0.0, 1.0, False, _deep, "dqn, ppo",
        ),
        Parameter(
            "target_update_interval",
            "decisions between DQN's target network copies (default 250)",
            "int", 1.0, 1e6, True, _dqn, "dqn",
        ),
        Parameter(
            "n_steps",
            "PPO's rollout length, in decisions (default 256)",
            "int", 2.0, 1e5, True, _ppo, "ppo",
        ),
        Parameter(
            "ent_coef",
            "PPO's entropy bonus (default 0.01)",
            "float", 0.0, 1.0, True, _ppo, "ppo",
        ),
    )
}  # fmt: skip


def get_parameter(name: str) -> Parameter:
    """The parameter called `name`."""
    try:
        return PARAMETERS[name]
    except KeyError:
        known = ", ".join(PARAMETERS)
        raise UnknownNameError(f"unknown parameter {name!r} (known: {known})") from None


def normalise(params: Mapping[str, ParamValue]) -> Params:
    """`params` checked and sorted into the hashable form tasks carry."""
    return tuple(sorted((n, get_parameter(n).check(v)) for n, v in params.items()))


def applicable(condition: Condition, params: Mapping[str, ParamValue]) -> Params:
    """The settings of `params` that `condition` uses, in the hashable form."""
    return normalise({n: v for n, v in params.items() if get_parameter(n).applies(condition)})


def _unused(condition: Condition, params: Mapping[str, ParamValue]) -> None:
    unused = [n for n in params if not get_parameter(n).applies(condition)]
    if unused:
        raise ParameterError(
            f"condition {condition.name!r} does not use {', '.join(sorted(unused))}"
        )


def configure(
    condition: Condition, params: Mapping[str, ParamValue] | Params = ()
) -> tuple[Condition, BrainConfig]:
    """The condition and brain configuration of the paper's architecture with `params` set.

    With no parameters this is exactly ``(condition, condition.brain_config())``.
    """
    values = dict(params)
    normalise(values)
    _unused(condition, values)
    if "epsilon" in values:
        condition = replace(condition, epsilon=float(values["epsilon"]))
    config = condition.brain_config(
        eta=float(values.get("eta", 0.1)), synthesize=bool(values.get("synthesize", False))
    )
    if "threshold" in values:
        config = replace(
            config, selection=replace(config.selection, threshold=float(values["threshold"]))
        )
    if "insert_threshold" in values:
        level = float(values["insert_threshold"])
        config = replace(
            config,
            learning=replace(config.learning, insert_threshold=level),
            kp=replace(config.kp, insert_threshold=level),
        )
    if "kp_window" in values:
        config = replace(config, kp=replace(config.kp, window_ticks=int(values["kp_window"])))
    if "kp_failure_penalty" in values:
        penalty = float(values["kp_failure_penalty"])
        config = replace(config, kp=replace(config.kp, failure_penalty=penalty))
    teacher = {
        n.removeprefix(TEACHER_PREFIX): float(v)
        for n, v in values.items()
        if n.startswith(TEACHER_PREFIX)
    }
    if teacher:
        condition = replace(condition, teacher=replace(condition.teacher, **teacher))
    return condition, config


TEACHER_PREFIX = "teacher_"
"""The teacher's imperfections as parameters: ``teacher_`` and the imperfection's name."""


def teacher_params(teacher: Imperfections) -> dict[str, ParamValue]:
    """A teacher's imperfections as the parameters that set them (none for the perfect one)."""
    return {f"{TEACHER_PREFIX}{n}": v for n, v in teacher.changed().items()}


def qlambda_config(
    condition: Condition, params: Mapping[str, ParamValue] | Params = ()
) -> QLambdaConfig:
    """Q(lambda)'s hyper-parameters with `params` set (its defaults otherwise)."""
    # Imported here: the engine uses this module and needs neither Q(lambda) nor Gymnasium.

    values = dict(params)
    normalise(values)
    _unused(condition, values)
    base = QLambdaConfig()
    return QLambdaConfig(
        alpha=float(values.get("alpha", base.alpha)),
        gamma=float(values.get("gamma", base.gamma)),
        lam=float(values.get("lambda", base.lam)),
        epsilon=float(values.get("epsilon", condition.epsilon)),
        prior=condition.network,
        defer=condition.hybrid,
        per_encounter=condition.hybrid,
        epsilon_half_life=float(values.get("epsilon_half_life", condition.epsilon_half_life)),
    )


def baseline_params(
    condition: Condition, params: Mapping[str, ParamValue] | Params = ()
) -> dict[str, float]:
    """A deep baseline's `core.learners.baselines.BaselineConfig` fields with `params` set.

    The condition's exploration rate is DQN's epsilon unless `params` sets it.
    """
    values = dict(params)
    normalise(values)
    _unused(condition, values)
    out = {n: float(v) for n, v in values.items()}
    if condition.agent == "dqn":
        out.setdefault("epsilon", condition.epsilon)
    return out


@cache
def tuned() -> dict[str, Params]:
    """The tuned parameters per condition, from `core/data/tuned.toml` (see `core.lab.tune`).

    Empty when nothing was tuned.
    """
    path = data_dir() / "tuned.toml"
    if not path.is_file():
        return {}
    try:
        with path.open("rb") as f:
            raw: dict[str, Any] = tomllib.load(f)
    except tomllib.TOMLDecodeError as e:
        raise CatalogError(f"{path}: {e}") from e
    out = {}
    for c, values in raw.items():
        get_condition(c)
        out[c] = normalise(values)
    return out


def tuned_params(condition: str) -> Params:
    """The tuned parameters of `condition` (none when it was not tuned)."""
    return tuned().get(condition, ())
