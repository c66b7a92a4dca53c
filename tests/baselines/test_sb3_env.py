"""`srlab/AmigoTrack-v0` under stable-baselines3: its env checker, predictions, vector envs."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import sb3_or_skip  # noqa: F401  # before SB3 and torch: skips the module without them
from gymnasium.utils.env_checker import check_env as gymnasium_check_env
from stable_baselines3 import DQN, PPO
from stable_baselines3.common.env_checker import check_env as sb3_check_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv

from core.learners.baselines import ALGOS, Algo, BaselineConfig, make_model
from core.learners.envs import ENV_ID, AmigoTrackEnv


@pytest.mark.parametrize("render_mode", [None, "rgb_array"])
@pytest.mark.parametrize("defer", [False, True])
def test_both_env_checkers_pass(defer: bool, render_mode: str | None) -> None:
    env = gym.make(ENV_ID, prior="kp", defer=defer, render_mode=render_mode)
    sb3_check_env(env.unwrapped, warn=True, skip_render_check=render_mode is None)
    gymnasium_check_env(env.unwrapped)
    env.close()


@pytest.mark.parametrize("algo", ALGOS)
@pytest.mark.parametrize("deterministic", [False, True])
def test_predictions_are_actions_the_env_takes(algo: Algo, deterministic: bool) -> None:
    """`model.predict` returns a 0-d array such as `array(20)`: `step` takes it as it is."""
    env = AmigoTrackEnv(prior="kp", defer=True)
    model = make_model(algo, env, 0, BaselineConfig())
    obs, _ = env.reset(seed=0)
    taken = set()
    for _ in range(60):
        action, _ = model.predict(obs, deterministic=deterministic)
        assert isinstance(action, np.ndarray) and action.shape == ()
        assert env.action_space.contains(np.int64(action))
        taken.add(int(action))
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            obs, _ = env.reset()
    assert taken


@pytest.mark.parametrize("defer", [False, True])
def test_dqn_learns_in_a_dummy_vec_env_of_two(defer: bool) -> None:
    envs = DummyVecEnv([lambda: AmigoTrackEnv(prior="kp", defer=defer) for _ in range(2)])
    model = DQN("MlpPolicy", envs, learning_starts=20, buffer_size=1000, seed=1, device="cpu")
    model.learn(total_timesteps=120)
    assert model.num_timesteps >= 120
    obs = envs.reset()
    assert isinstance(obs, np.ndarray)
    actions, _ = model.predict(obs, deterministic=True)
    assert actions.shape == (2,)
    envs.step(actions)
    envs.close()


def test_ppo_learns_in_make_vec_env_and_reports_episodes() -> None:
    envs = make_vec_env(AmigoTrackEnv, n_envs=2, seed=3, env_kwargs={"prior": "kp", "defer": True})
    model = PPO("MlpPolicy", envs, n_steps=64, batch_size=32, n_epochs=1, seed=3, device="cpu")
    model.learn(total_timesteps=256)
    assert model.num_timesteps >= 256
    # make_vec_env's Monitor reports episodes under "episode"; the env's own info no
    # longer has that key, so nothing collides.
    assert model.ep_info_buffer is not None and len(model.ep_info_buffer) >= 1
    assert all(info["l"] >= 1 for info in model.ep_info_buffer)
    envs.close()
