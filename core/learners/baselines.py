"""Deep RL baselines: stable-baselines3's DQN and PPO on `srlab/AmigoTrack-v0`.

Like the tabular Q(lambda) baseline (`core.learners.qlambda`), they learn on the Gymnasium
environment, so they see the same stimuli, choose among the same behaviours (and, with
``defer``, may let the built-in behaviour answer), meet the same episodes (obstacles and
lamp cycles per seed) and get the same delayed reward as the architecture's conditions.
They train for a number of episodes, not of timesteps, so that they compare episode for
episode with the others.

stable-baselines3 and torch are the optional extra ``srlab[baselines]`` (``make
install-baselines``); they are imported inside the functions, so this module imports
without them.

Determinism: SB3 seeds Python's, numpy's and torch's process-global generators from
`seed` when it builds a model (its exploration and replay sampling use numpy's global
one), and the environment from `seed` at its first reset; torch runs on one CPU thread
while training. The same call then gives the same episodes and the same network weights,
bit for bit, in any process of the same machine with the same torch build (tested). Across
machines whose CPUs make torch pick other kernels, the floats, and so perhaps the
episodes, may differ.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, fields, replace
from typing import TYPE_CHECKING, Any, Literal

import gymnasium as gym
import numpy as np
import numpy.typing as npt

from core.learners.envs import AmigoTrackEnv, Observation
from core.params import ParameterError
from core.run.conditions import Condition
from core.run.runner import EpisodeSummary
from core.run.setup import Setup

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

Algo = Literal["dqn", "ppo"]
ALGOS: tuple[Algo, ...] = ("dqn", "ppo")
INSTALL_HINT = "make install-baselines"
"""The command that installs the ``srlab[baselines]`` extra (on a CPU-only torch)."""
MAX_TIMESTEPS = 10**12
"""The timestep budget SB3 is given; never reached, training stops after its episodes."""


class BaselinesUnavailableError(ImportError):
    """stable-baselines3 or torch is not installed (the ``srlab[baselines]`` extra)."""


@dataclass(frozen=True, slots=True)
class BaselineConfig:
    """Hyper-parameters of the DQN and PPO baselines (SB3's names where they exist).

    A decision here is an S-R stimulus the prior leaves open, about 20 per episode, and
    each costs a stretch of simulation (~0.75 ms) much like a gradient step on a small
    network: so the defaults favour sample efficiency, and they are sized so that a run
    of 50 episodes (~1,000 decisions) already learns, where SB3's Atari-sized defaults
    (DQN's target update every 10,000 steps, PPO's 2,048-step rollouts) would not update
    once.

    Attributes:
        gamma: discount per decision; 0.99 keeps ~80% of a lap's reward at its first
            decision, ~20 decisions earlier.
        learning_rate: Adam's step size, of both algorithms.
        hidden_units: units per hidden layer of the MLPs: 22 binary inputs, 22 actions.
        hidden_layers: hidden layers of the MLPs.
        epsilon: DQN's exploration rate, constant like the other learners' 0.1 (SB3's
            annealing runs over a timestep budget, which training by episodes has not).
        buffer_size: DQN's replay buffer, every decision of ~2,500 episodes.
        learning_starts: DQN's random decisions before it learns (~5 episodes).
        batch_size: the minibatch of a DQN update and of a PPO epoch.
        train_freq: decisions between DQN updates (one gradient step each).
        target_update_interval: decisions between DQN's target network copies (~12
            episodes).
        n_steps: PPO's rollout, in decisions (~13 episodes).
        n_epochs: PPO's passes over a rollout.
        gae_lambda: PPO's generalised advantage estimation lambda.
        clip_range: PPO's clipping of the policy ratio.
        ent_coef: PPO's entropy bonus, which keeps it exploring under a sparse reward.
    """

    gamma: float = 0.99
    learning_rate: float = 5e-4
    hidden_units: int = 64
    hidden_layers: int = 2
    epsilon: float = 0.1
    buffer_size: int = 50_000
    learning_starts: int = 100
    batch_size: int = 64
    train_freq: int = 1
    target_update_interval: int = 250
    n_steps: int = 256
    n_epochs: int = 10
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    ent_coef: float = 0.01

    def __post_init__(self) -> None:
        for name in ("gamma", "epsilon", "gae_lambda"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ParameterError(f"{name} must be in [0, 1], got {getattr(self, name)!r}")
        for name in ("learning_rate", "clip_range"):
            if not 0.0 < getattr(self, name) <= 1.0:
                raise ParameterError(f"{name} must be in (0, 1], got {getattr(self, name)!r}")
        if not 0.0 <= self.ent_coef <= 1.0:
            raise ParameterError(f"ent_coef must be in [0, 1], got {self.ent_coef!r}")
        for name in _INTS:
            value = getattr(self, name)
            low = 0 if name == "learning_starts" else 1
            if value < low:
                raise ParameterError(f"{name} must be >= {low}, got {value!r}")

    @classmethod
    def with_params(cls, algo: Algo, params: Mapping[str, float] | None) -> BaselineConfig:
        """The defaults with `params` set; a name `algo` does not use is an error."""
        values = dict(params or {})
        unused = sorted(set(values) - USED_BY[algo])
        if unused:
            known = ", ".join(sorted(USED_BY[algo]))
            raise ParameterError(f"{algo} does not use {', '.join(unused)} (it uses: {known})")
        settings: dict[str, Any] = {}
        for name, value in values.items():
            if name in _INTS:
                if value != int(value):
                    raise ParameterError(f"{name} must be a whole number, got {value!r}")
                settings[name] = int(value)
            else:
                settings[name] = float(value)
        return replace(cls(), **settings)


_INTS = frozenset(f.name for f in fields(BaselineConfig) if f.type == "int")
_SHARED = frozenset({"gamma", "learning_rate", "hidden_units", "hidden_layers", "batch_size"})
USED_BY: dict[Algo, frozenset[str]] = {
    "dqn": _SHARED
    | {"epsilon", "buffer_size", "learning_starts", "train_freq", "target_update_interval"},
    "ppo": _SHARED | {"n_steps", "n_epochs", "gae_lambda", "clip_range", "ent_coef"},
}
"""The hyper-parameters each algorithm uses."""


@dataclass(frozen=True, slots=True)
class BaselineResult:
    """A deep baseline's run: its training episodes, then its frozen evaluation's.

    Attributes:
        algo: ``dqn`` or ``ppo``.
        seed: the training seed.
        episodes: the training episodes in order, with those the learner had no decision
            in (run inside the environment's `reset`), as `core.learners.qlambda.run_qlambda`
            counts them.
        ticks: the ticks of the training episodes.
        eval_seeds: the seeds of the frozen evaluation.
        evaluation: its episodes, `eval_episodes` per seed in `eval_seeds`' order.
    """

    algo: Algo
    seed: int
    episodes: tuple[EpisodeSummary, ...]
    ticks: int
    eval_seeds: tuple[int, ...] = ()
    evaluation: tuple[EpisodeSummary, ...] = ()


class EpisodeRecorder(gym.Wrapper[Observation, np.int64, Observation, np.int64]):
    """Records every episode the environment ends, the skipped ones too, in order."""

    def __init__(
        self, env: AmigoTrackEnv, on_episode: Callable[[EpisodeSummary], None] | None = None
    ) -> None:
        super().__init__(env)
        self.track = env
        self.episodes: list[EpisodeSummary] = []
        self._on_episode = on_episode

    def _record(self, e: EpisodeSummary) -> None:
        self.episodes.append(e)
        if self._on_episode is not None:
            self._on_episode(e)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Observation, dict[str, Any]]:
        """Reset the environment, recording the episodes it ran without a decision."""
        obs, info = self.track.reset(seed=seed, options=options)
        for e in info["skipped"]:
            self._record(e)
        return obs, info

    def step(
        self, action: np.int64 | int | npt.NDArray[np.integer[Any]]
    ) -> tuple[Observation, float, bool, bool, dict[str, Any]]:
        """Step the environment, recording the episode it ends."""
        obs, reward, terminated, truncated, info = self.track.step(action)
        if terminated or truncated:
            self._record(info["episode_summary"])
        return obs, float(reward), terminated, truncated, info


def available() -> bool:
    """Whether the ``srlab[baselines]`` extra (stable-baselines3 and torch) is installed."""
    try:
        _require()
    except BaselinesUnavailableError:
        return False
    return True


def answer(model: BaseAlgorithm, observation: Observation, defer_action: int) -> int:
    """The behaviour the trained policy gives for `observation` (-1: it defers)."""
    with _one_thread():
        action, _ = model.predict(observation, deterministic=True)
    a = int(action)
    return -1 if a == defer_action else a


def _require() -> None:
    try:
        import stable_baselines3  # noqa: F401
        import torch  # noqa: F401
    except ImportError as e:
        raise BaselinesUnavailableError(
            f"the deep baselines need the srlab[baselines] extra ({e.name} is missing): "
            f"run `{INSTALL_HINT}`"
        ) from e


@contextmanager
def _one_thread() -> Iterator[None]:
    """Run torch on one CPU thread: the same floats whatever the machine's core count."""
    _require()
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def make_model(
    algo: Algo, env: gym.Env[Observation, np.int64], seed: int, config: BaselineConfig
) -> BaseAlgorithm:
    """An untrained SB3 model of `algo` on `env`, seeded with `seed`, on the CPU."""
    _require()
    from stable_baselines3 import DQN, PPO

    shared: dict[str, Any] = {
        "learning_rate": config.learning_rate,
        "batch_size": config.batch_size,
        "gamma": config.gamma,
        "policy_kwargs": {"net_arch": [config.hidden_units] * config.hidden_layers},
        "seed": seed,
        "device": "cpu",
    }
    if algo == "dqn":
        return DQN(
            "MlpPolicy",
            env,
            buffer_size=config.buffer_size,
            learning_starts=config.learning_starts,
            train_freq=config.train_freq,
            gradient_steps=1,
            target_update_interval=config.target_update_interval,
            exploration_initial_eps=config.epsilon,
            exploration_final_eps=config.epsilon,
            **shared,
        )
    if algo == "ppo":
        return PPO(
            "MlpPolicy",
            env,
            n_steps=config.n_steps,
            n_epochs=config.n_epochs,
            gae_lambda=config.gae_lambda,
            clip_range=config.clip_range,
            ent_coef=config.ent_coef,
            **shared,
        )
    raise ValueError(f"unknown algorithm {algo!r} (known: {', '.join(ALGOS)})")


def learn(
    algo: Algo,
    seed: int,
    episodes: int,
    config: BaselineConfig | None = None,
    *,
    env: AmigoTrackEnv | None = None,
    on_episode: Callable[[EpisodeSummary], None] | None = None,
    on_model: Callable[[BaseAlgorithm], None] | None = None,
) -> tuple[list[EpisodeSummary], BaseAlgorithm, int]:
    """Train `algo` for `episodes` episodes of the track from `seed`.

    Returns the episodes' summaries (including those the learner had no decision in),
    the trained model, and the ticks of those episodes. `on_model` is given the model
    once it is built, before training, so that `on_episode` can look at it.
    """
    if episodes < 1:
        raise ValueError("episodes must be >= 1")
    cfg = config or BaselineConfig()
    recorder = EpisodeRecorder(env or AmigoTrackEnv(prior="kp", defer=True), on_episode)
    with _one_thread():
        model = make_model(algo, recorder, seed, cfg)
        if on_model is not None:
            on_model(model)

        def more(_locals: dict[str, Any], _globals: dict[str, Any]) -> bool:
            return len(recorder.episodes) < episodes

        model.learn(total_timesteps=MAX_TIMESTEPS, callback=more)
    if len(recorder.episodes) < episodes:
        raise RuntimeError(f"{algo} stopped after {len(recorder.episodes)} of {episodes} episodes")
    done = recorder.episodes[:episodes]
    return done, model, sum(e.ticks for e in done)


def evaluate(
    model: BaseAlgorithm,
    make_env: Callable[[], AmigoTrackEnv],
    seeds: Sequence[int],
    episodes: int,
) -> list[EpisodeSummary]:
    """The trained policy, greedy and frozen, for `episodes` episodes from each seed.

    Each seed gets a fresh environment from `make_env`; the model only predicts, with
    ``deterministic=True``, so nothing it has learned changes.
    """
    if episodes < 0:
        raise ValueError("episodes must be >= 0")
    out: list[EpisodeSummary] = []
    if episodes == 0:
        return out
    with _one_thread():
        for seed in seeds:
            env = EpisodeRecorder(make_env())
            obs, _ = env.reset(seed=seed)
            while len(env.episodes) < episodes:
                action, _ = model.predict(obs, deterministic=True)
                obs, _, terminated, truncated, _ = env.step(action)
                if (terminated or truncated) and len(env.episodes) < episodes:
                    obs, _ = env.reset()
            out.extend(env.episodes[:episodes])
    return out


def baseline_env(setup: Setup, prior: str = "kp", defer: bool = True) -> AmigoTrackEnv:
    """The environment a baseline learns in under `setup`, starting from `prior`.

    The setup's world and sensor definition; with ``--signal given`` the signal's
    responses added to the prior and the signal taken out of what is learned, exactly as
    for the architecture's conditions.
    """
    condition = setup.condition(Condition("baseline", "a deep RL baseline", network=prior))
    return AmigoTrackEnv(
        prior=prior,
        learnable=condition.learnable_sensors,
        world_config=setup.world_config(),
        catalog=setup.catalog(),
        extra_networks=condition.extra_networks,
        defer=defer,
    )


def run_baseline(
    algo: Algo,
    seed: int,
    episodes: int,
    setup: Setup,
    *,
    prior: str = "kp",
    defer: bool = True,
    eval_seeds: Sequence[int] = (),
    eval_episodes: int = 0,
    params: Mapping[str, float] | None = None,
) -> BaselineResult:
    """Train `algo` for `episodes` episodes from `seed`, then evaluate it frozen.

    A pure function of its arguments on a given machine and torch build (see the module's
    docstring). The evaluation runs the greedy policy for `eval_episodes` episodes on a
    fresh environment per seed of `eval_seeds`.

    Args:
        algo: ``dqn`` or ``ppo``.
        seed: the training seed (the environment's and the learner's).
        episodes: training episodes, counted as every other condition counts them.
        setup: the world, sensor definition and signal mode.
        prior: the knowledge set the robot keeps as its built-in behaviour.
        defer: whether the learner may let the built-in behaviour answer.
        eval_seeds: the seeds of the frozen evaluation (none: no evaluation).
        eval_episodes: evaluation episodes per seed.
        params: `BaselineConfig` fields to set, by name.

    Raises:
        BaselinesUnavailableError: the ``srlab[baselines]`` extra is not installed.
        ParameterError: a parameter `algo` does not use, or out of bounds.
    """
    if algo not in ALGOS:
        raise ValueError(f"unknown algorithm {algo!r} (known: {', '.join(ALGOS)})")
    config = BaselineConfig.with_params(algo, params)
    trained, model, ticks = learn(
        algo, seed, episodes, config, env=baseline_env(setup, prior, defer)
    )
    evaluation = evaluate(
        model, lambda: baseline_env(setup, prior, defer), eval_seeds, eval_episodes
    )
    return BaselineResult(algo, seed, tuple(trained), ticks, tuple(eval_seeds), tuple(evaluation))
