"""DQN and PPO trained by episodes: counts, a frozen evaluation, and what is deterministic."""

from __future__ import annotations

import multiprocessing
from concurrent.futures import ProcessPoolExecutor

import pytest
import sb3_or_skip  # noqa: F401  # before SB3 and torch: skips the module without them
import torch
from stable_baselines3.common.base_class import BaseAlgorithm

from core.events import Outcome
from core.learners.baselines import (
    ALGOS,
    Algo,
    BaselineConfig,
    BaselineResult,
    baseline_env,
    evaluate,
    learn,
    run_baseline,
)
from core.run.runner import EpisodeSummary
from core.run.setup import Setup

# Small enough for a test: DQN learns from its 10th decision, PPO updates every 32.
QUICK = {"learning_starts": 10.0, "batch_size": 16.0}
QUICK_PPO = {"n_steps": 32.0, "batch_size": 16.0, "n_epochs": 2.0}


def quick(algo: Algo) -> dict[str, float]:
    return QUICK if algo == "dqn" else QUICK_PPO


def weights(model: BaseAlgorithm) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in model.policy.state_dict().items()}


def same_weights(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def small_run(algo: Algo, seed: int = 2) -> BaselineResult:
    return run_baseline(
        algo, seed, 6, Setup(), eval_seeds=(900, 901), eval_episodes=2, params=quick(algo)
    )


@pytest.mark.parametrize("algo", ALGOS)
def test_a_short_run_trains_and_evaluates_the_episodes_asked(algo: Algo) -> None:
    result = small_run(algo)
    assert result.algo == algo and result.seed == 2
    assert [e.episode for e in result.episodes] == list(range(6))
    assert result.ticks == sum(e.ticks for e in result.episodes) > 0
    assert result.eval_seeds == (900, 901)
    # Two episodes per evaluation seed, each seed's counted from its own fresh env.
    assert [e.episode for e in result.evaluation] == [0, 1, 0, 1]
    for e in (*result.episodes, *result.evaluation):
        assert e.rewards == int(e.outcome is Outcome.SUCCESS)


@pytest.mark.parametrize("algo", ALGOS)
def test_training_counts_the_episodes_run_inside_reset(algo: Algo) -> None:
    """With the innate prior the robot often crashes before any learnable stimulus: those
    episodes are run inside `reset` and count, in order, as in `run_qlambda`."""
    env = baseline_env(Setup(), prior="innate")
    seen: list[EpisodeSummary] = []
    episodes, model, _ = learn(
        algo, 0, 12, BaselineConfig.with_params(algo, quick(algo)), env=env, on_episode=seen.append
    )
    assert [e.episode for e in episodes] == list(range(12))
    assert seen[:12] == episodes
    # SB3's Monitor saw only the episodes that ended in a step: some were skipped.
    assert model.ep_info_buffer is not None and len(model.ep_info_buffer) < 12


@pytest.mark.parametrize("algo", ALGOS)
def test_evaluation_changes_nothing_the_policy_learned(algo: Algo) -> None:
    setup = Setup()
    cfg = BaselineConfig.with_params(algo, quick(algo))
    _, model, _ = learn(algo, 4, 5, cfg, env=baseline_env(setup))
    before = weights(model)
    steps = model.num_timesteps
    first = evaluate(model, lambda: baseline_env(setup), (7, 8), 2)
    assert len(first) == 4
    assert same_weights(before, weights(model))
    assert model.num_timesteps == steps
    # Greedy and frozen: the same seeds give the same episodes again.
    assert evaluate(model, lambda: baseline_env(setup), (7, 8), 2) == first


def test_evaluation_of_no_episodes_is_empty() -> None:
    _, model, _ = learn("ppo", 0, 1, BaselineConfig.with_params("ppo", QUICK_PPO))
    assert evaluate(model, lambda: baseline_env(Setup()), (1, 2), 0) == []


@pytest.mark.parametrize("algo", ALGOS)
def test_the_same_call_learns_the_same_weights_and_episodes(algo: Algo) -> None:
    cfg = BaselineConfig.with_params(algo, quick(algo))
    eps1, m1, t1 = learn(algo, 5, 6, cfg, env=baseline_env(Setup()))
    eps2, m2, t2 = learn(algo, 5, 6, cfg, env=baseline_env(Setup()))
    assert (eps1, t1) == (eps2, t2)
    assert same_weights(weights(m1), weights(m2))
    assert m1.num_timesteps == m2.num_timesteps > 0


def test_another_seed_meets_other_episodes() -> None:
    assert small_run("dqn", seed=2).episodes != small_run("dqn", seed=3).episodes


def _in_fresh_process(algo: Algo) -> BaselineResult:
    return small_run(algo)


def test_a_fresh_process_gives_the_same_result() -> None:
    """SB3 seeds the process's global generators itself: nothing of this process leaks in."""
    torch.manual_seed(12345)  # this process's state is not the child's, and does not matter
    here = {algo: small_run(algo) for algo in ALGOS}
    spawn = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=1, mp_context=spawn) as pool:
        there = dict(zip(ALGOS, pool.map(_in_fresh_process, ALGOS), strict=True))
    assert there == here
