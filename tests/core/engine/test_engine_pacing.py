"""The engine's realtime pacing: rates, sleeps to the deadline, what wakes a sleeping run."""

from __future__ import annotations

import asyncio
import math
from dataclasses import replace
from typing import Any

import pytest
from enginehelpers import CATALOG, drive, realtime, wait_ticks
from fakes import InMemoryRunStore, ManualPacer

from core.engine import (
    HZ_MAX,
    HZ_MIN,
    RunEngine,
    sleep_until,
)
from core.ports import (
    RunStatus,
)


def test_realtime_pacing_is_measured() -> None:
    engine = RunEngine.create(realtime("delayed", 1, hz=100.0), InMemoryRunStore(CATALOG))

    async def script(e: RunEngine) -> None:
        await wait_ticks(e, 20)
        e.set_rate(200.0)
        assert e.hz == 200.0
        with pytest.raises(ValueError):
            e.set_rate(0.0)
        await wait_ticks(e, 10)
        e.stop()

    asyncio.run(drive(engine, script))
    assert len(engine.stats.lateness_s) >= 30
    assert engine.stats.lateness_s.min >= 0.0


@pytest.mark.parametrize("hz", [0.0, 1e-300, 0.05, HZ_MIN - 1e-9, HZ_MAX + 1, math.inf, math.nan])
def test_a_tick_rate_out_of_bounds_is_refused(hz: float) -> None:
    store = InMemoryRunStore(CATALOG)
    with pytest.raises(ValueError, match=r"hz must be a number from 0\.5 to 1000"):
        RunEngine.create(realtime("delayed", 1, hz=hz), store)
    engine = RunEngine.create(realtime("delayed", 1, hz=HZ_MIN), store)
    with pytest.raises(ValueError, match="hz must be"):
        engine.set_rate(hz)
    assert engine.hz == HZ_MIN


def test_a_run_stored_with_a_tiny_rate_ticks_at_the_slowest_bounded_one() -> None:
    store = InMemoryRunStore(CATALOG)
    engine = RunEngine.create(realtime("delayed", 1, hz=HZ_MIN), store)
    store._runs[engine.run_id].spec = replace(engine.spec, hz=1e-300)
    assert RunEngine.restore(engine.run_id, store).hz == HZ_MIN


def sleepy(pacer: ManualPacer) -> RunEngine:
    """A realtime run at the slowest rate on `pacer`'s clock."""
    return RunEngine.create(
        realtime("delayed", 1, hz=HZ_MIN), InMemoryRunStore(CATALOG), pacer=pacer
    )


async def _asleep_after_first_tick(
    pacer: ManualPacer, engine: RunEngine
) -> asyncio.Task[RunStatus]:
    task = asyncio.create_task(engine.run())
    await pacer.until(lambda: engine.stats.ticks == 1 and pacer.sleeping == 1)
    return task


@pytest.mark.parametrize("how", ["stop", "interrupt"])
def test_stopping_wakes_a_run_sleeping_through_its_tick_period(how: str) -> None:
    # At 0.5 Hz the run sleeps 2 s after its first tick; the pacer's clock never moves, so
    # the run can only end if the stop wakes it.
    pacer = ManualPacer()
    engine = sleepy(pacer)

    async def main() -> RunStatus:
        task = await _asleep_after_first_tick(pacer, engine)
        getattr(engine, how)()
        async with asyncio.timeout(30):  # a hang guard: with the clock still, it never ends
            return await task

    status = asyncio.run(main())
    assert status is (RunStatus.STOPPED if how == "stop" else RunStatus.INTERRUPTED)
    assert (pacer.time, engine.stats.ticks) == (0.0, 1)


def test_pause_and_resume_wake_a_sleeping_run() -> None:
    pacer = ManualPacer()
    engine = sleepy(pacer)

    async def main() -> None:
        task = await _asleep_after_first_tick(pacer, engine)
        async with asyncio.timeout(30):
            engine.pause()
            await pacer.until(lambda: pacer.sleeping == 0)  # waiting for resume, not the clock
            assert engine.status is RunStatus.PAUSED
            engine.resume()  # ticks at once: the pause reset the deadline
            await pacer.until(lambda: engine.stats.ticks == 2)
            engine.stop()
            await task

    asyncio.run(main())
    assert pacer.time == 0.0


def test_a_rate_change_wakes_a_sleeping_run_and_paces_from_its_last_tick() -> None:
    pacer = ManualPacer()
    engine = sleepy(pacer)

    async def main() -> None:
        task = await _asleep_after_first_tick(pacer, engine)
        async with asyncio.timeout(30):
            engine.set_rate(10.0)  # next tick due 0.1 s after the first, not 2 s
            await pacer.until(lambda: pacer.sleeping == 1)
            pacer.advance(0.05)
            await asyncio.sleep(0)
            assert engine.stats.ticks == 1
            pacer.advance(0.05)
            await pacer.until(lambda: engine.stats.ticks == 2)
            engine.stop()
            await task

    asyncio.run(main())
    assert pacer.time == pytest.approx(0.1)


def overshooting_sleep(start: float, overshoot_s: float) -> tuple[list[float], Any, Any]:
    """A clock at `start`, and a sleep whose first call overshoots by `overshoot_s` (as
    uvloop's does when the loop iteration goes on running after the timer is set)."""
    now = [start]
    asked: list[float] = []

    async def sleep(seconds: float) -> None:
        asked.append(seconds)
        now[0] += seconds + (overshoot_s if len(asked) == 1 else 0.0)

    return asked, lambda: now[0], sleep


@pytest.mark.parametrize(
    ("start", "overshoot", "asked", "woke"),
    [
        (0.0, 0.003, [0.045, 0.002], 0.050),  # the short sleep absorbs the overshoot
        (0.0, 0.0, [0.045, 0.005], 0.050),
        (0.0, 0.007, [0.045], 0.052),  # overshot past the deadline: no second sleep
        (0.047, 0.0, [0.003], 0.050),  # already within the approach: one sleep
        (0.051, 0.0, [], 0.051),  # already late: no sleep
    ],
)
def test_a_tick_sleeps_to_near_its_deadline_then_the_rest(
    start: float, overshoot: float, asked: list[float], woke: float
) -> None:
    sleeps, clock, sleep = overshooting_sleep(start, overshoot)
    asyncio.run(sleep_until(0.050, 0.005, clock, sleep))
    assert sleeps == pytest.approx(asked)
    assert clock() == pytest.approx(woke)
