"""The run's events to its subscribers: bounded queues that drop their oldest event.

Nothing a subscriber does can hold up the tick task: `EventBus.publish` offers each event
to every subscription without waiting, and a full subscription drops its oldest event.
Tick snapshots go only to subscriptions that asked for them, at most at their rate.

A subscription may be read on another event loop, in another thread, than the engine's
(the service reads its runs' events on its own loop while the engines tick on theirs): the
engine's side only appends to it and wakes its reader through the reader's loop.
`EventBus` itself is the engine's: attach and unsubscribe on the engine's loop.
"""

from __future__ import annotations

import asyncio
import math
import threading
import time
from collections import deque
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass

from core.brain.selection import Selector
from core.ports import RunStatus, RunTotals
from core.run.simulation import Snapshot

COMPETITORS = 8
"""How many of a tick's competing behaviours its event carries, strongest first."""


@dataclass(frozen=True, slots=True)
class Competition:
    """What competed for a tick's stimuli: each released behaviour's value, the threshold.

    `values` holds (behaviour, value, the stimulus releasing it most), strongest first, at
    most `COMPETITORS` of them, from the network as it stood when the tick was published.
    """

    threshold: float
    strategy: str
    values: tuple[tuple[int, float, int], ...]

    @classmethod
    def of(cls, selector: Selector, stimuli: tuple[int, ...]) -> Competition:
        """The competition `selector` holds for `stimuli` now."""
        values = selector.values(list(stimuli))
        ranked = sorted(values.items(), key=lambda kv: -kv[1][0])[:COMPETITORS]
        return cls(
            selector.config.threshold,
            selector.config.strategy.value,
            tuple((b, v, s) for b, (v, s) in ranked),
        )

    def __reduce__(self) -> tuple[type[Competition], tuple[object, ...]]:
        # Pickled as its fields in a tuple: a frozen slots class's own state methods cost
        # a lookup of its fields each time, and ticks go to the service many times a second.
        return Competition, (self.threshold, self.strategy, self.values)


@dataclass(frozen=True, slots=True)
class StatusChanged:
    """The run's status changed."""

    run_id: int
    status: RunStatus
    error: str | None = None


@dataclass(frozen=True, slots=True)
class TickPublished:
    """A tick's snapshot, as subscribers see it (throttled to their rate).

    With what a top-down view draws besides the pose: the sonars' readings of that tick
    (in the robot's sonar order, noisy as the robot read them), the first obstacle's centre
    (None: the episode has none) and every obstacle's, the competition among the behaviours
    its stimuli released and the run's totals at that tick (None: not taken), and whether
    its behaviour was released through an association KP taught. Read only when a tick is
    published, never per tick.
    """

    run_id: int
    snapshot: Snapshot
    sonar_m: tuple[float, ...] = ()
    obstacle: tuple[float, float] | None = None
    competition: Competition | None = None
    totals: RunTotals | None = None
    kp: bool = False
    obstacles: tuple[tuple[float, float], ...] = ()
    """Every obstacle's centre at that tick, the first (`obstacle`) first."""

    def __reduce__(self) -> tuple[type[TickPublished], tuple[object, ...]]:
        # As `Competition.__reduce__`: pickled as a tuple of its fields.
        fields = (self.run_id, self.snapshot, self.sonar_m, self.obstacle, self.competition)
        return TickPublished, (*fields, self.totals, self.kp, self.obstacles)


class SubscriptionClosed(Exception):
    """A subscription has ended and every event it held has been read."""


class Subscription:
    """A bounded queue of engine events; when full, the oldest event is dropped.

    A reader waiting in `get` is woken when the subscription closes, so a stream never outlives
    its run: once closed and drained, `get` raises `SubscriptionClosed` and iteration stops.
    `offer` and `close` may be called from another thread than the reader's (the engine's):
    the reader is woken through its own event loop, once for however many events arrived.

    Args:
        maxsize: how many events it holds.
        tick_hz: at most this many tick snapshots per second (0: none).
    """

    def __init__(self, maxsize: int = 256, tick_hz: float = 0.0) -> None:
        if maxsize < 1:
            raise ValueError(f"a subscription holds at least one event, not {maxsize}")
        self._events: deque[object] = deque(maxlen=maxsize)
        self._ready = asyncio.Event()
        self._reader: asyncio.AbstractEventLoop | None = None
        """The loop of the reader waiting in `get` (None: nobody has waited yet)."""
        self._reader_thread = 0
        self._wake_pending = False
        self.tick_period = 1.0 / tick_hz if tick_hz > 0 else math.inf
        self.next_tick_at = 0.0
        self.tick_sent = -1
        """The tick of the last snapshot it was offered (-1: none yet)."""
        self.dropped = 0
        self.closed = False

    @property
    def wants_ticks(self) -> bool:
        """Whether it asked for tick snapshots."""
        return self.tick_period < math.inf

    def due(self, now: float, run_period: float) -> bool:
        """Whether a tick published at `now` by a run ticking every `run_period` s is due.

        Due times keep to a grid one period apart, and the tick nearest to its due time is
        sent: up to half the run's period early (or half the subscription's, when it is the
        shorter). A subscription at its run's own rate is sent every tick, a little early or
        late as each comes; a slower one, evenly spaced ticks.
        """
        return now >= self.next_tick_at - min(run_period, self.tick_period) / 2

    def sent_tick_at(self, now: float) -> None:
        """A tick was sent at `now`: the next is due one period after this one was due.

        More than half a period late (the first tick, the ticks after a pause or a stall),
        the grid starts again from `now`: no burst to catch up.
        """
        period = self.tick_period
        late = now - self.next_tick_at > period / 2
        self.next_tick_at = (now if late else self.next_tick_at) + period

    @property
    def pending(self) -> int:
        """How many events wait to be read."""
        return len(self._events)

    @property
    def ended(self) -> bool:
        """Closed, and every event read."""
        return self.closed and not self._events

    def offer(self, event: object) -> bool:
        """Queue an event without blocking; False when an older one had to go."""
        dropped = len(self._events) == self._events.maxlen
        self.dropped += dropped
        self._events.append(event)
        self._notify()
        return not dropped

    def close(self) -> None:
        """No more events; a waiting reader gets what is left, then `SubscriptionClosed`."""
        self.closed = True
        self._notify()

    def _notify(self) -> None:
        """Wake the reader, on its own loop (from the engine's thread, through it)."""
        reader = self._reader
        if reader is None:
            return  # no reader has waited: it looks at the events before it waits
        if threading.get_ident() == self._reader_thread:
            self._ready.set()
            return
        if self._wake_pending:
            return  # a wake-up is on its way: it finds every event offered by then
        self._wake_pending = True
        try:
            reader.call_soon_threadsafe(self._wake)
        except RuntimeError:  # the reader's loop has closed: nobody is left to wake
            self._wake_pending = False

    def _wake(self) -> None:
        self._wake_pending = False
        self._ready.set()

    def drain(self) -> list[object]:
        """Every waiting event, without blocking."""
        out = []
        events = self._events
        while events:
            out.append(events.popleft())
        return out

    async def get(self) -> object:
        """The next event; raises `SubscriptionClosed` once closed and drained."""
        if self._reader is None:
            # Before looking at the events: an event offered from now on wakes this loop.
            self._reader_thread = threading.get_ident()
            self._reader = asyncio.get_running_loop()
        while not self._events:
            if self.closed:
                raise SubscriptionClosed
            self._ready.clear()
            await self._ready.wait()
        return self._events.popleft()

    async def __aiter__(self) -> AsyncIterator[object]:
        while True:
            try:
                yield await self.get()
            except SubscriptionClosed:
                return


class EventBus:
    """A run's subscriptions, and the offering of its events to them."""

    def __init__(self) -> None:
        self._subscribers: list[Subscription] = []
        self.tick_subscribers = 0
        """How many subscriptions want tick snapshots (0: a tick publishes nothing)."""
        self.closed = False
        """The run has ended: a subscription attached now is closed at once."""

    def attach(self, sub: Subscription) -> Subscription:
        """Feed a subscription from now on (close it, if the run has ended)."""
        if self.closed:
            sub.close()
            return sub
        self._subscribers.append(sub)
        self.tick_subscribers += sub.wants_ticks
        return sub

    def unsubscribe(self, sub: Subscription) -> None:
        """Stop feeding a subscription and close it."""
        if sub in self._subscribers:
            self._subscribers.remove(sub)
            self.tick_subscribers -= sub.wants_ticks
            sub.close()

    def end(self, last: object) -> None:
        """Offer `last` to every subscription, then close and drop them all."""
        self.closed = True
        for sub in list(self._subscribers):
            sub.offer(last)
            self.unsubscribe(sub)

    def close(self) -> None:
        """Close every subscription (the run ended); they stay attached."""
        self.closed = True
        for sub in self._subscribers:
            sub.close()

    def publish(self, event: object) -> None:
        """Offer an event to every subscription."""
        for sub in self._subscribers:
            sub.offer(event)

    def publish_tick(
        self,
        snap: Snapshot,
        event_for: Callable[[Snapshot], TickPublished],
        force: bool = False,
        *,
        run_period: float = 0.0,
        now: float | None = None,
    ) -> None:
        """Offer a tick to the subscriptions due one (all tick subscriptions when forced).

        `event_for` builds the event once, and only for a tick someone is sent.
        `run_period` is how far apart the run's ticks are due (0: as fast as they go), `now`
        the monotonic clock's reading (None: read it here).
        """
        if now is None:
            now = time.monotonic()
        event: TickPublished | None = None
        for sub in self._subscribers:
            if (
                sub.wants_ticks
                and sub.tick_sent != snap.tick
                and (force or sub.due(now, run_period))
            ):
                sub.sent_tick_at(now)
                sub.tick_sent = snap.tick
                if event is None:
                    event = event_for(snap)
                sub.offer(event)
