"""A sweep's wall time on local processes and on Ray with as many local workers, in one run.

Run as ``.venv/bin/python -m bench.sweep`` (``make bench``). It runs the issue's sweep, 5
values of epsilon x kp, qlambda x 20 seeds x 50 episodes (200 tasks, none shared), first
on ``--jobs`` local processes, then on a private local Ray instance with ``--jobs`` CPUs,
``--rounds`` times in alternation, and checks that both give the same results. Times are
end to end: the process pool's or the Ray instance's start and stop are included (Ray's
tasks alone are printed too); each backend's best round is compared, since other work on
a shared machine only adds time. Goals: local <= 120 s on 2 cores; Ray <= 1.3 x local.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from core.experiment import LocalBackend, TaskResult
from core.sweep import Sweep, parse_grid, run_sweep
from server.ray_backend import RayBackend


def timed_local(sweep: Sweep, jobs: int) -> tuple[float, list[TaskResult]]:
    started = time.perf_counter()
    results = run_sweep(sweep, LocalBackend(jobs))
    return time.perf_counter() - started, results


def timed_ray(sweep: Sweep, jobs: int) -> tuple[float, float, list[TaskResult]]:
    started = time.perf_counter()
    with RayBackend(None, jobs) as backend:
        tasks_started = time.perf_counter()
        results = run_sweep(sweep, backend)
        tasks_s = time.perf_counter() - tasks_started
    return time.perf_counter() - started, tasks_s, results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--param", default="epsilon=0.02,0.05,0.1,0.15,0.2")
    parser.add_argument("--conditions", default="kp,qlambda")
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--rounds", type=int, default=1)
    args = parser.parse_args()

    sweep = Sweep(
        parse_grid([args.param]),
        tuple(args.conditions.split(",")),
        tuple(range(args.seeds)),
        args.episodes,
    )
    local_s: list[float] = []
    ray_s: list[float] = []
    ray_tasks_s: list[float] = []
    same = True
    ticks = 0
    for _ in range(args.rounds):
        t, local = timed_local(sweep, args.jobs)
        local_s.append(t)
        t, tasks_t, on_ray = timed_ray(sweep, args.jobs)
        ray_s.append(t)
        ray_tasks_s.append(tasks_t)
        same = same and on_ray == local
        ticks = sum(r.ticks for r in local)
    failed = sum(not r.ok for r in local)
    # Other work on a shared machine only ever adds time: each backend's best round is its
    # least disturbed one. Per-round ratios compare runs made minutes apart.
    lo, ra = min(local_s), min(ray_s)
    rt = ray_tasks_s[ray_s.index(ra)]
    ratios = [b / a for a, b in zip(local_s, ray_s, strict=True)]
    load = os.getloadavg()
    print(
        f"sweep: {args.param} x {args.conditions} x {args.seeds} seeds x {args.episodes} "
        f"episodes = {len(sweep.tasks())} tasks, --jobs {args.jobs}, best of {args.rounds}"
    )
    print(f"  local processes        {lo:8.1f} s   (goal: <= 120 s)")
    print(f"  Ray, {args.jobs} local workers    {ra:8.1f} s   ({rt:.1f} s running tasks)")
    print(f"  Ray / local            {ra / lo:8.2f}     (goal: <= 1.3)")
    rounds = ", ".join(f"{a:.1f}/{b:.1f}" for a, b in zip(local_s, ray_s, strict=True))
    print(f"  each round, local/Ray  {rounds} s")
    print(f"  median round's ratio   {statistics.median(ratios):8.2f}")
    print(f"  ticks/s, local         {ticks / lo:8.0f}")
    print(f"  same results           {'yes' if same else 'NO'}")
    print(f"  load average           {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (1, 5, 15 min)")
    if failed:
        print(f"  FAILED tasks: {failed}")


if __name__ == "__main__":
    main()
