"""The store's reward path on SQLite: one reward's commit, and batches as fast mode makes.

Run as ``.venv/bin/python -m bench.store``. Measured in one process, on fresh databases,
with the writes on SQLite's driver (as the store runs them, `server.persistence.driver`)
and through SQLAlchemy sessions (``driver=False``), alternated: a trainer's reward logged
and then its learning committed (what a realtime run does per reward), back to back and
after ``--idle`` ms idle (as a realtime run's writer is woken: a CPU that idled runs the
same Python several times slower), and `commit_rewards` of 8 and 64 applied rewards (what
fast mode's writer batches), each with the LTM and RLTM changes a KP reward brings.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

from bench.figures import percentile
from core.brain.catalog import load_catalog
from core.ports import LearningUpdate, Mode, RewardCommit, RewardRecord, RunSpec
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade

PATHS = ("driver", "sessions")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=300)
    parser.add_argument("--idle", type=float, default=50.0, help="ms before each idle write")
    args = parser.parse_args()
    catalog = load_catalog()
    s = [x.name for x in catalog.stimuli][:6]
    b = [x.name for x in catalog.behaviours][:6]

    def update(i: int) -> LearningUpdate:
        ltm = {(s[i % 6], b[j]): 0.1 * j for j in range(3)}
        return LearningUpdate(ltm=ltm, rltm={(s[(i + 1) % 6], b[1]): 0.2})

    with tempfile.TemporaryDirectory() as tmp:
        stores: dict[str, tuple[SqlAlchemyRunStore, int]] = {}
        for path in PATHS:
            url = f"sqlite:///{tmp}/{path}.db"
            upgrade(url)
            store = SqlAlchemyRunStore(make_sessionmaker(make_engine(url)), driver=path == "driver")
            stores[path] = store, store.create_run(RunSpec("kp", 0, None, Mode.FAST), ())

        def one(path: str, i: int, idle_s: float) -> tuple[float, float]:
            """CPU time of a trainer's reward logged, then of its commit."""
            store, run_id = stores[path]
            record = RewardRecord(i, 0, 0.5, "trainer", "bench")
            time.sleep(idle_s)
            started = time.thread_time()
            logged = store.log_reward(run_id, record)
            time.sleep(idle_s)
            middle = time.thread_time()
            store.commit_rewards(run_id, (RewardCommit(record, update(i), 3, logged),))
            return middle - started, time.thread_time() - middle

        def batch(path: str, n: int) -> float:
            store, run_id = stores[path]
            commits = tuple(
                RewardCommit(RewardRecord(i, 0, 0.5, "task"), update(i), 3) for i in range(n)
            )
            started = time.thread_time()
            store.commit_rewards(run_id, commits)
            return time.thread_time() - started

        for path in PATHS:  # warm-up: statement caches, the WAL
            for i in range(50):
                one(path, i, 0.0)
        print(f"SQLite, CPU per write (median / p99 of {args.repeats}), driver vs sessions:")
        for label, idle_s, repeats in (
            ("back to back", 0.0, args.repeats),
            (f"after {args.idle:g} ms idle", args.idle / 1000, max(20, args.repeats // 5)),
        ):
            logs: dict[str, list[float]] = {p: [] for p in PATHS}
            commits: dict[str, list[float]] = {p: [] for p in PATHS}
            for i in range(repeats):
                for path in PATHS:  # alternated, so both see the same machine
                    log_s, commit_s = one(path, i, idle_s)
                    logs[path].append(log_s)
                    commits[path].append(commit_s)
            for what, samples in (("log a reward", logs), ("commit it", commits)):
                cells = "   ".join(
                    f"{p} {_ms(statistics.median(samples[p]))} / {_ms(percentile(samples[p], 99))}"
                    for p in PATHS
                )
                ratio = statistics.median(samples["driver"]) / statistics.median(
                    samples["sessions"]
                )
                print(f"  {label:22} {what:13} {cells}   ratio {ratio:4.2f}")
        for n in (8, 64):
            batches: dict[str, list[float]] = {p: [] for p in PATHS}
            for _ in range(30):
                for path in PATHS:  # alternated too
                    batches[path].append(batch(path, n))
            times = {p: statistics.median(batches[p]) for p in PATHS}
            cells = "   ".join(f"{p} {_ms(times[p])}" for p in PATHS)
            print(f"  a batch of {n:2} applied rewards, median of 30:   {cells}   "
                  f"ratio {times['driver'] / times['sessions']:4.2f}")  # fmt: skip


def _ms(seconds: float) -> str:
    return f"{seconds * 1000:5.2f} ms"


if __name__ == "__main__":
    main()
