"""The experiments' wall time, episodes/s and ticks/s beside bare physics, in one run.

Run as ``.venv/bin/python -m bench.experiment`` (``make bench``). Two figures, each with
bare pymunk stepping (eight ray casts, the same track) measured in the same run:

- the paper's six conditions x 20 seeds x 50 episodes on ``--jobs`` processes (goal: at
  most 60 s);
- the headline experiment: every condition but the deep baselines (innate, delayed, dp,
  rp, kp, sonar, expert, qlambda, qlambda-hybrid), both signal settings, 20 seeds x 50
  episodes, with 10 episodes of held-out evaluation and of the camera-only transfer test
  per task, and the placement probe computed afresh (goal: at most 120 s);
- with the srlab[baselines] extra installed (``make install-baselines``), the deep
  baselines' extra time: dqn and ppo, the same seeds, episodes and evaluation, both
  signal settings (no goal: printed so that it is known).

``--only results`` (not part of the default run: it takes most of half an hour) times
``bash scripts/results.sh``, every folder the README cites, written into a scratch folder
(or where ``RESULTS_OUT`` says: ``RESULTS_OUT=docs/results`` regenerates them), with
``--jobs`` processes: each folder's wall time, then the whole
set's wall and CPU time (goal: at most 30 minutes on 2 cores).
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from bench.ticks import bare_pymunk, measure
from core.lab.experiment import (
    LocalBackend,
    Task,
    TaskResult,
    experiment_tasks,
    run_experiment,
    run_tasks,
)
from core.lab.probe import probe
from core.learners import baselines
from core.run.setup import Setup, SignalMode

PAPER = ["innate", "delayed", "dp", "rp", "kp", "qlambda"]
DEEP = ["dqn", "ppo"]
HEADLINE = ["innate", "delayed", "dp", "rp", "kp", "sonar", "expert", "qlambda", "qlambda-hybrid"]
EVAL_EPISODES = 10
SIGNALS: tuple[SignalMode, ...] = ("given", "learned")


RESULTS_GOAL_S = 30 * 60
"""`bash scripts/results.sh`, every folder, on 2 cores."""
ROOT = Path(__file__).resolve().parents[1]

REFERENCE_BARE = 38_080
"""Bare pymunk's ticks/s on this project's machine at the speed the goals were set at."""


def _report(title: str, results: Sequence[TaskResult], elapsed: float, jobs: int, bare: float,
            goal_s: float) -> None:  # fmt: skip
    episodes = sum(len(r.episodes) + len(r.evaluation) + len(r.transfer) for r in results)
    ticks = sum(r.ticks for r in results)
    failed = [r for r in results if not r.ok]
    print(title)
    print(f"  wall time             {elapsed:8.1f} s   (goal: <= {goal_s:g} s)")
    # The same work at the reference machine's speed, scaled by bare physics measured in
    # this run: a slower machine (or a busy one) is told apart from a slower srlab.
    scaled = elapsed * bare / REFERENCE_BARE
    print(f"  at the reference speed {scaled:7.1f} s   (x bare / {REFERENCE_BARE:,} ticks/s)")
    print(f"  episodes/s            {episodes / elapsed:8.0f}  (evaluation episodes included)")
    print(f"  training ticks/s      {ticks / elapsed:8.0f}  (all jobs)")
    print(f"  per job / bare        {ticks / elapsed / jobs / bare:8.2f}")
    if failed:
        print(f"  FAILED tasks: {len(failed)}")


def _both_signals(
    conditions: Sequence[str], seeds: Sequence[int], episodes: int, jobs: int
) -> list[TaskResult]:
    """`conditions` tuned, with held-out evaluation, under both signal settings.

    One pool runs the tasks of both settings (longest first), as `srlab experiment` runs
    one setting's.
    """
    tasks: list[Task] = []
    for signal in SIGNALS:
        tasks += experiment_tasks(
            conditions, seeds, episodes, Setup(signal=signal), EVAL_EPISODES, tuned=True
        )
    return run_tasks(tasks, LocalBackend(jobs))


def _timed_probe() -> float:
    started = time.perf_counter()
    probe(Setup())
    return time.perf_counter() - started


def _results(jobs: int) -> None:
    """Time `bash scripts/results.sh` into a scratch folder, each folder as it ends."""
    print(f"bash scripts/results.sh, every folder, JOBS={jobs}")
    if not baselines.available():
        print(f"  (dqn and ppo left out: {baselines.INSTALL_HINT})")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="srlab-results-") as scratch:
        # RESULTS_OUT=docs/results regenerates the published folders while timing them.
        out = os.environ.get("RESULTS_OUT", scratch)
        print(f"  into {out}")
        env = {**os.environ, "RESULTS_OUT": out, "JOBS": str(jobs)}
        proc = subprocess.Popen(
            ["bash", "scripts/results.sh"], cwd=ROOT, env=env, text=True,
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )  # fmt: skip
        assert proc.stderr is not None
        said: list[str] = []
        for line in proc.stderr:
            said.append(line)
            if took := re.match(r"results: (\S+) took (\d+) s", line):
                print(f"  {took[1]:<20}{int(took[2]):8d} s", flush=True)
        if proc.wait() != 0:
            sys.exit(f"results.sh failed ({proc.returncode}):\n{''.join(said[-20:])}")
    elapsed = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    print(f"  wall time             {elapsed:8.0f} s   (goal: <= {RESULTS_GOAL_S} s)")
    print(f"  CPU time              {cpu:8.0f} s   ({cpu / elapsed:.2f} cores on average)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument(
        "--only",
        choices=["paper", "headline", "deep", "results"],
        help="run one of the three, or time scripts/results.sh (never run by default)",
    )
    args = parser.parse_args()
    seeds = list(range(args.seeds))
    if args.only == "results":
        _results(args.jobs)
        return

    bare = measure(bare_pymunk(Setup().world_config()), seconds=3.0, warmup_s=0.5)
    print(f"bare pymunk + 8 casts {bare:8.0f} ticks/s on one core")
    if args.only in (None, "paper"):
        started = time.perf_counter()
        results = run_experiment(PAPER, seeds, args.episodes, args.jobs, tuned=True)
        _report(
            f"the paper's comparison: {len(PAPER)} conditions x {args.seeds} seeds x "
            f"{args.episodes} episodes, --jobs {args.jobs}",
            results, time.perf_counter() - started, args.jobs, bare, 60,
        )  # fmt: skip
    if args.only in (None, "headline"):
        started = time.perf_counter()
        # The probe, computed afresh, runs in its own process beside the experiment's.
        with ProcessPoolExecutor(max_workers=1) as aside:
            probing = aside.submit(_timed_probe)
            results = _both_signals(HEADLINE, seeds, args.episodes, args.jobs)
            probe_s = probing.result()
        elapsed = time.perf_counter() - started
        _report(
            f"the headline: {len(HEADLINE)} conditions x 2 signal settings x {args.seeds} "
            f"seeds x {args.episodes} episodes, {EVAL_EPISODES} + {EVAL_EPISODES} held-out "
            f"episodes a task, and the probe, --jobs {args.jobs}",
            results, elapsed, args.jobs, bare, 120,
        )  # fmt: skip
        print(f"  the probe, beside it  {probe_s:8.1f} s")
    if args.only in (None, "deep"):
        if not baselines.available():
            print(f"deep baselines: skipped, the extra is not installed ({baselines.INSTALL_HINT})")
            return
        started = time.perf_counter()
        results = _both_signals(DEEP, seeds, args.episodes, args.jobs)
        elapsed = time.perf_counter() - started
        print(
            f"the deep baselines' extra time: {', '.join(DEEP)} x 2 signal settings x "
            f"{args.seeds} seeds x {args.episodes} episodes, with the same evaluation"
        )
        print(f"  wall time             {elapsed:8.1f} s   (no goal)")
        per_task = elapsed * args.jobs / len(results)
        print(f"  per task (one core)   {per_task:8.1f} s")


if __name__ == "__main__":
    main()
