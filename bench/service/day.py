"""``--part day``: a long day's bounds, D1-D4 (``--part runs``: D4 alone)."""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import random
import time
from collections import Counter

from bench.figures import live_ms, ms, percentile
from bench.service.clients import HOST, Client, RawClient, make_client
from bench.service.harness import (
    CONTROL_TIMEOUT_S,
    Server,
    call,
    edit_target,
    recover,
    start_run,
    stop_run,
    wait_healthy,
)
from bench.service.load import mixed, open_loop


def store_episodes(url: str, episodes: int) -> int:
    """A finished run with `episodes` stored episodes, written before the server starts.

    One real episode (an `innate` run's first, with its trace) is run in-process and its row
    copied under every other number: the reads cost what real episodes' do, without
    running millions of ticks first.
    """
    from sqlalchemy import insert

    from core.engine import RunEngine
    from core.ports import Mode, RunSpec
    from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade
    from server.persistence.orm import EpisodeRow, RunRow

    upgrade(url)
    engine = make_engine(url)
    sessions = make_sessionmaker(engine)
    store = SqlAlchemyRunStore(sessions)
    run = RunEngine.create(RunSpec("innate", seed=1, episodes=1, mode=Mode.FAST), store)
    asyncio.run(run.run())
    first = store.episode(run.run_id, 0)
    assert first is not None
    with sessions.begin() as s:
        for start in range(1, episodes, 1000):
            rows = [
                {
                    "run_id": run.run_id, "episode": n, "outcome": first.outcome,
                    "cause": first.cause, "ticks": first.ticks,
                    "start_tick": n * first.ticks, "rewards": first.rewards,
                    "trace": first.trace,
                }
                for n in range(start, min(episodes, start + 1000))
            ]  # fmt: skip
            s.execute(insert(EpisodeRow), rows)
        s.get_one(RunRow, run.run_id).episodes_done = episodes
    engine.dispose()
    return run.run_id


async def timed_gets(client: Client, paths: list[str]) -> tuple[list[float], Counter[int]]:
    """GET each path in turn (closed loop, one at a time): latencies of the 2xx, statuses."""
    latencies: list[float] = []
    statuses: Counter[int] = Counter()
    for path in paths:
        sent = time.perf_counter()
        status, _ = await client.request("GET", path)
        statuses[status] += 1
        if 200 <= status < 300:
            latencies.append(time.perf_counter() - sent)
    return latencies, statuses


async def open_streams(
    port: int, run_id: int, n: int
) -> tuple[list[asyncio.Task[int]], Counter[int]]:
    """`n` clients of the run's event stream; the accepted ones keep reading (tasks)."""
    statuses: Counter[int] = Counter()
    readers: list[asyncio.Task[int]] = []

    async def one() -> None:
        try:
            reader, writer = await asyncio.open_connection(HOST, port)
        except OSError:
            statuses[0] += 1
            return
        path = f"/api/runs/{run_id}/events?tick_hz=2"
        writer.write(f"GET {path} HTTP/1.1\r\nHost: {HOST}:{port}\r\n\r\n".encode())
        try:
            line = await asyncio.wait_for(reader.readline(), 30)
            status = int(line.split()[1]) if line else 0
        except (TimeoutError, OSError, ValueError, IndexError):
            status = 0
        statuses[status] += 1
        if status != 200:
            writer.close()
            return

        async def drain() -> int:
            got = 0
            with contextlib.suppress(OSError, asyncio.CancelledError):
                while chunk := await reader.read(65536):
                    got += len(chunk)
            writer.close()
            return got

        readers.append(asyncio.create_task(drain()))

    await asyncio.gather(*(one() for _ in range(n)))
    return readers, statuses


async def day(args: argparse.Namespace, server: Server, episodes_run: int) -> None:
    """The long day's figures: an old run's reads, 10,000 episodes, 500 streams, 32 runs."""
    control = RawClient(server.port, 2, CONTROL_TIMEOUT_S)
    reads = RawClient(server.port, 1, args.timeout)
    health = await wait_healthy(control, server, args.startup_timeout)
    print(
        f"A long day: srlab serve {health['version']} on {HOST}:{server.port}, "
        f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}"
    )
    rng = random.Random(args.seed)

    # D2. a run with stored episodes: a page of 50 and one episode with its trace.
    n = args.episodes
    base = f"/api/runs/{episodes_run}/episodes"
    await timed_gets(reads, [f"{base}?limit=50"] * 20)  # warm
    pages, page_status = await timed_gets(
        reads, [f"{base}?limit=50&offset={rng.randrange(0, n - 50)}" for _ in range(args.samples)]
    )
    ones, one_status = await timed_gets(
        reads, [f"{base}/{rng.randrange(n)}" for _ in range(args.samples)]
    )
    _, missing_status = await timed_gets(reads, [f"{base}/{n + 7}"] * 200)
    print(
        f"D2. a run with {n:,} stored episodes (run {episodes_run}), {args.samples} GETs "
        "each, one at a time:"
    )
    for label, values, answers in (
        ("GET .../episodes?limit=50", pages, page_status),
        ("GET .../episodes/{n}", ones, one_status),
        ("GET .../episodes/{missing}", [], missing_status),
    ):
        figures = (
            f"p50 {ms(percentile(values, 50))}  p99 {ms(percentile(values, 99))}  "
            f"max {ms(max(values))}   (goal: p99 <= 20 ms)"
            if values
            else ""
        )
        print(f"  {label:<28}{figures}   statuses {dict(answers)}")

    # D1. an old run: it ages at the fastest realtime rate, then side by side with a fresh one.
    old_id = await start_run(control, 1000.0)
    aged_from = time.perf_counter()
    while True:
        state = await call(control, "GET", f"/api/runs/{old_id}")
        if state["ticks"] >= args.old_ticks or state["status"] != "running":
            break
        await asyncio.sleep(1.0)
    aged_s = time.perf_counter() - aged_from
    fresh_id = await start_run(control, 1000.0)
    await asyncio.sleep(1.0)
    paths = [f"/api/runs/{r}" for _ in range(args.samples) for r in (old_id, fresh_id)]
    old_l: list[float] = []
    fresh_l: list[float] = []
    for path in paths:  # alternating: both see the same machine
        lat, _ = await timed_gets(reads, [path])
        (old_l if path.endswith(f"/{old_id}") else fresh_l).extend(lat)
    old_state = await call(control, "GET", f"/api/runs/{old_id}")
    fresh_state = await call(control, "GET", f"/api/runs/{fresh_id}")
    await stop_run(control, old_id)
    await stop_run(control, fresh_id)
    ratio = percentile(old_l, 99) / percentile(fresh_l, 99)
    print(
        f"D1. GET /api/runs/{{id}} of a run {old_state['ticks']:,} ticks old (aged "
        f"{aged_s:.0f} s at 1000 Hz) and of one {fresh_state['ticks']:,} ticks old, "
        f"{args.samples} each, alternating:"
    )
    print(f"  old   p50 {ms(percentile(old_l, 50))}  p99 {ms(percentile(old_l, 99))}")
    print(f"  fresh p50 {ms(percentile(fresh_l, 50))}  p99 {ms(percentile(fresh_l, 99))}")
    print(f"  p99 old / fresh {ratio:.2f}   (goal: <= 1.5)")
    await recover(control, 30)

    await event_streams(args, server, control)
    await recover(control, 30)
    await control.aclose()
    await reads.aclose()
    await many_runs(args, server)


async def event_streams(
    args: argparse.Namespace, server: Server, control: RawClient
) -> dict[str, float]:
    """D3: ``--streams`` clients of a realtime run's event stream; its figures."""
    run_id = await start_run(control, args.hz)
    await asyncio.sleep(1.0)
    before = (await call(control, "GET", f"/api/runs/{run_id}"))["live"]
    readers, statuses = await open_streams(server.port, run_id, args.streams)
    await asyncio.sleep(args.stream_seconds)
    after = (await call(control, "GET", f"/api/runs/{run_id}"))["live"]
    await stop_run(control, run_id)  # the streams end with the run
    got = await asyncio.gather(*readers)
    overruns = after["overruns"] - before["overruns"]
    print(
        f"D3. {args.streams} clients of one {args.hz:g} Hz run's event stream for "
        f"{args.stream_seconds:g} s (run {run_id}): answers {dict(sorted(statuses.items()))}, "
        f"{sum(got) / 1024:.0f} KiB read by the accepted ones"
    )
    print(
        f"  while they were open: overruns {overruns} "
        f"(goal: 0), lateness max over the run {ms(live_ms(after, 'lateness_max_ms'), 1)}, "
        f"p99 {ms(live_ms(after, 'lateness_p99_ms'), 1)}"
    )
    return {
        "overruns": float(overruns),
        "max_ms": (live_ms(after, "lateness_max_ms") or 0.0) * 1000,
        "p99_ms": (live_ms(after, "lateness_p99_ms") or 0.0) * 1000,
    }


async def many_runs(args: argparse.Namespace, server: Server) -> dict[str, float]:
    """D4: ``--runs`` realtime runs under mixed load (``--part runs`` runs it alone)."""
    control = RawClient(server.port, 2, CONTROL_TIMEOUT_S)
    await wait_healthy(control, server, args.startup_timeout)
    # D4. many realtime runs under mixed load.
    ids = [await start_run(control, args.hz) for _ in range(args.runs)]
    edits, _ = await edit_target(control, args.seed)
    plans = [mixed(r, edits, args.mix, args.seed + k) for k, r in enumerate(ids)]
    client = make_client(args.client, server.port, args.connections, args.timeout)
    await client.warm()
    load = await open_loop(
        client, args.rate, args.seconds, lambda i: plans[i % len(plans)](i), server.pid
    )
    states = [await call(control, "GET", f"/api/runs/{r}") for r in ids]
    failed = [s for s in states if s["status"] == "failed"]
    lives = [s["live"] for s in states if s["live"] is not None]
    for r in ids:
        await stop_run(control, r)
    if failed:
        print(f"D4. {len(failed)} of {args.runs} runs FAILED: {failed[0]['error']}")
    if not lives:
        raise SystemExit("D4: no run reported live figures")
    p99s = [live_ms(x, "lateness_p99_ms") or 0.0 for x in lives]
    maxes = [live_ms(x, "lateness_max_ms") or 0.0 for x in lives]
    overruns = sum(int(x["overruns"]) for x in lives)
    ticks = sum(int(x["ticks_run"]) for x in lives)
    print(
        f"D4. {args.runs} realtime rp runs at {args.hz:g} Hz under {args.rate:g} req/s mixed "
        f"({args.mix.describe(edits is not None)}) for {args.seconds:g} s: {ticks:,} ticks"
    )
    print(
        f"  tick lateness p99: worst run {ms(max(p99s))}, median run "
        f"{ms(percentile(p99s, 50))}   (goal: <= 5 ms)"
    )
    print(f"  tick lateness max: worst run {ms(max(maxes))}   (goal: <= 25 ms)")
    print(f"  overruns over all runs {overruns}   (goal: 0)")
    print(
        f"  requests {len(load.samples):,}, errors {load.errors}, p99 "
        f"{ms(percentile(load.latencies(), 99))}; {load.cpu}"
    )
    if isinstance(client, RawClient):
        await client.aclose()
    await control.aclose()
    return {
        "p99_worst_ms": max(p99s) * 1000,
        "p99_median_ms": percentile(p99s, 50) * 1000,
        "max_ms": max(maxes) * 1000,
        "overruns": float(overruns),
        "request_p99_ms": percentile(load.latencies(), 99) * 1000,
        "errors": float(load.errors),
    }


async def one_run_part(args: argparse.Namespace, server: Server) -> None:
    """``--part runs``: D4 alone."""
    await many_runs(args, server)
