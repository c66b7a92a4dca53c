"""The engine with storage: fast-mode throughput and realtime pacing, side by side.

Run as ``.venv/bin/python -m bench.engine`` (``make bench``). Measured in one run:

1. ticks/s of the plain headless loop (`core.run.runner.run`) against the engine in fast mode
   committing everything to SQLite, the store in the engine's process (worker threads)
   as `srlab serve` has it, seed by seed in alternating order: each seed's ratio,
   their mean with a 95% bootstrap interval (goal: at least 0.8);
2. a realtime run at 20 Hz for ``--seconds`` (default 60) with storage writes going on (the
   reinforcement program's rewards, trainer rewards injected 5 times a second, episodes),
   once with each store: tick lateness p99 and max, overruns, and per-reward commit p99
   (goals: p99 <= 5 ms, max <= 25 ms, 0 overruns; commit p99 <= 5 ms).

``--busy N`` runs it all beside N spinning processes (`bench.busy`): a machine with more
runnable work than cores. ``--stores threads,sessions`` measures the store's writes on
SQLite's driver (as it runs) against the same writes through SQLAlchemy sessions, side by
side.
"""

from __future__ import annotations

import argparse
import asyncio
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from bench.busy import busy
from bench.figures import percentile
from core.brain.catalog import load_catalog
from core.engine import EngineStats, RunEngine
from core.lab.stats import Estimate, bootstrap_mean
from core.ports import Mode, RunSpec, RunStore
from core.run.conditions import get_condition
from core.run.runner import run
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade
from server.runtime.tuning import configure_process, freeze_heap

STORES = ("threads", "sessions")
"""How the store writes: ``threads`` on SQLite's driver in the engine's worker threads, as it
runs; ``sessions`` with every write through a SQLAlchemy session instead
(`server.persistence.driver`), for comparison."""
UNTRACED = ", no trace"
"""Marks the engine run without recording episodes' traces (`--untraced`)."""


class Stores:
    """One SQLite database per store kind and name."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder

    def open(self, kind: str, name: str) -> RunStore:
        """A store of `kind` on a new, migrated database `name`."""
        url = f"sqlite:///{self.folder / f'{kind}-{name}'}"
        upgrade(url)
        sessions = make_sessionmaker(make_engine(url))
        return SqlAlchemyRunStore(sessions, driver=kind != "sessions")

    def close(self) -> None:
        """Nothing to stop: the stores are this process's."""


@dataclass(frozen=True, slots=True)
class Fast:
    """Fast mode's figures: median rates, and each store's ratio over seeds with its CI."""

    plain: float
    """Median ticks/s of the plain loop."""
    engine: dict[str, float]
    """Median ticks/s of the engine, by store."""
    ratios: dict[str, Estimate]
    """The engine's rate over the plain loop's, seed by seed: mean and 95% bootstrap CI."""
    ticks: int


def fast(
    stores: Stores,
    kinds: list[str],
    condition: str,
    episodes: int,
    repeats: int,
    *,
    untraced: bool = False,
) -> Fast:
    """The plain loop and the engine with each store, seed by seed, the order alternated.

    The same work runs at rates up to a third apart from one second to the next on a shared
    machine, so one pair of runs says little: each seed's runs go back to back (plain
    first on odd seeds, last on even ones, so a drift in the machine's speed favours
    neither) and the ratio is each seed's, averaged with a bootstrap interval.
    `untraced` adds each store's engine without the episodes' traces (`UNTRACED`), to
    show what recording them costs.
    """
    catalog = load_catalog()
    opened = {kind: stores.open(kind, "fast.db") for kind in kinds}
    run(get_condition(condition), 0, 3, catalog=catalog)  # warm-up of every path
    for store in opened.values():
        spec = RunSpec(condition, 0, 3, Mode.FAST)
        asyncio.run(RunEngine.create(spec, store, catalog=catalog).run())
    freeze_heap()  # as `srlab run` does once it is set up
    plain_rates: list[float] = []
    labels = [*kinds, *(f"{kind}{UNTRACED}" for kind in kinds if untraced)]
    engine_rates: dict[str, list[float]] = {label: [] for label in labels}
    total = 0
    for seed in range(1, repeats + 1):
        order: list[str | None] = [None, *labels]  # None: the plain loop
        ticks: dict[str | None, int] = {}
        for kind in order if seed % 2 else order[::-1]:
            if kind is None:
                started = time.perf_counter()
                ticks[kind] = run(get_condition(condition), seed, episodes, catalog=catalog).ticks
                plain_rates.append(ticks[kind] / (time.perf_counter() - started))
                continue
            store = opened[kind.removesuffix(UNTRACED)]
            spec = RunSpec(condition, seed, episodes, Mode.FAST)
            engine = RunEngine.create(
                spec, store, catalog=catalog, trace=not kind.endswith(UNTRACED)
            )
            started = time.perf_counter()
            asyncio.run(engine.run())
            ticks[kind] = engine.totals.ticks
            engine_rates[kind].append(ticks[kind] / (time.perf_counter() - started))
        assert len(set(ticks.values())) == 1, "the engine ran what the plain loop ran"
        total += ticks[None]
    return Fast(
        statistics.median(plain_rates),
        {kind: statistics.median(r) for kind, r in engine_rates.items()},
        {
            kind: bootstrap_mean([e / p for e, p in zip(r, plain_rates, strict=True)])
            for kind, r in engine_rates.items()
        },
        total,
    )


def realtime(store: RunStore, seconds: float, hz: float) -> tuple[EngineStats, list[float]]:
    """The run's figures, and the round trips of a call that does nothing on a worker thread.

    Every storage call hands its work to a worker thread and back; the empty calls, made
    beside the rewards in the same run, show what that hand-off alone costs the machine.
    """
    engine = RunEngine.create(RunSpec("rp", 2, None, Mode.REALTIME, hz=hz), store)
    hops: list[float] = []

    async def trainer() -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            await asyncio.sleep(0.2)
            await engine.reward(0.5, note="bench")
        engine.stop()

    async def hand_offs() -> None:
        end = time.monotonic() + seconds
        await asyncio.sleep(0.1)
        while time.monotonic() < end:
            started = time.perf_counter()
            await asyncio.to_thread(_nothing)
            hops.append(time.perf_counter() - started)
            await asyncio.sleep(0.2)

    async def main() -> None:
        async with asyncio.TaskGroup() as tg:
            tg.create_task(engine.run())
            tg.create_task(trainer())
            tg.create_task(hand_offs())

    asyncio.run(main())
    return engine.stats, hops


def _nothing() -> None:
    """A worker thread's call that does nothing."""


def ms(x: float) -> str:
    return f"{x * 1000:7.2f} ms"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--hz", type=float, default=20.0)
    parser.add_argument("--episodes", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=9, help="seeds, each a pair")
    parser.add_argument("--condition", default="kp")
    parser.add_argument("--busy", type=int, default=0, help="spinning processes beside")
    parser.add_argument(
        "--stores",
        default="threads",
        help=f"comma-separated, of {', '.join(STORES)} (default: threads)",
    )
    parser.add_argument(
        "--untraced",
        action="store_true",
        help="also run each store's engine without recording episodes' traces (fast mode)",
    )
    args = parser.parse_args()
    kinds = [k.strip() for k in args.stores.split(",") if k.strip()]
    unknown = sorted(set(kinds) - set(STORES))
    if unknown or not kinds:
        parser.error(f"--stores: unknown {', '.join(unknown) or 'nothing'}; of {STORES}")
    configure_process()  # as `srlab run` and `srlab serve` do
    with tempfile.TemporaryDirectory() as tmp, busy(args.busy):
        if args.busy:
            print(f"beside {args.busy} busy processes")
        stores = Stores(Path(tmp))
        try:
            figures = fast(
                stores,
                kinds,
                args.condition,
                args.episodes,
                args.repeats,
                untraced=args.untraced,
            )
            print(
                f"fast mode, {args.condition}, {args.repeats} seeds x {args.episodes} episodes "
                f"({figures.ticks:,} ticks each way), the order alternated seed by seed:"
            )
            print(f"  {'plain headless loop, median':36} {figures.plain:10,.0f} ticks/s")
            for label, rate in figures.engine.items():
                print(f"  {'engine + SQLite, ' + label:36} {rate:10,.0f} ticks/s")
            for label, r in figures.ratios.items():
                ci = f"[{r.low:.2f}, {r.high:.2f}]" if r.n > 1 else "(one seed: no interval)"
                goal = "" if label.endswith(UNTRACED) else "   (goal: >= 0.8)"
                print(f"  {'ratio, ' + label:36} {r.mean:10.2f}   {ci}{goal}")
            for kind in kinds:
                stats, hops = realtime(stores.open(kind, "realtime.db"), args.seconds, args.hz)
                print_realtime(kind, stats, hops, args.hz, args.seconds)
        finally:
            stores.close()


def print_realtime(
    kind: str, stats: EngineStats, hops: list[float], hz: float, seconds: float
) -> None:
    print(f"realtime, rp at {hz:g} Hz for {seconds:g} s with storage writes, store in {kind}:")
    print(f"  ticks                      {stats.ticks:10,}")
    print(f"  tick lateness p50          {ms(stats.lateness_s.percentile(50))}")
    print(f"  tick lateness p99          {ms(stats.lateness_s.percentile(99))}   (goal: <= 5 ms)")
    print(f"  tick lateness max          {ms(stats.lateness_s.max)}   (goal: <= 25 ms)")
    print(f"  overruns                   {stats.overruns:10}   (goal: 0)")
    print(f"  rewards committed          {len(stats.reward_commit_s):10}")
    commit_p99 = ms(stats.reward_commit_s.percentile(99))
    print(f"  reward commit p99          {commit_p99}   (goal: <= 5 ms)")
    print(f"  reward acknowledgement p99 {ms(stats.reward_ack_s.percentile(99))}")
    hop_p99 = percentile(hops, 99)
    print(f"  empty thread hand-off p99  {ms(hop_p99)}   (the floor of every storage call)")


if __name__ == "__main__":
    main()
