"""The 3D view's scene: the world's fixed parts built as viser nodes, then moved a frame at a time.

`SceneNodes` is the part of `server.viewer.render.Renderer` that owns the scene's nodes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser

from core.sim.types import Geometry
from core.sim.world import WorldConfig
from server.viewer.scene import (
    BULBS,
    CAMERA_HEIGHT_M,
    DIM,
    FLOOR_COLOR,
    KP_COLOR,
    STOPLINE_COLOR,
    SceneFrame,
    StaticScene,
    yaw_quaternion,
)

TRAIL_CHUNK = 64
"""Points per trail node: a growing trail resends only its last node."""
_BODY = (196, 30, 36)
_TRAIL = (37, 99, 235)
_WALL = (71, 85, 105)
_FLOOR = FLOOR_COLOR
_GROUND = (245, 245, 240)
_BOX = (180, 128, 72)
_FOV = (250, 204, 21)


@dataclass
class Cache:
    """The last value sent for each property, so unchanged ones are not sent again."""

    values: dict[str, Any]

    def changed(self, key: str, value: Any) -> bool:
        """Whether `value` differs from the one sent for `key` (remembering it if so)."""
        if self.values.get(key, _MISSING) == value:
            return False
        self.values[key] = value
        return True


_MISSING = object()


class SceneNodes:
    """The scene's nodes: lit and built once per world, then each frame sends what changed.

    A part of `Renderer`, which sets what is declared here.
    """

    server: viser.ViserServer | viser.ClientHandle
    static: StaticScene
    world: WorldConfig
    geometry: Geometry
    _cache: Cache
    _trail_nodes: list[viser.LineSegmentsHandle]
    _trail_sent: list[int]
    _wall_nodes: list[viser.BoxHandle]
    _obstacles: list[viser.BoxHandle]

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
        # Another world's walls and obstacles go: a track may have fewer than the one before.
        for node in (*self._wall_nodes, *self._obstacles):
            node.remove()
        self._wall_nodes = []
        for i, w in enumerate(s.walls):
            wall = sc.add_box(
                f"/track/walls/{i}",
                color=_WALL,
                dimensions=w.size,
                position=w.center,
                wxyz=yaw_quaternion(w.yaw_rad),
            )
            self._wall_nodes.append(wall)
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
        # One box per obstacle an episode can have: the first is "/obstacle", as on the ring.
        self._obstacles = [
            sc.add_box(
                "/obstacle" if i == 0 else f"/obstacle_{i}",
                color=_BOX,
                dimensions=(size, size, size),
                visible=False,
            )
            for i in range(s.obstacle_count)
        ]
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
        for i, box in enumerate(self._obstacles):
            at = f.obstacle_positions[i] if i < len(f.obstacle_positions) else None
            if changed(f"obstacle{i}", at):
                box.visible = at is not None
                if at is not None:
                    box.position = at
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
