"""The 3D view's controller: on the service's event loop, reaching runs through `Live`s.

It carries out the panel's commands (select a run, reward it, change its rate, replay a
stored episode) with the same engine calls and store reads the HTTP API uses, and feeds
the renderer: while a browser watches a live run, it subscribes to that run's events
(tick snapshots throttled to `MAX_HZ` by the engine, in a bounded queue that drops the
oldest), turns each snapshot into a `TickView` with names resolved, and pushes it to the
`Inbox`. With nobody watching it subscribes to nothing, so the engines pay nothing.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from dataclasses import replace

from core.brain.catalog import Catalog
from core.commands import RewardSource
from core.engine import StatusChanged, SubscriptionClosed, TickPublished, check_hz
from core.engine.messages import Latest, LatestTick, SetRate
from core.errors import CoreError
from core.events import EpisodeEnded
from core.ports import ACTIVE, Mode, RunQueries, RunTotals
from core.run.simulation import Snapshot
from core.sim.world import WorldConfig
from server.api.ratelimit import RateLimiter
from server.runtime import LiveRun as Live
from server.runtime import RunLetGo
from server.runtime import Runs as Engines
from server.viewer.render import MAX_HZ, REWARD_NOTE, run_label
from server.viewer.replay import ReplayClock, load_replay
from server.viewer.scene import TickView
from server.viewer.state import (
    ChangeRate,
    ClientsChanged,
    GiveReward,
    Inbox,
    LiveInfo,
    RefreshRuns,
    RunChoice,
    Seek,
    SelectEpisode,
    SelectRun,
    SetMode,
    SetSpeed,
    ShowNotice,
    TogglePlay,
    ViewerCommand,
    ViewState,
)

log = logging.getLogger("srlab.viewer")

WATCH_S = 1.0
"""How often, while someone watches, the controller looks for runs started or ended."""
READ_ONLY = "this view of one run is read-only: reward from the page it was opened from"
LIMITER_KEY = "3d-view"
"""The rate limiter's client name for rewards given from the panel, with the viewer's id."""


def tick_view(live: Live, snap: Snapshot, totals: RunTotals, kp: bool) -> TickView:
    """A live snapshot as the view shows it, with the run's totals at that tick.

    Read on the service's loop: the catalogue is immutable (KP's growth replaces it whole);
    `kp` (the behaviour was released through an association KP taught) was read where the
    run ticks, with the tick.
    """
    cat = live.catalog
    stimuli = tuple(cat.stimuli[i].name for i in snap.stimuli)
    b = snap.behaviour
    behaviour = cat.behaviours[b].name if 0 <= b < len(cat.behaviours) else None
    return TickView(
        run_id=live.run_id,
        episode=snap.episode,
        tick=snap.tick,
        episode_tick=snap.episode_tick,
        x=snap.x,
        y=snap.y,
        heading_rad=snap.heading_rad,
        lamp=snap.lamp,
        stimuli=stimuli,
        behaviour=behaviour,
        how=snap.how.value,
        kp=kp,
        successes=totals.successes,
        episodes_done=totals.episodes,
        origin=snap.origin,
        released_by=(
            cat.stimuli[snap.released_by].name if 0 <= snap.released_by < len(cat.stimuli) else None
        ),
    )


class Controller:
    """Owns the view's state on the service's event loop.

    Args:
        inbox: where the renderer reads the state and live ticks.
        manager: the service's engines.
        store: the service's run store.
        catalog: the shipped catalogue (names of stimuli and behaviours).
        limiter: the service's reward rate limiter (the panel is one more client).
        writable: the panel may reward and change rates (the service is on loopback).
        world: the world every replay is drawn in (None: each run's own preset).
        only: the one run this view may show, read-only (a participant's); None: any.
        loop: the service's event loop, when built on another thread (a viewer's connect).
    """

    def __init__(
        self,
        inbox: Inbox,
        manager: Engines,
        store: RunQueries,
        catalog: Catalog,
        limiter: RateLimiter,
        *,
        writable: bool,
        world: WorldConfig | None = None,
        loop: asyncio.AbstractEventLoop | None = None,
        only: int | None = None,
    ) -> None:
        self.inbox = inbox
        self.manager = manager
        self.store = store
        self.catalog = catalog
        self.limiter = limiter
        self.world = world
        self.only = only
        self.state = ViewState(writable=writable and only is None, only=only)
        self._commands: asyncio.Queue[ViewerCommand] = asyncio.Queue()
        self._loop: asyncio.AbstractEventLoop | None = loop
        if loop is None:
            # Built on the service's loop: commands posted before `run` starts wait.
            with contextlib.suppress(RuntimeError):
                self._loop = asyncio.get_running_loop()
        self._follow: asyncio.Task[None] | None = None
        self._signature: tuple[tuple[int, str], ...] | None = None
        self._stored: dict[int, tuple[str, str, int, str, float, str]] = {}
        """Per stored run: condition, mode, seed, status, hz, world (from the last refresh)."""
        self._background: set[asyncio.Task[None]] = set()
        self._chosen = False
        """A user chose the run (the dropdown, a link): stop following the newest one."""
        self.handled = 0
        """Commands handled so far (tests wait on it)."""

    # --- from other threads -----------------------------------------------------------

    def post(self, command: ViewerCommand) -> None:
        """Hand a command to the controller; safe from any thread (viser's callbacks)."""
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        with contextlib.suppress(RuntimeError):  # the loop is closing: nothing to do
            loop.call_soon_threadsafe(self._commands.put_nowait, command)

    # --- the task ---------------------------------------------------------------------

    async def run(self) -> None:
        """Carry out commands and watch the runs until cancelled."""
        self._loop = asyncio.get_running_loop()
        watcher = asyncio.create_task(self._watch(), name="viewer watch")
        try:
            while True:
                command = await self._commands.get()
                try:
                    await self.handle(command)
                except (CoreError, LookupError, ValueError) as e:
                    self._publish(notice=f"**Not done:** {e}")
                except Exception as e:
                    log.exception("the 3D view's command %r failed", command)
                    self._publish(notice=f"**Failed:** {type(e).__name__}: {e}")
                self.handled += 1
        finally:
            watcher.cancel()
            await self._stop_following()
            for t in list(self._background):
                t.cancel()
            await asyncio.gather(watcher, *self._background, return_exceptions=True)

    def _publish(self, **changes: object) -> None:
        self.state = replace(self.state, **changes)  # type: ignore[arg-type]
        self.inbox.publish(self.state)

    async def handle(self, command: ViewerCommand) -> None:
        """Carry out one command (on the event loop)."""
        st = self.state
        now = time.monotonic()
        if isinstance(command, ClientsChanged):
            self._publish(clients=command.clients)
            if command.clients > 0:
                await self._refresh_runs(force=True)
            self._update_following()
        elif isinstance(command, RefreshRuns):
            await self._refresh_runs(force=True)
        elif isinstance(command, SelectRun):
            await self._select(command.run_id)
            self._chosen = True
        elif isinstance(command, SetMode):
            if command.mode == st.mode:
                return
            self._publish(mode=command.mode, version=st.version + 1, notice="")
            if command.mode == "replay":
                await self._load_episodes()
                if self.state.replay is None and self.state.episodes:
                    await self._load_replay(self.state.episodes[-1][0])
            self._update_following()
        elif isinstance(command, SelectEpisode):
            await self._load_replay(command.episode)
        elif isinstance(command, TogglePlay):
            if st.clock is not None:
                clock = st.clock.pause(now) if st.clock.playing else st.clock.play(now)
                self._publish(clock=clock)
        elif isinstance(command, Seek):
            if st.clock is not None:
                self._publish(clock=st.clock.seek(command.index, now))
        elif isinstance(command, SetSpeed):
            if st.clock is not None:
                self._publish(clock=st.clock.with_speed(command.speed, now))
        elif isinstance(command, ChangeRate):
            await self._change_rate(command.hz)
        elif isinstance(command, GiveReward):
            self._spawn(self._reward(command.value, command.client))
        elif isinstance(command, ShowNotice):
            self._publish(notice=command.text)

    def _spawn(self, coro: object) -> None:
        task: asyncio.Task[None] = asyncio.create_task(coro)  # type: ignore[arg-type]
        self._background.add(task)
        task.add_done_callback(self._background.discard)

    # --- runs -------------------------------------------------------------------------

    def _engines_signature(self) -> tuple[tuple[int, str], ...]:
        return tuple(sorted((e.run_id, e.status.value) for e in self.manager.engines()))

    async def _refresh_runs(self, *, force: bool = False) -> None:
        signature = self._engines_signature()
        if not force and signature == self._signature:
            return
        self._signature = signature
        stored = await asyncio.to_thread(self.store.list_runs)
        if self.only is not None:  # the others' runs are not listed, not even their ids
            stored = [r for r in stored if r.id == self.only]
        self._stored = {
            r.id: (
                r.spec.condition,
                r.spec.mode.value,
                r.spec.seed,
                r.status.value,
                r.spec.hz,
                r.spec.world,
            )
            for r in stored
        }
        runs = []
        for r in stored:
            engine = self.manager.get(r.id)
            live = engine is not None and engine.status in ACTIVE
            runs.append(RunChoice(r.id, run_label(r.id, r.spec.condition, r.spec.mode.value), live))
        self._publish(runs=tuple(runs))
        st = self.state
        newest = max((r.id for r in runs if r.live), default=None)
        selected = next((r for r in runs if r.id == st.run_id), None)
        if st.run_id is None or selected is None:
            target = newest if newest is not None else (runs[-1].id if runs else None)
            if target is not None:
                await self._select(target)
        elif st.mode == "live" and not selected.live and newest is not None and not self._chosen:
            # Follow the newest live run, unless the user chose one or looks at a replay.
            await self._select(newest)
        else:
            self._publish(live=self._live_info(st.run_id))

    def _live_info(self, run_id: int | None) -> LiveInfo | None:
        info = self._run_info(run_id)
        if info is not None and self.only is not None:
            # A study's participant is not told their condition (docs/studies.md).
            return replace(info, condition="")
        return info

    def _run_info(self, run_id: int | None) -> LiveInfo | None:
        if run_id is None:
            return None
        engine = self.manager.get(run_id)
        if engine is not None:
            spec = engine.spec
            return LiveInfo(
                run_id,
                spec.condition,
                spec.seed,
                engine.status.value,
                spec.mode is Mode.REALTIME,
                engine.hz,
                engine.status in ACTIVE,
                spec.world,
            )
        stored = self._stored.get(run_id)
        if stored is None:
            return None
        condition, mode, seed, status, hz, world = stored
        realtime = mode == Mode.REALTIME.value
        return LiveInfo(run_id, condition, seed, status, realtime, hz, False, world)

    async def _select(self, run_id: int) -> None:
        st = self.state
        if run_id == st.run_id and st.live is not None:
            return
        if self.only is not None and run_id != self.only:
            raise LookupError(f"this view shows run {self.only} only")
        if run_id not in self._stored and self.manager.get(run_id) is None:
            await self._refresh_runs(force=True)
            if run_id not in self._stored:
                raise LookupError(f"there is no run {run_id}")
        self._publish(
            run_id=run_id,
            live=self._live_info(run_id),
            replay=None,
            clock=None,
            episodes=(),
            version=st.version + 1,
            notice="",
        )
        if self.state.mode == "replay":
            await self._load_episodes()
            if self.state.episodes:
                await self._load_replay(self.state.episodes[-1][0])
        self._update_following()

    async def _watch(self) -> None:
        """While someone watches: notice runs started or ended, and the replay's end."""
        while True:
            await asyncio.sleep(WATCH_S)
            st = self.state
            if st.clients == 0:
                continue
            try:
                await self._refresh_runs()
                if st.clock is not None and st.clock.playing:
                    settled = st.clock.settle(time.monotonic())
                    if settled is not st.clock:
                        self._publish(clock=settled)
                if st.mode == "replay" and st.live is not None and st.live.ticking:
                    await self._load_episodes()
            except CoreError as e:  # storage trouble: say so, keep watching
                self._publish(notice=f"**Storage:** {e}")

    # --- replay -----------------------------------------------------------------------

    async def _load_episodes(self) -> None:
        run_id = self.state.run_id
        if run_id is None:
            return
        records = await asyncio.to_thread(self.store.episode_summaries, run_id)
        episodes = tuple((e.episode, f"{e.episode} {e.outcome}, {e.ticks} ticks") for e in records)
        if episodes != self.state.episodes:
            self._publish(episodes=episodes)

    async def _load_replay(self, episode: int) -> None:
        run_id = self.state.run_id
        if run_id is None:
            raise LookupError("select a run first")
        replay = await asyncio.to_thread(
            load_replay, self.store, self.catalog, run_id, episode, self.world
        )
        if self.state.run_id != run_id:
            return  # another run was selected meanwhile
        speed = self.state.clock.speed if self.state.clock is not None else 1.0
        clock = ReplayClock(replay.ticks, replay.world.dt_s, speed=speed).play(time.monotonic())
        self._publish(
            mode="replay", replay=replay, clock=clock, version=self.state.version + 1, notice=""
        )
        self._update_following()

    # --- live -------------------------------------------------------------------------

    def _update_following(self) -> None:
        """Follow the selected run's events only while someone watches it live."""
        st = self.state
        want = st.clients > 0 and st.mode == "live" and st.run_id is not None
        current = self._follow
        if current is not None and not current.done():
            if want and current.get_name() == f"viewer follows run {st.run_id}":
                return
            current.cancel()
            self._follow = None
        if want:
            assert st.run_id is not None
            self._follow = asyncio.create_task(
                self._follow_run(st.run_id), name=f"viewer follows run {st.run_id}"
            )

    async def _stop_following(self) -> None:
        task, self._follow = self._follow, None
        if task is not None:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)

    async def _follow_run(self, run_id: int) -> None:
        """Push the run's tick snapshots to the renderer; wait out its pauses and restarts."""
        shown: Live | None = None
        while True:
            live = self.manager.get(run_id)
            if live is None or live.status not in ACTIVE:
                if live is not None and live is not shown:
                    # A run that ended here: show where it stopped.
                    shown = live
                    await self._show_now(live)
                await asyncio.sleep(0.5)
                continue
            sub = live.subscribe(maxsize=64, tick_hz=MAX_HZ)
            try:
                self._publish(live=self._live_info(run_id))
                await self._show_now(live)
                while True:
                    try:
                        event = await sub.get()
                    except SubscriptionClosed:
                        break
                    if isinstance(event, TickPublished):
                        if event.totals is not None:
                            self.inbox.push(tick_view(live, event.snapshot, event.totals, event.kp))
                    elif isinstance(event, StatusChanged | EpisodeEnded):
                        self._publish(live=self._live_info(run_id))
            finally:
                live.unsubscribe(sub)
            self._publish(live=self._live_info(run_id))

    async def _show_now(self, live: Live) -> None:
        """Push the run's latest tick (none before its first episode, or once it ended)."""
        try:
            now: LatestTick | None = await live.ask(Latest())
        except RunLetGo:  # ended there while the read was on its way
            return
        if now is not None:
            self.inbox.push(tick_view(live, now.snapshot, now.totals, now.kp))

    async def _change_rate(self, hz: float) -> None:
        st = self.state
        if st.only is not None:
            raise ValueError(READ_ONLY)
        if not st.writable:
            raise ValueError("the panel changes rates on loopback only: use the API's token")
        live = self.manager.get(st.run_id) if st.run_id is not None else None
        if live is None or live.status not in ACTIVE:
            raise ValueError("the selected run is not running here")
        if live.spec.mode is not Mode.REALTIME:
            raise ValueError("a fast run has no tick rate to change")
        check_hz(hz)  # ValueError (shown) out of HZ_MIN..HZ_MAX
        await live.send(SetRate(hz))
        self._publish(live=self._live_info(st.run_id), notice=f"Tick rate set to {hz:g} Hz")

    async def _reward(self, value: float, client: int | None = None) -> None:
        st = self.state
        sign = f"{value:+g}"
        try:
            if st.only is not None:
                raise ValueError(READ_ONLY)
            if not st.writable:
                raise ValueError("the panel rewards on loopback only: use the API's token")
            engine = self.manager.get(st.run_id) if st.run_id is not None else None
            if engine is None or engine.status not in ACTIVE:
                # A paused run takes rewards as the API does: at the boundary it waits at.
                raise ValueError("the selected run is not running or paused")
            wait = self.limiter.allow(f"{LIMITER_KEY}:{client}", run=engine.run_id)
            if wait > 0:
                raise ValueError(f"too many rewards: wait {wait:.1f} s")
            ack = await engine.reward(value, note=REWARD_NOTE, source=RewardSource.TRAINER)
        except (CoreError, ValueError) as e:
            self._publish(notice=f"**Reward {sign} not given:** {e}")
            return
        self._publish(
            notice=f"Reward {sign} stored as #{ack.id}, at tick {ack.tick} of episode {ack.episode}"
        )


__all__ = ["Controller", "tick_view"]
