"""A run's engine: the paper's two threads as two asyncio tasks around one simulation.

The **tick task** paces ticks (realtime: drift-free deadlines behind a `Pacer`; fast: no
sleeping) and at each tick boundary makes sure every reward stamped with that boundary has
been applied, then applies commands (association edits), then runs the tick (sense,
perceive, select, KP percept, motor, STM). The **reward task** takes rewards off a queue in
order and applies them (pop STM, Eq. (1), network insertions, KP).

The one hand-over between them is the **boundary** (`boundary`): a reward is stamped with
the boundary it arrives before and queued for the reward task, which applies it only once
the tick task releases it there, and the tick task waits until it is applied before the
tick after. So a reward credits exactly the STM records of earlier ticks and a run is
reproducible from its seed and command log: in fast mode it gives the same LTM as the
plain headless loop, and a resumed run replays its log from the last checkpoint (`replay`).

Around the two tasks, the writer's tasks (`writer`) keep storage in step without holding
either up, and subscribers read events through bounded queues (`bus`). The service reads a
run through `RunEngine.view()` (`view`).
"""

from __future__ import annotations

import asyncio
import math
import time
from collections import deque
from dataclasses import replace

from core.brain.brain import BrainConfig, RewardOutcome
from core.brain.catalog import Catalog
from core.brain.network import Association, BehaviourNetwork
from core.commands import EditAssociation, InjectReward, RewardSource
from core.engine.boundary import Boundary
from core.engine.bus import Competition, EventBus, StatusChanged, Subscription, TickPublished
from core.engine.jobs import (
    CLOSE,
    CommandJob,
    EpisodeJob,
    RewardAck,
    RewardJob,
    RewardWrite,
)
from core.engine.learning import apply_edit, learning_update, pair
from core.engine.pacing import (
    APPROACH_S,
    HZ_MAX,
    HZ_MIN,
    MonotonicPacer,
    Pacer,
    Wake,
    check_hz,
    sleep_until,
)
from core.engine.replay import ReplayLog
from core.engine.stats import EngineStats
from core.engine.view import RunView
from core.engine.writer import RunWriter, reward_record
from core.errors import CatalogError, RunStateError, StorageError
from core.events import EpisodeEnded, Event, Outcome, RewardDue
from core.params import applicable, configure
from core.ports import (
    ACTIVE,
    Checkpoint,
    EpisodeRecord,
    Mode,
    RewardCommit,
    RunSpec,
    RunStatus,
    RunStore,
    RunTotals,
    StoredRun,
)
from core.run.checkpoint import decode, encode, export_state, restore_simulation
from core.run.conditions import Condition, get_condition
from core.run.setup import Setup, condition_network
from core.run.simulation import Simulation, Snapshot
from core.run.trace import TraceRecorder
from core.sim.world import WorldConfig
from core.text import check_storable

FAST_YIELD_TICKS = 128
"""In fast mode the tick task yields to the event loop this often, so commands get in."""


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
        last_external_id: int = 0,
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
        self._replay = None if replay is None else ReplayLog(replay, last_external_id)
        """The log a resumed run replays first (None once replayed): the replayed ticks'
        own rewards are matched with its entries."""
        t = totals or RunTotals(0, 0, sim.tick_count)
        self._episodes_done = t.episodes
        self._successes = t.successes
        self._episode_rewards = 0
        # A run stored before rates were bounded ticks at the nearest bounded rate.
        self._hz = min(max(float(spec.hz), HZ_MIN), HZ_MAX)
        self._pacer: Pacer = pacer or MonotonicPacer()
        self._wake = Wake()
        """Set by stop, pause, interrupt and rate changes: a sleeping tick task wakes now."""
        self._rate_changed = False
        self._trace = TraceRecorder() if trace else None
        self._boundary = Boundary()
        self._commands: deque[CommandJob] = deque()
        """The tick task's hand-over to the reward task: rewards, then applied edits."""
        self._writer = RunWriter(
            run_id,
            store,
            self.stats,
            batch=spec.mode is Mode.FAST,
            last_external_id=last_external_id,
        )
        self.bus = EventBus()
        self._last_reward_job: RewardJob | None = None
        self._last_snap: Snapshot | None = None
        self._paused = False
        self._resumed = asyncio.Event()
        self._resumed.set()
        self._stop = False
        self._interrupt = False
        self._episode_start_tick = sim.tick_count
        self._need_reset = True
        self._until_tick: int | None = None
        self._last_external_job: RewardJob | None = None
        """The newest trainer's reward applied since the checkpoint (its log id may come
        later)."""
        self._closing = False
        self._replayed = asyncio.Event()
        """Set once a resumed run has replayed its log (at once for a new run)."""
        if replay is None:
            self._replayed.set()
        self._steps: deque[asyncio.Future[int]] = deque()
        """Single-tick steps asked of the paused run, answered with the tick they ran."""
        self._arrivals = 0
        """Rewards this engine took from outside (the last part of a `uid` it makes)."""
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
        (`core.run.setup.condition_network`).
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
        pairs = tuple(pair(sim, a) for a in sim.brain.network)
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
        return cls(
            run_id,
            spec,
            store,
            sim,
            replay=stored,
            totals=totals,
            trace=trace,
            pacer=pacer,
            last_external_id=skip,
        )

    # --- the outside's calls --------------------------------------------------------

    def subscribe(self, maxsize: int = 256, tick_hz: float = 0.0) -> Subscription:
        """A bounded queue of this run's events (ticks at most `tick_hz` per second)."""
        return self.attach(Subscription(maxsize, tick_hz))

    def attach(self, sub: Subscription) -> Subscription:
        """Feed an existing subscription (one made while the run had no engine)."""
        return self.bus.attach(sub)

    def unsubscribe(self, sub: Subscription) -> None:
        """Stop feeding a subscription."""
        self.bus.unsubscribe(sub)

    def view(self) -> RunView:
        """What the service reads of this run (`core.engine.view`).

        A new window each call: an engine holding its own view would be a reference cycle,
        kept alive until the garbage collector's next full pass.
        """
        return RunView(self)

    def close_subscriptions(self) -> None:
        """End every subscription: its reader gets the current status, then the end.

        For a service shutting down: the live streams of a run that is not ticking (created,
        finished) end instead of holding their connections open.
        """
        self.bus.end(StatusChanged(self.run_id, self.status, self.error))

    async def reward(
        self,
        value: float,
        *,
        note: str = "",
        source: RewardSource = RewardSource.TRAINER,
        uid: str = "",
    ) -> RewardAck:
        """Inject a reward; returns once it is in the reward log (durable).

        It is stamped with the next tick boundary, so it credits every STM record so far.
        `uid` is its id from its arrival on ("": one made of its source, episode, boundary
        and how many rewards this engine took).
        """
        # Refused before it is queued: a note no database stores would fail the writer
        # that logs it, and with it the run. (A logged note is replayed as it was.)
        check_storable(note, "a reward's note")
        self._check_running()
        if not self._replayed.is_set():
            # A resumed run replays its log first; a new reward stamped inside the replay
            # would be applied in an order a later replay could not repeat.
            await self._replayed.wait()
            self._check_running()
        next_boundary = self.sim.tick_count + 1
        stamp = self._boundary.stamp(next_boundary)
        self._arrivals += 1
        uid = uid or f"{source.value}-{self.sim.episode}-{stamp}-{self._arrivals}"
        job = RewardJob(
            stamp,
            self.sim.episode,
            InjectReward(value, note=note, source=source, uid=uid),
            external=True,
            ack=asyncio.get_running_loop().create_future(),
            arrived=time.perf_counter(),
        )
        self._boundary.add(job, next_boundary)
        self._writer.acknowledge(job)
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
        job = CommandJob(
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
        ok = ACTIVE if paused else (RunStatus.RUNNING,)
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
        await self._writer.set_status(RunStatus.RUNNING, None)
        self._set_status(RunStatus.RUNNING)
        failure: BaseException | None = None
        try:
            async with asyncio.TaskGroup() as tg:
                tg.create_task(self._reward_task(), name=f"run {self.run_id} rewards")
                writer = self._writer
                tg.create_task(writer.learning_task(), name=f"run {self.run_id} learning writer")
                tg.create_task(writer.episode_task(), name=f"run {self.run_id} episodes")
                tg.create_task(writer.ack_task(), name=f"run {self.run_id} acknowledgements")
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
                await self._writer.set_status(status, self.error)
                self.end_stored = True
            except StorageError as e:
                self.error = self.error or str(e)
                status = RunStatus.FAILED
        self._set_status(status)
        self.bus.close()

    def _fail_pending(self, error: BaseException) -> None:
        # Held rewards (stamped while a boundary was being settled) are not due yet, but
        # their senders wait for an answer all the same.
        # A trainer's reward applied before its log entry failed is in neither: the
        # writer answers those, and the edits it has yet to log.
        for job in self._boundary.waiting():
            if job.ack is not None and not job.ack.done():
                job.ack.set_exception(StorageError(f"the reward was not stored: {error}"))
        for c in self._commands:
            if c.ack is not None and not c.ack.done():
                c.ack.set_exception(StorageError(f"the edit was not stored: {error}"))
        self._writer.fail_pending(error)

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
        self.bus.publish(event)

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
            # No more rewards now; those that arrived after the last tick apply at their
            # boundaries, reached as the run would have reached them.
            self._closing = True
            self._boundary.release_held()
            await self._reach_last_boundary()
            await self._settle(self.sim.tick_count + 1, until=math.inf)
        finally:
            self._closing = True
            self._refuse_steps(RunStateError(f"run {self.run_id} ended before the step"))
            self._boundary.close()
            self._writer.end_of_ticks()

    async def _reach_last_boundary(self) -> None:
        """Bring a stopping run to the boundary its last due reward was stamped with.

        A reward is stored as applied at its stamp, and a replay of the log (a resumed
        run's) applies it there: after the ticks before the stamp, and after the reset when
        an episode ended just before it, so it credits the new episode's STM (cleared at
        the reset), not the ended one's. Applied instead to whatever state the run stops
        in, its stored learning would differ from the replay's, and a resumed run would go
        on from an LTM other than the stored one. So the run ticks on to a reward held past
        the next boundary (stamped while an episode's own rewards settled), and starts the
        next episode before the rewards due after an episode's end.
        """
        due = self._boundary.due
        while due and max(job.stamp for job in due) > self.sim.tick_count + 1:
            await self._step()
        if due and self._need_reset:
            self._start_episode()

    def _episodes_left(self) -> bool:
        limit = self.spec.episodes
        return limit is None or self._episodes_done < limit

    def _more(self) -> bool:
        """Whether the tick task should run another tick."""
        if self._until_tick is not None and self.sim.tick_count >= self._until_tick:
            self._stop = True
        return not self._stop and (not self._need_reset or self._episodes_left())

    async def _fast(self) -> None:
        while self._more():
            await asyncio.sleep(0)  # edits, trainers' rewards, pauses and the writers get in
            if self._paused:
                await self._resumed.wait()
                continue
            await self._step()
            ended = self._burst(FAST_YIELD_TICKS - 1)
            if ended is not None:
                await self._settle(self.sim.tick_count + 1, internal_only=True)
                self._end_episode(ended)

    def _burst(self, ticks: int) -> EpisodeEnded | None:
        """Up to `ticks` ticks with no await between them: fast mode's common path.

        Nothing else runs meanwhile, so no edit, pause, stop, trainer's reward or
        subscriber can arrive; it returns early when a tick needs the event loop (a reward
        due at the next boundary, or an episode that ended with its own rewards to apply
        first: returned, for the caller to settle and end) or the episodes are done.
        Unwatched and with no reward held, which is how fast runs go, a tick is just the
        simulation's tick, its trace row and its events: what `_tick` checks each tick
        cannot change, and the tick count and last snapshot are kept once, at the end.
        """
        if self._commands:
            return None
        if self._until_tick is not None:
            ticks = min(ticks, self._until_tick - self.sim.tick_count)
        watched = bool(self.bus.tick_subscribers or self._boundary.held)
        sim = self.sim
        due, step, sim_tick, hand_on = self._boundary.due, self._tick, sim.tick, self._hand_on
        add = self._trace.add if self._trace is not None else None
        first, result = sim.tick_count, None
        try:
            for _ in range(ticks):
                if due:
                    return None
                if self._need_reset:
                    if not self._episodes_left():
                        return None
                    self._start_episode()
                if watched:
                    ended = step()
                else:
                    result = sim_tick()
                    if add is not None:
                        add(result.snapshot)
                    ended = hand_on(result.events) if result.events else None
                if ended is not None:
                    if due:
                        return ended
                    self._end_episode(ended)
            return None
        finally:
            if not watched:  # `_tick` kept these
                self.stats.ticks += sim.tick_count - first
                if result is not None:
                    self._last_snap = result.snapshot

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
                if self.bus.tick_subscribers and self._last_snap is not None:
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
        if self._boundary.due or self._commands:
            await self._settle(sim.tick_count + 1)
        ended = self._tick()
        if ended is not None:
            if self._boundary.due:
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
        if self.bus.tick_subscribers:
            # A single step of a paused run is always shown: no later tick would replace it.
            self._publish_tick(snap, force=self._paused)
        ended = self._hand_on(result.events) if result.events else None
        if self._boundary.held:
            self._boundary.release_held()
        return ended

    def _hand_on(self, events: tuple[Event, ...]) -> EpisodeEnded | None:
        """A tick's events to the reward task and the subscribers; its episode's end."""
        ended: EpisodeEnded | None = None
        for e in events:
            if isinstance(e, RewardDue):
                self._enqueue_internal(e)
            elif isinstance(e, EpisodeEnded):
                ended = e
            else:
                self._publish(e)
        return ended

    def _start_episode(self) -> None:
        self.sim.reset()
        self._need_reset = False
        self._episode_start_tick = self.sim.tick_count
        self._episode_rewards = 0

    def _publish_tick(self, snap: Snapshot, force: bool = False) -> None:
        """Offer a tick to the subscribers due one (all tick subscribers when forced)."""
        self.bus.publish_tick(snap, self._tick_event, force)

    def _tick_event(self, snap: Snapshot) -> TickPublished:
        sim = self.sim
        return TickPublished(
            self.run_id,
            snap,
            sim.sonar_m(),
            sim.world.layout.obstacle_center,
            Competition.of(sim.brain.selector, snap.stimuli),
            self.totals,
            self.view().released_by_kp(snap),
        )

    def _enqueue_internal(self, e: RewardDue) -> None:
        # Made again alike when the run is replayed.
        uid = f"{e.source}-{e.episode}-{e.tick}"
        reward = InjectReward(e.value, note=e.note, source=RewardSource(e.source), uid=uid)
        job = RewardJob(e.tick, e.episode, reward, False)
        if self._replay is not None:
            self._replay.match(job)
        self._boundary.queue(job)

    async def _settle(
        self, boundary: int, *, internal_only: bool = False, until: float | None = None
    ) -> None:
        """At the boundary before tick `boundary`: apply its rewards, then its commands.

        `until` widens the stamps taken (shutdown takes every reward still due).
        """
        limit = boundary if until is None else until
        await self._boundary.settle(boundary, internal_only=internal_only, limit=limit)
        if self._commands and not internal_only:
            self._apply_commands(boundary)

    def _apply_commands(self, boundary: int) -> None:
        while self._commands and self._commands[0].stamp <= boundary:
            job = self._commands.popleft()
            job.update = apply_edit(self.sim, job.command)
            self._writer.applied(job)
            self._boundary.applied(job)

    def _end_episode(self, ended: EpisodeEnded) -> None:
        sim = self.sim
        self._episodes_done += 1
        self._successes += ended.outcome is Outcome.SUCCESS
        record = EpisodeRecord(
            episode=ended.episode,
            outcome=ended.outcome.value,
            cause=ended.cause.value if ended.cause else None,
            ticks=ended.ticks,
            start_tick=self._episode_start_tick,
            rewards=self._episode_rewards,
            trace=b"",  # compressed by the writer (`EpisodeJob.stored`)
        )
        state = export_state(sim)
        self._writer.episodes.put(
            EpisodeJob(
                record,
                sim.episode + 1,
                sim.tick_count,
                state,
                self.totals,
                self._last_reward_job,
                self._last_external_job,
                self._trace.take() if self._trace is not None else None,
            )
        )
        self._need_reset = True
        self._publish(ended)

    # --- replay ---------------------------------------------------------------------

    async def _replay_log(self, log: ReplayLog) -> None:
        """Re-run the ticks after the checkpoint, applying the log at its stamps.

        Trainers' rewards and edits come from the log; the task's and the program's are
        produced again by the replayed ticks and matched with their entries (`replay`).
        """
        sim = self.sim
        while sim.tick_count + 1 <= log.last_tick and self._more():
            if self._need_reset:
                if not self._episodes_left():
                    break
                self._start_episode()
            boundary = sim.tick_count + 1
            for job in log.rewards_at(boundary):
                self._boundary.queue(job)
            for edit in log.edits_at(boundary):
                apply_edit(sim, edit)
            await self._step()
            if sim.tick_count % FAST_YIELD_TICKS == 0:
                await asyncio.sleep(0)

    # --- the reward task ------------------------------------------------------------

    async def _reward_task(self) -> None:
        try:
            while True:
                job = await self._boundary.feed.get()
                if job is CLOSE:
                    break
                if isinstance(job, RewardJob):
                    await self._process_reward(job)
                else:  # an edit, applied by the tick task: stored in its place in order
                    self._writer.learning.put(job)
        finally:
            self._writer.learning.close()

    async def _process_reward(self, job: RewardJob) -> None:
        record = reward_record(job)
        # A trainer's reward is applied at its boundary even if the log is slow to take it
        # (the tick waits for it there); only its commit waits for the log entry.
        await job.release.wait()
        outcome = self._apply_in_memory(job)
        if job.committed_before:
            job.committed.set()
            return
        commit = RewardCommit(
            record, learning_update(self.sim, outcome), len(outcome.credits), job.logged_id
        )
        self._writer.learning.put(RewardWrite(job, commit, time.perf_counter()))

    def _apply_in_memory(self, job: RewardJob) -> RewardOutcome:
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
