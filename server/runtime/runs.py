"""The service's side of its runs: `Runs`, the books, and `LiveRun`, one run as it ticks.

The routes, the 3D view and the network service reach the runs only here. Whatever link
carries the messages (`server.runtime.links`: a host on the service's own loop, or in a
process of its own), this side is the same: it sends commands and queries
(`core.engine.messages`) and keeps each run's last `RunState`, from which it answers what
a run is without asking it; it caps the event streams and keeps the runs they follow.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import uuid
from collections.abc import Callable, Iterable
from dataclasses import replace
from typing import Any, Protocol, TypeVar

from core.brain.catalog import Catalog
from core.brain.memory import DEFAULT_REACTION_S
from core.brain.network import Association
from core.commands import EditAssociation, InjectReward, RewardSource
from core.engine import RewardAck, RunEngine, Subscription
from core.engine.build import REACTION_WINDOW
from core.engine.messages import Command, EditBatch, Query, RunState, Step
from core.errors import RunStateError, StorageError
from core.ports import ACTIVE, NetworkPair, RunSpec, RunStatus, RunStore
from core.run.setup import Setup
from server.runtime.host import RunLetGo

log = logging.getLogger("srlab.engines")
T = TypeVar("T")


class TooManyStreamsError(RunStateError):
    """The service (or the run) has as many live event streams open as it may."""


class Link(Protocol):
    """What carries the messages between `Runs` and a `RunHost` (`server.runtime.links`).

    A link tells its `Runs` what the host says through `Runs.heard_started`,
    `heard_state`, `heard_ended` and `heard_lost`.
    """

    async def start(self, run_id: int) -> None:
        """Start a stored run on the host (heard of as started before this returns)."""
        ...

    async def started(self, run_id: int, timeout_s: float) -> None:
        """Wait until a started run ticks (or has already ended)."""
        ...

    async def request(self, run_id: int, message: Command | Query) -> Any:
        """A command's or query's answer (its state heard before it)."""
        ...

    def subscribe(
        self, run_id: int, maxsize: int, tick_hz: float, *, next_start: bool = True
    ) -> Subscription:
        """A subscription here, fed with the run's events from the host.

        From the run's next start if it is not running (`next_start`), else closed.
        """
        ...

    def unsubscribe(self, sub: Subscription) -> None:
        """Stop feeding a subscription `subscribe` gave, and close it."""
        ...

    def running(self) -> int:
        """How many runs are ticking, paused or starting on the host, as known here."""
        ...

    def outage(self) -> str | None:
        """What keeps the host from running or storing runs (None: nothing)."""
        ...

    def interrupt_all(self) -> None:
        """Ask every run on the host to end at its next tick boundary, as interrupted."""
        ...

    async def shutdown(self, grace_s: float) -> None:
        """Interrupt every run and wait for them (runs stay resumable)."""
        ...

    async def close(self) -> None:
        """Let the host go (after `shutdown`)."""
        ...


class LiveRun:
    """One run ticking (or paused, or ended but not yet let go), as the service reaches it.

    What it is comes from its last `RunState`; what it does, from the commands and
    queries sent to its host.
    """

    def __init__(
        self, runs: Runs, run_id: int, spec: RunSpec, state: RunState, catalog: Catalog
    ) -> None:
        self._runs = runs
        self.run_id = run_id
        self.spec = spec
        """What the run was started with (its mode as it runs)."""
        self.state = state
        """What the run is, as its host last said."""
        self.catalog = catalog
        """The brain's catalogue of `state` (immutable: KP's growth replaces it)."""
        self.done = asyncio.Event()
        """Set when the run's task on the host has ended."""

    @property
    def status(self) -> RunStatus:
        """The run's status as last heard."""
        return self.state.status

    @property
    def error(self) -> str | None:
        """Why the run failed (None: it has not)."""
        return self.state.error

    @property
    def hz(self) -> float:
        """The realtime tick rate."""
        return self.state.hz

    async def send(self, command: Command) -> Any:
        """Apply a command where the run ticks; its answer (`core.engine.messages`)."""
        return await self._runs.link.request(self.run_id, command)

    async def ask(self, query: Query) -> Any:
        """A query's answer, read where the run ticks: one consistent state of the run."""
        return await self._runs.link.request(self.run_id, query)

    async def reward(
        self,
        value: float,
        *,
        note: str = "",
        source: RewardSource = RewardSource.TRAINER,
        tick_seen: int | None = None,
        seen_episode: int | None = None,
        records: tuple[tuple[int, int, int], ...] | None = None,
    ) -> RewardAck:
        """A reward, answered once it is in the reward log.

        It gets its id (`uid`) here, as it arrives: the answer, the log, its event on the
        stream and the console all name it by that. With `tick_seen` it credits the
        reaction window before the tick its trainer saw (`core.engine.RunEngine.reward`).
        """
        reward = InjectReward(
            value,
            note=note,
            source=source,
            uid=uuid.uuid4().hex,
            tick_seen=tick_seen,
            seen_episode=seen_episode,
            records=records,
        )
        ack: RewardAck = await self.send(reward)
        return ack

    async def edit_all(self, edits: Iterable[EditAssociation]) -> list[int | BaseException]:
        """Edits landing at one tick boundary, in order: each one's log id or its error."""
        out: list[int | BaseException] = await self.send(EditBatch(tuple(edits)))
        return out

    async def step(self) -> int:
        """One tick of a paused realtime run; the tick it ran."""
        tick: int = await self.send(Step())
        return tick

    def subscribe(self, maxsize: int, tick_hz: float) -> Subscription:
        """A subscription to the run's events (not counted against the stream caps)."""
        return self._runs.link.subscribe(self.run_id, maxsize, tick_hz, next_start=False)

    def unsubscribe(self, sub: Subscription) -> None:
        """Stop feeding a subscription (closed here at once)."""
        self._runs.link.unsubscribe(sub)

    def __repr__(self) -> str:
        return f"LiveRun(run {self.run_id}, {self.status.value})"


class StreamBook:
    """The event streams `Runs.subscribe` gave and not yet took back, by run, capped."""

    def __init__(self, total: int, per_run: int) -> None:
        self.total = total
        self.per_run = per_run
        self._open: dict[int, set[Subscription]] = {}
        self._followed: dict[int, LiveRun] = {}
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

    def started(self, run_id: int, live: LiveRun) -> None:
        """`run_id` started as `live`: the streams open to it follow it."""
        if run_id in self._open:
            self._followed[run_id] = live

    def followed(self, run_id: int) -> LiveRun | None:
        """The run the streams open to `run_id` follow (None: none has started)."""
        return self._followed.get(run_id)


class Runs:
    """The runs of this service: start, find, subscribe, shut down (over one `Link`).

    `link` is set by whoever builds the two (`server.runtime.links.open_runs`).
    """

    def __init__(
        self,
        store: RunStore,
        *,
        max_streams: int = 64,
        max_streams_per_run: int = 16,
        reaction_window_s: tuple[float, float] = DEFAULT_REACTION_S,
    ) -> None:
        self.store = store
        self.reaction_window_s = reaction_window_s
        """The reaction window a run created here gets unless its spec names one."""
        """The service's storage: runs are created here, and failures stored when the host
        is gone (the host has its own for everything else)."""
        self.link: Link
        self.ended_hooks: list[Callable[[int, RunState], None]] = []
        """Told each run's end as it is heard (its last state), on the service's loop: for
        what must know at once, not poll (`server.services.studies.StudyWatch`)."""
        self._runs: dict[int, LiveRun] = {}
        self._new: dict[int, LiveRun] = {}
        """Runs just started, until `start` takes them (they may have ended and been let go
        by then)."""
        self._streams = StreamBook(max_streams, max_streams_per_run)

    # --- what the link hears --------------------------------------------------------

    def heard_started(self, run_id: int, spec: RunSpec, state: RunState, catalog: Catalog) -> None:
        """The host started a run."""
        live = LiveRun(self, run_id, spec, state, catalog)
        self._runs[run_id] = self._new[run_id] = live
        self._streams.started(run_id, live)

    def heard_state(self, run_id: int, state: RunState, catalog: Catalog | None) -> None:
        """A run's new state (and catalogue, when it changed)."""
        if (live := self._runs.get(run_id)) is not None:
            live.state = state
            if catalog is not None:
                live.catalog = catalog

    def heard_ended(self, run_id: int, state: RunState, let_go: bool) -> None:
        """A run's task ended on the host (`let_go`: its end is stored)."""
        for hook in self.ended_hooks:
            hook(run_id, state)
        if (live := self._runs.get(run_id)) is not None:
            live.state = state
            live.done.set()
            if let_go:
                del self._runs[run_id]

    async def heard_lost(self, error: str) -> None:
        """The host is gone: its runs fail with `error`, stored here (the host could not)."""
        runs = tuple(self._runs.values())
        for live in runs:
            if live.status in ACTIVE:
                live.state = _failed(live.state, error)
            live.done.set()
        self._new.clear()
        for run_id in await asyncio.to_thread(self._store_failed, runs):
            self._runs.pop(run_id, None)  # read from storage from now on

    def _store_failed(self, runs: tuple[LiveRun, ...]) -> list[int]:
        """Store how a lost host's runs ended; the ids stored (blocking: in a thread)."""
        stored = []
        for live in runs:
            try:
                if self.store.load_run(live.run_id).status in ACTIVE:
                    self.store.set_status(live.run_id, live.status, live.error)
            except StorageError as e:  # says what failed; storage's own log has the rest
                log.error("run %s: its failure could not be stored: %s", live.run_id, e)
                continue
            stored.append(live.run_id)
        return stored

    # --- what the service asks ------------------------------------------------------

    def get(self, run_id: int) -> LiveRun | None:
        """The run ticking or paused (or one whose end is not stored)."""
        return self._runs.get(run_id)

    def engines(self) -> Iterable[LiveRun]:
        """Every run there is an engine for (a copy: safe to await over)."""
        return tuple(self._runs.values())

    def running(self) -> int:
        """How many runs are ticking, paused or starting."""
        return self.link.running()

    def outage(self) -> str | None:
        """What keeps runs from starting or storing, in a sentence (None: nothing).

        Beyond the service's own storage, which /api/health reads itself. Cheap: health asks
        at every poll.
        """
        return self.link.outage()

    def create(self, spec: RunSpec, network: tuple[NetworkPair, ...] | None) -> int:
        """Store a new run (`create_run`; blocking: call in a thread).

        Its spec keeps its reaction window (the service's unless it names one), so a
        replay credits as the run did whatever the setting is by then.
        """
        if REACTION_WINDOW not in spec.params:
            params = {**spec.params, REACTION_WINDOW: list(self.reaction_window_s)}
            spec = replace(spec, params=params)
        return create_run(self.store, spec, network)

    async def start(self, run_id: int) -> LiveRun:
        """Start a stored run from its checkpoint and log (`RunHost.start`'s checks)."""
        await self.link.start(run_id)
        return self._new.pop(run_id)

    async def started(self, run_id: int, timeout_s: float = 5.0) -> None:
        """Wait until a started run ticks (or has already ended)."""
        if run_id in self._runs:
            await self.link.started(run_id, timeout_s)

    async def ended(self, run_id: int, timeout_s: float) -> bool:
        """Wait up to `timeout_s` for a run's task to end; whether it has."""
        live = self._runs.get(run_id)
        if live is None:
            return True
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout_s):
                await live.done.wait()
        return live.done.is_set()

    async def ask(self, run_id: int, query: Query) -> Any:
        """`query` answered by the live run; None when it is not running here.

        None too when it ended and was let go while the query was on its way (`RunLetGo`):
        read storage then.
        """
        live = self._runs.get(run_id)
        if live is None:
            return None
        try:
            return await live.ask(query)
        except RunLetGo:
            return None

    def streams(self, run_id: int | None = None) -> int:
        """How many subscriptions `subscribe` gave are open (to one run, or to all)."""
        return self._streams.count(run_id)

    def subscribe(self, run_id: int, maxsize: int, tick_hz: float) -> Subscription:
        """A subscription to a run's events, now if it runs, else from its next start.

        At most `max_streams` are open at once, `max_streams_per_run` to one run: past
        either, `TooManyStreamsError`, and nothing is subscribed.
        """
        self._streams.admit(run_id)
        sub = self.link.subscribe(run_id, maxsize, tick_hz)
        self._streams.add(run_id, sub)
        return sub

    def followed(self, run_id: int) -> LiveRun | None:
        """The run a stream to `run_id` follows, for the names its events use.

        `get`'s; or, after it was let go, the last one started while a stream to it was
        open (until the last of those closes).
        """
        return self.get(run_id) or self._streams.followed(run_id)

    def unsubscribe(self, run_id: int, sub: Subscription) -> None:
        """Stop feeding a subscription `subscribe` gave."""
        self.link.unsubscribe(sub)
        self._streams.discard(run_id, sub)

    def interrupt_all(self) -> None:
        """Ask every run to end at its next tick boundary, as interrupted (resumable)."""
        self.link.interrupt_all()

    async def shutdown(self, grace_s: float = 5.0) -> None:
        """Interrupt every run and wait for them (runs stay resumable)."""
        await self.link.shutdown(grace_s)


def _failed(state: RunState, error: str) -> RunState:
    return replace(state, status=RunStatus.FAILED, error=error)


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
