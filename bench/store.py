"""The store's reward path on SQLite: one reward's commit, and batches as fast mode makes.

Run as ``.venv/bin/python -m bench.store``. Measured in one process, on a fresh database:
a trainer's reward logged and then its learning committed (what a realtime run does per
reward), and `commit_rewards` of 8 and 64 applied rewards (what fast mode's writer
batches), each with the LTM and RLTM changes a KP reward brings.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time

from core.brain.catalog import load_catalog
from core.ports import LearningUpdate, Mode, RewardCommit, RewardRecord, RunSpec
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=300)
    args = parser.parse_args()
    catalog = load_catalog()
    s = [x.name for x in catalog.stimuli][:6]
    b = [x.name for x in catalog.behaviours][:6]

    def update(i: int) -> LearningUpdate:
        ltm = {(s[i % 6], b[j]): 0.1 * j for j in range(3)}
        return LearningUpdate(ltm=ltm, rltm={(s[(i + 1) % 6], b[1]): 0.2})

    with tempfile.TemporaryDirectory() as tmp:
        url = f"sqlite:///{tmp}/store.db"
        upgrade(url)
        store = SqlAlchemyRunStore(make_sessionmaker(make_engine(url)))
        run_id = store.create_run(RunSpec("kp", 0, None, Mode.FAST), ())

        def one(i: int) -> float:
            record = RewardRecord(i, 0, 0.5, "trainer", "bench")
            logged = store.log_reward(run_id, record)
            started = time.perf_counter()
            store.commit_rewards(run_id, (RewardCommit(record, update(i), 3, logged),))
            return time.perf_counter() - started

        def batch(n: int) -> float:
            commits = tuple(
                RewardCommit(RewardRecord(i, 0, 0.5, "task"), update(i), 3) for i in range(n)
            )
            started = time.perf_counter()
            store.commit_rewards(run_id, commits)
            return time.perf_counter() - started

        for i in range(50):  # warm-up: statement caches, the WAL
            one(i)
        singles = sorted(one(i) for i in range(args.repeats))
        print(f"SQLite, {args.repeats} rewards logged then committed one by one:")
        p99 = singles[min(len(singles) - 1, int(len(singles) * 0.99))]
        print(
            f"  commit median {statistics.median(singles) * 1000:6.2f} ms, p99 {p99 * 1000:6.2f} ms"
        )
        for n in (8, 64):
            times = [batch(n) for _ in range(30)]
            print(f"  a batch of {n:2} applied rewards, median of 30: "
                  f"{statistics.median(times) * 1000:6.2f} ms")  # fmt: skip


if __name__ == "__main__":
    main()
