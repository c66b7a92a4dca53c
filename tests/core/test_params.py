"""Learning parameters: names, bounds, which conditions use them, and what they configure."""

from __future__ import annotations

import math

import pytest

from core.errors import UnknownNameError
from core.lab.experiment import Task, run_task
from core.learners.qlambda import QLambdaConfig
from core.params import (
    PARAMETERS,
    ParameterError,
    applicable,
    configure,
    get_parameter,
    normalise,
    qlambda_config,
)
from core.run.conditions import CONDITIONS, get_condition
from core.run.trainer import IMPERFECTIONS


@pytest.mark.parametrize("name", sorted(CONDITIONS))
def test_no_parameters_configure_exactly_the_conditions_defaults(name: str) -> None:
    condition = get_condition(name)
    if condition.agent == "qlambda":
        hybrid = condition.hybrid  # defers to kp's design and explores per encounter
        assert qlambda_config(condition) == QLambdaConfig(
            epsilon=condition.epsilon,
            defer=hybrid,
            per_encounter=hybrid,
            epsilon_half_life=condition.epsilon_half_life,
        )
        assert condition.epsilon_half_life == 0.0 or condition.name.endswith("-decay")
    else:
        assert configure(condition) == (condition, condition.brain_config())


def test_each_brain_parameter_sets_its_field() -> None:
    kp = get_condition("kp")
    condition, config = configure(
        kp,
        {
            "eta": 0.3,
            "epsilon": 0.2,
            "threshold": 0.4,
            "insert_threshold": 0.7,
            "kp_window": 35,
            "synthesize": True,
            "kp_failure_penalty": 0.5,
        },
    )
    assert condition.epsilon == 0.2
    assert config.selection.epsilon == 0.2
    assert config.learning.eta == config.kp.eta == 0.3
    assert config.selection.threshold == 0.4
    assert config.learning.insert_threshold == config.kp.insert_threshold == 0.7
    assert config.kp.window_ticks == 35
    assert config.kp.synthesize is True
    assert config.kp.failure_penalty == 0.5
    default = kp.brain_config()
    assert default.kp.failure_penalty == 0.0, "a failure punishes nothing unless asked"
    assert config.selection.hysteresis == default.selection.hysteresis
    assert config.learning.stm_capacity == default.learning.stm_capacity


def test_each_qlambda_parameter_sets_its_field() -> None:
    config = qlambda_config(
        get_condition("qlambda"), {"alpha": 0.1, "gamma": 0.9, "lambda": 0.8, "epsilon": 0.05}
    )
    assert config == QLambdaConfig(alpha=0.1, gamma=0.9, lam=0.8, epsilon=0.05)


@pytest.mark.parametrize(
    ("condition", "uses"),
    [
        ("innate", {"threshold"}),
        ("expert", {"threshold"}),
        ("delayed", {"eta", "epsilon", "threshold", "insert_threshold"}),
        ("dp", {"eta", "epsilon", "threshold", "insert_threshold"}),
        (
            "rp",
            {"eta", "epsilon", "threshold", "insert_threshold"}
            | {f"teacher_{n}" for n in IMPERFECTIONS},
        ),
        ("trainer", {"eta", "epsilon", "threshold", "insert_threshold"}),
        (
            "kp",
            {"eta", "epsilon", "threshold", "insert_threshold", "kp_window", "synthesize"}
            | {"kp_failure_penalty"},
        ),
        ("qlambda", {"epsilon", "alpha", "gamma", "lambda", "epsilon_half_life"}),
    ],
)
def test_which_parameters_each_condition_uses(condition: str, uses: set[str]) -> None:
    c = get_condition(condition)
    assert {p.name for p in PARAMETERS.values() if p.applies(c)} == uses


def test_applicable_keeps_only_what_the_condition_uses_sorted() -> None:
    point = {"eta": 0.2, "epsilon": 0.05, "alpha": 0.5}
    assert applicable(get_condition("qlambda"), point) == (("alpha", 0.5), ("epsilon", 0.05))
    assert applicable(get_condition("kp"), point) == (("epsilon", 0.05), ("eta", 0.2))
    assert applicable(get_condition("innate"), point) == ()


def test_a_parameter_the_condition_does_not_use_is_refused() -> None:
    with pytest.raises(ParameterError, match="condition 'innate' does not use eta"):
        configure(get_condition("innate"), {"eta": 0.2})
    with pytest.raises(ParameterError, match="condition 'qlambda' does not use threshold"):
        qlambda_config(get_condition("qlambda"), {"threshold": 0.2})


def test_unknown_parameter_names_the_known_ones() -> None:
    with pytest.raises(UnknownNameError, match=r"unknown parameter 'etta' \(known: eta, epsilon"):
        get_parameter("etta")
    with pytest.raises(UnknownNameError, match="etta"):
        normalise({"etta": 0.1})


@pytest.mark.parametrize(
    ("name", "text", "value"),
    [
        ("eta", "0.05", 0.05),
        ("eta", "0", 0.0),
        ("epsilon", "1", 1.0),
        ("insert_threshold", "1", 1.0),
        ("kp_window", "40", 40),
        ("synthesize", "true", True),
        ("synthesize", "No", False),
        ("lambda", " 0.9 ", 0.9),
    ],
)
def test_parse_accepts_values_in_bounds(name: str, text: str, value: object) -> None:
    parsed = get_parameter(name).parse(text)
    assert parsed == value
    assert type(parsed) is type(value)


@pytest.mark.parametrize(
    ("name", "text", "message"),
    [
        ("eta", "abc", "eta: 'abc' is not a number"),
        ("eta", "1.5", r"eta must be in \[0, 1\], got 1.5"),
        ("eta", "-0.1", r"eta must be in \[0, 1\], got -0.1"),
        ("eta", "nan", "eta must be in"),
        ("insert_threshold", "0", r"insert_threshold must be in \(0, 1\], got 0"),
        ("kp_window", "2.5", "kp_window: '2.5' is not a whole number"),
        ("kp_window", "0", r"kp_window must be in \[1, 1000\]"),
        ("synthesize", "maybe", "synthesize: 'maybe' is not true or false"),
    ],
)
def test_parse_refuses_bad_values_clearly(name: str, text: str, message: str) -> None:
    with pytest.raises(ParameterError, match=message):
        get_parameter(name).parse(text)


def test_check_refuses_a_bool_for_a_number_and_a_number_for_a_bool() -> None:
    with pytest.raises(ParameterError, match="eta must be a number"):
        get_parameter("eta").check(True)
    with pytest.raises(ParameterError, match="synthesize must be true or false"):
        get_parameter("synthesize").check(1)
    assert math.isclose(float(get_parameter("eta").check(1)), 1.0)


def test_a_parameter_changes_what_a_task_does() -> None:
    # Exploring every encounter against never exploring: the same seed must differ.
    never = run_task(Task("kp", 3, 3, (("epsilon", 0.0),)))
    always = run_task(Task("kp", 3, 3, (("epsilon", 1.0),)))
    assert never.ok and always.ok, (never.error, always.error)
    assert never.episodes != always.episodes


def test_a_task_with_its_default_values_equals_the_task_without_parameters() -> None:
    plain = run_task(Task("kp", 2, 2))
    explicit = run_task(Task("kp", 2, 2, (("epsilon", 0.1), ("eta", 0.1))))
    assert plain.ok and explicit.ok
    assert plain.episodes == explicit.episodes
    assert plain.rltm == explicit.rltm
