"""The engine with storage: fast-mode throughput and realtime pacing, side by side.

Run as ``.venv/bin/python -m bench.engine`` (``make bench``). Measured in one run:

1. ticks/s of the plain headless loop (`core.runner.run`) against the engine in fast mode
   committing everything to SQLite (goal: at least 2/3);
2. a realtime run at 20 Hz for ``--seconds`` (default 60) with storage writes going on (the
   reinforcement program's rewards, trainer rewards injected 5 times a second, episodes):
   tick lateness p99 and max, overruns, and per-reward commit p99
   (goals: p99 <= 5 ms, max <= 25 ms, 0 overruns; commit p99 <= 5 ms).
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import tempfile
import time
from pathlib import Path

from core.brain.catalog import load_catalog
from core.conditions import get_condition
from core.engine import EngineStats, RunEngine
from core.ports import Mode, RunSpec
from core.runner import run
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade
from server.tuning import configure_process


def _store(folder: Path, name: str) -> SqlAlchemyRunStore:
    url = f"sqlite:///{folder / name}"
    upgrade(url)
    return SqlAlchemyRunStore(make_sessionmaker(make_engine(url)))


def fast(folder: Path, condition: str, episodes: int, repeats: int) -> tuple[float, float, int]:
    """Median ticks/s of the plain loop and of the engine with storage, alternated."""
    catalog = load_catalog()
    store = _store(folder, "fast.db")
    run(get_condition(condition), 0, 3, catalog=catalog)  # warm-up of both paths
    asyncio.run(RunEngine.create(RunSpec(condition, 0, 3, Mode.FAST), store, catalog=catalog).run())
    plain_rates, engine_rates = [], []
    ticks = 0
    for seed in range(1, repeats + 1):
        started = time.perf_counter()
        plain = run(get_condition(condition), seed, episodes, catalog=catalog)
        plain_rates.append(plain.ticks / (time.perf_counter() - started))
        engine = RunEngine.create(
            RunSpec(condition, seed, episodes, Mode.FAST), store, catalog=catalog
        )
        started = time.perf_counter()
        asyncio.run(engine.run())
        engine_rates.append(engine.totals.ticks / (time.perf_counter() - started))
        assert engine.totals.ticks == plain.ticks, "the engine ran what the plain loop ran"
        ticks += plain.ticks
    return statistics.median(plain_rates), statistics.median(engine_rates), ticks


def realtime(folder: Path, seconds: float, hz: float) -> EngineStats:
    engine = RunEngine.create(
        RunSpec("rp", 2, None, Mode.REALTIME, hz=hz), _store(folder, "realtime.db")
    )

    async def trainer() -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            await asyncio.sleep(0.2)
            await engine.reward(0.5, note="bench")
        engine.stop()

    async def main() -> None:
        async with asyncio.TaskGroup() as tg:
            tg.create_task(engine.run())
            tg.create_task(trainer())

    asyncio.run(main())
    return engine.stats


def ms(x: float) -> str:
    return f"{x * 1000:7.2f} ms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--hz", type=float, default=20.0)
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--condition", default="kp")
    args = parser.parse_args()
    configure_process()  # as `srlab run` and `srlab serve` do
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        plain, engine, ticks = fast(folder, args.condition, args.episodes, args.repeats)
        print(
            f"fast mode, {args.condition}, {args.repeats} x {args.episodes} episodes "
            f"({ticks:,} ticks each way), medians:"
        )
        print(f"  plain headless loop        {plain:10,.0f} ticks/s")
        print(f"  engine + SQLite storage    {engine:10,.0f} ticks/s")
        print(f"  ratio                      {engine / plain:10.2f}   (goal: >= 0.67)")
        stats = realtime(folder, args.seconds, args.hz)
    print(f"realtime, rp at {args.hz:g} Hz for {args.seconds:g} s with storage writes:")
    print(f"  ticks                      {stats.ticks:10,}")
    print(f"  tick lateness p50          {ms(stats.lateness_s.percentile(50))}")
    print(f"  tick lateness p99          {ms(stats.lateness_s.percentile(99))}   (goal: <= 5 ms)")
    print(f"  tick lateness max          {ms(stats.lateness_s.max)}   (goal: <= 25 ms)")
    print(f"  overruns                   {stats.overruns:10}   (goal: 0)")
    print(f"  rewards committed          {len(stats.reward_commit_s):10}")
    commit_p99 = ms(stats.reward_commit_s.percentile(99))
    print(f"  reward commit p99          {commit_p99}   (goal: <= 5 ms)")
    print(f"  reward acknowledgement p99 {ms(stats.reward_ack_s.percentile(99))}")


if __name__ == "__main__":
    main()
