"""The baseline a user would pick instead: tabular Watkins Q(lambda) with replacing traces.

It learns on the Gymnasium environment (`core.envs`), so it sees the same stimuli, chooses
among the same behaviours, meets the same episodes (obstacles and lamp cycles per seed) and
gets the same delayed reward as the architecture's conditions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from core.envs import AmigoTrackEnv, Observation
from core.runner import EpisodeSummary


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
    """

    alpha: float = 0.3
    gamma: float = 0.99
    lam: float = 0.5
    epsilon: float = 0.1
    prior: str = "kp"

    def __post_init__(self) -> None:
        for name in ("alpha", "gamma", "lam", "epsilon"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in [0, 1]")


class WatkinsQLambda:
    """Tabular Q over observations, Watkins' cut of traces after exploratory actions."""

    def __init__(self, n_actions: int, config: QLambdaConfig, rng: np.random.Generator) -> None:
        self.n_actions = n_actions
        self.config = config
        self.q: dict[bytes, np.ndarray[tuple[int], np.dtype[np.float64]]] = {}
        self._traces: dict[tuple[bytes, int], float] = {}
        self._rng = rng

    def values(self, state: bytes) -> np.ndarray[tuple[int], np.dtype[np.float64]]:
        """Q(state, .), created at 0."""
        q = self.q.get(state)
        if q is None:
            q = np.zeros(self.n_actions)
            self.q[state] = q
        return q

    def greedy(self, state: bytes) -> int:
        """An action of maximal value, ties broken at random."""
        q = self.values(state)
        best = np.flatnonzero(q == q.max())
        return int(best[0] if len(best) == 1 else self._rng.choice(best))

    def act(self, state: bytes) -> int:
        """The epsilon-greedy action."""
        if self._rng.random() < self.config.epsilon:
            return int(self._rng.integers(self.n_actions))
        return self.greedy(state)

    def start_episode(self) -> None:
        """Clear the eligibility traces."""
        self._traces.clear()

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
) -> tuple[list[EpisodeSummary], WatkinsQLambda, int]:
    """Learn for `episodes` episodes of the track from `seed`.

    Returns the episodes' summaries (including those the learner had no decision in), the
    agent, and the total ticks simulated.
    """
    if episodes < 1:
        raise ValueError("episodes must be >= 1")
    cfg = config or QLambdaConfig()
    env = env or AmigoTrackEnv(prior=cfg.prior)
    agent = WatkinsQLambda(
        len(env.catalog.behaviours),
        cfg,
        np.random.default_rng(np.random.SeedSequence([seed, 0, 4])),
    )
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
        agent.start_episode()
        s = _key(obs)
        a = agent.act(s)
        while True:
            obs, reward, terminated, truncated, info = env.step(a)
            s2 = _key(obs)
            a2 = agent.act(s2)
            agent.update(s, a, reward, s2, a2, terminated)
            s, a = s2, a2
            if terminated or truncated:
                record(info["episode_summary"])
                break
        if len(done_episodes) >= episodes:
            break
        obs, info = env.reset()
    return done_episodes, agent, env.simulation.tick_count


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
