"""The experiment's wall time, episodes/s and ticks/s beside bare physics, in one run.

Run as ``.venv/bin/python -m bench.experiment`` (``make bench``). It runs the issue's full
command, 6 conditions x 20 seeds x 50 episodes on ``--jobs`` processes, and measures bare
pymunk stepping with eight ray casts on the same track in the same run. Goal: at most 60 s.
"""

from __future__ import annotations

import argparse
import os
import time

from bench.ticks import bare_pymunk, measure
from core.experiment import run_experiment
from core.setup import Setup

CONDITIONS = ["innate", "delayed", "dp", "rp", "kp", "qlambda"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    args = parser.parse_args()

    bare = measure(bare_pymunk(Setup().world_config()), seconds=3.0, warmup_s=0.5)
    started = time.perf_counter()
    results = run_experiment(CONDITIONS, list(range(args.seeds)), args.episodes, args.jobs)
    elapsed = time.perf_counter() - started
    episodes = sum(len(r.episodes) for r in results)
    ticks = sum(r.ticks for r in results)
    failed = [r for r in results if not r.ok]

    print(
        f"experiment: {len(CONDITIONS)} conditions x {args.seeds} seeds x {args.episodes} "
        f"episodes, --jobs {args.jobs}"
    )
    print(f"  wall time             {elapsed:8.1f} s   (goal: <= 60 s)")
    print(f"  episodes/s            {episodes / elapsed:8.0f}")
    print(f"  ticks/s, all jobs     {ticks / elapsed:8.0f}")
    print(f"  ticks/s per job       {ticks / elapsed / args.jobs:8.0f}")
    print(f"  bare pymunk + 8 casts {bare:8.0f} ticks/s on one core")
    print(f"  ratio per job / bare  {ticks / elapsed / args.jobs / bare:8.2f}")
    if failed:
        print(f"  FAILED tasks: {len(failed)}")


if __name__ == "__main__":
    main()
