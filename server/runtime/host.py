"""The runs' host: where every run's engine ticks, on the event loop it is started on.

`RunHost` owns the `RunEngine` of every run ticking (or paused) there, and no other. It
takes the closed message set of `core.engine.messages` and nothing else: a command
(`perform`), a query (answered by the handler registered for its type), a subscription
to a run's events. What it tells the outside goes to its `Outlet`: each run's start, its
`RunState` (after tick boundaries at most every `STATE_PERIOD_S`, or less often past
`STATES_PER_S` over all runs; on every status change, before every answer, and before
events its catalogue has changed for), its events, its end. The service reaches a host
through a link (`server.runtime.links`): in its own process, or in a process of its own.

A created run is stored with a checkpoint before its first tick, and a run that has ended
has all of its state in storage: neither keeps an engine here, so memory does not grow with
the number of stored runs. Starting a run rebuilds its engine from its checkpoint and log,
after its slot under `max_runs` is taken; when the run ends, its engine is let go once its
final status is stored (an engine whose status could not be stored is kept until then: it
is the truth about how the run ended).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Awaitable, Callable, Mapping
from typing import Any, Protocol

from core.brain.catalog import Catalog
from core.engine import RunEngine, RunView, Subscription, SubscriptionClosed
from core.engine.messages import Command, Latest, Query, RunState, latest, perform, state_of
from core.errors import RunStateError, StorageError
from core.ports import ACTIVE, RunSpec, RunStatus, RunStore
from server.robots.connect import Robots

log = logging.getLogger("srlab.engines")

STATE_PERIOD_S = 0.1
"""The shortest time between two `RunState`s of a run published for its ticks alone."""
STATES_PER_S = 500.0
"""The most `RunState`s published a second for ticks alone, over all runs (256 runs: each
every 0.5 s): each is built, and with the engines in a process of their own, pickled and
read by the service."""

QueryHandler = Callable[[RunView, Any], object]
"""Answers one type of `Query` from a run's view, on the host's loop: a value."""

CORE_QUERIES: Mapping[type[Query], QueryHandler] = {Latest: lambda view, _: latest(view)}
"""The queries the core answers itself."""


class TooManyRunsError(RunStateError):
    """The service runs as many runs as it may."""


class RunLetGo(RunStateError):
    """The run ended and its engine was let go (its end stored) before a message reached it.

    With the runs in a process of their own, a message can leave the service while the run
    is ending there and arrive after: a query then reads the run from storage instead, a
    command is refused as for any run not running (409).
    """


class Outlet(Protocol):
    """Where a host says what happens to its runs (the link to the service)."""

    def run_started(self, run_id: int, spec: RunSpec, state: RunState, catalog: Catalog) -> None:
        """A run started here (before any state or event of it)."""
        ...

    def run_state(self, run_id: int, state: RunState, catalog: Catalog | None) -> None:
        """A run's state changed (`catalog`: the new one, when the version changed)."""
        ...

    def run_ended(self, run_id: int, state: RunState, let_go: bool) -> None:
        """A run's task ended (`let_go`: its end is stored and its engine gone)."""
        ...


Deliver = Callable[[list[object]], Awaitable[None]]
"""Hands a batch of a subscription's events on (and waits while the receiver is behind)."""


class RunHost:
    """The runs ticking on this loop, served by the message set (see the module)."""

    def __init__(
        self,
        store: RunStore,
        max_runs: int,
        outlet: Outlet,
        queries: Mapping[type[Query], QueryHandler] = CORE_QUERIES,
    ) -> None:
        self.store = store
        self.max_runs = max_runs
        self.outlet = outlet
        self.queries = {**CORE_QUERIES, **queries}
        self.robots = Robots()
        """The robots its runs drive (a run's world ``ros2:ROBOT``: docs/robots.md)."""
        self._engines: dict[int, RunEngine] = {}
        self._tasks: dict[int, asyncio.Task[RunStatus]] = {}
        self._starting: set[int] = set()
        self._waiting: dict[int, list[Subscription]] = {}
        """Subscriptions to runs not running here: fed from the run's next start."""
        self._sent: dict[int, tuple[RunState, Catalog, int]] = {}
        """What was last published of each run: its state, catalogue and version."""
        self._forwarders: set[asyncio.Task[None]] = set()
        self._watchers: dict[int, asyncio.Task[None]] = {}
        self._publisher: asyncio.Task[None] | None = None

    # --- what the service asks --------------------------------------------------------

    def engine(self, run_id: int) -> RunEngine | None:
        """The run's engine, while it is here (tests and benches read it; nothing else)."""
        return self._engines.get(run_id)

    def running(self) -> int:
        """How many runs are ticking, paused or starting."""
        return len(self._starting) + sum(1 for t in self._tasks.values() if not t.done())

    async def start(self, run_id: int) -> None:
        """Start a stored run from its checkpoint and log (created, stopped, interrupted).

        The run slot is taken first: a start refused (`TooManyRunsError`) or one that fails
        leaves no engine behind, so the run stays as it was stored. The outlet hears of the
        start before this returns.
        """
        task = self._tasks.get(run_id)
        if run_id in self._starting or (task is not None and not task.done()):
            engine = self._engines.get(run_id)
            status = engine.status.value if engine is not None else "starting"
            raise RunStateError(f"run {run_id} is {status}")
        if self.running() >= self.max_runs:
            raise TooManyRunsError(
                f"{self.max_runs} runs are running already (SRLAB_MAX_RUNS): stop one first"
            )
        self._starting.add(run_id)
        try:
            stale = self._engines.get(run_id)
            if stale is not None:  # it ended here without its status stored
                await asyncio.to_thread(self._settle_status, stale)
            # In its stored world and definition (on its robot, for a robot's run).
            engine = await asyncio.to_thread(
                RunEngine.restore, run_id, self.store, connect=self.robots.connect_for(run_id)
            )
        except BaseException:
            await asyncio.to_thread(self.robots.release, run_id)
            raise
        finally:
            self._starting.discard(run_id)
        robot = self.robots.world(run_id)
        if robot is not None:
            loop = asyncio.get_running_loop()
            robot.on_lost(lambda: loop.call_soon_threadsafe(self._robot_lost, engine))
        self._engines[run_id] = engine
        view = engine.view()
        state = state_of(view, 1)
        self._sent[run_id] = (state, view.catalog, 1)
        self.outlet.run_started(run_id, engine.spec, state, view.catalog)
        for sub in self._waiting.pop(run_id, []):
            engine.attach(sub)
        task = asyncio.create_task(self._run(engine), name=f"run {run_id}")
        task.add_done_callback(lambda _: self._ended(engine))
        self._tasks[run_id] = task
        self._watchers[run_id] = asyncio.create_task(
            self._watch(engine), name=f"run {run_id}'s statuses"
        )
        if self._publisher is None:
            self._publisher = asyncio.create_task(self._publish(), name="run states")

    async def started(self, run_id: int, timeout_s: float = 5.0) -> None:
        """Wait until a started run ticks (or has already ended)."""
        engine = self._engines.get(run_id)
        task = self._tasks.get(run_id)
        if engine is None or task is None:
            return

        async def ticking() -> None:
            while engine.status in (RunStatus.CREATED, RunStatus.INTERRUPTED, RunStatus.STOPPED):
                await engine.next_status()

        waiting = asyncio.create_task(ticking())
        try:
            async with asyncio.timeout(timeout_s):
                await asyncio.wait((task, waiting), return_when=asyncio.FIRST_COMPLETED)
        finally:
            waiting.cancel()

    async def request(self, run_id: int, message: Command | Query) -> object:
        """Apply a command or answer a query; the run's state is published before the answer."""
        engine = self._engines.get(run_id)
        if engine is None:  # it ended, and the service has not heard yet
            raise RunLetGo(f"run {run_id} is not running here")
        try:
            if isinstance(message, Query):
                handler = self.queries.get(type(message))
                if handler is None:
                    raise TypeError(f"no run host answers {type(message).__name__}")
                return handler(engine.view(), message)
            return await perform(engine, message)
        finally:
            self.sync(run_id)

    def subscribe(
        self, run_id: int, sub: Subscription, deliver: Deliver, *, next_start: bool = True
    ) -> asyncio.Task[None]:
        """Feed `sub` from the run's events, now or from its next start, into `deliver`.

        Without `next_start`, only the events of the run as it is now: closed at once if
        it is not running here.

        The run's state is published before each batch of events, so the catalogue that
        names what they carry is never older than they are. The returned task ends when the
        subscription closes (cancel it to stop).
        """
        engine = self._engines.get(run_id)
        task = self._tasks.get(run_id)
        if engine is not None and task is not None and not task.done():
            engine.attach(sub)
        elif next_start:
            self._waiting.setdefault(run_id, []).append(sub)
        else:
            sub.close()
        forwarder = asyncio.create_task(self._forward(run_id, sub, deliver))
        self._forwarders.add(forwarder)
        forwarder.add_done_callback(self._forwarders.discard)
        return forwarder

    def interrupt_all(self) -> None:
        """Ask every run to end at its next tick boundary, as interrupted (resumable).

        Its event streams end with it, with a last status event; those of a run that is not
        ticking end at once.
        """
        for run_id, engine in self._engines.items():
            task = self._tasks.get(run_id)
            engine.interrupt()
            if task is None or task.done():
                engine.close_subscriptions()
        for subs in self._waiting.values():
            for sub in subs:
                sub.close()
        self._waiting.clear()

    async def shutdown(self, grace_s: float = 5.0) -> None:
        """Interrupt every run, wait for them, cancel stragglers (runs stay resumable)."""
        self.interrupt_all()
        tasks = [t for t in self._tasks.values() if not t.done()]
        if tasks:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(grace_s):
                    await asyncio.gather(*tasks, return_exceptions=True)
            for t in tasks:
                t.cancel()  # each ends interrupted and stores so
            await asyncio.gather(*tasks, return_exceptions=True)
        if self._publisher is not None:
            self._publisher.cancel()
            await asyncio.gather(self._publisher, return_exceptions=True)
            self._publisher = None

    # --- what the host says -------------------------------------------------------------

    def sync(self, run_id: int, *, catalog_only: bool = False) -> None:
        """Publish the run's state if it changed since it was last published.

        With `catalog_only`, only if its catalogue did (what names a run's events).
        """
        engine = self._engines.get(run_id)
        last = self._sent.get(run_id)
        if engine is None or last is None:
            return
        view = engine.view()
        catalog = view.catalog
        sent, sent_catalog, version = last
        new_catalog = catalog is not sent_catalog
        if new_catalog:
            version += 1
        if not new_catalog and (catalog_only or _same(sent, view)):
            return
        state = state_of(view, version)
        self._sent[run_id] = (state, catalog, version)
        self.outlet.run_state(run_id, state, catalog if new_catalog else None)

    async def _publish(self) -> None:
        """Every `STATE_PERIOD_S`, the state of each run that ticked since.

        One run at a time, spread over the period (all at once, hundreds of runs' states
        would hold up their ticks), and at most `STATES_PER_S` a second over all runs: the
        period grows with the number of runs past that.
        """
        while True:
            runs = list(self._engines)
            period = max(STATE_PERIOD_S, len(runs) / STATES_PER_S)
            if not runs:
                await asyncio.sleep(period)
            for run_id in runs:
                await asyncio.sleep(period / len(runs))
                self.sync(run_id)

    async def _watch(self, engine: RunEngine) -> None:
        """Publish a run's status changes as they come (cancelled when its task ends)."""
        while True:
            await engine.next_status()
            self.sync(engine.run_id)

    async def _forward(self, run_id: int, sub: Subscription, deliver: Deliver) -> None:
        try:
            while True:
                try:
                    first = await sub.get()
                except SubscriptionClosed:
                    return
                events = [first, *sub.drain()]
                # A new catalogue before the events that name it; the figures the events
                # move follow every STATE_PERIOD_S (a state per event batch would double
                # what crosses to the service for every followed run).
                self.sync(run_id, catalog_only=True)
                await deliver(events)
        finally:
            self._unsubscribe(run_id, sub)

    def _unsubscribe(self, run_id: int, sub: Subscription) -> None:
        engine = self._engines.get(run_id)
        if engine is not None:
            engine.unsubscribe(sub)
        waiting = self._waiting.get(run_id)
        if waiting is not None and sub in waiting:
            waiting.remove(sub)
            if not waiting:
                del self._waiting[run_id]
        sub.close()

    # --- a run's life -------------------------------------------------------------------

    def _settle_status(self, engine: RunEngine) -> None:
        """Store how a run this host ran ended, if storage still says it is going.

        A run that failed because storage failed often could not store that either. This
        host is the run's only writer, so its own view is the truth.
        """
        if self.store.load_run(engine.run_id).status in ACTIVE:
            final = engine.status if engine.status not in ACTIVE else RunStatus.INTERRUPTED
            self.store.set_status(engine.run_id, final, engine.error)

    async def _run(self, engine: RunEngine) -> RunStatus:
        try:
            return await engine.run()
        except StorageError as e:
            # An outage, not a bug: its message says what failed, a traceback adds nothing.
            log.error("run %s failed: %s", engine.run_id, e)
            return RunStatus.FAILED
        except Exception:
            log.exception("run %s failed", engine.run_id)
            return RunStatus.FAILED
        finally:
            if self.robots.world(engine.run_id) is not None:
                await asyncio.to_thread(self.robots.release, engine.run_id)

    def _robot_lost(self, engine: RunEngine) -> None:
        """The run's robot went silent (it was sent a zero Twist): interrupt the run."""
        world = self.robots.world(engine.run_id)
        silent = world.robot.lost_after_s if world is not None else math.nan
        engine.error = (
            f"the robot went silent for {silent:g} s: it was stopped; start the run again"
        )
        log.warning("run %s: %s", engine.run_id, engine.error)
        engine.interrupt()

    def _ended(self, engine: RunEngine) -> None:
        """The run's task ended: say so, and let its engine go if its end is stored."""
        run_id = engine.run_id
        watcher = self._watchers.pop(run_id, None)
        if watcher is not None:
            watcher.cancel()
        if self._engines.get(run_id) is not engine:
            return
        self.sync(run_id)
        version = self._sent.pop(run_id, (None, None, 1))[2]
        let_go = engine.end_stored
        if let_go:
            del self._engines[run_id]
            self._tasks.pop(run_id, None)
        self.outlet.run_ended(run_id, state_of(engine.view(), version), let_go)


def _same(sent: RunState, view: RunView) -> bool:
    """Whether `sent` still says what `view` does (a run's figures change with its ticks)."""
    return (sent.status, sent.error, sent.hz, sent.tick, sent.figures.ticks_run) == (
        view.status,
        view.error,
        view.hz,
        view.tick,
        view.stats.ticks,
    )
