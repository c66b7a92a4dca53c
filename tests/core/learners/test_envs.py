"""The Gymnasium environment `srlab/AmigoTrack-v0`: API conformance, seeding, rewards."""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from core.events import Outcome
from core.learners.envs import ENV_ID, AmigoTrackEnv, register
from core.run.runner import EpisodeSummary
from core.sim.corridor_world import CorridorWorld
from core.sim.worlds import load_world


@pytest.mark.parametrize("prior", ["innate", "kp"])
@pytest.mark.parametrize("defer", [False, True])
def test_check_env_passes(prior: str, defer: bool) -> None:
    env = gym.make(ENV_ID, prior=prior, defer=defer, render_mode="rgb_array")
    check_env(env.unwrapped)
    env.close()


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
    assert info["episode_index"] == 0
    assert "episode" not in info  # RecordEpisodeStatistics' key
    env.close()


def test_spaces_match_the_catalogue() -> None:
    env = AmigoTrackEnv()
    # every stimulus but the stop-line beacon's, which a world without a beacon never raises
    beacon = [s for s in env.catalog.stimuli if s.sensor == "beacon"]
    assert len(beacon) == 3
    assert env.observation_space == gym.spaces.MultiBinary(len(env.catalog.stimuli) - 3)
    assert env.action_space == gym.spaces.Discrete(len(env.catalog.behaviours))


@pytest.mark.parametrize("seed", [0, 3, 11])
def test_reset_with_the_same_seed_gives_the_same_observation(seed: int) -> None:
    env = AmigoTrackEnv(prior="kp")
    obs1, info1 = env.reset(seed=seed)
    env.step(int(env.action_space.sample()))
    obs2, info2 = env.reset(seed=seed)
    np.testing.assert_array_equal(obs1, obs2)
    assert obs1.dtype == np.int8
    assert info1["episode_index"] == info2["episode_index"]
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
            assert reward == 0.0
            assert set(info) == {"stimulus"} and info["stimulus"] >= 0
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


@pytest.mark.parametrize(
    "action", [np.int64(20), np.int32(3), np.array(20), np.array(0, dtype=np.uint8)]
)
def test_step_takes_numpy_integers_and_0d_arrays(action: object) -> None:
    """stable-baselines3's `model.predict` returns `array(20)`."""
    env = AmigoTrackEnv(prior="kp")
    env.reset(seed=0)
    env.step(action)  # type: ignore[arg-type]


@pytest.mark.parametrize("action", [np.array([1]), np.array(2.0), 2.0, True, np.bool_(True), "3"])
def test_step_refuses_what_is_not_one_integer(action: object) -> None:
    env = AmigoTrackEnv(prior="kp")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="not in"):
        env.step(action)  # type: ignore[arg-type]


def test_deferring_every_decision_is_the_built_in_behaviour_alone() -> None:
    """The defer action lets the prior answer: always deferring lives exactly the episodes
    of the condition without a learner."""
    from core.run.conditions import Condition
    from core.run.runner import run

    env = AmigoTrackEnv(prior="kp", defer=True)
    assert env.action_space == gym.spaces.Discrete(len(env.catalog.behaviours) + 1)
    _, info = env.reset(seed=5)
    episodes: list[EpisodeSummary] = list(info["skipped"])
    while len(episodes) < 6:
        _, _, terminated, truncated, info = env.step(env.defer_action)
        if terminated or truncated:
            episodes.append(info["episode_summary"])
            _, info = env.reset()
            episodes.extend(info["skipped"])
    alone = run(Condition("alone", "the prior, no learner", network="kp"), 5, len(episodes))
    assert [(e.outcome, e.cause, e.ticks) for e in episodes] == [
        (e.outcome, e.cause, e.ticks) for e in alone.episodes
    ]


def test_rgb_array_frames_show_the_robot_where_it_is() -> None:
    env = AmigoTrackEnv(prior="kp", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame is not None and frame.dtype == np.uint8 and frame.ndim == 3
    assert frame.shape[0] % 16 == 0 and frame.shape[1] % 16 == 0
    snap = env.simulation.snapshot
    top_down = env._frame
    assert top_down is not None
    # A point just behind the robot's centre (the heading line runs forward from it).
    back = 0.08
    col, row = top_down._px(
        snap.x - back * math.cos(snap.heading_rad), snap.y - back * math.sin(snap.heading_rad)
    )
    assert tuple(frame[round(row), round(col)]) == (200, 30, 30)  # the robot's red
    env.step(0)
    later = env.render()
    assert later is not None and not np.array_equal(later, frame)
    assert AmigoTrackEnv(prior="kp").render() is None  # no render mode, no frame
    with pytest.raises(ValueError, match="human"):
        AmigoTrackEnv(render_mode="human")


@pytest.mark.parametrize("mode", ["sync", "async"])
def test_vector_environments_with_episode_statistics(mode: str) -> None:
    """`make_vec` in both vector modes, with RecordEpisodeStatistics: no key collides."""
    envs = gym.make_vec(
        ENV_ID,
        num_envs=2,
        vectorization_mode=mode,
        wrappers=[gym.wrappers.RecordEpisodeStatistics],
        prior="kp",
    )
    try:
        envs.reset(seed=3)
        finished = 0
        for _ in range(400):
            *_, info = envs.step(envs.action_space.sample())
            if "episode" in info:
                done = info["_episode"]
                finished += int(done.sum())
                assert (info["episode"]["l"][done] >= 1).all()
            if finished >= 2:
                break
        assert finished >= 2
    finally:
        envs.close()


def test_record_video_writes_an_episode(tmp_path: Path) -> None:
    folder = tmp_path / "videos"  # RecordVideo warns about a folder that exists already
    env = gym.wrappers.RecordVideo(
        gym.make(ENV_ID, prior="kp", render_mode="rgb_array"), str(folder), disable_logger=True
    )
    env.reset(seed=0)
    for _ in range(200):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            break
    env.close()  # type: ignore[no-untyped-call]  # gymnasium's RecordVideo.close is untyped
    videos = list(folder.glob("*.mp4"))
    assert videos and videos[0].stat().st_size > 1000


def test_rgb_array_frames_draw_a_corridor_track_and_its_obstacles() -> None:
    env = AmigoTrackEnv(
        prior="kp", render_mode="rgb_array", world_config=load_world("l-shape").config
    )
    env.reset(seed=0)
    frame = env.render()
    assert frame is not None and frame.shape == (6 * 64, 8 * 64, 3)
    top_down = env._frame
    assert top_down is not None
    world = env.simulation.world
    assert isinstance(world, CorridorWorld)
    for ox, oy in world.obstacle_centers():  # both the seeded obstacle and the trolley
        col, row = top_down._px(ox, oy)
        assert tuple(frame[round(row), round(col)]) == (150, 95, 40)
    col, row = top_down._px(6.0, 5.0)  # outside the L: no floor there
    assert tuple(frame[round(row), round(col)]) == (120, 120, 120)
