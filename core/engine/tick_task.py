"""The tick task, the paper's first thread: ticks with their boundaries, and episodes.

At each tick boundary the tick task makes sure every reward stamped with that boundary has
been applied (`boundary`), then applies the edits due there, then runs the tick (sense,
perceive, select, KP percept, motor, STM) and hands its events on: rewards the tick
produced to the reward task, the rest to the subscribers. It owns the simulation between
boundaries, the edits queued for them and the episodes' books; when an episode ends it
hands the record and the checkpoint after it to the episode writer. When ticks run, and
how many at a time, is the pacing policy's (`pacing`).
"""

from __future__ import annotations

import asyncio
import math
from collections import deque

from core.commands import InjectReward, RewardSource
from core.engine.boundary import Boundary
from core.engine.bus import Competition, EventBus, TickPublished
from core.engine.jobs import CommandJob, EpisodeJob, RewardJob
from core.engine.learning import apply_edit
from core.engine.pacing import Controls, Fast, Pacer, Realtime, Replay, pace
from core.engine.replay import ReplayLog
from core.engine.reward_task import RewardTask
from core.engine.stats import EngineStats
from core.engine.view import released_by_kp
from core.engine.writer import RunWriter
from core.errors import RunStateError, SeenTickError
from core.events import EpisodeEnded, Event, Outcome, RewardDue
from core.ports import EpisodeRecord, Mode, RunSpec, RunTotals
from core.run.checkpoint import export_state
from core.run.simulation import Simulation, Snapshot
from core.run.trace import TraceRecorder, trace_records


class TickTask:
    """A run's ticks, paced by its policy; `run` is the task.

    Args:
        run_id: the run.
        spec: what it runs (its mode picks the policy, its episodes the end).
        sim: the simulation it ticks.
        stats: where ticks, lateness and overruns are counted.
        bus: the run's subscriptions.
        boundary: the hand-over to the reward task.
        writer: the run's writers (episodes, and applied edits for the log).
        rewards: the reward task, whose books an episode's checkpoint records.
        controls: what the outside asks of the pace.
        pacer: a realtime run's clock.
        trace: records episodes' traces (None: none kept).
        totals: the episodes and successes so far.
        replay: the log a resumed run replays first (None: a new run).
    """

    def __init__(
        self,
        run_id: int,
        spec: RunSpec,
        sim: Simulation,
        *,
        stats: EngineStats,
        bus: EventBus,
        boundary: Boundary,
        writer: RunWriter,
        rewards: RewardTask,
        controls: Controls,
        pacer: Pacer,
        trace: TraceRecorder | None,
        totals: RunTotals,
        replay: ReplayLog | None,
    ) -> None:
        self.run_id = run_id
        self.spec = spec
        self.sim = sim
        self.stats = stats
        self.bus = bus
        self.boundary = boundary
        self.writer = writer
        self.rewards = rewards
        self.controls = controls
        self.pacer = pacer
        self.trace = trace
        self.episodes_done = totals.episodes
        self.successes = totals.successes
        self.commands: deque[CommandJob] = deque()
        """Edits queued for their boundaries."""
        self.replay = replay
        """The log a resumed run replays first (None once replayed): the replayed ticks'
        own rewards are matched with its entries."""
        self.replayed = asyncio.Event()
        """Set once a resumed run has replayed its log (at once for a new run)."""
        if replay is None:
            self.replayed.set()
        self.closing = False
        """No more rewards or edits: the run is stopping."""
        self.last_snap: Snapshot | None = None
        self.episode_start_tick = sim.tick_count
        self.ended: tuple[int, int, int] | None = None
        """The episode that ended last: (episode, start tick, last tick)."""
        self.ended_records: tuple[tuple[int, int, int], ...] = ()
        """That episode's last records, kept aside at its reset as its trace has them (the
        brain's, `Brain.ended`, if no trace is kept): a reward on its replay takes its
        window's records from them, as from the stored trace."""
        self._ending_records: tuple[tuple[int, int, int], ...] | None = None
        self.need_reset = True

    @property
    def tick_count(self) -> int:
        """Ticks run so far."""
        return self.sim.tick_count

    @property
    def totals(self) -> RunTotals:
        """Episodes, successes and ticks so far."""
        return RunTotals(self.episodes_done, self.successes, self.sim.tick_count)

    async def run(self) -> None:
        """The task: replay the log (a resumed run), tick at the run's pace, then stop."""
        try:
            if self.replay is not None:
                try:
                    await pace(self, Replay(self, self.replay.last_tick))
                finally:
                    self.replay = None
                    self.replayed.set()
            if self.spec.mode is Mode.REALTIME:
                await pace(self, Realtime(self, self.controls, self.pacer, self.stats))
            else:
                await pace(self, Fast(self, self.controls))
            # No more rewards now; those that arrived after the last tick apply at their
            # boundaries, reached as the run would have reached them.
            self.closing = True
            self.boundary.release_held()
            await self._reach_last_boundary()
            await self.settle(self.sim.tick_count + 1, until=math.inf)
        finally:
            self.closing = True
            self.controls.refuse_steps(RunStateError(f"run {self.run_id} ended before the step"))
            self.boundary.close()
            self.writer.end_of_ticks()

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
        due = self.boundary.due
        while due and max(job.stamp for job in due) > self.sim.tick_count + 1:
            await self.step()
        if due and self.need_reset:
            self._start_episode()

    def _episodes_left(self) -> bool:
        limit = self.spec.episodes
        return limit is None or self.episodes_done < limit

    def more(self) -> bool:
        """Whether the tick task should run another tick."""
        controls = self.controls
        if controls.until_tick is not None and self.sim.tick_count >= controls.until_tick:
            controls.stopping = True
        return not controls.stopping and (not self.need_reset or self._episodes_left())

    async def step(self) -> None:
        """One tick, with its boundary before and its episode's end after.

        While a resumed run replays, the boundary's trainers' rewards and edits come from
        the log.
        """
        sim = self.sim
        if self.need_reset:
            self._start_episode()
        if self.replay is not None:
            boundary = sim.tick_count + 1
            for job in self.replay.rewards_at(boundary):
                self.boundary.queue(job)
            for edit in self.replay.edits_at(boundary):
                apply_edit(sim, edit)
        if self.boundary.due or self.commands:
            await self.settle(sim.tick_count + 1)
        ended = self._tick()
        if ended is not None:
            await self.end(ended)

    async def end(self, ended: EpisodeEnded) -> None:
        """End an episode; its own rewards (the task's, the program's) apply first.

        A trainer's reward arriving now applies after the next reset.
        """
        if self.boundary.due:
            await self.settle(self.sim.tick_count + 1, internal_only=True)
        self._end_episode(ended)

    def burst(self, ticks: int) -> EpisodeEnded | None:
        """Up to `ticks` ticks with no await between them: fast mode's common path.

        Nothing else runs meanwhile, so no edit, pause, stop, trainer's reward or
        subscriber can arrive; it returns early when a tick needs the event loop (a reward
        due at the next boundary, or an episode that ended with its own rewards to apply
        first: returned, for the caller to `end`) or the episodes are done.
        Unwatched and with no reward held, which is how fast runs go, a tick is just the
        simulation's tick, its trace row and its events: what `_tick` checks each tick
        cannot change, and the tick count and last snapshot are kept once, at the end.
        """
        if self.commands:
            return None
        until_tick = self.controls.until_tick
        if until_tick is not None:
            ticks = min(ticks, until_tick - self.sim.tick_count)
        watched = bool(self.bus.tick_subscribers or self.boundary.held)
        sim = self.sim
        due, step, sim_tick, hand_on = self.boundary.due, self._tick, sim.tick, self._hand_on
        add = self.trace.add if self.trace is not None else None
        first, result = sim.tick_count, None
        try:
            for _ in range(ticks):
                if due:
                    return None
                if self.need_reset:
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
                    self.last_snap = result.snapshot

    def _tick(self) -> EpisodeEnded | None:
        """Run one tick of the simulation and hand its events on."""
        result = self.sim.tick()
        self.stats.ticks += 1
        snap = result.snapshot
        if self.trace is not None:
            self.trace.add(snap)
        self.last_snap = snap
        if self.bus.tick_subscribers:
            # A single step of a paused run is always shown: no later tick would replace it.
            self._publish_tick(snap, force=self.controls.paused)
        ended = self._hand_on(result.events) if result.events else None
        if self.boundary.held:
            self.boundary.release_held()
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
                self.bus.publish(e)
        return ended

    def seen_episode(self, tick_seen: int, episode: int | None) -> int:
        """The episode a trainer's seen tick lies in; `SeenTickError` if none the run holds.

        The run's current episode (ticks from its start, the reset's tick, to the last
        tick run) or the one that ended last, whose last records are kept for the rewards
        pressed as it ended; `episode`, if given, must be the one the tick lies in.
        """
        sim = self.sim
        if tick_seen > sim.tick_count:
            raise SeenTickError(
                "tick_seen", f"tick {tick_seen} is in the future: run {self.run_id} has "
                f"reached tick {sim.tick_count}",
            )  # fmt: skip
        # The ended episode first: the reset's tick (the current episode's start) is its
        # last tick, and the records before it are its own.
        held = [(sim.episode, self.episode_start_tick, sim.tick_count)]
        if self.ended is not None and self.ended[0] != sim.episode:
            held.insert(0, self.ended)
        if episode is not None and all(e != episode for e, _, _ in held):
            known = " or ".join(str(e) for e, _, _ in held)
            raise SeenTickError(
                "episode", f"episode {episode} is not one a seen tick may lie in: {known}"
            )
        for e, first, last in held:
            if (episode is None or e == episode) and first <= tick_seen <= last:
                return e
        where = ", ".join(f"episode {e}: ticks {first}-{last}" for e, first, last in held)
        raise SeenTickError("tick_seen", f"tick {tick_seen} lies in no episode held ({where})")

    def start_paused(self) -> None:
        """A run paused at an episode's end starts the next one now, its first tick not run.

        So a trainer's reward arriving then is credited at once, at the boundary the run is
        paused at, and after the reset, where a replay of the log applies it. Not while a
        boundary is being settled (its rewards apply at the next tick, as before).
        """
        controls = self.controls
        if (
            controls.paused
            and not controls.stopping
            and self.need_reset
            and not self.boundary.settling
            and self._episodes_left()
        ):
            self._start_episode()

    def _start_episode(self) -> None:
        if self.sim.episode >= 0:
            self.ended = (self.sim.episode, self.episode_start_tick, self.sim.tick_count)
        self.sim.reset()
        ending, self._ending_records = self._ending_records, None
        self.ended_records = tuple(self.sim.brain.ended) if ending is None else ending
        self.need_reset = False
        self.episode_start_tick = self.sim.tick_count
        self.rewards.in_episode = 0

    def show_paused(self) -> None:
        """Offer the tick the run paused at to viewers whose throttle skipped it."""
        if self.bus.tick_subscribers and self.last_snap is not None:
            self._publish_tick(self.last_snap, force=True)

    def _publish_tick(self, snap: Snapshot, force: bool = False) -> None:
        """Offer a tick to the subscribers due one (all tick subscribers when forced)."""
        realtime = self.spec.mode is Mode.REALTIME
        period = 1.0 / self.controls.hz if realtime and self.controls.hz > 0 else 0.0
        self.bus.publish_tick(snap, self._tick_event, force, run_period=period)

    def _tick_event(self, snap: Snapshot) -> TickPublished:
        sim = self.sim
        obstacles = sim.obstacle_centers()
        return TickPublished(
            self.run_id,
            snap,
            sim.sonar_m(),
            obstacles[0] if obstacles else None,
            Competition.of(sim.brain.selector, snap.stimuli),
            self.totals,
            released_by_kp(sim.brain.network, snap),
            obstacles,
        )

    def _enqueue_internal(self, e: RewardDue) -> None:
        # Made again alike when the run is replayed.
        uid = f"{e.source}-{e.episode}-{e.tick}"
        reward = InjectReward(e.value, note=e.note, source=RewardSource(e.source), uid=uid)
        job = RewardJob(e.tick, e.episode, reward, False)
        if self.replay is not None:
            self.replay.match(job)
        self.boundary.queue(job)

    def command(self, job: CommandJob) -> None:
        """Queue an edit for its boundary (a paused run applies it at once)."""
        self.commands.append(job)
        if self.controls.paused:
            self._apply_commands(job.stamp)

    def credit_paused(self) -> None:
        """A paused run's rewards due at its boundary apply now, not at the next tick.

        Nothing ticks before that boundary, so they credit what they would credit there:
        the STM records before it. Not while the boundary is being settled (a step runs:
        a reward then is held for the next); a run paused at an episode's end has started
        the next one first (`start_paused`), as a replay applies them after the reset.
        """
        if self.controls.paused and not self.need_reset and not self.boundary.settling:
            self.boundary.release(self.sim.tick_count + 1)

    async def settle(
        self, boundary: int, *, internal_only: bool = False, until: float | None = None
    ) -> None:
        """At the boundary before tick `boundary`: apply its rewards, then its commands.

        `until` widens the stamps taken (shutdown takes every reward still due).
        """
        limit = boundary if until is None else until
        await self.boundary.settle(boundary, internal_only=internal_only, limit=limit)
        if self.commands and not internal_only:
            self._apply_commands(boundary)

    def _apply_commands(self, boundary: int) -> None:
        while self.commands and self.commands[0].stamp <= boundary:
            job = self.commands.popleft()
            job.update = apply_edit(self.sim, job.command)
            self.writer.applied(job)
            self.boundary.applied(job)

    def _end_episode(self, ended: EpisodeEnded) -> None:
        sim = self.sim
        self.episodes_done += 1
        self.successes += ended.outcome is Outcome.SUCCESS
        record = EpisodeRecord(
            episode=ended.episode,
            outcome=ended.outcome.value,
            cause=ended.cause.value if ended.cause else None,
            ticks=ended.ticks,
            start_tick=self.episode_start_tick,
            rewards=self.rewards.in_episode,
            trace=b"",  # compressed by the writer (`EpisodeJob.stored`)
        )
        state = export_state(sim)
        trace = self.trace.take() if self.trace is not None else None
        if trace is not None:
            self._ending_records = trace_records(trace, sim.brain.window.hi_ticks + 1)
        self.writer.episodes.put(
            EpisodeJob(
                record,
                sim.episode + 1,
                sim.tick_count,
                state,
                self.totals,
                self.rewards.last_applied,
                self.rewards.last_external,
                trace,
            )
        )
        self.need_reset = True
        self.bus.publish(ended)
