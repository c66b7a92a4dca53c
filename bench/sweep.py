"""A sweep's wall time on local processes and on Ray with as many local workers, in one run.

Run as ``.venv/bin/python -m bench.sweep`` (``make bench``). It runs a sweep of 5
values of epsilon x kp, qlambda x 20 seeds x 50 episodes (200 tasks, none shared),
``--rounds`` times, each round in turn:

* on ``--jobs`` local processes (``--backend local``);
* on Ray with ``--jobs`` local workers, joining a Ray instance that is already running
  (``--backend ray --address ...``, as on a cluster): the bench starts that instance once,
  before the rounds, with Ray's ``cluster_utils.Cluster``, and does not count its start;
* on a private Ray instance with ``--jobs`` CPUs that the backend starts and stops itself
  (``--backend ray`` without an address), its start and stop counted.

It checks that all three give the same results. Times are end to end for the sweep: the
process pool's start and stop, the Ray driver's connection (and for the private instance
Ray's start and stop) are included; the time running tasks is printed too. Each backend's
best round is compared, since other work on a shared machine only adds time. Goals: local
<= 120 s on 2 cores; Ray with 2 local workers <= 1.3 x local. A running instance is how
the Ray backend is meant to be used (a cluster outlives its sweeps); the private one adds
Ray's start and stop, a fixed cost of several seconds that the ratio shows for this
25-second sweep.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from ray.cluster_utils import Cluster

from core.lab.experiment import LocalBackend, TaskResult
from core.lab.sweep import Sweep, parse_grid, run_sweep
from server.backends.ray import OBJECT_STORE_BYTES, RayBackend


def timed_local(sweep: Sweep, jobs: int) -> tuple[float, list[TaskResult]]:
    started = time.perf_counter()
    results = run_sweep(sweep, LocalBackend(jobs))
    return time.perf_counter() - started, results


def timed_ray(
    sweep: Sweep, jobs: int, address: str | None
) -> tuple[float, float, list[TaskResult]]:
    """The sweep on Ray at `address` (None: a private instance, started and stopped)."""
    started = time.perf_counter()
    with RayBackend(address, jobs) as backend:
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
    print(f"starting a local Ray instance with {args.jobs} CPUs to join (not counted) ...")
    started = time.perf_counter()
    cluster = running_instance(args.jobs)
    print(f"  up in {time.perf_counter() - started:.1f} s at {cluster.address}")
    local_s: list[float] = []
    ray_s: dict[str, list[float]] = {JOINED: [], PRIVATE: []}
    ray_tasks_s: dict[str, list[float]] = {JOINED: [], PRIVATE: []}
    same = True
    ticks = 0
    try:
        for r in range(args.rounds):
            t, local = timed_local(sweep, args.jobs)
            local_s.append(t)
            for kind, address in ((JOINED, cluster.address), (PRIVATE, None)):
                t, tasks_t, on_ray = timed_ray(sweep, args.jobs, address)
                ray_s[kind].append(t)
                ray_tasks_s[kind].append(tasks_t)
                same = same and on_ray == local
            ticks = sum(x.ticks for x in local)
            print(
                f"  round {r + 1}: local {local_s[-1]:.1f} s, Ray joined {ray_s[JOINED][-1]:.1f}"
                f" s, Ray private {ray_s[PRIVATE][-1]:.1f} s"
            )
    finally:
        cluster.shutdown()  # type: ignore[no-untyped-call]
    failed = sum(not x.ok for x in local)
    # Other work on a shared machine only ever adds time: each backend's best round is its
    # least disturbed one. Per-round ratios compare runs made minutes apart.
    lo = min(local_s)
    load = os.getloadavg()
    print(
        f"sweep: {args.param} x {args.conditions} x {args.seeds} seeds x {args.episodes} "
        f"episodes = {len(sweep.tasks())} tasks, --jobs {args.jobs}, best of {args.rounds}"
    )
    print(f"  {'local processes':31} {lo:8.1f} s   (goal: <= 120 s)")
    for kind, goal in ((JOINED, "   (goal: <= 1.3)"), (PRIVATE, "")):
        best = min(ray_s[kind])
        tasks_s = ray_tasks_s[kind][ray_s[kind].index(best)]
        ratios = [b / a for a, b in zip(local_s, ray_s[kind], strict=True)]
        print(f"  {kind:31} {best:8.1f} s   ({tasks_s:.1f} s running tasks)")
        print(
            f"    {'Ray / local':29} {best / lo:8.2f}{goal}; median round's "
            f"{statistics.median(ratios):.2f}"
        )
    print(f"  {'ticks/s, local':31} {ticks / lo:8.0f}")
    print(f"  {'same results':31} {'yes' if same else 'NO':>8}")
    print(f"  {'load average':31} {load[0]:8.2f} {load[1]:.2f} {load[2]:.2f} (1, 5, 15 min)")
    if failed:
        print(f"  FAILED tasks: {failed}")


JOINED = "Ray, joining a running instance"
PRIVATE = "Ray, a private instance"


def running_instance(cpus: int) -> Cluster:
    """A local Ray instance with `cpus` CPUs, as `ray start --head` would run it."""
    return Cluster(
        initialize_head=True,
        head_node_args={
            "num_cpus": cpus,
            "include_dashboard": False,
            "object_store_memory": OBJECT_STORE_BYTES,
        },
    )


if __name__ == "__main__":
    main()
