"""Pacing: the realtime tick rate's bounds, the clock the tick task reads, and exact sleeps.

The engine never reads the wall clock itself: a realtime run reads a `Pacer` (the engine's
clock), so tests drive it with a clock that moves only when they say (`tests/fakes/`'s
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


class Wake:
    """What cuts a sleeping tick task's sleep short (stop, pause, interrupt, a new rate).

    Set by those controls, cleared by the tick task; set and read it on the engine's event
    loop. As `asyncio.Event`, but a sleep can wait for it and a timer together without a
    task or an exception (`MonotonicPacer.sleep`): a realtime tick sleeps twice, and with
    `asyncio.timeout` around `Event.wait` each sleep that ran out cancelled its task, about
    a sixth of the engines' thread's time with 32 runs under load (py-spy).
    """

    __slots__ = ("_flag", "_waiters")

    def __init__(self) -> None:
        self._flag = False
        self._waiters: list[asyncio.Future[None]] = []

    def is_set(self) -> bool:
        """Whether it is set."""
        return self._flag

    def set(self) -> None:
        """Set it, and end every wait for it."""
        self._flag = True
        waiters, self._waiters = self._waiters, []
        for w in waiters:
            if not w.done():
                w.set_result(None)

    def clear(self) -> None:
        """Unset it: a wait from now on lasts until the next `set`."""
        self._flag = False

    def waiter(self) -> asyncio.Future[None]:
        """A future done when it is set (at once, if it is); `forget` it if unused."""
        fut: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        if self._flag:
            fut.set_result(None)
        else:
            self._waiters.append(fut)
        return fut

    def forget(self, fut: asyncio.Future[None]) -> None:
        """Stop tracking a waiter that ended otherwise (its timer)."""
        with contextlib.suppress(ValueError):
            self._waiters.remove(fut)

    async def wait(self) -> None:
        """Until it is set."""
        await self.waiter()


class Pacer(Protocol):
    """The realtime tick task's clock: the time, and sleeps that a wake-up cuts short."""

    def now(self) -> float:
        """Seconds on a monotonic clock."""
        ...

    async def sleep(self, seconds: float, wake: Wake) -> None:
        """Sleep `seconds`, or until `wake` is set if that comes first."""
        ...


class MonotonicPacer:
    """`time.monotonic` and the event loop's timers: the engine's pacer outside tests.

    time.monotonic, not loop.time(): uvloop's clock ticks in whole milliseconds.
    """

    def now(self) -> float:
        """`time.monotonic()`."""
        return time.monotonic()

    async def sleep(self, seconds: float, wake: Wake) -> None:
        """Wait for `wake` at most `seconds`: one future, ended by a timer or by `wake`."""
        if wake.is_set():
            return
        fut = wake.waiter()
        timer = fut.get_loop().call_later(max(0.0, seconds), _end_sleep, fut)
        try:
            await fut
        finally:
            timer.cancel()
            if not wake.is_set():
                wake.forget(fut)


def _end_sleep(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)


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
