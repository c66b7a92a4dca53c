"""The engine's event streams: slow and throttled subscribers, a stream's ticks at any rate."""

from __future__ import annotations

import asyncio
from functools import partial
from itertools import pairwise

import pytest
from enginehelpers import CATALOG, drive, fast, realtime, wait_ticks
from fakes import InMemoryRunStore

from core.engine import (
    EventBus,
    RunEngine,
    StatusChanged,
    Subscription,
    SubscriptionClosed,
    TickPublished,
)
from core.ports import RunStatus


def test_a_slow_subscriber_never_stalls_the_tick_task() -> None:
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(fast("delayed", 6, 20), store, catalog=CATALOG)
    slow = engine.subscribe(maxsize=2, tick_hz=1e6)
    assert asyncio.run(engine.run()) is RunStatus.FINISHED
    assert engine.totals.episodes == 20
    assert slow.dropped > 0
    assert slow.pending == 2


def test_tick_snapshots_are_throttled_per_subscriber() -> None:
    engine = RunEngine.create(realtime("delayed", 8, hz=500.0), InMemoryRunStore(CATALOG))
    few = engine.subscribe(maxsize=10_000, tick_hz=20.0)
    none = engine.subscribe(maxsize=10_000)

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 100)
        e.stop()

    asyncio.run(drive(engine, script))
    ticks = [ev for ev in few.drain() if isinstance(ev, TickPublished)]
    assert 1 <= len(ticks) < engine.stats.ticks / 2
    assert not any(isinstance(ev, TickPublished) for ev in none.drain())


def _ticks_sent(tick_hz: float, run_hz: float, jitter_s: list[float]) -> list[int]:
    """The ticks a `tick_hz` subscription is sent of a `run_hz` run whose tick k is
    published `jitter_s[k]` after its due time, the clock injected."""
    bus = EventBus()
    sub = bus.attach(Subscription(maxsize=10_000, tick_hz=tick_hz))
    sim = RunEngine.create(realtime("delayed", 8), InMemoryRunStore(CATALOG)).sim
    sim.reset()
    snap = sim.snapshot
    for tick, jitter in enumerate(jitter_s):
        at = 1000.0 + tick / run_hz + jitter
        event = partial(TickPublished, 1)
        bus.publish_tick(snap._replace(tick=tick), event, run_period=1 / run_hz, now=at)
    return [ev.snapshot.tick for ev in sub.drain() if isinstance(ev, TickPublished)]


# A run's ticks arrive up to 15 ms early or late at 10 Hz, alternating (a loaded machine).
JITTER = [(-1) ** k * 0.015 * ((k * 7) % 5) / 4 for k in range(100)]


def test_a_stream_at_the_runs_own_rate_gets_every_tick_early_or_late() -> None:
    assert _ticks_sent(10.0, 10.0, [0.0] * 100) == list(range(100))
    assert _ticks_sent(10.0, 10.0, JITTER) == list(range(100))
    assert _ticks_sent(10.0, 10.0, [-0.001] * 100) == list(range(100))  # always a bit early


def test_a_slower_stream_gets_evenly_spaced_ticks() -> None:
    for run_hz, tick_hz, every in [(10.0, 5.0, 2), (10.0, 2.0, 5), (500.0, 20.0, 25)]:
        for jitter in ([0.0] * 200, [j * 10.0 / run_hz for j in JITTER * 2]):
            sent = _ticks_sent(tick_hz, run_hz, jitter)
            gaps = {b - a for a, b in pairwise(sent)}
            assert gaps == {every}, (run_hz, tick_hz, gaps)
    # After a stall the stream picks up at the next tick, and does not burst to catch up.
    stalled = [0.0] * 10 + [0.55] * 10
    assert _ticks_sent(5.0, 10.0, stalled) == [0, 2, 4, 6, 8, 10, 12, 14, 16, 18]


def test_a_throttled_subscriber_sees_the_paused_tick_and_every_step() -> None:
    """Steps come faster than the throttle allows, yet each one is shown: nothing after a
    step would replace a skipped one, so a viewer would be left a tick behind for good."""
    engine = RunEngine.create(realtime("delayed", 8, hz=50.0), InMemoryRunStore(CATALOG))
    sub = engine.subscribe(maxsize=10_000, tick_hz=0.5)  # one tick per 2 s at most
    shown: list[int] = []

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 5)
        e.pause()
        while e.status is not RunStatus.PAUSED:
            await asyncio.sleep(0.001)
        async with asyncio.timeout(60):  # a bound for a hang, not a speed test
            while not shown or shown[-1] != e.sim.tick_count:
                await asyncio.sleep(0.001)
                shown.extend(
                    ev.snapshot.tick for ev in sub.drain() if isinstance(ev, TickPublished)
                )
        for _ in range(3):
            tick = await e.step()
            ticks = [ev.snapshot.tick for ev in sub.drain() if isinstance(ev, TickPublished)]
            assert ticks == [tick]
            shown.extend(ticks)
        e.stop()

    asyncio.run(drive(engine, script))
    assert shown[-3:] == [shown[-4] + 1, shown[-4] + 2, shown[-4] + 3]
    assert len(set(shown)) == len(shown)  # no tick offered twice


def test_a_waiting_reader_is_released_when_its_subscription_closes() -> None:
    """A stream of a run that is not ticking ends at shutdown instead of waiting forever."""
    engine = RunEngine.create(fast("delayed", 3, 2), InMemoryRunStore(CATALOG))
    waiting = engine.subscribe(maxsize=4)
    iterating = engine.subscribe(maxsize=4)

    async def scenario() -> tuple[list[object], list[object]]:
        async def read_all(sub: Subscription) -> list[object]:
            return [ev async for ev in sub]

        readers = [asyncio.create_task(read_all(s)) for s in (waiting, iterating)]
        await asyncio.sleep(0.01)
        assert not any(r.done() for r in readers)  # nothing to read yet: they wait
        engine.unsubscribe(waiting)  # no event comes: closing alone must wake it
        engine.close_subscriptions()  # the status, then the end
        async with asyncio.timeout(2.0):
            first, second = await asyncio.gather(*readers)
        return first, second

    first, second = asyncio.run(scenario())
    assert first == []
    assert [type(ev) for ev in second] == [StatusChanged]
    assert waiting.ended and iterating.ended
    with pytest.raises(SubscriptionClosed):
        asyncio.run(waiting.get())


def test_a_full_subscription_keeps_the_newest_events() -> None:
    sub = Subscription(maxsize=3)
    accepted = [sub.offer(n) for n in range(5)]
    assert accepted == [True, True, True, False, False]
    assert (sub.dropped, sub.pending) == (2, 3)
    assert sub.drain() == [2, 3, 4]
    with pytest.raises(ValueError, match="at least one"):
        Subscription(maxsize=0)
