"""The baseline a user would pick instead: tabular Watkins Q(lambda) with replacing traces.

It learns on the Gymnasium environment (`core.learners.envs`), so it sees the same stimuli, chooses
among the same behaviours, meets the same episodes (obstacles and lamp cycles per seed) and
gets the same delayed reward as the architecture's conditions.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from core.learners.envs import AmigoTrackEnv, Observation
from core.params import QLambdaConfig as QLambdaConfig  # its home is core.params
from core.run.runner import EpisodeSummary


def epsilon_at(config: QLambdaConfig, episode: int) -> float:
    """The exploration rate in episode `episode` (0 is the first) of a learner's training.

    ``epsilon * 0.5 ** (episode / epsilon_half_life)``: it halves every
    `epsilon_half_life` episodes, so the learner stops exploring as KP's robot does once
    its responses are confident; constant at `epsilon` when the half-life is 0.
    """
    if episode < 0:
        raise ValueError("episode must be >= 0")
    if config.epsilon_half_life == 0.0:
        return config.epsilon
    return config.epsilon * math.pow(0.5, episode / config.epsilon_half_life)


class WatkinsQLambda:
    """Tabular Q over observations, Watkins' cut of traces after exploratory actions."""

    def __init__(
        self,
        n_actions: int,
        config: QLambdaConfig,
        rng: np.random.Generator,
        defer_action: int = -1,
    ) -> None:
        self.n_actions = n_actions
        self.config = config
        self.defer_action = defer_action
        self.q: dict[bytes, np.ndarray[tuple[int], np.dtype[np.float64]]] = {}
        self._traces: dict[tuple[bytes, int], float] = {}
        self._rng = rng
        self._encounter: tuple[int, int] = (-1, -1)
        """(open stimulus, action) of the current encounter, for per-encounter exploration."""
        self.episodes = 0
        """Episodes started so far."""
        self.epsilon = config.epsilon
        """The exploration rate of the current episode (`epsilon_at`)."""

    def values(self, state: bytes) -> np.ndarray[tuple[int], np.dtype[np.float64]]:
        """Q(state, .), created at 0 (the defer action at `defer_prior`)."""
        q = self.q.get(state)
        if q is None:
            q = np.zeros(self.n_actions)
            if self.defer_action >= 0:
                q[self.defer_action] = self.config.defer_prior
            self.q[state] = q
        return q

    def peek(self, state: bytes) -> np.ndarray[tuple[int], np.dtype[np.float64]] | None:
        """Q(state, .) if the state was ever met, without creating it."""
        return self.q.get(state)

    def greedy(self, state: bytes) -> int:
        """An action of maximal value, ties broken at random."""
        q = self.values(state)
        best = np.flatnonzero(q == q.max())
        return int(best[0] if len(best) == 1 else self._rng.choice(best))

    def act(self, state: bytes, stimulus: int = -1) -> int:
        """The epsilon-greedy action for `state`, whose open stimulus is `stimulus`.

        With `per_encounter`, exploration is drawn when a stimulus becomes the open one and
        the explored action is kept while it stays open (greedy decisions stay greedy).
        """
        if self.config.per_encounter:
            current, explored = self._encounter
            if stimulus >= 0 and stimulus == current:
                return explored if explored >= 0 else self.greedy(state)
            if self._rng.random() < self.epsilon:
                action = int(self._rng.integers(self.n_actions))
                self._encounter = (stimulus, action)
                return action
            self._encounter = (stimulus, -1)
            return self.greedy(state)
        if self._rng.random() < self.epsilon:
            return int(self._rng.integers(self.n_actions))
        return self.greedy(state)

    def start_episode(self, episode: int | None = None) -> None:
        """Clear the eligibility traces and the encounter; set episode `episode`'s epsilon.

        `episode` counts the training's episodes from 0, those the learner had no decision
        in too (None: the episodes this agent started before).
        """
        self._traces.clear()
        self._encounter = (-1, -1)
        self.epsilon = epsilon_at(self.config, self.episodes if episode is None else episode)
        self.episodes += 1

    def update(self, s: bytes, a: int, reward: float, s2: bytes, a2: int, terminal: bool) -> None:
        """One Watkins Q(lambda) backup with replacing traces."""
        cfg = self.config
        q2 = self.values(s2)
        a_star = int(np.argmax(q2)) if q2[a2] != q2.max() else a2
        target = reward if terminal else reward + cfg.gamma * q2[a_star]
        delta = target - self.values(s)[a]
        # Replacing traces: the visited pair's trace is set to 1, other actions' cleared.
        for b in range(self.n_actions):
            self._traces.pop((s, b), None)
        self._traces[(s, a)] = 1.0
        keep = not terminal and a2 == a_star
        decay = cfg.gamma * cfg.lam
        for (ts, ta), e in list(self._traces.items()):
            self.values(ts)[ta] += cfg.alpha * delta * e
            if keep:
                self._traces[(ts, ta)] = e * decay
        if not keep:
            self._traces.clear()


def _key(obs: Observation) -> bytes:
    return obs.tobytes()


def run_qlambda(
    seed: int,
    episodes: int,
    config: QLambdaConfig | None = None,
    *,
    on_episode: Callable[[EpisodeSummary], None] | None = None,
    env: AmigoTrackEnv | None = None,
    on_agent: Callable[[WatkinsQLambda], None] | None = None,
) -> tuple[list[EpisodeSummary], WatkinsQLambda, int]:
    """Learn for `episodes` episodes of the track from `seed`.

    Returns the episodes' summaries (including those the learner had no decision in), the
    agent, and the total ticks simulated.
    """
    if episodes < 1:
        raise ValueError("episodes must be >= 1")
    cfg = config or QLambdaConfig()
    env = env or AmigoTrackEnv(prior=cfg.prior, defer=cfg.defer)
    if env.defer != cfg.defer:
        raise ValueError("the environment's defer action must match the config's")
    agent = WatkinsQLambda(
        len(env.catalog.behaviours) + int(env.defer),
        cfg,
        np.random.default_rng(np.random.SeedSequence([seed, 0, 4])),
        env.defer_action,
    )
    if on_agent is not None:
        on_agent(agent)  # before any episode, so `on_episode` can read what it learned
    done_episodes: list[EpisodeSummary] = []

    def record(e: EpisodeSummary) -> None:
        if len(done_episodes) < episodes:
            done_episodes.append(e)
            if on_episode is not None:
                on_episode(e)

    obs, info = env.reset(seed=seed)
    while True:
        for e in info["skipped"]:
            record(e)
        if len(done_episodes) >= episodes:
            break
        agent.start_episode(len(done_episodes))
        s = _key(obs)
        a = agent.act(s, info["stimulus"])
        while True:
            obs, reward, terminated, truncated, info = env.step(a)
            s2 = _key(obs)
            a2 = agent.act(s2, info.get("stimulus", -1))
            agent.update(s, a, reward, s2, a2, terminated)
            s, a = s2, a2
            if terminated or truncated:
                record(info["episode_summary"])
                break
        if len(done_episodes) >= episodes:
            break
        obs, info = env.reset()
    return done_episodes, agent, env.simulation.tick_count


def answer(agent: WatkinsQLambda, observation: Observation) -> int:
    """The behaviour the learned policy gives for `observation` (-1: none of its own).

    None when the state was never met (no learned value) or when the greedy action is to
    defer to the built-in behaviour.
    """
    q = agent.peek(_key(observation))
    if q is None:
        return -1
    best = int(np.argmax(q))
    if best == agent.defer_action or np.all(q == q[0]):
        return -1
    return best


def evaluate_qlambda(
    agent: WatkinsQLambda, env: AmigoTrackEnv, seed: int, episodes: int
) -> list[EpisodeSummary]:
    """Run the greedy policy frozen (no exploration, no updates) in `env`.

    `episodes` episodes of seed `seed`. A state never met takes the defer action, or the
    first action (goforward1) when the learner has none, deterministically.
    """
    out: list[EpisodeSummary] = []
    if episodes < 1:
        return out
    obs, info = env.reset(seed=seed)
    while True:
        out.extend(info["skipped"])
        if len(out) >= episodes:
            return out[:episodes]
        while True:
            q = agent.peek(_key(obs))
            if q is None:
                a = agent.defer_action if agent.defer_action >= 0 else 0
            else:
                a = int(np.argmax(q))
            obs, _, terminated, truncated, info = env.step(a)
            if terminated or truncated:
                out.append(info["episode_summary"])
                break
        if len(out) >= episodes:
            return out[:episodes]
        obs, info = env.reset()


def _sweep_task(args: tuple[QLambdaConfig, int, int]) -> tuple[int, int, list[bool]]:
    config, seed, episodes = args
    eps, _, _ = run_qlambda(seed, episodes, config)
    return 0, seed, [e.outcome.value == "success" for e in eps]


def sweep(
    grid: list[QLambdaConfig],
    seeds: list[int],
    episodes: int,
    jobs: int = 1,
    on_done: Callable[[], None] | None = None,
) -> list[dict[str, float]]:
    """Every setting of `grid` on every seed; rows sorted best first by late success."""
    from concurrent.futures import ProcessPoolExecutor

    tasks = [(c, s, episodes) for c in grid for s in seeds]
    outcomes: list[list[bool]] = []
    if jobs == 1:
        for t in tasks:
            outcomes.append(_sweep_task(t)[2])
            if on_done is not None:
                on_done()
    else:
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            for r in pool.map(_sweep_task, tasks):
                outcomes.append(r[2])
                if on_done is not None:
                    on_done()
    rows = []
    late = min(50, episodes)
    for i, c in enumerate(grid):
        runs = outcomes[i * len(seeds) : (i + 1) * len(seeds)]
        rows.append(
            {
                "alpha": c.alpha,
                "lambda": c.lam,
                "epsilon": c.epsilon,
                "success_last50": float(np.mean([np.mean(r[-late:]) for r in runs])),
                "success_all": float(np.mean([np.mean(r) for r in runs])),
            }
        )
    rows.sort(key=lambda r: (-r["success_last50"], -r["success_all"]))
    return rows
