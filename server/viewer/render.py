"""The renderer: the one thread that calls viser, drawing the view's state at most 30 Hz.

It waits for the controller's news (a live tick, a new state), takes the latest, maps it to
a `SceneFrame` with the pure functions of `server.viewer.scene`, and sends viser only what
changed since the last frame, all in one `atomic()` group. Ticks that arrive faster than
the frame rate only extend the trail; the robot is drawn where the newest one puts it.
Panel callbacks run on viser's own thread and only hand `ViewerCommand`s to `post`. The
scene's nodes are `server.viewer.nodes`', the panel's inputs `server.viewer.panel`'s.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import viser

from core.sim.types import build_geometry
from core.sim.world import EpisodeLayout, WorldConfig, episode_layout
from server.viewer.nodes import Cache, SceneNodes
from server.viewer.panel import Panel, episode_of_label, run_label, run_of_label, speed_label
from server.viewer.replay import run_world
from server.viewer.scene import SceneFrame, StaticScene, TickView, Trail, scene_frame, static_scene
from server.viewer.state import Inbox, ViewerCommand, ViewState

log = logging.getLogger("srlab.viewer")

MAX_HZ = 30.0
"""The scene is redrawn at most this often."""
REWARD_NOTE = "3D view"


def late(state: ViewState, since_tick_s: float) -> bool:
    """Whether a frame of a realtime run's tick `since_tick_s` old is too late to draw.

    A frame is drawn right after the tick that caused it, in the quiet first half of the
    tick period. If this thread ran late (a busy machine), drawing now could hold the
    interpreter just as the next tick is due: the frame is dropped, the next tick's
    comes soon.
    """
    live = state.live
    if state.mode != "live" or live is None or not live.realtime or live.status != "running":
        return False
    return since_tick_s > 0.5 / live.hz


class Renderer(SceneNodes, Panel):
    """Builds the scene and the panel on a viser server and draws frames on it.

    The scene is of the shown run's world (its preset): when another run or a replay of
    another world is shown, the track, the obstacle and the robot are built again.

    It draws for one viewer (a `viser.ClientHandle`: its own scene and panel, which
    shadow the server's) or on the server's own scene and panel, which every browser sees
    (a `viser.ViserServer`: tests and scripts).

    Args:
        server: where it draws: one client's handle, or the viser server (listening).
        scene: the world's fixed parts.
        world: the world's configuration (the episodes' layouts are drawn from it).
        post: hands a panel command to the service's event loop (thread-safe).
        fixed: draw every run in this world instead of its own (None: each run's).
    """

    def __init__(
        self,
        server: viser.ViserServer | viser.ClientHandle,
        scene: StaticScene,
        world: WorldConfig,
        post: Callable[[ViewerCommand], None],
        *,
        fixed: WorldConfig | None = None,
    ) -> None:
        self.server = server
        self.static = scene
        self.world = world
        self.geometry = build_geometry(world.track)
        self.post = post
        self.fixed = fixed
        self.frames = 0
        """Frames drawn (for tests and the bench)."""
        self.dropped = 0
        """Frames dropped because the tick they showed was too old (see `late`)."""
        self.last_frame: SceneFrame | None = None
        self.last_view: TickView | None = None
        """The newest live tick of the selected run."""
        self.drawn: TickView | None = None
        """The tick the last frame showed (live or replayed)."""
        self._cache = Cache({})
        self._trail = Trail()
        self._trail_nodes: list[viser.LineSegmentsHandle] = []
        self._trail_sent: list[int] = []
        self._wall_nodes: list[viser.BoxHandle] = []
        self._obstacles: list[viser.BoxHandle] = []
        self._replay_trail: tuple[int, int, Trail] | None = None
        """(version, index, trail) of the replay's trail so far."""
        self._layouts: dict[tuple[int, int], EpisodeLayout] = {}
        self._version = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._light()
        self._build_scene()
        self._build_panel()

    # --- the thread -----------------------------------------------------------------

    def start(self, inbox: Inbox) -> None:
        """Draw `inbox`'s news on a thread of its own until `stop`."""
        self._thread = threading.Thread(
            target=self._loop, args=(inbox,), name="srlab viewer renderer", daemon=True
        )
        self._thread.start()

    def stop(self, inbox: Inbox) -> None:
        """End the thread (it finishes the frame it is drawing)."""
        self._stop.set()
        inbox.wake.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    def _loop(self, inbox: Inbox) -> None:
        period = 1.0 / MAX_HZ
        next_at = 0.0
        while not self._stop.is_set():
            state = inbox.state
            playing = state.mode == "replay" and state.clock is not None and state.clock.playing
            inbox.wake.wait(period if playing else 1.0)
            inbox.wake.clear()
            if self._stop.is_set():
                break
            now = time.monotonic()
            if now < next_at:
                # At most MAX_HZ: what arrives meanwhile is drawn together, newest on top.
                self._stop.wait(next_at - now)
            next_at = time.monotonic() + period
            now = time.monotonic()
            state = inbox.state
            try:
                send = not late(state, now - inbox.pushed_at)
                if not send:
                    self.dropped += 1
                self.draw(state, inbox.drain(), now, send=send)
            except Exception:  # a bad frame must not end the view
                log.exception("the 3D view could not draw a frame")

    # --- drawing --------------------------------------------------------------------

    def world_of(self, state: ViewState) -> WorldConfig:
        """The world `state` shows: the replay's, else the selected run's, else the last."""
        if self.fixed is not None:
            return self.fixed
        if state.mode == "replay" and state.replay is not None:
            return state.replay.world
        if state.live is not None:
            return run_world(state.live.world)
        return self.world

    def use_world(self, world: WorldConfig) -> None:
        """Show `world`: build the scene again if it is not the one shown."""
        if world is self.world or world == self.world:
            return
        self.world = world
        self.static = static_scene(world)
        self.geometry = build_geometry(world.track)
        self._layouts.clear()
        with self.server.atomic():
            self._build_scene()  # the same node names: each replaces the one before
        self._cache = Cache({})  # the new nodes have none of the values sent before

    def layout(self, seed: int, episode: int) -> EpisodeLayout:
        """The obstacle and lamp cycle of an episode (cached)."""
        key = (seed, episode)
        found = self._layouts.get(key)
        if found is None:
            if len(self._layouts) > 64:
                self._layouts.clear()
            found = episode_layout(self.world, self.geometry, seed, episode)
            self._layouts[key] = found
        return found

    def draw(
        self, state: ViewState, ticks: Sequence[TickView], now: float, *, send: bool = True
    ) -> None:
        """Draw one frame of `state` with the live ticks that arrived since the last one.

        With `send` false (or nobody watching) only the trail takes the ticks in.
        """
        if state.version != self._version:
            self._version = state.version
            self._trail.clear()
            self._replay_trail = None
            self.last_view = None
        self.use_world(self.world_of(state))
        view: TickView | None = None
        layout: EpisodeLayout | None = None
        trail: Trail
        if state.mode == "replay" and state.replay is not None and state.clock is not None:
            replay = state.replay
            index = state.clock.at(now)
            view = replay.views[index]
            layout = replay.layout
            trail = self._replay_trail_to(state.version, replay.views, index)
        else:
            for v in ticks:
                if v.run_id == state.run_id:
                    self._trail.add(v)
                    self.last_view = v
            view = self.last_view
            trail = self._trail
            if view is not None and state.live is not None:
                layout = self.layout(state.live.seed, view.episode)
        if state.clients == 0 or not send:
            return  # nobody watches, or a dropped frame: keep the trail, send nothing
        if view is not None and state.blind:
            view = replace(view, kp=False)  # a participant's: "(KP)" would tell the condition
        frame = scene_frame(self.static, view, layout) if view is not None else None
        with self.server.atomic():
            if frame is not None:
                self._draw_frame(frame)
            self._draw_trail(trail.points if view is not None else [])
            self._draw_panel(state, view, now)
        # Send now rather than within viser's next 1/60 s window: the work stays next to
        # the tick that caused it, far from the next tick's deadline.
        self.server.flush()
        self.last_frame = frame
        self.drawn = view
        self.frames += 1

    def _replay_trail_to(self, version: int, views: Sequence[TickView], index: int) -> Trail:
        cached = self._replay_trail
        if cached is None or cached[0] != version or cached[1] > index:
            cached = (version, -1, Trail())
        _, done, trail = cached
        for v in views[done + 1 : index + 1]:
            trail.add(v)
        self._replay_trail = (version, index, trail)
        return trail


__all__ = [
    "MAX_HZ",
    "REWARD_NOTE",
    "Renderer",
    "episode_of_label",
    "late",
    "run_label",
    "run_of_label",
    "speed_label",
]
