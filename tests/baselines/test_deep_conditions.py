"""DQN and PPO as conditions of `srlab experiment`: trained, evaluated, reported like the rest."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import sb3_or_skip  # noqa: F401  # before SB3 and torch: skips the module without them

from core.events import Outcome
from core.lab.experiment import LocalBackend, Task, run_experiment, run_task
from core.params import ParameterError, baseline_params
from core.run.conditions import get_condition
from core.run.setup import Setup
from server.cli import main

EPISODES = 4


@pytest.mark.parametrize("name", ["dqn", "ppo"])
def test_a_deep_condition_trains_answers_and_is_evaluated_frozen(name: str) -> None:
    result = run_task(Task(name, 3, EPISODES, setup=Setup(signal="given"), eval_episodes=2))
    assert result.ok, result.error
    assert len(result.episodes) == EPISODES
    assert result.ticks == sum(e.ticks for e in result.episodes)
    assert len(result.evaluation) == 2 and len(result.transfer) == 2
    # One answer per training episode for each of the nine camera obstacle stimuli.
    assert len(result.answers) == EPISODES
    assert {len(a) for a in result.answers} == {9}
    answered = {b for a in result.answers for b in a if b is not None}
    assert answered <= {b.name for b in Setup().catalog().behaviours}
    assert all(e.outcome in (Outcome.SUCCESS, Outcome.FAILURE) for e in result.evaluation)


@pytest.mark.parametrize("name", ["dqn", "ppo"])
def test_a_deep_checkpoint_is_what_a_task_trained_that_long_reports(name: str) -> None:
    setup = Setup(signal="given").resolved()
    long = run_task(Task(name, 3, 2 * EPISODES, setup=setup, eval_episodes=2,
                         eval_after=(EPISODES,)))  # fmt: skip
    short = run_task(Task(name, 3, EPISODES, setup=setup, eval_episodes=2))
    assert long.ok and short.ok, (long.error, short.error)
    assert long.episodes[:EPISODES] == short.episodes
    at = long.frozen_after(EPISODES)
    assert (at.evaluation, at.transfer) == (short.evaluation, short.transfer)


def test_deep_conditions_are_the_same_in_one_process_and_in_two() -> None:
    seeds = [0, 1]
    one = run_experiment(["dqn", "ppo"], seeds, 3, backend=LocalBackend(1), eval_episodes=1)
    two = run_experiment(["dqn", "ppo"], seeds, 3, backend=LocalBackend(2), eval_episodes=1)
    assert [r.episodes for r in one] == [r.episodes for r in two]
    assert [r.answers for r in one] == [r.answers for r in two]
    assert [r.evaluation for r in one] == [r.evaluation for r in two]


def test_deep_parameters_are_checked_by_condition() -> None:
    assert baseline_params(get_condition("dqn")) == {"epsilon": 0.1}
    assert baseline_params(get_condition("ppo"), {"ent_coef": 0.05}) == {"ent_coef": 0.05}
    with pytest.raises(ParameterError, match="'ppo' does not use epsilon"):
        baseline_params(get_condition("ppo"), {"epsilon": 0.2})
    with pytest.raises(ParameterError, match="'dqn' does not use n_steps"):
        baseline_params(get_condition("dqn"), {"n_steps": 64})


def test_srlab_experiment_reports_the_deep_conditions(tmp_path: Path) -> None:
    argv = ["experiment", "--conditions", "kp,dqn,ppo", "--seeds", "2", "--episodes", "3"]
    assert main([*argv, "--eval-episodes", "1", "--out", str(tmp_path), "--quiet"]) == 0
    doc = json.loads((tmp_path / "summary.json").read_text())
    assert doc["failed"] == []
    for name in ("dqn", "ppo"):
        c = doc["conditions"][name]
        assert c["seeds"] == 2 and len(c["success_curve"]) == 3
        assert c["evaluation"]["episodes"] == 1
        assert "correctness" in c
    assert "kp - dqn" in doc["paired"]
