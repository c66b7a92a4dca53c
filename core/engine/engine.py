"""A run's engine: the paper's two threads as two asyncio tasks around one simulation.

The **tick task** (`tick_task`) paces ticks in one loop whose policy (`pacing`) is fast (no
sleeping), realtime (drift-free deadlines behind a `Pacer`) or a resumed run's replay, and
at each tick boundary makes sure every reward stamped with that boundary has been applied,
then applies commands (association edits), then runs the tick (sense, perceive, select, KP
percept, motor, STM). The **reward task** (`reward_task`) takes rewards off a queue in
order and applies them (pop STM, Eq. (1), network insertions, KP).

The one hand-over between them is the **boundary** (`boundary`): a reward is stamped with
the boundary it arrives before and queued for the reward task, which applies it only once
the tick task releases it there, and the tick task waits until it is applied before the
tick after. So a reward credits exactly the STM records of earlier ticks and a run is
reproducible from its seed and command log: in fast mode it gives the same LTM as the
plain headless loop, and a resumed run replays its log from the last checkpoint (`replay`).

Around the two tasks, the writer's tasks (`writer`) keep storage in step without holding
either up, and subscribers read events through bounded queues (`bus`). The service reads a
run through `RunEngine.view()` (`view`). This module is the run's lifecycle and the calls
the outside makes; `build` makes its simulation.
"""

from __future__ import annotations

import asyncio
import time

from core.brain.catalog import Catalog
from core.brain.memory import ReactionWindow
from core.brain.network import Association
from core.commands import EditAssociation, InjectReward, RewardSource
from core.engine.boundary import Boundary
from core.engine.build import (
    Connect,
    create_run,
    reaction_seconds,
    reaction_window,
    restore_run,
)
from core.engine.bus import EventBus, StatusChanged, Subscription
from core.engine.jobs import CommandJob, RewardAck, RewardJob
from core.engine.pacing import HZ_MAX, HZ_MIN, Controls, MonotonicPacer, Pacer, check_hz
from core.engine.replay import ReplayLog
from core.engine.reward_task import RewardTask
from core.engine.stats import EngineStats
from core.engine.tick_task import TickTask
from core.engine.view import RunView
from core.engine.writer import RunWriter
from core.errors import RunStateError, SeenTickError, StorageError
from core.ports import ACTIVE, Mode, RunSpec, RunStatus, RunStore, RunTotals, StoredRun
from core.run.simulation import Simulation
from core.run.trace import TraceRecorder
from core.sim.world import World, WorldConfig
from core.text import check_storable


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
        self.bus = EventBus()
        # A run stored before rates were bounded ticks at the nearest bounded rate.
        self._controls = Controls(min(max(float(spec.hz), HZ_MIN), HZ_MAX))
        self._boundary = Boundary()
        self._writer = RunWriter(
            run_id,
            store,
            self.stats,
            batch=spec.mode is Mode.FAST,
            last_external_id=last_external_id,
        )
        self._rewards = RewardTask(sim, self._boundary, self._writer, self.bus)
        self._ticks = TickTask(
            run_id,
            spec,
            sim,
            stats=self.stats,
            bus=self.bus,
            boundary=self._boundary,
            writer=self._writer,
            rewards=self._rewards,
            controls=self._controls,
            pacer=pacer or MonotonicPacer(),
            trace=TraceRecorder() if trace else None,
            totals=totals or RunTotals(0, 0, sim.tick_count),
            replay=None if replay is None else ReplayLog(replay, last_external_id),
        )
        self._arrivals = 0
        """Rewards this engine took from outside (the last part of a `uid` it makes)."""
        self._status_waiters: list[asyncio.Future[RunStatus]] = []
        """`next_status` futures, answered by the next status change."""

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
        world: World | None = None,
    ) -> RunEngine:
        """A new run, stored with status created.

        It runs in the spec's world preset and sensor definition, stored by name with the
        defaults resolved (an unknown name raises `UnknownNameError`). `catalog` and
        `world_config` replace the setup's: a catalogue must use the definition the spec
        names, and is the definition of a spec that names none. `network` replaces the
        spec's knowledge set. `world` replaces the simulated world (a robot,
        `server.robots.ros2.Ros2World`: a realtime spec paces it at the robot's rate).
        """
        run_id, spec, sim = create_run(
            spec, store, catalog=catalog, world_config=world_config, network=network, world=world
        )
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
        connect: Connect | None = None,
    ) -> RunEngine:
        """A stored run, rebuilt from its last checkpoint; `run()` replays its log first.

        It runs in the world and sensor definition it was stored with (the defaults for a
        run stored before runs kept them). A robot's run runs on the robot `connect`
        reaches, paced by its clock, and replays nothing (`Restored.replays`).
        """
        r = restore_run(
            run_id, store, catalog=catalog, world_config=world_config, mode=mode, connect=connect
        )
        return cls(
            run_id,
            r.spec,
            store,
            r.sim,
            replay=r.stored if r.replays else None,
            totals=r.totals,
            trace=trace,
            pacer=pacer or r.pacer,
            last_external_id=r.last_external_id,
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
        tick_seen: int | None = None,
        seen_episode: int | None = None,
        records: tuple[tuple[int, int, int], ...] | None = None,
    ) -> RewardAck:
        """Inject a reward; returns once it is in the reward log (durable).

        It is stamped with the next tick boundary, so it credits every STM record so far;
        with `tick_seen` (the tick its trainer saw, in `seen_episode`: by default the one
        it lies in), the reaction window before that tick (`core.brain.memory.credit_seen`;
        `SeenTickError` for a tick the run has not reached or no longer holds). With
        `seen_episode` naming an ended episode (a reward on its replay), the records of its
        window up to `tick_seen`: `records`, from its stored trace, or the records kept aside
        at its end while they hold that window (else `SeenTickError` on `episode`: the
        caller reads its stored trace).
        A paused run takes it too and applies it at once, at the boundary it is paused at
        (paused just as an episode ended, after starting the next, `TickTask.start_paused`).
        `uid` is its id from its arrival on ("": one made of its source, episode, boundary
        and how many rewards this engine took).
        """
        # Refused before it is queued: a note no database stores would fail the writer
        # that logs it, and with it the run. (A logged note is replayed as it was.)
        check_storable(note, "a reward's note")
        self._check_running(paused=True)
        if not self._ticks.replayed.is_set():
            # A resumed run replays its log first; a new reward stamped inside the replay
            # would be applied in an order a later replay could not repeat.
            await self._ticks.replayed.wait()
            self._check_running(paused=True)
        self._ticks.start_paused()
        window = None
        if tick_seen is None:
            seen_episode = None
        elif records is not None:
            # A stored episode's tick, looked at at leisure: its window ends there.
            if seen_episode is None or seen_episode >= self.sim.episode:
                raise SeenTickError("episode", "a stored episode's records need its number")
            window = self._replay_window(tick_seen)
            records = tuple(r for r in records if window[0] <= r[0] <= window[1])
        elif seen_episode is not None and seen_episode < self.sim.episode:
            # The ended episode's tick, scrubbed on its replay: the same rule as a stored
            # episode's, from the records kept aside at its end while they hold the window.
            seen_episode = self._ticks.seen_episode(tick_seen, seen_episode)
            window = self._replay_window(tick_seen)
            records = self._kept_records(window)
        else:
            seen_episode = self._ticks.seen_episode(tick_seen, seen_episode)
            window = self._seen_window(tick_seen)
        next_boundary = self.sim.tick_count + 1
        stamp = self._boundary.stamp(next_boundary)
        self._arrivals += 1
        uid = uid or f"{source.value}-{self.sim.episode}-{stamp}-{self._arrivals}"
        reward = InjectReward(
            value,
            note=note,
            source=source,
            uid=uid,
            tick_seen=tick_seen,
            seen_episode=seen_episode,
            window=window,
            records=records,
        )
        job = RewardJob(
            stamp,
            self.sim.episode,
            reward,
            external=True,
            ack=asyncio.get_running_loop().create_future(),
            arrived=time.perf_counter(),
        )
        self._boundary.add(job, next_boundary)
        self._ticks.credit_paused()
        self._writer.acknowledge(job)
        assert job.ack is not None
        return await job.ack

    def _replay_window(self, tick_seen: int) -> tuple[int, int]:
        """The ticks a reward on an ended episode's replay credits: up to the seen tick."""
        return tick_seen - reaction_window(self.spec).hi_ticks, tick_seen

    def _kept_records(self, window: tuple[int, int]) -> tuple[tuple[int, int, int], ...]:
        """The ended episode's records kept aside at its end, in `window`.

        Only while they hold the whole window: it starts no earlier than they do, and the
        reward comes at most the window's length after the episode's end (later the brain
        has let them go). Else `SeenTickError` on `episode`: its stored trace has them.
        """
        ticks, brain = self._ticks, self.sim.brain
        assert ticks.ended is not None  # an episode before the current one is held
        episode, _, last = ticks.ended
        hi = brain.window.hi_ticks
        held = brain.ended_tick == last and self.sim.tick_count - last <= hi
        if not held or window[0] < last - hi:
            raise SeenTickError(
                "episode", f"episode {episode}'s records before tick {last} are its stored trace's"
            )
        return tuple(r for r in ticks.ended_records if window[0] <= r[0] <= window[1])

    def _seen_window(self, tick_seen: int) -> tuple[int, int]:
        """The ticks a reward seen at `tick_seen` credits, as it arrives (then logged).

        The run's reaction window at the rate it ticks now (a realtime run's may have been
        changed); a paused run's ends at the seen tick itself, which the person has looked
        at as long as they liked.
        """
        lo_s, hi_s = reaction_seconds(self.spec)
        hz = self.hz if self.spec.mode is Mode.REALTIME else self.spec.hz
        first, last = ReactionWindow.of_seconds(lo_s, hi_s, hz).span(tick_seen)
        return (first, tick_seen) if self.status is RunStatus.PAUSED else (first, last)

    async def edit(self, command: EditAssociation) -> int:
        """Change the running robot's network at the next tick boundary; returns the log id."""
        self._check_running(paused=True)
        if not self._ticks.replayed.is_set():
            await self._ticks.replayed.wait()
            self._check_running(paused=True)
        cat = self.sim.brain.catalog
        cat.stimulus(command.stimulus)
        cat.behaviour(command.behaviour)
        job = CommandJob(
            self.sim.tick_count + 1, command, asyncio.get_running_loop().create_future()
        )
        self._ticks.command(job)
        assert job.ack is not None
        return await job.ack

    def _check_running(self, *, paused: bool = False) -> None:
        """`RunStateError` unless the run is running (or paused, with `paused`).

        Checked before waiting for a replay too: a run that was never started answers at
        once instead of holding a reward until it is.
        """
        ok = ACTIVE if paused else (RunStatus.RUNNING,)
        if self.status not in ok or self._ticks.closing:
            raise RunStateError(f"run {self.run_id} is {self.status.value}, not running")

    def pause(self) -> None:
        """Stop ticking at the next boundary until `resume` (a sleeping tick task wakes)."""
        controls = self._controls
        if self.status is RunStatus.RUNNING:
            controls.paused = True
            controls.resumed.clear()
            self._set_status(RunStatus.PAUSED)
            controls.wake.set()

    def resume(self) -> None:
        """Tick again after a pause."""
        controls = self._controls
        if self.status is RunStatus.PAUSED:
            controls.paused = False
            self._set_status(RunStatus.RUNNING)
            controls.resumed.set()

    async def step(self) -> int:
        """Run exactly one tick of a paused realtime run; returns the tick it ran.

        The tick task runs it at a tick boundary, as any other tick (rewards and edits due
        there first), and the run stays paused. `RunStateError` unless the run is paused
        and realtime (a fast run has no ticks to wait for), or if it ends first.
        """
        if self.status is not RunStatus.PAUSED or self._ticks.closing:
            raise RunStateError(f"run {self.run_id} is {self.status.value}, not paused")
        if self.spec.mode is not Mode.REALTIME:
            raise RunStateError(f"run {self.run_id} is a fast run: it has no single ticks")
        if not self._ticks.replayed.is_set():
            await self._ticks.replayed.wait()
        return await self._controls.step()

    def stop(self) -> None:
        """End the run now, at the boundary after its current tick (status stopped).

        A realtime run sleeping until its next tick wakes at once: a stop never waits out
        a tick period.
        """
        self._controls.stop()

    def interrupt(self) -> None:
        """End the run at the next tick boundary (status interrupted: it can be resumed)."""
        self._controls.interrupted = True
        self.stop()

    def set_rate(self, hz: float) -> None:
        """Change the realtime tick rate (`HZ_MIN` to `HZ_MAX`, else `ValueError`).

        The next tick is due one new period after the last one started: a sleeping tick
        task wakes and sleeps again for what is left of that.
        """
        self._controls.set_rate(check_hz(hz))

    @property
    def hz(self) -> float:
        """The realtime tick rate."""
        return self._controls.hz

    @property
    def totals(self) -> RunTotals:
        """Episodes, successes and ticks so far."""
        return self._ticks.totals

    # --- running --------------------------------------------------------------------

    async def run(self, until_tick: int | None = None) -> RunStatus:
        """Run until the episodes are done or the run is stopped; returns the final status.

        `until_tick` stops the run (status stopped) once that many ticks have run.
        """
        self._controls.until_tick = until_tick
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
                tg.create_task(self._rewards.run(), name=f"run {self.run_id} rewards")
                writer = self._writer
                tg.create_task(writer.learning_task(), name=f"run {self.run_id} learning writer")
                tg.create_task(writer.episode_task(), name=f"run {self.run_id} episodes")
                tg.create_task(writer.ack_task(), name=f"run {self.run_id} acknowledgements")
                tg.create_task(self._ticks.run(), name=f"run {self.run_id} ticks")
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
        if self._controls.interrupted:
            status = RunStatus.INTERRUPTED
        elif self._controls.stopping:
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
        for c in self._ticks.commands:
            if c.ack is not None and not c.ack.done():
                c.ack.set_exception(StorageError(f"the edit was not stored: {error}"))
        self._writer.fail_pending(error)

    def _set_status(self, status: RunStatus) -> None:
        self.status = status
        waiters, self._status_waiters = self._status_waiters, []
        for waiter in waiters:
            if not waiter.done():
                waiter.set_result(status)
        self.bus.publish(StatusChanged(self.run_id, status, self.error))

    def next_status(self) -> asyncio.Future[RunStatus]:
        """A future answered with the run's next status (cancel it to stop waiting)."""
        waiter: asyncio.Future[RunStatus] = asyncio.get_running_loop().create_future()
        self._status_waiters.append(waiter)
        return waiter
