"""What the 3D view shows, as pure functions of the world's geometry and one tick's state.

Nothing here talks to viser: `static_scene` describes the parts that never move (floor,
walls, stop line, lamp, the robot's body and sensor mounts), `scene_frame` the parts one
tick moves (robot pose, sonar rays and their colours, lamp colour, obstacle, KP highlight,
labels), and `Trail` the robot's path through an episode. `server.viewer.render` turns
these values into viser calls, sending only what changed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from core.sim._kernel import ray_entry, ray_exit, walls_hit
from core.sim.corridor import CorridorGeometry, floor_quads
from core.sim.corridor_world import obstacles_at
from core.sim.robot import RobotConfig
from core.sim.types import Geometry, build_geometry
from core.sim.world import EpisodeLayout, LampColor, WorldConfig

Rgb = tuple[int, int, int]
Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
Mesh = tuple[tuple[Vec3, ...], tuple[tuple[int, int, int], ...]]
Footprint = tuple[float, float, float, float]
"""An obstacle's box from above: x0, y0, x1, y1."""

WALL_HEIGHT_M = 0.3
WALL_THICKNESS_M = 0.04
ROBOT_HEIGHT_M = 0.22
"""The AmigoBot's shell stands about this high off the floor."""
SONAR_HEIGHT_M = 0.12
CAMERA_HEIGHT_M = 0.26
TRAIL_MIN_STEP_M = 0.02
"""The trail keeps a point only once the robot moved this far from the last one."""

RED: Rgb = (220, 38, 38)
YELLOW: Rgb = (250, 204, 21)
GREEN: Rgb = (22, 163, 74)
DIM: Rgb = (55, 55, 60)
"""A lamp bulb that is off."""
FLOOR_COLOR: Rgb = (176, 180, 186)
"""The corridor's floor: a light grey."""
STOPLINE_COLOR: Rgb = (17, 24, 39)
"""The stop line: near black, so it stands out on the light floor (white did not)."""
KP_COLOR: Rgb = (217, 70, 239)
"""The highlight of a behaviour released by a KP-made association."""
BULBS: tuple[LampColor, LampColor, LampColor] = (LampColor.RED, LampColor.YELLOW, LampColor.GREEN)
_LIT = {LampColor.RED: RED, LampColor.YELLOW: YELLOW, LampColor.GREEN: GREEN}


@dataclass(frozen=True, slots=True)
class Box:
    """An axis-aligned box (before its yaw) at `center`, `size` along x, y, z."""

    center: Vec3
    size: Vec3
    yaw_rad: float = 0.0


@dataclass(frozen=True, slots=True)
class StaticScene:
    """The parts of the scene that do not move during a run."""

    floor_vertices: tuple[Vec3, ...]
    floor_faces: tuple[tuple[int, int, int], ...]
    walls: tuple[Box, ...]
    stopline: Box
    lamp_position: Vec3
    """The top of the lamp's pole; the three bulbs stack above it."""
    body_vertices: tuple[Vec3, ...]
    body_faces: tuple[tuple[int, int, int], ...]
    fov_vertices: tuple[Vec3, ...]
    """The camera's field of view on the floor, in the robot's frame (a fan)."""
    fov_faces: tuple[tuple[int, int, int], ...]
    sonar_origins: tuple[tuple[float, float], ...]
    """Where each sonar reads from, in the robot's frame."""
    sonar_angles_rad: tuple[float, ...]
    sonar_mount_m: float
    sonar_range_m: float
    obstacle_size_m: float
    center: Vec3
    """The middle of the track, where the camera looks."""
    outer_box: tuple[float, float, float, float]
    inner_box: tuple[float, float, float, float]
    geometry: Geometry = field(compare=False, repr=False)
    """The track's geometry: where the obstacles are at a tick is a function of it."""
    dt_s: float = 0.1
    wall_segments: np.ndarray[Any, np.dtype[np.float64]] | None = field(
        default=None, compare=False, repr=False
    )
    """A corridor track's walls, one row x0 y0 x1 y1 each, that its sonar rays end at (None:
    the ring, whose rays end at its two boxes)."""
    obstacle_count: int = 1
    """How many obstacles an episode has at most (the ring: one)."""
    obstacle_echo_m: float = math.inf
    """How far away the sonars hear an obstacle (`ObstacleConfig.echo_range_m`)."""


def static_scene(config: WorldConfig) -> StaticScene:
    """The fixed parts of the world `config` describes."""
    geo = build_geometry(config.track)
    robot = config.robot
    ox0, oy0, ox1, oy1 = (float(v) for v in geo.outer_box)
    ix0, iy0, ix1, iy1 = (float(v) for v in geo.inner_box)
    floor_faces: list[tuple[int, int, int]] = []
    if isinstance(geo, CorridorGeometry):
        # A quadrilateral per segment between its mitred walls, two triangles facing up.
        quads = floor_quads(geo.centre_line(), [float(w) for w in geo.widths_m])
        floor_vertices: tuple[Vec3, ...] = tuple((x, y, 0.0) for q in quads for x, y in q)
        for k in range(len(quads)):
            i = 4 * k
            floor_faces += [(i, i + 2, i + 1), (i, i + 3, i + 2)]
        walls = tuple(_wall(a, b, side=0.0) for a, b in geo.wall_segments())
    else:
        floor_vertices = (
            (ox0, oy0, 0.0), (ox1, oy0, 0.0), (ox1, oy1, 0.0), (ox0, oy1, 0.0),
            (ix0, iy0, 0.0), (ix1, iy0, 0.0), (ix1, iy1, 0.0), (ix0, iy1, 0.0),
        )  # fmt: skip
        # The ring between the two rectangles: two triangles per side, facing up (+z).
        for i in range(4):
            j = (i + 1) % 4
            floor_faces += [(i, j, 4 + j), (i, 4 + j, 4 + i)]
        # Both rectangles run counter-clockwise: beyond an outer wall is to its right, beyond
        # an inner wall (inside the island) to its left. The box stands there, off the track.
        walls = tuple(
            _wall(a, b, side=-1.0 if n < 4 else 1.0) for n, (a, b) in enumerate(geo.wall_segments())
        )
    d = geo.directions[config.track.signal.leg]
    sx, sy = geo.stopline_point
    stopline = Box(
        (sx, sy, 0.003),
        (0.06, config.track.corridor_width_m, 0.006),
        math.atan2(float(d[1]), float(d[0])),
    )
    lx, ly = geo.lamp_point
    body_vertices, body_faces = robot_body_mesh(robot)
    fov_vertices, fov_faces = fov_fan(robot)
    mount = robot.sonar_mount_m
    angles = tuple(math.radians(a) for a in robot.sonar_angles_deg)
    return StaticScene(
        floor_vertices=floor_vertices,
        floor_faces=tuple(floor_faces),
        walls=walls,
        stopline=stopline,
        lamp_position=(lx, ly, 0.5),
        body_vertices=body_vertices,
        body_faces=body_faces,
        fov_vertices=fov_vertices,
        fov_faces=fov_faces,
        sonar_origins=tuple((mount * math.cos(a), mount * math.sin(a)) for a in angles),
        sonar_angles_rad=angles,
        sonar_mount_m=mount,
        sonar_range_m=robot.sonar_range_m,
        obstacle_size_m=config.track.obstacle.size_m,
        center=((ox0 + ox1) / 2, (oy0 + oy1) / 2, 0.0),
        outer_box=(ox0, oy0, ox1, oy1),
        inner_box=(ix0, iy0, ix1, iy1),
        geometry=geo,
        dt_s=config.dt_s,
        obstacle_echo_m=config.track.obstacle.echo_range_m,
        wall_segments=geo.walls if isinstance(geo, CorridorGeometry) else None,
        obstacle_count=max(1, len(geo.config.obstacles))
        if isinstance(geo, CorridorGeometry)
        else 1,
    )


def _wall(a: tuple[float, float], b: tuple[float, float], *, side: float) -> Box:
    """A wall segment as a box standing on the floor, its thickness to the `side`.

    `side`: +1 left of a to b, -1 right, 0 centred on the segment.
    """
    (x0, y0), (x1, y1) = a, b
    length = math.hypot(x1 - x0, y1 - y0)
    yaw = math.atan2(y1 - y0, x1 - x0)
    nx, ny = -math.sin(yaw) * side, math.cos(yaw) * side
    shift = WALL_THICKNESS_M / 2
    cx = (x0 + x1) / 2 + nx * shift
    cy = (y0 + y1) / 2 + ny * shift
    return Box((cx, cy, WALL_HEIGHT_M / 2), (length + WALL_THICKNESS_M, WALL_THICKNESS_M,
               WALL_HEIGHT_M), yaw)  # fmt: skip


def robot_outline(robot: RobotConfig, points: int = 12) -> tuple[tuple[float, float], ...]:
    """The AmigoBot's outline from above, counter-clockwise: a flat back, a rounded nose."""
    half_l, half_w = robot.length_m / 2, robot.width_m / 2
    nose_start = half_l - half_w  # the front is a half-ellipse as deep as half the width
    outline = [(-half_l, -half_w)]
    for k in range(points + 1):
        a = -math.pi / 2 + math.pi * k / points
        outline.append((nose_start + half_w * math.cos(a), half_w * math.sin(a)))
    outline.append((-half_l, half_w))
    return tuple(outline)


def robot_body_mesh(
    robot: RobotConfig, bottom_m: float = 0.04, top_m: float = ROBOT_HEIGHT_M
) -> Mesh:
    """The robot's shell: its outline extruded from `bottom_m` to `top_m` (robot frame)."""
    outline = robot_outline(robot)
    n = len(outline)
    vertices = [(x, y, bottom_m) for x, y in outline] + [(x, y, top_m) for x, y in outline]
    vertices += [(0.0, 0.0, bottom_m), (0.0, 0.0, top_m)]
    lo, hi = 2 * n, 2 * n + 1
    faces: list[tuple[int, int, int]] = []
    for i in range(n):
        j = (i + 1) % n
        faces += [(i, j, n + j), (i, n + j, n + i)]  # the side, facing out
        faces += [(hi, n + i, n + j), (lo, j, i)]  # the top facing up, the bottom down
    return tuple(vertices), tuple(faces)


def fov_fan(robot: RobotConfig, steps: int = 10) -> Mesh:
    """The camera's field of view as a fan on the floor, in the robot's frame."""
    half = math.radians(robot.camera_fov_deg / 2)
    r = robot.camera_range_m
    cx = robot.camera_offset_m
    z = 0.01
    vertices: list[Vec3] = [(cx, 0.0, z)]
    for k in range(steps + 1):
        a = -half + 2 * half * k / steps
        vertices.append((cx + r * math.cos(a), r * math.sin(a), z))
    faces = tuple((0, k, k + 1) for k in range(1, steps + 1))
    return tuple(vertices), faces


def yaw_quaternion(yaw_rad: float) -> Quat:
    """The (w, x, y, z) quaternion of a rotation by `yaw_rad` about +z."""
    return (math.cos(yaw_rad / 2), 0.0, 0.0, math.sin(yaw_rad / 2))


def obstacle_box(scene: StaticScene, center: tuple[float, float] | None) -> Footprint | None:
    """The obstacle's footprint (x0, y0, x1, y1), None when the episode has none."""
    if center is None:
        return None
    half = scene.obstacle_size_m / 2
    return (center[0] - half, center[1] - half, center[0] + half, center[1] + half)


def sonar_ranges(
    scene: StaticScene,
    x: float,
    y: float,
    heading_rad: float,
    obstacles: Sequence[Footprint],
) -> tuple[float, ...]:
    """What each sonar reads at a pose, without the sensor's noise.

    The same geometry as the sensing kernel (`core.sim._kernel.sense` on the ring, against
    its two boxes; `sense_corridor` on a corridor track, against its wall segments), with
    its ray casts, recomputed here so that a replay, whose trace keeps poses but not
    readings, shows the rays too.
    """
    out = []
    mount = scene.sonar_mount_m
    walls = scene.wall_segments
    for a in scene.sonar_angles_rad:
        th = heading_rad + a
        dx, dy = math.cos(th), math.sin(th)
        ox, oy = x + mount * dx, y + mount * dy
        if walls is not None:
            seen = walls_hit(ox, oy, dx, dy, walls)
        else:
            seen = min(
                ray_exit(ox, oy, dx, dy, scene.outer_box),
                ray_entry(ox, oy, dx, dy, scene.inner_box),
            )
        for box in obstacles:
            hit = ray_entry(ox, oy, dx, dy, box)
            if hit <= scene.obstacle_echo_m:  # beyond its echo range, what lies behind
                seen = min(seen, hit)
        out.append(min(max(seen, 0.0), scene.sonar_range_m))
    return tuple(out)


def contrast_ratio(a: Rgb, b: Rgb) -> float:
    """WCAG's contrast ratio of two colours (1: none, 21: black on white)."""

    def luminance(c: Rgb) -> float:
        lin = [(v / 255) / 12.92 if v <= 10 else ((v / 255 + 0.055) / 1.055) ** 2.4 for v in c]
        return 0.2126 * lin[0] + 0.7152 * lin[1] + 0.0722 * lin[2]

    hi, lo = sorted((luminance(a), luminance(b)), reverse=True)
    return (hi + 0.05) / (lo + 0.05)


def range_color(range_m: float, max_m: float) -> Rgb:
    """A sonar ray's colour: red when something is close, through yellow, to green at range."""
    u = min(max(range_m / max_m, 0.0), 1.0) if max_m > 0 else 1.0
    near, mid, far = RED, YELLOW, GREEN
    # Most of the interesting readings are under a metre: spend half the scale on them.
    u = min(1.0, u * 1.5)
    if u < 0.5:
        a, b, t = near, mid, u / 0.5
    else:
        a, b, t = mid, far, (u - 0.5) / 0.5
    return (
        round(a[0] + (b[0] - a[0]) * t),
        round(a[1] + (b[1] - a[1]) * t),
        round(a[2] + (b[2] - a[2]) * t),
    )


@dataclass(frozen=True, slots=True)
class TickView:
    """One tick as the view shows it, from a live snapshot or a stored trace row.

    Names are resolved already (stimuli, behaviour), so the scene needs no catalogue.
    """

    run_id: int
    episode: int
    tick: int
    episode_tick: int
    x: float
    y: float
    heading_rad: float
    lamp: LampColor
    stimuli: tuple[str, ...] = ()
    behaviour: str | None = None
    how: str = "default"
    kp: bool = False
    """The behaviour was released by an association knowledge propagation made."""
    successes: int | None = None
    episodes_done: int | None = None
    origin: str = ""
    """What made the behaviour run: an association's source, explored, default or
    commanded ("" when unknown: a trace stored before traces kept it)."""
    released_by: str | None = None
    """The stimulus the behaviour answered."""


@dataclass(frozen=True, slots=True)
class SceneFrame:
    """Everything one tick moves in the scene."""

    robot_position: Vec3
    robot_wxyz: Quat
    sonar_ranges_m: tuple[float, ...]
    sonar_points: tuple[tuple[Vec3, Vec3], ...]
    """Each ray from its sonar to what it hit, in the robot's frame."""
    sonar_colors: tuple[Rgb, ...]
    bulbs: tuple[Rgb, Rgb, Rgb]
    """The lamp's red, yellow and green bulbs: lit in their colour or dim."""
    obstacle_position: Vec3
    obstacle_visible: bool
    kp: bool
    behaviour_label: str
    obstacle_positions: tuple[Vec3, ...] = ()
    """Every obstacle's centre at that tick, the first (`obstacle_position`) first."""


def scene_frame(scene: StaticScene, view: TickView, layout: EpisodeLayout | None) -> SceneFrame:
    """The scene at one tick: where everything is and what colour it has.

    Every obstacle is where it has moved to by the tick's place in its episode.
    """
    centers = (
        obstacles_at(scene.geometry, layout, view.episode_tick * scene.dt_s)
        if layout is not None
        else []
    )
    center = centers[0] if centers else None
    boxes = [b for c in centers if (b := obstacle_box(scene, c)) is not None]
    ranges = sonar_ranges(scene, view.x, view.y, view.heading_rad, boxes)
    points = []
    for (sx, sy), a, r in zip(scene.sonar_origins, scene.sonar_angles_rad, ranges, strict=True):
        end = (sx + r * math.cos(a), sy + r * math.sin(a), SONAR_HEIGHT_M)
        points.append(((sx, sy, SONAR_HEIGHT_M), end))
    bulbs = tuple(_LIT[c] if view.lamp == c else DIM for c in BULBS)
    label = view.behaviour or "-"
    if view.kp:
        label += " (KP)"
    return SceneFrame(
        robot_position=(view.x, view.y, 0.0),
        robot_wxyz=yaw_quaternion(view.heading_rad),
        sonar_ranges_m=ranges,
        sonar_points=tuple(points),
        sonar_colors=tuple(range_color(r, scene.sonar_range_m) for r in ranges),
        bulbs=(bulbs[0], bulbs[1], bulbs[2]),
        obstacle_position=(
            (center[0], center[1], scene.obstacle_size_m / 2) if center else (0.0, 0.0, -1.0)
        ),
        obstacle_visible=center is not None,
        kp=view.kp,
        behaviour_label=label,
        obstacle_positions=tuple((cx, cy, scene.obstacle_size_m / 2) for cx, cy in centers),
    )


@dataclass
class Trail:
    """The robot's path through the current episode, thinned to `min_step_m`."""

    min_step_m: float = TRAIL_MIN_STEP_M
    key: tuple[int, int] | None = None
    """(run, episode) the points belong to; another one starts a new trail."""
    points: list[tuple[float, float]] = field(default_factory=list)

    def add(self, view: TickView) -> bool:
        """Record a tick's position; True when the trail changed."""
        key = (view.run_id, view.episode)
        if key != self.key:
            self.key = key
            self.points = [(view.x, view.y)]
            return True
        last = self.points[-1]
        if math.hypot(view.x - last[0], view.y - last[1]) < self.min_step_m:
            return False
        self.points.append((view.x, view.y))
        return True

    def clear(self) -> None:
        """Forget the trail."""
        self.key = None
        self.points = []


def trail_of(views: Sequence[TickView], min_step_m: float = TRAIL_MIN_STEP_M) -> Trail:
    """The trail of a sequence of ticks (a replay up to its cursor)."""
    trail = Trail(min_step_m)
    for v in views:
        trail.add(v)
    return trail


Mode = Literal["live", "replay"]


def why(view: TickView, blind: bool = False) -> str:
    """How a tick's behaviour came to run, e.g. ``released by `Corner` (designed)``.

    The stimulus it answered, and in brackets what made it run when that is not its
    `how` already: the releasing association's source (a continued primitive keeps it).
    `blind`: without the source, which would tell a study's participant their condition.
    """
    parts = [] if view.how == "released" and view.released_by else [view.how]
    if view.released_by:
        verb = "released by" if view.how in ("released", "continued") else "answering"
        parts.append(f"{verb} `{view.released_by}`")
    text = ", ".join(parts)
    if view.origin and view.origin != view.how and not blind:
        text += f" ({view.origin})"
    return text


def decision_markdown(
    view: TickView | None, mode: Mode, heading: str, *, blind: bool = False
) -> str:
    """The panel's account of a tick: stimuli, the selected behaviour and how, counters.

    `blind`: a study participant's view, which says nothing that tells their condition (a
    behaviour's source, whether KP made it).
    """
    lines = [heading]
    if view is None:
        lines.append("No tick to show yet.")
        return "\n\n".join(lines)
    where = f"Episode **{view.episode}**, tick **{view.tick}** (tick {view.episode_tick} of it)"
    lines.append(where)
    if view.successes is not None and view.episodes_done is not None:
        lines.append(f"Successes so far: **{view.successes}** of {view.episodes_done} episodes")
    behaviour = f"`{view.behaviour}`" if view.behaviour else "none"
    kp = " - **KP-made**" if view.kp and not blind else ""
    lines.append(f"Behaviour: {behaviour} ({why(view, blind)}){kp}")
    stimuli = ", ".join(f"`{s}`" for s in view.stimuli) if view.stimuli else "none"
    lines.append(f"Stimuli: {stimuli}")
    lines.append(f"Lamp: {view.lamp.name.lower() if view.lamp else 'not seen'}")
    if mode == "replay":
        lines.append("_Replay of a stored episode._")
    return "\n\n".join(lines)


__all__ = [
    "Box",
    "SceneFrame",
    "StaticScene",
    "TickView",
    "Trail",
    "contrast_ratio",
    "decision_markdown",
    "range_color",
    "robot_body_mesh",
    "scene_frame",
    "sonar_ranges",
    "static_scene",
    "trail_of",
    "why",
    "yaw_quaternion",
]
