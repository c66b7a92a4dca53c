"""The Gymnasium environment `srlab/AmigoTrack-v0`: API conformance, seeding, rewards."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from core.envs import ENV_ID, AmigoTrackEnv, register
from core.events import Outcome
from core.runner import EpisodeSummary


@pytest.mark.parametrize("prior", ["innate", "kp"])
def test_check_env_passes(prior: str) -> None:
    # The environment has no render modes, so there is nothing to render-check; without a
    # spec Gymnasium would only warn that it cannot try them.
    check_env(AmigoTrackEnv(prior=prior), skip_render_check=True)


def test_check_env_passes_with_the_registered_spec() -> None:
    env = gym.make(ENV_ID, prior="kp")
    check_env(env.unwrapped)
    env.close()


def test_make_builds_the_environment_after_importing_core_envs() -> None:
    register()  # idempotent
    env = gym.make(ENV_ID)
    assert isinstance(env.unwrapped, AmigoTrackEnv)
    assert env.unwrapped.prior == "innate"
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    assert info["episode"] == 0
    env.close()


def test_spaces_match_the_catalogue() -> None:
    env = AmigoTrackEnv()
    assert env.observation_space == gym.spaces.MultiBinary(len(env.catalog.stimuli))
    assert env.action_space == gym.spaces.Discrete(len(env.catalog.behaviours))


@pytest.mark.parametrize("seed", [0, 3, 11])
def test_reset_with_the_same_seed_gives_the_same_observation(seed: int) -> None:
    env = AmigoTrackEnv(prior="kp")
    obs1, info1 = env.reset(seed=seed)
    env.step(int(env.action_space.sample()))
    obs2, info2 = env.reset(seed=seed)
    np.testing.assert_array_equal(obs1, obs2)
    assert obs1.dtype == np.int8
    assert info1["episode"] == info2["episode"]
    assert info1["skipped"] == info2["skipped"]


def test_a_fresh_environment_replays_the_same_trajectory() -> None:
    def rollout() -> list[tuple[bytes, float, bool, bool]]:
        env = AmigoTrackEnv(prior="kp")
        env.reset(seed=4)
        out = []
        for t in range(30):
            obs, reward, terminated, truncated, _ = env.step(t % len(env.catalog.behaviours))
            out.append((obs.tobytes(), reward, terminated, truncated))
            if terminated or truncated:
                env.reset()
        return out

    assert rollout() == rollout()


@pytest.mark.parametrize("action", [-1, 21, 10**6])
def test_step_rejects_an_invalid_action(action: int) -> None:
    env = AmigoTrackEnv()
    env.reset(seed=0)
    assert len(env.catalog.behaviours) == 21
    with pytest.raises(ValueError, match="not in"):
        env.step(action)


def test_step_before_reset_needs_a_reset() -> None:
    with pytest.raises(gym.error.ResetNeeded):
        AmigoTrackEnv().step(0)


def test_unknown_learnable_sensor_raises() -> None:
    with pytest.raises(ValueError, match="no_such_sensor"):
        AmigoTrackEnv(learnable=("signal", "no_such_sensor"))


def test_unknown_prior_raises() -> None:
    from core.errors import UnknownNameError

    with pytest.raises(UnknownNameError, match="nowhere"):
        AmigoTrackEnv(prior="nowhere")


def test_reward_is_one_exactly_on_success() -> None:
    env = AmigoTrackEnv(prior="kp")
    rng = np.random.default_rng(0)
    obs, info = env.reset(seed=0)
    endings: list[tuple[float, bool, bool, EpisodeSummary]] = []
    skipped: list[EpisodeSummary] = list(info["skipped"])
    while len(endings) < 15:
        obs, reward, terminated, truncated, info = env.step(
            int(rng.integers(len(env.catalog.behaviours)))
        )
        assert env.observation_space.contains(obs)
        if not (terminated or truncated):
            assert (reward, info) == (0.0, {})
            continue
        endings.append((reward, terminated, truncated, info["episode_summary"]))
        obs, info = env.reset()
        skipped.extend(info["skipped"])
    outcomes = {e.outcome for *_, e in endings}
    assert outcomes == {Outcome.SUCCESS, Outcome.FAILURE}, "both kinds of ending are needed"
    for reward, terminated, truncated, summary in endings:
        success = summary.outcome is Outcome.SUCCESS
        assert reward == (1.0 if success else 0.0)
        assert terminated != truncated
        assert truncated == (summary.cause is not None and summary.cause.value == "timeout")
        assert summary.rewards == int(success)
    for s in skipped:
        assert s.rewards == int(s.outcome is Outcome.SUCCESS)


def test_success_reward_is_configurable() -> None:
    env = AmigoTrackEnv(prior="kp", success_reward=0.25)
    rng = np.random.default_rng(0)
    env.reset(seed=0)
    rewards: set[float] = set()
    for _ in range(2000):
        _, reward, terminated, truncated, info = env.step(
            int(rng.integers(len(env.catalog.behaviours)))
        )
        if terminated or truncated:
            success = info["episode_summary"].outcome is Outcome.SUCCESS
            assert reward == (0.25 if success else 0.0)
            rewards.add(reward)
            if len(rewards) == 2:
                break
            env.reset()
    assert rewards == {0.0, 0.25}


def test_the_learner_only_decides_for_stimuli_the_prior_leaves_open() -> None:
    env = AmigoTrackEnv(prior="kp")
    obs, _ = env.reset(seed=1)
    learnable = {s.id for s in env.catalog.stimuli if s.sensor in env.learnable_sensors}
    for _ in range(20):
        active = set(np.flatnonzero(obs).tolist())
        assert active & learnable, "a decision is only asked for a learnable stimulus"
        obs, _, terminated, truncated, _ = env.step(int(env.action_space.sample()))
        if terminated or truncated:
            obs, _ = env.reset()
