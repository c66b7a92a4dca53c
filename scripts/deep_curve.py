"""A long-budget learning curve: DQN and PPO beside Q(lambda) and KP, episode for episode.

Each learner trains on the same seeds (so on the same obstacles and lamp cycles) for the
same number of episodes, counted the same way; the curve is the rolling success over the
last `--window` episodes, the mean over seeds with its 95% band (`core.lab.stats.mean_interval`,
Student's t, clipped to the seeds' range: with 3 seeds that is often the range itself).
Needs the srlab[baselines] extra (``make install-baselines``):

    .venv/bin/python scripts/deep_curve.py docs/results/deep-curve --episodes 1000 --seeds 3 \
        --signal given

(what ``scripts/results.sh`` runs). Without the extra, ``--learners`` without dqn and ppo
still runs.

It writes ``curve.png`` and ``curve.json`` (every episode's success per learner and seed,
and the seconds each run took) into the folder, and prints each learner's success over
the last 100 episodes with the time it took. The seeds are 0, 1, ... as in
``srlab experiment``; the runs go to ``--jobs`` processes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np

from core.errors import ExtraMissingError
from core.events import Outcome
from core.lab.experiment import Task, parse_conditions, run_task
from core.lab.stats import mean_interval
from core.params import tuned_params
from core.run.setup import SIGNAL_MODES, Setup

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # after choosing the headless backend

LEARNERS = ("dqn", "ppo", "qlambda", "qlambda-hybrid", "kp", "sonar")
COLOURS = {
    "dqn": "tab:red",
    "ppo": "tab:purple",
    "qlambda": "tab:blue",
    "qlambda-hybrid": "tab:cyan",
    "kp": "tab:green",
    "sonar": "tab:olive",
}
LATE = 100


def train(learner: str, seed: int, episodes: int, setup: Setup) -> tuple[list[bool], float]:
    """One learner's episodes' successes on one seed, and the seconds it took.

    Every learner runs as its `srlab experiment` condition does, with its tuned
    parameters (core/data/tuned.toml).
    """
    started = time.perf_counter()
    task = Task(learner, seed, episodes, params=tuned_params(learner), setup=setup)
    result = run_task(task)
    if not result.ok:
        raise RuntimeError(f"{learner} seed {seed}: {result.error}")
    successes = [e.outcome is Outcome.SUCCESS for e in result.episodes]
    return successes, time.perf_counter() - started


def _train(args: tuple[str, int, int, Setup]) -> tuple[list[bool], float]:
    return train(*args)


def rolling(successes: Sequence[bool], window: int) -> np.ndarray[Any, np.dtype[np.float64]]:
    """Success over the last `window` episodes at each episode (fewer at the start)."""
    x = np.cumsum(np.asarray(successes, dtype=np.float64))
    n = np.arange(1, len(x) + 1)
    lagged = np.concatenate([np.zeros(window), x[:-window]]) if len(x) > window else 0.0
    return (x - lagged) / np.minimum(n, window)


def plot(runs: dict[str, list[list[bool]]], window: int, title: str, path: Path) -> None:
    """Each learner's rolling success: the mean over seeds and its 95% band."""
    fig, ax = plt.subplots(figsize=(9, 5))
    for learner, per_seed in runs.items():
        curves = np.array([rolling(s, window) for s in per_seed])
        estimates = [mean_interval(curves[:, i].tolist()) for i in range(curves.shape[1])]
        x = np.arange(1, curves.shape[1] + 1)
        colour = COLOURS.get(learner)
        ax.plot(x, [e.mean for e in estimates], color=colour, label=learner)
        ax.fill_between(
            x, [e.low for e in estimates], [e.high for e in estimates], color=colour, alpha=0.2
        )
    ax.set_xlabel("episode")
    ax.set_ylabel(f"success over the last {window} episodes")
    ax.set_ylim(0.0, 1.0)
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> None:
    """Train every learner on every seed, then write the curve and its data."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", type=Path, help="folder for curve.png and curve.json")
    parser.add_argument("--episodes", type=int, default=2000)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--learners", default=",".join(LEARNERS))
    parser.add_argument("--window", type=int, default=100)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--world", default="")
    parser.add_argument("--sensors", default="")
    parser.add_argument("--signal", choices=SIGNAL_MODES, default="learned")
    args = parser.parse_args(argv)
    learners = [n.strip() for n in args.learners.split(",") if n.strip()]
    for n in learners:
        if n not in LEARNERS:
            parser.error(f"unknown learner {n!r} (known: {', '.join(LEARNERS)})")
    try:
        parse_conditions(",".join(learners))
    except ExtraMissingError as e:
        parser.error(str(e))
    setup = Setup(args.world, args.sensors, args.signal).resolved()
    seeds = list(range(args.seeds))
    tasks = [(n, s, args.episodes, setup) for n in learners for s in seeds]

    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        outcomes = list(pool.map(_train, tasks))
    wall = time.perf_counter() - started

    runs: dict[str, list[list[bool]]] = {n: [] for n in learners}
    seconds: dict[str, list[float]] = {n: [] for n in learners}
    for (n, *_), (successes, took) in zip(tasks, outcomes, strict=True):
        runs[n].append(successes)
        seconds[n].append(took)
    args.out.mkdir(parents=True, exist_ok=True)
    late = min(LATE, args.episodes)
    summary = {}
    for n in learners:
        est = mean_interval([float(np.mean(s[-late:])) for s in runs[n]])
        summary[n] = {f"success_last{late}": est.as_dict(), "seconds_per_seed": seconds[n]}
    report = {
        "episodes": args.episodes,
        "seeds": seeds,
        "window": args.window,
        "setup": {"world": setup.world, "sensors": setup.sensors, "signal": setup.signal},
        "wall_seconds": wall,
        "jobs": args.jobs,
        "summary": summary,
        "successes": {n: [[int(x) for x in s] for s in runs[n]] for n in learners},
    }
    (args.out / "curve.json").write_text(json.dumps(report) + "\n", encoding="utf-8")
    title = (
        f"{len(seeds)} seeds x {args.episodes} episodes, world {setup.world}, sensors "
        f"{setup.sensors}, signal {setup.signal}"
    )
    plot(runs, args.window, title, args.out / "curve.png")

    out = sys.stdout
    out.write(f"{title}; wall time {wall:.0f} s on {args.jobs} processes\n")
    out.write(f"{'learner':8}  success, last {late} episodes [95% CI]   seconds per seed\n")
    for n in learners:
        ci = summary[n][f"success_last{late}"]
        assert isinstance(ci, dict)
        out.write(
            f"{n:8}  {ci['mean']:6.1%} [{ci['low']:6.1%}, {ci['high']:6.1%}]"
            f"            {np.mean(seconds[n]):7.1f}\n"
        )
    out.write(f"wrote {args.out / 'curve.png'} and {args.out / 'curve.json'}\n")


if __name__ == "__main__":
    main()
