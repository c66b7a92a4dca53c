"""Pacing: the realtime tick rate's bounds, the clock the tick task reads, and exact sleeps.

The engine never reads the wall clock itself: a realtime run reads a `Pacer` (the engine's
clock), so tests drive it with a clock that moves only when they say (`tests/fakes.py`'s
`ManualPacer`); fast runs never sleep.
"""

from __future__ import annotations

import asyncio
import contextlib
import time
from collections.abc import Awaitable, Callable
from typing import Protocol

APPROACH_S = 0.005
"""A realtime tick first sleeps until this long before its deadline (at most a quarter of
the period), then sleeps the rest: see `sleep_until`."""

HZ_MIN = 0.5
"""The slowest realtime tick rate: a tick at least every 2 s, so a reward is applied and a
run answers its controls within a couple of seconds even before `Pacer` wakes it."""
HZ_MAX = 1000.0
"""The fastest realtime tick rate."""


def check_hz(hz: float) -> float:
    """`hz` if it is a realtime tick rate from `HZ_MIN` to `HZ_MAX`, else `ValueError`."""
    if isinstance(hz, bool) or not isinstance(hz, int | float) or not HZ_MIN <= hz <= HZ_MAX:
        raise ValueError(f"hz must be a number from {HZ_MIN:g} to {HZ_MAX:g}, got {hz!r}")
    return float(hz)


class Pacer(Protocol):
    """The realtime tick task's clock: the time, and sleeps that a wake-up cuts short."""

    def now(self) -> float:
        """Seconds on a monotonic clock."""
        ...

    async def sleep(self, seconds: float, wake: asyncio.Event) -> None:
        """Sleep `seconds`, or until `wake` is set if that comes first."""
        ...


class MonotonicPacer:
    """`time.monotonic` and the event loop's timers: the engine's pacer outside tests.

    time.monotonic, not loop.time(): uvloop's clock ticks in whole milliseconds.
    """

    def now(self) -> float:
        """`time.monotonic()`."""
        return time.monotonic()

    async def sleep(self, seconds: float, wake: asyncio.Event) -> None:
        """Wait for `wake` at most `seconds`."""
        if wake.is_set():
            return
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(max(0.0, seconds)):
                await wake.wait()


async def sleep_until(
    deadline: float,
    approach_s: float,
    clock: Callable[[], float],
    sleep: Callable[[float], Awaitable[None]] = asyncio.sleep,
) -> None:
    """Sleep until `clock()` reaches `deadline`: to `approach_s` before it, then the rest.

    One long sleep can overshoot by as long as its event-loop iteration goes on running
    after the sleep is set: libuv (uvloop) works out how long to wait for a timer from a
    clock it reads once per iteration, and the tick's iteration goes on with other
    callbacks and waits for the GIL while the 3D view draws the tick. The second sleep is
    set at the start of a quiet iteration, so it is exact, and it is short.
    """
    now = clock()
    if now < deadline - approach_s:
        await sleep(deadline - approach_s - now)
        now = clock()
    if now < deadline:
        await sleep(deadline - now)
