"""The renderer: the one thread that calls viser, drawing the view's state at most 30 Hz.

It waits for the controller's news (a live tick, a new state), takes the latest, maps it to
a `SceneFrame` with the pure functions of `server.viewer.scene`, and sends viser only what
changed since the last frame, all in one `atomic()` group. Ticks that arrive faster than
the frame rate only extend the trail; the robot is drawn where the newest one puts it.
Panel callbacks run on viser's own thread and only hand `ViewerCommand`s to `post`.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser

from core.sim.track import TrackGeometry
from core.sim.world import EpisodeLayout, WorldConfig, episode_layout
from server.viewer.inbound import guard_panel
from server.viewer.replay import SPEEDS, run_world
from server.viewer.scene import (
    BULBS,
    CAMERA_HEIGHT_M,
    DIM,
    FLOOR_COLOR,
    KP_COLOR,
    STOPLINE_COLOR,
    SceneFrame,
    StaticScene,
    TickView,
    Trail,
    decision_markdown,
    scene_frame,
    static_scene,
    yaw_quaternion,
)
from server.viewer.state import (
    ChangeRate,
    GiveReward,
    Inbox,
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

MAX_HZ = 30.0
"""The scene is redrawn at most this often."""
TRAIL_CHUNK = 64
"""Points per trail node: a growing trail resends only its last node."""
REWARD_NOTE = "3D view"
NO_RUNS = "(no runs yet)"
NO_EPISODES = "(no stored episodes)"

_BODY = (196, 30, 36)
_TRAIL = (37, 99, 235)
_WALL = (71, 85, 105)
_FLOOR = FLOOR_COLOR
_GROUND = (245, 245, 240)
_BOX = (180, 128, 72)
_FOV = (250, 204, 21)


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


def run_label(run_id: int, condition: str, mode: str) -> str:
    """A dropdown entry; it starts with ``#<id>`` so the id can be read back."""
    return f"#{run_id} {condition} {mode}"


def _number(value: object) -> float:
    """A panel control's value as a finite float (ValueError otherwise, TypeError for bools)."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise TypeError(f"not a number: {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f"not a finite number: {value!r}")
    return x


def run_of_label(label: str) -> int | None:
    """The run id of a dropdown entry, None for the placeholder."""
    head = label.split(" ", 1)[0]
    if head.startswith("#") and head[1:].isdigit():
        return int(head[1:])
    return None


def speed_label(speed: float) -> str:
    """A replay speed as the dropdown shows it."""
    return f"{speed:g}x"


def episode_of_label(label: str) -> int | None:
    """The episode number of an episode dropdown entry."""
    head = label.split(" ", 1)[0]
    return int(head) if head.isdigit() else None


@dataclass
class _Cache:
    """The last value sent for each property, so unchanged ones are not sent again."""

    values: dict[str, Any]

    def changed(self, key: str, value: Any) -> bool:
        if self.values.get(key, _MISSING) == value:
            return False
        self.values[key] = value
        return True


_MISSING = object()


def _assign(handle: Any, value: object) -> None:
    """Set a panel input's value.

    viser's setter takes more types than its getter gives, which mypy cannot express.
    """
    handle.value = value


class Renderer:
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
        self.geometry = TrackGeometry.build(world.track)
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
        self._cache = _Cache({})
        self._trail = Trail()
        self._trail_nodes: list[viser.LineSegmentsHandle] = []
        self._trail_sent: list[int] = []
        self._replay_trail: tuple[int, int, Trail] | None = None
        """(version, index, trail) of the replay's trail so far."""
        self._layouts: dict[tuple[int, int], EpisodeLayout] = {}
        self._version = -1
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._light()
        self._build_scene()
        self._build_panel()

    # --- building -------------------------------------------------------------------

    def _light(self) -> None:
        """Light the scene once: the lights do not depend on the world shown."""
        scene = self.server.scene
        # Lit by viser's default lights and a sky light, not by an environment map: with the
        # map a frame took a software renderer (a machine without a GPU, CI's Chromium) about
        # 1.7 CPU-seconds, so an open view kept two cores busy; without it, a third of one
        # core, and the scene looks the same (docs/viewer.md). Nothing here casts a shadow.
        scene.configure_environment_map(hdri=None)
        scene.configure_default_lights(enabled=True, cast_shadow=False)
        scene.add_light_hemisphere(
            "/light/sky",
            sky_color=(255, 255, 255),
            ground_color=(200, 200, 200),
            intensity=2.0,
            position=(0.0, 0.0, 1.0),  # the sky is up: +z
        )

    def _build_scene(self) -> None:
        s = self.static
        sc = self.server.scene
        if isinstance(self.server, viser.ViserServer):  # a client's scene has no axes of its own
            sc.world_axes.visible = False
        cx, cy, _ = s.center
        ox0, oy0, ox1, oy1 = s.outer_box
        camera: Any = (
            self.server.initial_camera
            if isinstance(self.server, viser.ViserServer)
            else self.server.camera
        )
        # Far enough that the whole track fits the canvas beside the docked panel at 1024 px.
        camera.position = (cx, cy - 1.0 * (oy1 - oy0) - 0.5, 0.9 * (ox1 - ox0))
        camera.look_at = (cx, cy - 0.1, 0.0)
        sc.add_box(
            "/ground",
            color=_GROUND,
            dimensions=(ox1 - ox0 + 4.0, oy1 - oy0 + 4.0, 0.02),
            position=(cx, cy, -0.012),
            cast_shadow=False,
        )
        sc.add_mesh_simple(
            "/track/floor",
            np.asarray(s.floor_vertices, dtype=np.float32),
            np.asarray(s.floor_faces, dtype=np.uint32),
            color=_FLOOR,
            side="double",
            cast_shadow=False,
        )
        for i, w in enumerate(s.walls):
            sc.add_box(
                f"/track/walls/{i}",
                color=_WALL,
                dimensions=w.size,
                position=w.center,
                wxyz=yaw_quaternion(w.yaw_rad),
            )
        sl = s.stopline
        sc.add_box(
            "/track/stopline",
            color=STOPLINE_COLOR,
            dimensions=sl.size,
            position=sl.center,
            wxyz=yaw_quaternion(sl.yaw_rad),
            cast_shadow=False,
        )
        lx, ly, lz = s.lamp_position
        sc.add_cylinder(
            "/track/lamp/pole",
            radius=0.02,
            height=lz,
            color=(60, 60, 60),
            position=(lx, ly, lz / 2),
        )
        sc.add_box(
            "/track/lamp/housing",
            color=(25, 25, 25),
            dimensions=(0.1, 0.1, 0.36),
            position=(lx, ly, lz + 0.16),
        )
        self._bulbs = [
            sc.add_icosphere(
                f"/track/lamp/{c.name.lower()}",
                radius=0.06,
                color=DIM,
                position=(lx, ly, lz + 0.27 - 0.11 * k),
            )
            for k, c in enumerate(BULBS)
        ]
        size = s.obstacle_size_m
        self._obstacle = sc.add_box(
            "/obstacle", color=_BOX, dimensions=(size, size, size), visible=False
        )
        x, y, th = self.geometry.start_pose
        self._robot = sc.add_frame(
            "/robot", show_axes=False, position=(x, y, 0.0), wxyz=yaw_quaternion(th)
        )
        sc.add_mesh_simple(
            "/robot/body",
            np.asarray(s.body_vertices, dtype=np.float32),
            np.asarray(s.body_faces, dtype=np.uint32),
            color=_BODY,
            flat_shading=False,
        )
        wheel = (math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0)  # axis along y
        half_w = self.world.robot.width_m / 2
        for side, sign in (("left", 1.0), ("right", -1.0)):
            sc.add_cylinder(
                f"/robot/wheel_{side}",
                radius=0.05,
                height=0.03,
                color=(20, 20, 20),
                position=(0.0, sign * (half_w + 0.005), 0.05),
                wxyz=wheel,
            )
        sc.add_box(
            "/robot/camera",
            color=(20, 20, 20),
            dimensions=(0.05, 0.09, 0.05),
            position=(self.world.robot.camera_offset_m, 0.0, CAMERA_HEIGHT_M - 0.025),
        )
        sc.add_mesh_simple(
            "/robot/fov",
            np.asarray(s.fov_vertices, dtype=np.float32),
            np.asarray(s.fov_faces, dtype=np.uint32),
            color=_FOV,
            opacity=0.22,
            side="double",
            cast_shadow=False,
            receive_shadow=False,
        )
        self._kp = sc.add_cylinder(
            "/robot/kp",
            radius=0.32,
            height=0.012,
            color=KP_COLOR,
            opacity=0.55,
            position=(0.0, 0.0, 0.006),
            visible=False,
            cast_shadow=False,
        )
        n = len(s.sonar_angles_rad)
        self._sonar = sc.add_line_segments(
            "/robot/sonar",
            np.zeros((n, 2, 3), dtype=np.float32),
            np.zeros((n, 2, 3), dtype=np.uint8),
            thickness=0.012,
        )
        self._label = sc.add_label(
            "/robot/label", "-", position=(0.0, 0.0, 0.42), anchor="bottom-center"
        )

    def _build_panel(self) -> None:
        gui = self.server.gui
        post = self.post
        # Before the inputs exist: a socket may send values as soon as it learns their ids.
        guard_panel(gui, lambda problem: post(ShowNotice(f"**Refused:** {problem}")))
        gui.configure_theme(show_share_button=False, control_width="medium")
        # Docked, the panel takes its own strip and the canvas the rest: floating over the
        # canvas, it covered the track's right side (and the robot there) at 1024 px.
        gui.main_panel.dock_right()
        gui.set_panel_label("srlab 3D view")
        self._header = gui.add_markdown("**srlab**: waiting for a run")
        self._runs = gui.add_dropdown("Run", (NO_RUNS,))
        self._mode = gui.add_button_group("View", ("Live", "Replay"))
        self._live_folder = gui.add_folder("Live run")
        with self._live_folder:
            self._rate = gui.add_slider("Tick rate (Hz)", 1.0, 100.0, 1.0, 10.0)
            self._plus = gui.add_button("+ reward", color="green", hint="reward +1 now")
            self._minus = gui.add_button("- reward", color="red", hint="reward -1 now")
        self._replay_folder = gui.add_folder("Replay", visible=False)
        with self._replay_folder:
            self._episode = gui.add_dropdown("Episode", (NO_EPISODES,))
            self._play = gui.add_button("Play")
            # Counted from 1, as the decision panel counts an episode's ticks.
            self._scrub = gui.add_slider("Tick", 1, 2, 1, 1)
            self._speed = gui.add_dropdown(
                "Speed", tuple(speed_label(s) for s in SPEEDS), initial_value=speed_label(1.0)
            )
        self._decision = gui.add_markdown("")
        self._notice = gui.add_markdown("")

        def command(make: Callable[[viser.GuiEvent[Any]], ViewerCommand | None]) -> Any:
            """A callback that posts `make(event)`: a value it cannot read is ignored.

            `guard_panel` refuses what viser's page would not send; whatever else cannot be
            read must not leave a failed task ("Task exception was never retrieved") in
            viser's loop either.
            """

            async def callback(event: viser.GuiEvent[Any]) -> None:
                try:
                    made = make(event)
                except (TypeError, ValueError, AttributeError, OverflowError) as e:
                    log.warning("the 3D view ignored a malformed panel value: %s", e)
                    return
                if made is not None:
                    post(made)

            return callback

        def from_client(event: viser.GuiEvent[Any]) -> bool:
            return event.client_id is not None

        # Callbacks run on viser's event loop: they only hand commands on. Assignments
        # made here by the renderer call them too, without a client: those are ignored.
        self._runs.on_update(
            command(
                lambda e: (
                    SelectRun(run)
                    if from_client(e) and (run := run_of_label(self._runs.value)) is not None
                    else None
                )
            )
        )
        self._mode.on_click(
            command(lambda e: SetMode("replay" if self._mode.value == "Replay" else "live"))
        )
        self._rate.on_update(
            command(lambda e: ChangeRate(_number(self._rate.value)) if from_client(e) else None)
        )
        self._plus.on_click(command(lambda e: GiveReward(1.0, e.client_id)))
        self._minus.on_click(command(lambda e: GiveReward(-1.0, e.client_id)))
        self._episode.on_update(
            command(
                lambda e: (
                    SelectEpisode(n)
                    if from_client(e) and (n := episode_of_label(self._episode.value)) is not None
                    else None
                )
            )
        )
        self._play.on_click(command(lambda e: TogglePlay()))
        self._scrub.on_update(
            command(lambda e: Seek(int(_number(self._scrub.value)) - 1) if from_client(e) else None)
        )
        self._speed.on_update(
            command(
                lambda e: (
                    SetSpeed(_number(str(self._speed.value).rstrip("x")))
                    if from_client(e)
                    else None
                )
            )
        )

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
        self.geometry = TrackGeometry.build(world.track)
        self._layouts.clear()
        with self.server.atomic():
            self._build_scene()  # the same node names: each replaces the one before
        self._cache = _Cache({})  # the new nodes have none of the values sent before

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

    def _draw_frame(self, f: SceneFrame) -> None:
        changed = self._cache.changed
        if changed("robot.position", f.robot_position):
            self._robot.position = f.robot_position
        if changed("robot.wxyz", f.robot_wxyz):
            self._robot.wxyz = f.robot_wxyz
        if changed("sonar", (f.sonar_points, f.sonar_colors)):
            self._sonar.points = np.asarray(f.sonar_points, dtype=np.float32)
            colors = np.asarray(f.sonar_colors, dtype=np.uint8)
            self._sonar.colors = np.repeat(colors[:, None, :], 2, axis=1)
        for bulb, color, k in zip(self._bulbs, f.bulbs, range(3), strict=True):
            if changed(f"bulb{k}", color):
                bulb.color = color
        if changed("obstacle", (f.obstacle_position, f.obstacle_visible)):
            self._obstacle.position = f.obstacle_position
            self._obstacle.visible = f.obstacle_visible
        if changed("kp", f.kp):
            self._kp.visible = f.kp
        if changed("label", f.behaviour_label):
            self._label.text = f.behaviour_label

    def _draw_trail(self, points: Sequence[tuple[float, float]]) -> None:
        step = TRAIL_CHUNK - 1
        chunks = [points[i : i + TRAIL_CHUNK] for i in range(0, max(len(points) - 1, 0), step)]
        for k, chunk in enumerate(chunks):
            if k < len(self._trail_sent) and self._trail_sent[k] == len(chunk):
                continue
            xyz = np.array([(x, y, 0.015) for x, y in chunk], dtype=np.float32)
            segments = np.stack([xyz[:-1], xyz[1:]], axis=1)
            if k < len(self._trail_nodes):
                node = self._trail_nodes[k]
                node.points = segments
                node.visible = True
                self._trail_sent[k] = len(chunk)
            else:
                node = self.server.scene.add_line_segments(
                    f"/trail/{k}", segments, _TRAIL, thickness=0.02
                )
                self._trail_nodes.append(node)
                self._trail_sent.append(len(chunk))
        for k in range(len(chunks), len(self._trail_nodes)):
            if self._trail_sent[k]:
                self._trail_nodes[k].visible = False
                self._trail_sent[k] = 0

    def _draw_panel(self, state: ViewState, view: TickView | None, now: float) -> None:
        changed = self._cache.changed
        options = tuple(r.label for r in state.runs) or (NO_RUNS,)
        if changed("runs.options", options):
            self._runs.options = options
        selected = next((r.label for r in state.runs if r.id == state.run_id), options[0])
        if changed("runs.value", selected):
            _assign(self._runs, selected)
        replaying = state.mode == "replay"
        if changed("mode", replaying):
            self._live_folder.visible = not replaying
            self._replay_folder.visible = replaying
        live = state.live
        if live is not None and changed("rate", (live.run_id, live.hz)):
            _assign(self._rate, float(min(max(round(live.hz), 1), 100)))
        writable = live is not None and live.ticking and state.writable
        if changed("writable", (writable, live is not None and live.realtime)):
            self._plus.disabled = not writable
            self._minus.disabled = not writable
            self._rate.disabled = not (writable and live is not None and live.realtime)
        episodes = tuple(label for _, label in state.episodes) or (NO_EPISODES,)
        if changed("episodes", episodes):
            self._episode.options = episodes
        if state.replay is not None:
            label = next((lb for n, lb in state.episodes if n == state.replay.episode), None)
            if label is not None and changed("episode", label):
                _assign(self._episode, label)
        clock = state.clock
        if clock is not None:
            if changed("scrub.max", clock.ticks):
                self._scrub.max = max(clock.ticks, 2)
            index = clock.at(now)
            if changed("scrub", index):
                _assign(self._scrub, index + 1)  # the episode tick the panel shows
            if changed("play", clock.playing):
                self._play.label = "Pause" if clock.playing else "Play"
            if changed("speed", clock.speed):
                _assign(self._speed, speed_label(clock.speed))
        if changed("header", self._heading(state)):
            self._header.content = self._heading(state)
        heading = state.replay.heading() if replaying and state.replay else "**Decision**"
        text = decision_markdown(view, "replay" if replaying else "live", heading)
        if changed("decision", text):
            self._decision.content = text
        if changed("notice", state.notice):
            self._notice.content = state.notice

    @staticmethod
    def _heading(state: ViewState) -> str:
        live = state.live
        if state.run_id is None or live is None:
            return "**srlab**: no run selected. Create one in the editor or with `srlab run`."
        mode = f"realtime {live.hz:g} Hz" if live.realtime else "fast"
        world = f", world {live.world}" if live.world else ""
        text = (
            f"**Run {live.run_id}**: {live.condition}, seed {live.seed}{world}, {mode}, "
            f"**{live.status}**"
        )
        if not live.ticking and state.mode == "live":
            text += ". Not running now: **Replay** shows its stored episodes."
        return text


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
