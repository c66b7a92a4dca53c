"""The service's run engines: created, started, paused and stopped over HTTP.

What the routes, the 3D view and the network service need of the runs is two protocols:
`Engines` (the runs of this service: start, find, subscribe, shut down) and `Live` (one
run as it ticks: read it, reward it, edit it, control it). `EngineManager` and
`server.engine_loop.LiveRun` are them with the engines on an event loop of this process;
`server.engine_process` is them with the engines in a process of their own.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Iterable, Sequence
from typing import Protocol, TypeVar

from core.brain.catalog import Catalog
from core.brain.network import Association
from core.commands import EditAssociation, RewardSource
from core.engine import RewardAck, RunEngine, RunView, Subscription
from core.errors import RunStateError, StorageError
from core.ports import ACTIVE, NetworkPair, RunSpec, RunStatus, RunStore, RunTotals
from core.setup import Setup
from server.engine_loop import EngineLoop, LiveRun

log = logging.getLogger("srlab.engines")
T = TypeVar("T")


class TooManyRunsError(RunStateError):
    """The service runs as many runs as it may."""


class TooManyStreamsError(RunStateError):
    """The service (or the run) has as many live event streams open as it may."""


class RunLetGo(RunStateError):
    """The run ended and its engine was let go (its end stored) before a call reached it.

    With the engines in a process of their own, a call can leave the service while the
    run is ending there and arrive after: a read then finds the run in storage instead
    (`read_live`), anything else is refused as for any run not running (409).
    """


class Live(Protocol):
    """One run ticking (or paused, or ended but not yet let go), as the service reaches it.

    Readers and actions run where the run ticks, between two steps of its tasks; with the
    engines in a process of their own they are pickled, so pass module-level functions,
    `functools.partial`s or `operator.methodcaller`s, never lambdas or closures.
    """

    @property
    def run_id(self) -> int:
        """The run's id."""
        ...

    @property
    def spec(self) -> RunSpec:
        """What the run was started with (its mode as it runs)."""
        ...

    @property
    def status(self) -> RunStatus:
        """The run's status as last known here."""
        ...

    @property
    def error(self) -> str | None:
        """Why the run failed (None: it has not)."""
        ...

    @property
    def hz(self) -> float:
        """The realtime tick rate."""
        ...

    @property
    def catalog(self) -> Catalog:
        """The brain's catalogue of now (immutable: KP's growth replaces it)."""
        ...

    async def read(self, reader: Callable[[RunView], T]) -> T:
        """`reader(view)` where the run ticks: one consistent state of the run."""
        ...

    async def totals(self) -> RunTotals:
        """Episodes, successes and ticks so far."""
        ...

    async def reward(
        self, value: float, *, note: str = "", source: RewardSource = RewardSource.TRAINER
    ) -> RewardAck:
        """`RunEngine.reward`: answered once the reward is in the reward log."""
        ...

    async def edit(self, command: EditAssociation) -> int:
        """`RunEngine.edit`: the edit's log id once it is applied and stored."""
        ...

    async def edit_all(self, commands: Sequence[EditAssociation]) -> list[int | BaseException]:
        """Edits landing at one tick boundary, in order: each one's log id or its error."""
        ...

    async def step(self) -> int:
        """`RunEngine.step`: one tick of a paused realtime run; the tick it ran."""
        ...

    async def control(self, action: Callable[[RunEngine], T]) -> T:
        """`action(engine)` where the run ticks (pause, resume, stop, a rate change)."""
        ...

    def subscribe(self, maxsize: int, tick_hz: float) -> Subscription:
        """A subscription to the run's events; `unsubscribe` it when done."""
        ...

    def unsubscribe(self, sub: Subscription) -> None:
        """Stop feeding a subscription (closed here at once)."""
        ...


class Engines(Protocol):
    """The runs of this service (`EngineManager`'s docstrings say more of each call)."""

    def get(self, run_id: int) -> Live | None:
        """The run ticking or paused here (or one whose end is not stored)."""
        ...

    def engines(self) -> Iterable[Live]:
        """Every run there is an engine for (a copy: safe to await over)."""
        ...

    def running(self) -> int:
        """How many runs are ticking, paused or starting."""
        ...

    def outage(self) -> str | None:
        """What keeps runs from starting or storing, in a sentence (None: nothing).

        Beyond the service's own storage, which /api/health reads itself. Cheap: health asks
        at every poll.
        """
        ...

    def create(self, spec: RunSpec, network: tuple[NetworkPair, ...] | None) -> int:
        """Store a new run (`create_run`; blocking: call in a thread)."""
        ...

    async def start(self, run_id: int) -> Live:
        """Start a stored run from its checkpoint and log."""
        ...

    async def started(self, run_id: int, timeout_s: float = 5.0) -> None:
        """Wait until a started run ticks (or has already ended)."""
        ...

    async def ended(self, run_id: int, timeout_s: float) -> bool:
        """Wait up to `timeout_s` for a run to end; whether it has."""
        ...

    def streams(self, run_id: int | None = None) -> int:
        """How many subscriptions `subscribe` gave are open (to one run, or to all)."""
        ...

    def subscribe(self, run_id: int, maxsize: int, tick_hz: float) -> Subscription:
        """A subscription to a run's events, now or from its next start (capped)."""
        ...

    def followed(self, run_id: int) -> Live | None:
        """The run a stream to `run_id` follows, for the names its events use.

        `get`'s; or, after it was let go, the last one started while a stream to it was
        open (until the last of those closes).
        """
        ...

    def unsubscribe(self, run_id: int, sub: Subscription) -> None:
        """Stop feeding a subscription `subscribe` gave."""
        ...

    def interrupt_all(self) -> None:
        """Ask every run to end at its next tick boundary, as interrupted."""
        ...

    async def shutdown(self, grace_s: float = 5.0) -> None:
        """Interrupt every run and wait for them (runs stay resumable)."""
        ...


class _Finds(Protocol):
    def get(self, run_id: int) -> Live | None: ...


async def read_live(engines: _Finds, run_id: int, reader: Callable[[RunView], T]) -> T | None:
    """`reader` run on the live run; None when it is not running here (read storage then).

    None too when it ended and was let go while the read was on its way (`RunLetGo`).
    """
    live = engines.get(run_id)
    if live is None:
        return None
    try:
        return await live.read(reader)
    except RunLetGo:
        return None


def create_run(store: RunStore, spec: RunSpec, network: tuple[NetworkPair, ...] | None) -> int:
    """Store a new run (status created) and return its id (blocking: call in a thread).

    `network` overrides the condition's. It runs in the spec's world preset and sensor
    definition (an unknown name raises `UnknownNameError`).
    """
    assoc = None
    if network is not None:
        cat = Setup(spec.world, spec.sensors).catalog()
        assoc = tuple(
            Association(
                cat.stimulus(p.stimulus).id,
                cat.behaviour(p.behaviour).id,
                p.strength,
                p.source,  # type: ignore[arg-type]
                p.locked,
            )
            for p in network
        )
    return RunEngine.create(spec, store, network=assoc).run_id


class StreamBook:
    """The event streams `Engines.subscribe` gave and not yet took back, by run, capped."""

    def __init__(self, total: int, per_run: int) -> None:
        self.total = total
        self.per_run = per_run
        self._open: dict[int, set[Subscription]] = {}
        self._followed: dict[int, Live] = {}
        """The run each open stream follows, from its start on: kept until the last stream
        to it closes, so its last events are read with its names after it was let go."""

    def count(self, run_id: int | None = None) -> int:
        """How many are open (to one run, or to all)."""
        if run_id is not None:
            return len(self._open.get(run_id, ()))
        return sum(len(subs) for subs in self._open.values())

    def admit(self, run_id: int) -> None:
        """`TooManyStreamsError` if one more stream to `run_id` would pass a cap."""
        if self.count() >= self.total:
            raise TooManyStreamsError(
                f"{self.total} event streams are open already (SRLAB_MAX_STREAMS)"
            )
        if self.count(run_id) >= self.per_run:
            raise TooManyStreamsError(
                f"run {run_id} has {self.per_run} event streams open already "
                "(SRLAB_MAX_STREAMS_PER_RUN)"
            )

    def add(self, run_id: int, sub: Subscription) -> None:
        """Count a stream given."""
        self._open.setdefault(run_id, set()).add(sub)

    def discard(self, run_id: int, sub: Subscription) -> None:
        """Stop counting a stream taken back."""
        open_ = self._open.get(run_id)
        if open_ is not None:
            open_.discard(sub)
            if not open_:
                del self._open[run_id]
                self._followed.pop(run_id, None)

    def started(self, run_id: int, live: Live) -> None:
        """`run_id` started as `live`: the streams open to it follow it."""
        if run_id in self._open:
            self._followed[run_id] = live

    def followed(self, run_id: int) -> Live | None:
        """The run the streams open to `run_id` follow (None: none has started)."""
        return self._followed.get(run_id)


class EngineManager:
    """Owns the `RunEngine` of every run ticking (or paused) in this process, and no other.

    A created run is stored with a checkpoint before its first tick, and a run that has
    ended has all of its state in storage: neither keeps an engine in memory, so memory
    does not grow with the number of stored runs. Starting a run rebuilds its engine from
    its checkpoint and log, after its slot under `max_runs` is taken; when the run ends, its
    engine is let go once its final status is stored (an engine whose status could not be
    stored is kept until then: it is the truth about how the run ended).

    The engines tick on `loop` (`server.engine_loop`); the manager and its books live on
    the service's loop, and hand runs out as `LiveRun`s, through which the service calls
    and reads them.
    """

    def __init__(
        self,
        store: RunStore,
        catalog: Catalog,
        max_runs: int,
        *,
        loop: EngineLoop,
        max_streams: int = 64,
        max_streams_per_run: int = 16,
    ) -> None:
        self.store = store
        self.catalog = catalog
        """The shipped catalogue under the default sensor definition (names only: each
        run's engine loads its own definition's, see `core.setup.Setup`)."""
        self.max_runs = max_runs
        self.loop = loop
        self._engines: dict[int, LiveRun] = {}
        self._tasks: dict[int, asyncio.Future[RunStatus]] = {}
        """Each run's `RunEngine.run` on the engines' loop, as a future of this loop."""
        self._starting: set[int] = set()
        """Runs whose slot is taken while their engine is rebuilt."""
        self._waiting: dict[int, list[Subscription]] = {}
        """Subscriptions to runs not running here: fed from the run's next start."""
        self._streams = StreamBook(max_streams, max_streams_per_run)
        """The subscriptions `subscribe` gave, by run, until `unsubscribe`."""
        self._ticking: dict[int, asyncio.Task[RunStatus]] = {}
        """The engines' loop's own: each run's task there, while it runs."""

    def get(self, run_id: int) -> LiveRun | None:
        """The run ticking or paused here (or one whose end is not stored)."""
        return self._engines.get(run_id)

    def followed(self, run_id: int) -> Live | None:
        """The run a stream to `run_id` follows (`Engines.followed`)."""
        return self.get(run_id) or self._streams.followed(run_id)

    def engines(self) -> Iterable[LiveRun]:
        """Every run this process has an engine for (a copy: safe to await over)."""
        return tuple(self._engines.values())

    def running(self) -> int:
        """How many runs are ticking, paused or starting."""
        return len(self._starting) + sum(1 for t in self._tasks.values() if not t.done())

    def outage(self) -> str | None:
        """None: the runs here store through the service's storage, which health checks."""
        return None

    def create(self, spec: RunSpec, network: tuple[NetworkPair, ...] | None) -> int:
        """Store a new run (`create_run`; blocking: call in a thread)."""
        return create_run(self.store, spec, network)

    async def start(self, run_id: int) -> LiveRun:
        """Start a stored run from its checkpoint and log (created, stopped, interrupted).

        The run slot is taken first: a start refused (`TooManyRunsError`) or one that fails
        leaves no engine behind, so the run stays as it was stored.
        """
        task = self._tasks.get(run_id)
        if run_id in self._starting or (task is not None and not task.done()):
            live = self._engines.get(run_id)
            status = live.status.value if live is not None else "starting"
            raise RunStateError(f"run {run_id} is {status}")
        if self.running() >= self.max_runs:
            raise TooManyRunsError(
                f"{self.max_runs} runs are running already (SRLAB_MAX_RUNS): stop one first"
            )
        self._starting.add(run_id)
        try:
            stale = self._engines.get(run_id)
            if stale is not None:  # it ended here without its status stored
                await asyncio.to_thread(self._settle_status, stale.engine)
            # In its stored world and definition.
            engine = await asyncio.to_thread(RunEngine.restore, run_id, self.store)
        finally:
            self._starting.discard(run_id)
        live = LiveRun(engine, self.loop)
        self._engines[run_id] = live
        self._streams.started(run_id, live)
        waiting = self._waiting.pop(run_id, [])
        task = asyncio.wrap_future(self.loop.submit(self._run(engine, waiting)))
        task.add_done_callback(lambda _: self._forget(live))
        self._tasks[run_id] = task
        return live

    def streams(self, run_id: int | None = None) -> int:
        """How many subscriptions `subscribe` gave are open (to one run, or to all)."""
        return self._streams.count(run_id)

    def subscribe(self, run_id: int, maxsize: int, tick_hz: float) -> Subscription:
        """A subscription to a run's events, now if it runs here, else from its next start.

        At most `max_streams` are open at once, `max_streams_per_run` to one run: past
        either, `TooManyStreamsError`, and nothing is subscribed.
        """
        self._streams.admit(run_id)
        live = self._engines.get(run_id)
        task = self._tasks.get(run_id)
        if live is not None and task is not None and not task.done():
            # Closed at once if the run has ended meanwhile on the engines' loop.
            sub = live.subscribe(maxsize, tick_hz)
        else:
            sub = Subscription(maxsize, tick_hz)
            self._waiting.setdefault(run_id, []).append(sub)
        self._streams.add(run_id, sub)
        return sub

    def unsubscribe(self, run_id: int, sub: Subscription) -> None:
        """Stop feeding a subscription `subscribe` gave."""
        live = self._engines.get(run_id)
        if live is not None:
            live.unsubscribe(sub)
        waiting = self._waiting.get(run_id)
        if waiting is not None and sub in waiting:
            waiting.remove(sub)
            if not waiting:
                del self._waiting[run_id]
        self._streams.discard(run_id, sub)
        sub.close()

    def _settle_status(self, engine: RunEngine) -> None:
        """Store how a run this process ran ended, if storage still says it is going.

        A run that failed because storage failed often could not store that either. This
        process is the run's only writer, so its own view is the truth.
        """
        if self.store.load_run(engine.run_id).status in ACTIVE:
            final = engine.status if engine.status not in ACTIVE else RunStatus.INTERRUPTED
            self.store.set_status(engine.run_id, final, engine.error)

    async def started(self, run_id: int, timeout_s: float = 5.0) -> None:
        """Wait until a started run ticks (or has already ended)."""
        live = self._engines.get(run_id)
        task = self._tasks.get(run_id)
        if live is None or task is None:
            return
        engine = live.engine

        async def ticking() -> None:  # on the engines' loop
            while engine.status in (RunStatus.CREATED, RunStatus.INTERRUPTED, RunStatus.STOPPED):
                await engine.next_status()

        waiting = asyncio.wrap_future(self.loop.submit(ticking()))
        try:
            async with asyncio.timeout(timeout_s):
                await asyncio.wait((task, waiting), return_when=asyncio.FIRST_COMPLETED)
        finally:
            waiting.cancel()

    def when_ended(self, run_id: int, callback: Callable[[object], None]) -> None:
        """Call `callback` when the run's task ends, after its engine is let go (if it is)."""
        task = self._tasks.get(run_id)
        if task is not None:
            task.add_done_callback(callback)

    async def ended(self, run_id: int, timeout_s: float) -> bool:
        """Wait up to `timeout_s` for a run's task to end; whether it has."""
        task = self._tasks.get(run_id)
        if task is None:
            return True
        done, _ = await asyncio.wait({task}, timeout=timeout_s)
        return bool(done)

    async def _run(self, engine: RunEngine, waiting: list[Subscription]) -> RunStatus:
        """The run on the engines' loop, fed to the subscriptions made before it started."""
        for sub in waiting:
            engine.attach(sub)
        task = asyncio.current_task()
        assert task is not None
        task.set_name(f"run {engine.run_id}")
        self._ticking[engine.run_id] = task
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
            del self._ticking[engine.run_id]

    def _forget(self, live: LiveRun) -> None:
        """Let an ended run's engine go, unless its final status is not in storage."""
        run_id = live.run_id
        if self._engines.get(run_id) is live and live.engine.end_stored:
            del self._engines[run_id]
            self._tasks.pop(run_id, None)

    def interrupt_all(self) -> None:
        """Ask every run to end at its next tick boundary, as interrupted (resumable).

        Its event streams end with it, with a last status event; those of a run that is not
        ticking end at once.
        """
        for run_id, live in self._engines.items():
            task = self._tasks.get(run_id)
            ticking = task is not None and not task.done()
            self.loop.post(_interrupt, live.engine, ticking)
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
            if any(not t.done() for t in tasks):
                # Cancelled on the engines' loop, where each ends interrupted and stores so.
                await self.loop.run(self._cancel_ticking())
            await asyncio.gather(*tasks, return_exceptions=True)

    async def _cancel_ticking(self) -> None:
        """On the engines' loop: cancel every run still going and wait for each to end."""
        tasks = list(self._ticking.values())
        for t in tasks:
            t.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


def _interrupt(engine: RunEngine, ticking: bool) -> None:
    """On the engines' loop: end a run at its next boundary, or its streams now."""
    engine.interrupt()
    if not ticking:
        engine.close_subscriptions()
