"""Pacing: when the tick task ticks, in one loop whose decisions are a small policy.

The tick task runs one loop (`pace`): while the run goes on, its policy waits until a tick
is due, then runs it. The policies are **fast** (no sleeping: a step, then a burst of ticks
with no await, a turn for the event loop between bursts), **realtime** (drift-free
deadlines, a paused run's wait and its single steps) and **replay** (a resumed run's log,
tick after tick). What the outside asks of the pace (pause, resume, a step, stop, a new
rate) is `Controls`, read at tick boundaries.

The engine never reads the wall clock itself: a realtime run reads a `Pacer` (the engine's
clock), so tests drive it with a clock that moves only when they say (`tests/fakes/`'s
`ManualPacer`); fast runs never sleep.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Protocol

from core.engine.stats import EngineStats
from core.events import EpisodeEnded

FAST_YIELD_TICKS = 128
"""In fast mode the tick task yields to the event loop this often, so commands get in."""

ON_TIME_S = 1e-4
"""A tick woken this little before its deadline is on time: a clock that steps by whole
periods (a robot's, `server.robots.ros2.RobotPacer`) lands on a deadline summed period by
period only to within float rounding."""

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


class Controls:
    """What the outside asks of the tick task's pace; the tick task reads it at boundaries.

    Args:
        hz: the realtime tick rate.
    """

    def __init__(self, hz: float) -> None:
        self.hz = hz
        self.rate_changed = False
        """A new rate since the last tick: the next is due one new period after it."""
        self.paused = False
        self.resumed = asyncio.Event()
        """Cleared while paused; set to resume, to stop, or for a single step."""
        self.resumed.set()
        self.stopping = False
        """The run stops at the next boundary."""
        self.interrupted = False
        """The stop is an interruption (the run can be resumed)."""
        self.until_tick: int | None = None
        """The run stops once this many ticks have run."""
        self.steps: deque[asyncio.Future[int]] = deque()
        """Single-tick steps asked of the paused run, answered with the tick they ran."""
        self.wake = Wake()
        """Set by stop, pause, interrupt and rate changes: a sleeping tick task wakes now."""

    def stop(self) -> None:
        """Stop at the next boundary, waking a paused or sleeping tick task."""
        self.stopping = True
        self.resumed.set()
        self.wake.set()

    def set_rate(self, hz: float) -> None:
        """A new realtime rate (`check_hz` first), from the next tick."""
        self.hz = hz
        self.rate_changed = True
        self.wake.set()

    def step(self) -> asyncio.Future[int]:
        """Ask the paused run for one tick; the future is answered with it."""
        done: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        self.steps.append(done)
        self.resumed.set()  # wakes the paused tick task, which stays paused
        return done

    def answer_step(self, tick: int) -> None:
        """Answer the oldest step asked with the tick just run (each step has a tick)."""
        while self.steps:
            done = self.steps.popleft()
            if not done.done():  # its caller may have given up
                done.set_result(tick)
                return

    def refuse_steps(self, error: BaseException) -> None:
        """Answer every step asked with `error` (the run ended first)."""
        while self.steps:
            done = self.steps.popleft()
            if not done.done():
                done.set_exception(error)


class Ticks(Protocol):
    """What a policy paces: the tick task's ticks (`core.engine.tick_task.TickTask`)."""

    @property
    def tick_count(self) -> int:
        """Ticks run so far."""
        ...

    def more(self) -> bool:
        """Whether the run goes on (episodes left, no stop asked)."""
        ...

    async def step(self) -> None:
        """One tick, with its boundary before and its episode's end after."""
        ...

    def burst(self, ticks: int) -> EpisodeEnded | None:
        """Up to `ticks` ticks with no await; an episode that ended with rewards due."""
        ...

    async def end(self, ended: EpisodeEnded) -> None:
        """End an episode, after the rewards it produced for the next boundary."""
        ...

    def show_paused(self) -> None:
        """Offer the tick the run paused at to viewers whose throttle skipped it."""
        ...


class Policy(Protocol):
    """When the tick task ticks and how many ticks at a time."""

    def more(self) -> bool:
        """Whether this policy has ticks left (a replay ends at its log's last boundary)."""
        ...

    async def due(self) -> bool:
        """Wait until a tick is due: True to run it, False to look again (paused, woken)."""
        ...

    async def tick(self) -> None:
        """Run the ticks due."""
        ...


async def pace(ticks: Ticks, policy: Policy) -> None:
    """The tick task's one loop: while the run goes on, wait for a tick and run it."""
    while ticks.more() and policy.more():
        if await policy.due():
            await policy.tick()


class Fast:
    """No sleeping: a step, then up to `FAST_YIELD_TICKS - 1` ticks with no await between.

    The event loop gets a turn between bursts, so edits, trainers' rewards, pauses and the
    writers get in.
    """

    def __init__(self, ticks: Ticks, controls: Controls) -> None:
        self._ticks = ticks
        self._controls = controls

    def more(self) -> bool:
        """Always: the run's episodes and stops end a fast run."""
        return True

    async def due(self) -> bool:
        """At once, after a turn for the event loop; a paused run waits for its resume."""
        await asyncio.sleep(0)
        if self._controls.paused:
            await self._controls.resumed.wait()
            return False
        return True

    async def tick(self) -> None:
        """A step, then a burst; an episode the burst ended with rewards due ends here."""
        await self._ticks.step()
        ended = self._ticks.burst(FAST_YIELD_TICKS - 1)
        if ended is not None:
            await self._ticks.end(ended)


class Realtime:
    """Drift-free deadlines at `Controls.hz`, overruns skipped, single steps while paused.

    The first tick is due at once.
    """

    def __init__(self, ticks: Ticks, controls: Controls, pacer: Pacer, stats: EngineStats) -> None:
        self._ticks = ticks
        self._controls = controls
        self._pacer = pacer
        self._clock = pacer.now
        self._stats = stats
        self._deadline = self._started = self._clock()

    def more(self) -> bool:
        """Always: the run's episodes and stops end a realtime run."""
        return True

    async def _nap(self, seconds: float) -> None:
        await self._pacer.sleep(seconds, self._controls.wake)

    async def due(self) -> bool:
        """Sleep to the deadline; whether a tick is due then (a wake-up looks again)."""
        controls, clock = self._controls, self._clock
        # A control that arrives from here on sets `wake` again: none is lost.
        controls.wake.clear()
        approach = min(APPROACH_S, 0.25 / controls.hz)
        await sleep_until(self._deadline, approach, clock, self._nap)
        if controls.stopping:
            return False
        if controls.paused:
            await self._paused()
            self._deadline = clock()
            return False
        if controls.rate_changed:
            controls.rate_changed = False
            self._deadline = self._started + 1.0 / controls.hz
        if clock() < self._deadline - ON_TIME_S:
            return False  # woken early (a rate change): sleep what is left
        self._started = clock()
        self._stats.lateness_s.add(max(0.0, self._started - self._deadline))
        return True

    async def _paused(self) -> None:
        """Wait for a resume, or run the single step asked and stay paused."""
        controls, ticks = self._controls, self._ticks
        ticks.show_paused()
        await controls.resumed.wait()
        if controls.paused and controls.steps and not controls.stopping:
            # A single-tick step: one tick at this boundary, then paused again.
            controls.resumed.clear()
            await ticks.step()
            controls.answer_step(ticks.tick_count)
            if controls.steps:
                controls.resumed.set()  # the next one, at the next boundary

    async def tick(self) -> None:
        """One tick; the next deadline one period on, past any periods it overran."""
        controls, clock = self._controls, self._clock
        await self._ticks.step()
        if controls.steps:  # asked for just before a resume: this tick is the oldest's
            controls.answer_step(self._ticks.tick_count)
        period = 1.0 / controls.hz
        self._deadline += period
        behind = clock() - self._deadline
        if behind > 0:
            # An overrun: skip the missed periods instead of bursting to catch up.
            missed = math.floor(behind / period) + 1
            self._stats.overruns += missed
            self._deadline += missed * period


class Replay:
    """A resumed run's ticks up to its log's last boundary, with no sleeping.

    Each step applies the log's entries for its boundary first (`TickTask.step`).
    """

    def __init__(self, ticks: Ticks, last_tick: int) -> None:
        self._ticks = ticks
        self._last_tick = last_tick

    def more(self) -> bool:
        """Until the log's last boundary."""
        return self._ticks.tick_count + 1 <= self._last_tick

    async def due(self) -> bool:
        """At once."""
        return True

    async def tick(self) -> None:
        """One step, and a turn for the event loop every `FAST_YIELD_TICKS` ticks."""
        await self._ticks.step()
        if self._ticks.tick_count % FAST_YIELD_TICKS == 0:
            await asyncio.sleep(0)
