"""The engine: the paper's two threads as two asyncio tasks around one simulation.

The **tick task** paces ticks (realtime: drift-free deadlines; fast: no sleeping) and at
each tick boundary makes sure every reward stamped with that boundary has been applied,
then applies commands (association edits), then runs the tick (sense, perceive, select,
KP percept, motor, STM). The **reward task** takes rewards off a queue in order and
applies them (pop STM, Eq. (1), network insertions, KP). Around them, writer tasks keep
storage in step without holding either up: trainers' rewards are logged durably on arrival
(that is the acknowledgement), what each applied reward and edit changed is committed in
the order it happened, and episodes with their checkpoints after the rewards before them.

A reward is stamped with the boundary it arrives before and credits exactly the STM
records of earlier ticks, so a run is reproducible from its seed and command log: in fast
mode it gives the same LTM as the plain headless loop, and a resumed run replays its log
from the last checkpoint. Storage is reached only through `core.ports.RunStore`, from a
worker thread; subscribers read events through bounded queues that drop their oldest
event rather than ever block the tick task.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections import deque
from collections.abc import AsyncIterator, Awaitable, Callable
from dataclasses import dataclass, field, replace
from typing import Any, Protocol, TypeVar

from core.brain.brain import BrainConfig, RewardOutcome
from core.brain.catalog import Catalog
from core.brain.network import Association, BehaviourNetwork
from core.checkpoint import decode, encode, export_state, restore_simulation
from core.commands import INTERNAL_SOURCES, EditAssociation, InjectReward, RewardSource
from core.conditions import Condition, get_condition
from core.errors import CatalogError, RunStateError, StorageError
from core.events import (
    AssociationDemoted,
    AssociationPromoted,
    EpisodeEnded,
    Outcome,
    RewardApplied,
    RewardDue,
)
from core.latency import LatencyHistogram
from core.params import applicable, configure
from core.ports import (
    BehaviourSpec,
    Checkpoint,
    CommandRecord,
    EpisodeRecord,
    LearningUpdate,
    Mode,
    NetworkPair,
    RewardCommit,
    RewardRecord,
    RunSpec,
    RunStatus,
    RunStore,
    RunTotals,
    StoredRun,
)
from core.setup import Setup, condition_network
from core.sim.world import WorldConfig
from core.simulation import Simulation, Snapshot
from core.trace import TraceRecorder

_T = TypeVar("_T")

EPISODE_BATCH_S = 0.05
"""How long the episode writer gathers episodes before it commits them together."""
EPISODE_BATCH_MAX = 64
"""The most episodes it commits in one transaction."""

WRITE_BATCH_S = 0.05
"""In fast mode, how long the learning writer gathers rewards before it commits them."""
WRITE_BATCH_MAX = 256
"""The most rewards it commits in one transaction."""

FAST_YIELD_TICKS = 128
"""In fast mode the tick task yields to the event loop this often, so commands get in."""

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


@dataclass(frozen=True, slots=True)
class RewardAck:
    """What a trainer's reward was stored as."""

    id: int
    tick: int
    episode: int
    value: float


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
    (in the robot's sonar order, noisy as the robot read them) and the obstacle's centre
    (None: the episode has none). Read only when a tick is published, never per tick.
    """

    run_id: int
    snapshot: Snapshot
    sonar_m: tuple[float, ...] = ()
    obstacle: tuple[float, float] | None = None


class SubscriptionClosed(Exception):
    """A subscription has ended and every event it held has been read."""


class Subscription:
    """A bounded queue of engine events; when full, the oldest event is dropped.

    A reader waiting in `get` is woken when the subscription closes, so a stream never outlives
    its run: once closed and drained, `get` raises `SubscriptionClosed` and iteration stops.

    Args:
        maxsize: how many events it holds.
        tick_hz: at most this many tick snapshots per second (0: none).
    """

    def __init__(self, maxsize: int = 256, tick_hz: float = 0.0) -> None:
        if maxsize < 1:
            raise ValueError(f"a subscription holds at least one event, not {maxsize}")
        self._events: deque[object] = deque(maxlen=maxsize)
        self._ready = asyncio.Event()
        self.tick_period = 1.0 / tick_hz if tick_hz > 0 else math.inf
        self.next_tick_at = 0.0
        self.tick_sent = -1
        """The tick of the last snapshot it was offered (-1: none yet)."""
        self.dropped = 0
        self.closed = False

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
        self._ready.set()
        return not dropped

    def close(self) -> None:
        """No more events; a waiting reader gets what is left, then `SubscriptionClosed`."""
        self.closed = True
        self._ready.set()

    def drain(self) -> list[object]:
        """Every waiting event, without blocking."""
        out = list(self._events)
        self._events.clear()
        return out

    async def get(self) -> object:
        """The next event; raises `SubscriptionClosed` once closed and drained."""
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


@dataclass
class EngineStats:
    """Pacing and storage figures, for benchmarks and the live view.

    The latencies are histograms (`core.latency`): reading them costs the same whatever
    the run's age.
    """

    ticks: int = 0
    overruns: int = 0
    """Tick periods skipped because a tick ran past its deadline."""
    lateness_s: LatencyHistogram = field(default_factory=LatencyHistogram)
    """How late each realtime tick started after its deadline."""
    reward_commit_s: LatencyHistogram = field(default_factory=LatencyHistogram)
    """Time from applying each reward to committing its learning (queueing included)."""
    reward_ack_s: LatencyHistogram = field(default_factory=LatencyHistogram)
    """Time from a trainer's reward arriving to its acknowledgement."""


@dataclass
class _RewardJob:
    stamp: int
    episode: int
    reward: InjectReward
    external: bool
    release: asyncio.Event = field(default_factory=asyncio.Event)
    """Set by the tick task at the job's boundary: only then is it applied."""
    applied: asyncio.Event = field(default_factory=asyncio.Event)
    committed: asyncio.Event = field(default_factory=asyncio.Event)
    ack: asyncio.Future[RewardAck] | None = None
    arrived: float = 0.0
    logged_id: int | None = None
    logged: asyncio.Event = field(default_factory=asyncio.Event)
    """Set once the reward is in the log (external rewards are logged by the ack task)."""
    committed_before: bool = False
    """Its learning is already in storage (a replayed reward applied before a crash)."""


@dataclass
class _CommandJob:
    stamp: int
    command: EditAssociation
    ack: asyncio.Future[int] | None = None
    update: LearningUpdate | None = None


@dataclass
class _EpisodeJob:
    record: EpisodeRecord
    next_episode: int
    tick: int
    state: dict[str, Any]
    """The learning state after the episode: encoded only if it is a batch's last."""
    totals: RunTotals
    after: _RewardJob | None
    """The last reward applied before the checkpoint: it is committed first."""
    external: _RewardJob | None
    """The last trainer's reward applied before the checkpoint: once `after` is committed
    it is in the log, and its id tells a replay which logged rewards the state holds."""


@dataclass
class _RewardWrite:
    job: _RewardJob
    commit: RewardCommit
    queued: float
    """perf_counter() when it was handed to the writer."""


_CLOSE = object()


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


async def _gather(
    queue: asyncio.Queue[object], window_s: float, limit: int
) -> tuple[list[object], bool]:
    """The next item of `queue` and those arriving within `window_s` after it.

    At most `limit` items; the flag says whether `_CLOSE` came (it ends the gathering and
    is not returned).
    """
    item = await queue.get()
    deadline = asyncio.get_running_loop().time() + window_s
    batch: list[object] = []
    while True:
        if item is _CLOSE:
            return batch, True
        batch.append(item)
        if len(batch) >= limit:
            return batch, False
        if not queue.empty():
            item = queue.get_nowait()
            continue
        if window_s <= 0:
            return batch, False
        try:
            # asyncio.timeout, not wait_for: 3.11's wait_for can swallow the cancellation
            # of a task group whose other task failed.
            async with asyncio.timeout_at(deadline):
                item = await queue.get()
        except TimeoutError:
            return batch, False


class RunEngine:
    """One run: a simulation driven by a tick task and a reward task.

    Build it with `RunEngine.create` (a new run) or `RunEngine.restore` (a stored one), then
    `await engine.run()`. While it runs, `reward`, `edit`, `pause`, `resume`, `stop`,
    `set_rate` and `subscribe` are safe to call from the same event loop.
    """

    def __init__(
        self,
        run_id: int,
        spec: RunSpec,
        store: RunStore,
        sim: Simulation,
        *,
        replay: StoredRun | None = None,
        totals: RunTotals | None = None,
        trace: bool = True,
        pacer: Pacer | None = None,
    ) -> None:
        self.run_id = run_id
        self.spec = spec
        self.store = store
        self.sim = sim
        self.stats = EngineStats()
        self.status = RunStatus.CREATED
        self.error: str | None = None
        self.end_stored = False
        """The run has ended and storage holds its final status."""
        self._replay = replay
        t = totals or RunTotals(0, 0, sim.tick_count)
        self._episodes_done = t.episodes
        self._successes = t.successes
        self._episode_rewards = 0
        # A run stored before rates were bounded ticks at the nearest bounded rate.
        self._hz = min(max(float(spec.hz), HZ_MIN), HZ_MAX)
        self._pacer: Pacer = pacer or MonotonicPacer()
        self._wake = asyncio.Event()
        """Set by stop, pause, interrupt and rate changes: a sleeping tick task wakes now."""
        self._rate_changed = False
        self._trace = TraceRecorder() if trace else None
        self._due: deque[_RewardJob] = deque()
        self._commands: deque[_CommandJob] = deque()
        self._unlogged: list[_CommandJob] = []
        """Edits applied whose log entry the writer has yet to commit."""
        self._queue: asyncio.Queue[object] = asyncio.Queue()
        self._episode_queue: asyncio.Queue[object] = asyncio.Queue()
        self._write_queue: asyncio.Queue[object] = asyncio.Queue()
        self._last_reward_job: _RewardJob | None = None
        self._subscribers: list[Subscription] = []
        self._tick_subscribers = 0
        self._last_snap: Snapshot | None = None
        self._paused = False
        self._resumed = asyncio.Event()
        self._resumed.set()
        self._stop = False
        self._interrupt = False
        self._episode_start_tick = sim.tick_count
        self._need_reset = True
        self._logged_internal: dict[tuple[int, str, float], deque[Any]] = {}
        self._until_tick: int | None = None
        self._last_external_id = 0
        """The newest trainer's reward in the state restored from the checkpoint."""
        self._last_external_job: _RewardJob | None = None
        """The newest trainer's reward applied since (its log id may come later)."""
        self._unacked: deque[_RewardJob] = deque()
        """Trainers' rewards not acknowledged yet, in arrival order (applied ones too)."""
        self._replay_skip_upto = 0
        self._closing = False
        self._settling = 0
        """The boundary being settled (0: none)."""
        self._replayed = asyncio.Event()
        """Set once a resumed run has replayed its log (at once for a new run)."""
        self._held: list[_RewardJob] = []
        if replay is None:
            self._replayed.set()
        self._ack_queue: asyncio.Queue[object] = asyncio.Queue()
        self._steps: deque[asyncio.Future[int]] = deque()
        """Single-tick steps asked of the paused run, answered with the tick they ran."""
        self._status_waiters: list[asyncio.Future[RunStatus]] = []
        """`next_status` futures, answered by the next status change."""

    # --- construction ---------------------------------------------------------------

    @staticmethod
    def _condition(spec: RunSpec) -> tuple[Condition, BrainConfig]:
        condition = get_condition(spec.condition)
        if condition.agent != "brain":
            raise RunStateError(f"condition {condition.name!r} is not run by the engine")
        params = dict(spec.params)
        unknown = set(params) - {"eta", "epsilon", "synthesize"}
        if unknown:
            raise ValueError(f"unknown learning parameters: {', '.join(sorted(unknown))}")
        # The API accepts these for every condition and ignores those a condition does not use.
        return configure(condition, applicable(condition, params))

    @staticmethod
    def _setup(spec: RunSpec, catalog: Catalog | None) -> tuple[Setup, Catalog]:
        """The run's setup and catalogue: `catalog` if given (it must fit), else the setup's.

        A spec that names no sensor definition takes the given catalogue's.
        """
        sensors = spec.sensors or (catalog.definition if catalog is not None else "")
        setup = Setup(spec.world, sensors)
        if catalog is None:
            return setup, setup.catalog()
        if catalog.definition and catalog.definition != setup.sensors_name:
            raise CatalogError(
                f"the catalogue uses sensor definition {catalog.definition!r}, the run "
                f"{setup.sensors_name!r}"
            )
        return setup, catalog

    @classmethod
    def _new_simulation(
        cls,
        spec: RunSpec,
        catalog: Catalog,
        world_config: WorldConfig,
        network: tuple[Association, ...] | None,
    ) -> Simulation:
        """A fresh simulation for a run.

        Its network is `network`, else the spec's knowledge set, else the condition's own;
        a knowledge set is taken in its variant for the catalogue's sensor definition
        (`core.setup.condition_network`).
        """
        condition, config = cls._condition(spec)
        if network is not None:
            net = BehaviourNetwork(len(catalog.stimuli), network)
        else:
            base = condition if spec.network is None else replace(condition, network=spec.network)
            net = condition_network(catalog, base)
        return Simulation(
            condition,
            spec.seed,
            catalog=catalog,
            world_config=world_config,
            network=net,
            brain_config=config,
            defer_rewards=True,
        )

    @classmethod
    def create(
        cls,
        spec: RunSpec,
        store: RunStore,
        *,
        catalog: Catalog | None = None,
        world_config: WorldConfig | None = None,
        network: tuple[Association, ...] | None = None,
        trace: bool = True,
        pacer: Pacer | None = None,
    ) -> RunEngine:
        """A new run, stored with status created.

        It runs in the spec's world preset and sensor definition, stored by name with the
        defaults resolved (an unknown name raises `UnknownNameError`). `catalog` and
        `world_config` replace the setup's: a catalogue must use the definition the spec
        names, and is the definition of a spec that names none.
        """
        check_hz(spec.hz)
        setup, catalog = cls._setup(spec, catalog)
        setup = setup.resolved()
        spec = replace(spec, world=setup.world, sensors=setup.sensors)
        sim = cls._new_simulation(spec, catalog, world_config or setup.world_config(), network)
        pairs = tuple(_pair(sim, a) for a in sim.brain.network)
        run_id = store.create_run(spec, pairs)
        # A checkpoint before the first tick: a run can be rebuilt whatever network it
        # started from (an edited one may change later) and however early it stopped.
        state = export_state(sim)
        state["last_external_reward_id"] = 0
        store.end_episodes(run_id, (), Checkpoint(0, 0, encode(state)), RunTotals(0, 0, 0))
        return cls(run_id, spec, store, sim, trace=trace, pacer=pacer)

    @classmethod
    def restore(
        cls,
        run_id: int,
        store: RunStore,
        *,
        catalog: Catalog | None = None,
        world_config: WorldConfig | None = None,
        trace: bool = True,
        mode: Mode | None = None,
        pacer: Pacer | None = None,
    ) -> RunEngine:
        """A stored run, rebuilt from its last checkpoint; `run()` replays its log first.

        It runs in the world and sensor definition it was stored with (the defaults for a
        run stored before runs kept them).
        """
        stored = store.load_run(run_id)
        if stored.status in (RunStatus.FINISHED, RunStatus.RUNNING):
            raise RunStateError(f"run {run_id} is {stored.status.value}: nothing to resume")
        spec = stored.spec
        setup, catalog = cls._setup(spec, catalog)
        world_config = world_config or setup.world_config()
        if mode is not None:
            spec = replace(spec, mode=mode)
        condition, config = cls._condition(spec)
        skip = 0
        if stored.checkpoint is not None:
            state = decode(stored.checkpoint.state)
            skip = int(state.get("last_external_reward_id", 0))
            sim = restore_simulation(
                condition,
                spec.seed,
                state,
                catalog,
                world_config=world_config,
                defer_rewards=True,
                brain_config=config,
            )
            totals = stored.totals
        else:  # stored before runs got a checkpoint at creation
            sim = cls._new_simulation(spec, catalog, world_config, None)
            totals = RunTotals(0, 0, 0)
        engine = cls(
            run_id, spec, store, sim, replay=stored, totals=totals, trace=trace, pacer=pacer
        )
        engine._replay_skip_upto = skip
        engine._last_external_id = skip
        return engine

    # --- the outside's calls --------------------------------------------------------

    def subscribe(self, maxsize: int = 256, tick_hz: float = 0.0) -> Subscription:
        """A bounded queue of this run's events (ticks at most `tick_hz` per second)."""
        return self.attach(Subscription(maxsize, tick_hz))

    def attach(self, sub: Subscription) -> Subscription:
        """Feed an existing subscription (one made while the run had no engine)."""
        self._subscribers.append(sub)
        self._tick_subscribers += sub.tick_period < math.inf
        return sub

    def unsubscribe(self, sub: Subscription) -> None:
        """Stop feeding a subscription."""
        if sub in self._subscribers:
            self._subscribers.remove(sub)
            self._tick_subscribers -= sub.tick_period < math.inf
            sub.close()

    def close_subscriptions(self) -> None:
        """End every subscription: its reader gets the current status, then the end.

        For a service shutting down: the live streams of a run that is not ticking (created,
        finished) end instead of holding their connections open.
        """
        for sub in list(self._subscribers):
            sub.offer(StatusChanged(self.run_id, self.status, self.error))
            self.unsubscribe(sub)

    async def reward(
        self, value: float, *, note: str = "", source: RewardSource = RewardSource.TRAINER
    ) -> RewardAck:
        """Inject a reward; returns once it is in the reward log (durable).

        It is stamped with the next tick boundary, so it credits every STM record so far.
        """
        self._check_running()
        if not self._replayed.is_set():
            # A resumed run replays its log first; a new reward stamped inside the replay
            # would be applied in an order a later replay could not repeat.
            await self._replayed.wait()
            self._check_running()
        stamp = self.sim.tick_count + 1
        if self._settling >= stamp:
            # That boundary is being settled: a reward arriving now takes the next one, so
            # a stream of rewards can never hold a boundary open.
            stamp = self._settling + 1
        job = _RewardJob(
            stamp,
            self.sim.episode,
            InjectReward(value, note=note, source=source),
            external=True,
            ack=asyncio.get_running_loop().create_future(),
            arrived=time.perf_counter(),
        )
        if stamp > self.sim.tick_count + 1:
            # Held until the tick being settled has run: the rewards it produces for the
            # next boundary come first there, as they do when the log is replayed.
            self._held.append(job)
        else:
            self._due.append(job)
            self._queue.put_nowait(job)
        self._ack_queue.put_nowait(job)
        self._unacked.append(job)
        assert job.ack is not None
        return await job.ack

    async def edit(self, command: EditAssociation) -> int:
        """Change the running robot's network at the next tick boundary; returns the log id."""
        self._check_running(paused=True)
        if not self._replayed.is_set():
            await self._replayed.wait()
            self._check_running(paused=True)
        cat = self.sim.brain.catalog
        cat.stimulus(command.stimulus)
        cat.behaviour(command.behaviour)
        job = _CommandJob(
            self.sim.tick_count + 1, command, asyncio.get_running_loop().create_future()
        )
        self._commands.append(job)
        if self._paused:
            self._apply_commands(job.stamp)
        assert job.ack is not None
        return await job.ack

    def _check_running(self, *, paused: bool = False) -> None:
        """`RunStateError` unless the run is running (or paused, with `paused`).

        Checked before waiting for a replay too: a run that was never started answers at
        once instead of holding a reward until it is.
        """
        ok = (RunStatus.RUNNING, RunStatus.PAUSED) if paused else (RunStatus.RUNNING,)
        if self.status not in ok or self._closing:
            raise RunStateError(f"run {self.run_id} is {self.status.value}, not running")

    def pause(self) -> None:
        """Stop ticking at the next boundary until `resume` (a sleeping tick task wakes)."""
        if self.status is RunStatus.RUNNING:
            self._paused = True
            self._resumed.clear()
            self._set_status(RunStatus.PAUSED)
            self._wake.set()

    def resume(self) -> None:
        """Tick again after a pause."""
        if self.status is RunStatus.PAUSED:
            self._paused = False
            self._set_status(RunStatus.RUNNING)
            self._resumed.set()

    async def step(self) -> int:
        """Run exactly one tick of a paused realtime run; returns the tick it ran.

        The tick task runs it at a tick boundary, as any other tick (rewards and edits due
        there first), and the run stays paused. `RunStateError` unless the run is paused
        and realtime (a fast run has no ticks to wait for), or if it ends first.
        """
        if self.status is not RunStatus.PAUSED or self._closing:
            raise RunStateError(f"run {self.run_id} is {self.status.value}, not paused")
        if self.spec.mode is not Mode.REALTIME:
            raise RunStateError(f"run {self.run_id} is a fast run: it has no single ticks")
        if not self._replayed.is_set():
            await self._replayed.wait()
        done: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        self._steps.append(done)
        self._resumed.set()  # wakes the paused tick task, which stays paused
        return await done

    def _answer_step(self) -> None:
        """Answer the oldest step asked with the tick just run (each step has a tick)."""
        while self._steps:
            done = self._steps.popleft()
            if not done.done():  # its caller may have given up
                done.set_result(self.sim.tick_count)
                return

    def _refuse_steps(self, error: BaseException) -> None:
        while self._steps:
            done = self._steps.popleft()
            if not done.done():
                done.set_exception(error)

    def stop(self) -> None:
        """End the run now, at the boundary after its current tick (status stopped).

        A realtime run sleeping until its next tick wakes at once: a stop never waits out
        a tick period.
        """
        self._stop = True
        self._resumed.set()
        self._wake.set()

    def interrupt(self) -> None:
        """End the run at the next tick boundary (status interrupted: it can be resumed)."""
        self._interrupt = True
        self.stop()

    def set_rate(self, hz: float) -> None:
        """Change the realtime tick rate (`HZ_MIN` to `HZ_MAX`, else `ValueError`).

        The next tick is due one new period after the last one started: a sleeping tick
        task wakes and sleeps again for what is left of that.
        """
        self._hz = check_hz(hz)
        self._rate_changed = True
        self._wake.set()

    @property
    def hz(self) -> float:
        """The realtime tick rate."""
        return self._hz

    @property
    def totals(self) -> RunTotals:
        """Episodes, successes and ticks so far."""
        return RunTotals(self._episodes_done, self._successes, self.sim.tick_count)

    # --- running --------------------------------------------------------------------

    async def run(self, until_tick: int | None = None) -> RunStatus:
        """Run until the episodes are done or the run is stopped; returns the final status.

        `until_tick` stops the run (status stopped) once that many ticks have run.
        """
        self._until_tick = until_tick
        try:
            return await self._run()
        except asyncio.CancelledError:
            await asyncio.shield(self._finish(RunStatus.INTERRUPTED))
            raise

    async def _run(self) -> RunStatus:
        await self._io(self.store.set_status, self.run_id, RunStatus.RUNNING, None)
        self._set_status(RunStatus.RUNNING)
        failure: BaseException | None = None
        try:
            async with asyncio.TaskGroup() as tg:
                tg.create_task(self._reward_task(), name=f"run {self.run_id} rewards")
                tg.create_task(self._write_task(), name=f"run {self.run_id} learning writer")
                tg.create_task(self._episode_task(), name=f"run {self.run_id} episodes")
                tg.create_task(self._ack_task(), name=f"run {self.run_id} acknowledgements")
                tg.create_task(self._tick_task(), name=f"run {self.run_id} ticks")
        except* StorageError as group:
            failure = group.exceptions[0]
            self.error = str(failure)
            self._fail_pending(failure)
            await self._finish(RunStatus.FAILED)  # best effort: storage may be down
        except* Exception as group:
            failure = group.exceptions[0]
            self.error = f"{type(failure).__name__}: {failure}"
            self._fail_pending(failure)
            await self._finish(RunStatus.FAILED)
        if failure is not None:
            raise failure
        if self._interrupt:
            status = RunStatus.INTERRUPTED
        elif self._stop:
            status = RunStatus.STOPPED
        else:
            status = RunStatus.FINISHED
        await self._finish(status)
        return status

    async def _finish(self, status: RunStatus, persist: bool = True) -> None:
        if persist:
            try:
                await self._io(self.store.set_status, self.run_id, status, self.error)
                self.end_stored = True
            except StorageError as e:
                self.error = self.error or str(e)
                status = RunStatus.FAILED
        self._set_status(status)
        for sub in self._subscribers:
            sub.close()

    def _fail_pending(self, error: BaseException) -> None:
        # Held rewards (stamped while a boundary was being settled) are not due yet, but
        # their senders wait for an answer all the same.
        # A trainer's reward applied before its log entry failed is in neither.
        for job in (*self._due, *self._held, *self._unacked):
            if job.ack is not None and not job.ack.done():
                job.ack.set_exception(StorageError(f"the reward was not stored: {error}"))
        for c in (*self._commands, *self._unlogged):
            if c.ack is not None and not c.ack.done():
                c.ack.set_exception(StorageError(f"the edit was not stored: {error}"))

    def _set_status(self, status: RunStatus) -> None:
        self.status = status
        waiters, self._status_waiters = self._status_waiters, []
        for waiter in waiters:
            if not waiter.done():
                waiter.set_result(status)
        self._publish(StatusChanged(self.run_id, status, self.error))

    def next_status(self) -> asyncio.Future[RunStatus]:
        """A future answered with the run's next status (cancel it to stop waiting)."""
        waiter: asyncio.Future[RunStatus] = asyncio.get_running_loop().create_future()
        self._status_waiters.append(waiter)
        return waiter

    def _publish(self, event: object) -> None:
        for sub in self._subscribers:
            sub.offer(event)

    async def _io(self, fn: Callable[..., _T], *args: Any) -> _T:
        return await asyncio.to_thread(fn, *args)

    # --- the tick task --------------------------------------------------------------

    async def _tick_task(self) -> None:
        try:
            if self._replay is not None:
                try:
                    await self._replay_log(self._replay)
                finally:
                    self._replay = None
                    self._replayed.set()
            if self.spec.mode is Mode.REALTIME:
                await self._realtime()
            else:
                await self._fast()
            # No more rewards now; those that arrived after the last tick apply at the
            # boundary after it.
            self._closing = True
            self._release_held()
            await self._settle(self.sim.tick_count + 1, until=math.inf)
        finally:
            self._closing = True
            self._refuse_steps(RunStateError(f"run {self.run_id} ended before the step"))
            self._queue.put_nowait(_CLOSE)
            self._episode_queue.put_nowait(_CLOSE)
            self._ack_queue.put_nowait(_CLOSE)

    def _episodes_left(self) -> bool:
        limit = self.spec.episodes
        return limit is None or self._episodes_done < limit

    def _more(self) -> bool:
        """Whether the tick task should run another tick."""
        if self._until_tick is not None and self.sim.tick_count >= self._until_tick:
            self._stop = True
        return not self._stop and (not self._need_reset or self._episodes_left())

    async def _fast(self) -> None:
        n = 0
        while self._more():
            n += 1
            if n % FAST_YIELD_TICKS == 0 or self._due or self._commands:
                await asyncio.sleep(0)
                if self._paused:
                    await self._resumed.wait()
                    continue
                await self._step()
                continue
            # The common case needs no await: a plain call is the fast path.
            if self._need_reset:
                self._start_episode()
            ended = self._tick()
            if ended is not None:
                if self._due:
                    await self._settle(self.sim.tick_count + 1, internal_only=True)
                self._end_episode(ended)

    async def _nap(self, seconds: float) -> None:
        await self._pacer.sleep(seconds, self._wake)

    async def _realtime(self) -> None:
        clock = self._pacer.now
        wake = self._wake
        deadline = clock()
        started = deadline
        while self._more():
            # A control that arrives from here on sets `wake` again: none is lost.
            wake.clear()
            await sleep_until(deadline, min(APPROACH_S, 0.25 / self._hz), clock, self._nap)
            if self._stop:
                break
            if self._paused:
                if self._tick_subscribers and self._last_snap is not None:
                    # The tick the run paused at, to viewers whose throttle skipped it.
                    self._publish_tick(self._last_snap, force=True)
                await self._resumed.wait()
                if self._paused and self._steps and not self._stop:
                    # A single-tick step: one tick at this boundary, then paused again.
                    self._resumed.clear()
                    await self._step()
                    self._answer_step()
                    if self._steps:
                        self._resumed.set()  # the next one, at the next boundary
                deadline = clock()
                continue
            if self._rate_changed:
                self._rate_changed = False
                deadline = started + 1.0 / self._hz
            if clock() < deadline:
                continue  # woken early (a rate change): sleep what is left
            started = clock()
            self.stats.lateness_s.add(max(0.0, started - deadline))
            await self._step()
            if self._steps:  # asked for just before a resume: this tick is the oldest's
                self._answer_step()
            period = 1.0 / self._hz
            deadline += period
            behind = clock() - deadline
            if behind > 0:
                # An overrun: skip the missed periods instead of bursting to catch up.
                missed = math.floor(behind / period) + 1
                self.stats.overruns += missed
                deadline += missed * period

    async def _step(self) -> None:
        """One tick, with its boundary before and its episode's end after."""
        sim = self.sim
        if self._need_reset:
            self._start_episode()
        if self._due or self._commands:
            await self._settle(sim.tick_count + 1)
        ended = self._tick()
        if ended is not None:
            if self._due:
                # The episode's own rewards (the task's, the program's) apply before it
                # ends; a trainer's reward arriving now applies after the next reset.
                await self._settle(sim.tick_count + 1, internal_only=True)
            self._end_episode(ended)

    def _tick(self) -> EpisodeEnded | None:
        """Run one tick of the simulation and hand its events on."""
        result = self.sim.tick()
        self.stats.ticks += 1
        snap = result.snapshot
        if self._trace is not None:
            self._trace.add(snap)
        self._last_snap = snap
        if self._tick_subscribers:
            # A single step of a paused run is always shown: no later tick would replace it.
            self._publish_tick(snap, force=self._paused)
        ended: EpisodeEnded | None = None
        if result.events:
            for e in result.events:
                if isinstance(e, RewardDue):
                    self._enqueue_internal(e)
                elif isinstance(e, EpisodeEnded):
                    ended = e
                else:
                    self._publish(e)
        if self._held:
            self._release_held()
        return ended

    def _release_held(self) -> None:
        for job in self._held:
            self._due.append(job)
            self._queue.put_nowait(job)
        self._held.clear()

    def _start_episode(self) -> None:
        self.sim.reset()
        self._need_reset = False
        self._episode_start_tick = self.sim.tick_count
        self._episode_rewards = 0

    def _publish_tick(self, snap: Snapshot, force: bool = False) -> None:
        """Offer a tick to the subscribers due one (all tick subscribers when forced)."""
        now = time.monotonic()
        event: TickPublished | None = None
        for sub in self._subscribers:
            if (
                sub.tick_period < math.inf
                and sub.tick_sent != snap.tick
                and (force or now >= sub.next_tick_at)
            ):
                sub.next_tick_at = now + sub.tick_period
                sub.tick_sent = snap.tick
                if event is None:  # built once, and only for a tick someone is sent
                    sim = self.sim
                    event = TickPublished(
                        self.run_id, snap, sim.sonar_m(), sim.world.layout.obstacle_center
                    )
                sub.offer(event)

    def _enqueue_internal(self, e: RewardDue) -> None:
        reward = InjectReward(e.value, note=e.note, source=RewardSource(e.source))
        job = _RewardJob(e.tick, e.episode, reward, False)
        logged = self._logged_internal.get((e.tick, e.source, e.value))
        if logged:
            stored = logged.popleft()
            job.logged_id, job.committed_before = stored.id, stored.applied
        self._due.append(job)
        self._queue.put_nowait(job)

    async def _settle(
        self, boundary: int, *, internal_only: bool = False, until: float | None = None
    ) -> None:
        """At the boundary before tick `boundary`: apply its rewards, then its commands.

        `until` widens the stamps taken (shutdown takes every reward still due).
        """
        limit = boundary if until is None else until
        due = self._due
        self._settling = boundary
        try:
            while due and due[0].stamp <= limit:
                job = due[0]
                if internal_only and job.external:
                    break
                job.release.set()
                await job.applied.wait()
                due.popleft()
        finally:
            self._settling = 0
        if self._commands and not internal_only:
            self._apply_commands(boundary)

    def _apply_commands(self, boundary: int) -> None:
        while self._commands and self._commands[0].stamp <= boundary:
            job = self._commands.popleft()
            job.update = self._apply_edit(job.command)
            self._unlogged.append(job)
            self._queue.put_nowait(job)

    def _apply_edit(self, edit: EditAssociation) -> LearningUpdate:
        brain = self.sim.brain
        s = brain.catalog.stimulus(edit.stimulus).id
        b = brain.catalog.behaviour(edit.behaviour).id
        if edit.strength is None:
            brain.network.remove(s, b, force=True)
            return LearningUpdate(network_removals=((edit.stimulus, edit.behaviour),))
        from core.brain.catalog import SOURCES

        source = edit.source if edit.source in SOURCES else "dp"
        assoc = Association(s, b, edit.strength, source, edit.locked)
        brain.network.put(assoc, force=True)
        return LearningUpdate(network_upserts=(_pair(self.sim, assoc),))

    def _end_episode(self, ended: EpisodeEnded) -> None:
        sim = self.sim
        self._episodes_done += 1
        self._successes += ended.outcome is Outcome.SUCCESS
        trace = self._trace.pack() if self._trace is not None else b""
        record = EpisodeRecord(
            episode=ended.episode,
            outcome=ended.outcome.value,
            cause=ended.cause.value if ended.cause else None,
            ticks=ended.ticks,
            start_tick=self._episode_start_tick,
            rewards=self._episode_rewards,
            trace=trace,
        )
        state = export_state(sim)
        self._episode_queue.put_nowait(
            _EpisodeJob(
                record,
                sim.episode + 1,
                sim.tick_count,
                state,
                self.totals,
                self._last_reward_job,
                self._last_external_job,
            )
        )
        self._need_reset = True
        self._publish(ended)

    # --- replay ---------------------------------------------------------------------

    async def _replay_log(self, stored: StoredRun) -> None:
        """Re-run the ticks after the checkpoint, applying the log at its stamps.

        Trainer rewards and edits come from the log. The task's and the reinforcement
        program's rewards are produced again by the replayed ticks and matched with the log,
        so each is stored once; a logged reward whose learning was never committed (the
        process died in between) is committed now.
        """
        skip = self._replay_skip_upto
        rewards = deque(
            r
            for r in stored.rewards_after
            if r.record.source not in INTERNAL_SOURCES and r.id > skip
        )
        self._logged_internal = {}
        for r in stored.rewards_after:
            if r.record.source in INTERNAL_SOURCES:
                key = (r.record.tick, r.record.source, r.record.value)
                self._logged_internal.setdefault(key, deque()).append(r)
        commands = deque(stored.commands_after)
        last = max(
            [r.record.tick for r in stored.rewards_after] + [c.record.tick for c in commands],
            default=0,
        )
        sim = self.sim
        while sim.tick_count + 1 <= last and self._more():
            if self._need_reset:
                if not self._episodes_left():
                    break
                self._start_episode()
            boundary = sim.tick_count + 1
            while rewards and rewards[0].record.tick <= boundary:
                r = rewards.popleft()
                job = _RewardJob(
                    r.record.tick,
                    r.record.episode,
                    InjectReward(
                        r.record.value, note=r.record.note, source=RewardSource(r.record.source)
                    ),
                    external=True,
                    logged_id=r.id,
                    committed_before=r.applied,
                )
                self._due.append(job)
                self._queue.put_nowait(job)
            while commands and commands[0].record.tick <= boundary:
                c = commands.popleft()
                p = c.record.payload
                strength = p.get("strength")
                self._apply_edit(
                    EditAssociation(
                        str(p["stimulus"]),
                        str(p["behaviour"]),
                        None if strength is None else float(strength),
                        str(p.get("source", "dp")),
                        bool(p.get("locked", False)),
                    )
                )
            await self._step()
            if sim.tick_count % FAST_YIELD_TICKS == 0:
                await asyncio.sleep(0)
        self._logged_internal = {}

    # --- the reward task ------------------------------------------------------------

    async def _reward_task(self) -> None:
        try:
            while True:
                job = await self._queue.get()
                if job is _CLOSE:
                    break
                if isinstance(job, _RewardJob):
                    await self._process_reward(job)
                else:  # an edit, applied by the tick task: stored in its place in order
                    self._write_queue.put_nowait(job)
        finally:
            self._write_queue.put_nowait(_CLOSE)

    async def _write_task(self) -> None:
        """Commits what applied rewards and edits changed, in the order they happened.

        What queued up while the last commit ran goes into one transaction; in fast mode,
        where only the episode writer waits for these commits, it also gathers for
        `WRITE_BATCH_S`, so a fast run commits its learning a few times a second instead
        of once a reward.
        """
        window = WRITE_BATCH_S if self.spec.mode is Mode.FAST else 0.0
        closing = False
        while not closing:
            batch, closing = await _gather(self._write_queue, window, WRITE_BATCH_MAX)
            rewards: list[_RewardWrite] = []
            for item in batch:
                if isinstance(item, _RewardWrite):
                    rewards.append(item)
                    continue
                assert isinstance(item, _CommandJob)
                await self._commit_rewards(rewards)  # the rewards before it come first
                rewards = []
                await self._log_command(item)
            await self._commit_rewards(rewards)

    async def _commit_rewards(self, writes: list[_RewardWrite]) -> None:
        if not writes:
            return
        for i, w in enumerate(writes):
            if w.job.external and w.commit.logged_id is None:
                # Applied before its log entry was written: commit it as that entry.
                await w.job.logged.wait()
                writes[i] = replace(w, commit=replace(w.commit, logged_id=w.job.logged_id))
        ids = await self._io(
            self.store.commit_rewards, self.run_id, tuple(w.commit for w in writes)
        )
        done = time.perf_counter()
        for w, reward_id in zip(writes, ids, strict=True):
            w.job.logged_id = reward_id
            self.stats.reward_commit_s.add(done - w.queued)
            w.job.committed.set()

    async def _log_command(self, job: _CommandJob) -> None:
        assert job.update is not None
        c = job.command
        record = CommandRecord(
            job.stamp,
            "edit_association",
            {
                "stimulus": c.stimulus,
                "behaviour": c.behaviour,
                "strength": c.strength,
                "source": c.source,
                "locked": c.locked,
            },
        )
        command_id = await self._io(self.store.log_command, self.run_id, record, job.update)
        self._unlogged.remove(job)
        if job.ack is not None and not job.ack.done():
            job.ack.set_result(command_id)

    async def _episode_task(self) -> None:
        """Commits episodes and checkpoints, each after the rewards applied before it.

        Episodes are nobody's acknowledgement and a lost one is replayed from the log, so
        the writer gathers what arrives within `EPISODE_BATCH_S` and commits it at once:
        in fast mode that is one transaction for many episodes.
        """
        closing = False
        while not closing:
            jobs, closing = await _gather(self._episode_queue, EPISODE_BATCH_S, EPISODE_BATCH_MAX)
            batch = [j for j in jobs if isinstance(j, _EpisodeJob)]
            if not batch:
                continue
            last = batch[-1]
            if last.after is not None:
                await last.after.committed.wait()
            # Trainer rewards stamped with the next boundary may already be in this state;
            # replay skips those the checkpoint includes. The rewards up to `after` are
            # committed, so the last trainer's one is logged and has its id.
            external = last.external
            if external is not None:
                assert external.logged_id is not None
            last.state["last_external_reward_id"] = (
                self._last_external_id if external is None else external.logged_id
            )
            await self._io(self._end_episodes, tuple(j.record for j in batch), last)

    def _end_episodes(self, records: tuple[EpisodeRecord, ...], last: _EpisodeJob) -> None:
        """Store episodes with the checkpoint after the last (on a worker thread)."""
        checkpoint = Checkpoint(last.next_episode, last.tick, encode(last.state))
        self.store.end_episodes(self.run_id, records, checkpoint, last.totals)

    async def _ack_task(self) -> None:
        """Logs trainers' rewards in arrival order; the log entry is the acknowledgement.

        It never waits for a tick boundary, so acknowledging does not wait for the
        previous reward to be applied.
        """
        while True:
            job = await self._ack_queue.get()
            if job is _CLOSE:
                break
            assert isinstance(job, _RewardJob)
            record = RewardRecord(
                job.stamp, job.episode, job.reward.value, job.reward.source, job.reward.note
            )
            job.logged_id = await self._io(self.store.log_reward, self.run_id, record)
            job.logged.set()
            self._unacked.remove(job)
            if job.ack is not None and not job.ack.done():
                self.stats.reward_ack_s.add(time.perf_counter() - job.arrived)
                job.ack.set_result(
                    RewardAck(job.logged_id, job.stamp, job.episode, job.reward.value)
                )

    async def _process_reward(self, job: _RewardJob) -> None:
        record = RewardRecord(
            job.stamp, job.episode, job.reward.value, job.reward.source, job.reward.note
        )
        # A trainer's reward is applied at its boundary even if the log is slow to take it
        # (the tick waits for it there); only its commit waits for the log entry.
        await job.release.wait()
        outcome = self._apply_in_memory(job)
        if job.committed_before:
            job.committed.set()
            return
        commit = RewardCommit(
            record, self._learning_update(outcome), len(outcome.credits), job.logged_id
        )
        self._write_queue.put_nowait(_RewardWrite(job, commit, time.perf_counter()))

    def _apply_in_memory(self, job: _RewardJob) -> RewardOutcome:
        self._last_reward_job = job
        if job.external:
            self._last_external_job = job
        event, outcome = self.sim.apply_reward(job.reward, job.stamp, job.episode)
        job.applied.set()
        if job.episode == self.sim.episode:
            self._episode_rewards += 1
        self._publish(event)
        for change in outcome.changes:
            self._publish(change)
        return outcome

    def _learning_update(self, outcome: RewardOutcome) -> LearningUpdate:
        brain = self.sim.brain
        cat = brain.catalog
        s = [x.name for x in cat.stimuli]
        b = [x.name for x in cat.behaviours]
        ltm = {
            (s[c.stimulus], b[c.behaviour]): brain.ltm.reliability(c.stimulus, c.behaviour)
            for c in outcome.credits
        }
        rltm = {(s[p.stimulus], b[p.behaviour]): p.after for p in outcome.propagated}
        upserts: list[NetworkPair] = []
        removals: list[tuple[str, str]] = []
        for ch in outcome.changes:
            if isinstance(ch, AssociationPromoted):
                a = brain.network.get(ch.stimulus, ch.behaviour)
                if a is not None:
                    upserts.append(_pair(self.sim, a))
            elif isinstance(ch, AssociationDemoted):
                removals.append((s[ch.stimulus], b[ch.behaviour]))
        # Strength changes of pairs already in the network follow their reliability.
        for (st, be), v in {**ltm, **rltm}.items():
            a = brain.network.get(cat.stimulus(st).id, cat.behaviour(be).id)
            if a is not None and a.source in ("learned", "kp") and a.strength == v:
                pair = _pair(self.sim, a)
                if pair not in upserts:
                    upserts.append(pair)
        added = tuple(
            BehaviourSpec(x.name, x.family, x.speed_mps, x.turn_dps, x.ticks, x.mode)
            for p in outcome.propagated
            if p.synthesized
            for x in (cat.behaviours[p.behaviour],)
        )
        return LearningUpdate(ltm, rltm, tuple(upserts), tuple(removals), added)


def _pair(sim: Simulation, a: Association) -> NetworkPair:
    cat = sim.brain.catalog
    return NetworkPair(
        cat.stimuli[a.stimulus].name,
        cat.behaviours[a.behaviour].name,
        a.strength,
        a.source,
        a.locked,
    )


__all__ = [
    "HZ_MAX",
    "HZ_MIN",
    "MonotonicPacer",
    "Pacer",
    "RewardAck",
    "RunEngine",
    "StatusChanged",
    "Subscription",
    "SubscriptionClosed",
    "TickPublished",
    "check_hz",
    "sleep_until",
]
_ = RewardApplied  # re-exported type of published reward events
