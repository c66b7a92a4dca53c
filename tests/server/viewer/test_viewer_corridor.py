"""The 3D view of a corridor track: its walls as segments, its floor from the centre line and
widths, every obstacle where it is at the tick, and sonar rays cut against the walls."""

from __future__ import annotations

import math

import numpy as np
import pytest
import viser

from core.sim.corridor import CorridorConfig, CorridorGeometry
from core.sim.corridor_world import CorridorWorld
from core.sim.world import LampColor, MotorCommand, WorldConfig, episode_layout
from core.sim.worlds import load_world, world_names
from server.viewer.render import Renderer
from server.viewer.scene import TickView, obstacle_box, scene_frame, sonar_ranges, static_scene

L_SHAPE = load_world("l-shape").config
SCENE = static_scene(L_SHAPE)
GEO = CorridorGeometry.build(L_SHAPE.track)  # type: ignore[arg-type]
CORRIDORS = [n for n in world_names() if isinstance(load_world(n).config.track, CorridorConfig)]


def view(**kw: object) -> TickView:
    base: dict[str, object] = {
        "run_id": 1, "episode": 0, "tick": 1, "episode_tick": 0, "x": 1.8, "y": 0.6,
        "heading_rad": 0.0, "lamp": LampColor.GREEN,
    }  # fmt: skip
    base.update(kw)
    return TickView(**base)  # type: ignore[arg-type]


def triangle_area(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> float:
    """Signed area of a triangle from above (+: counter-clockwise, facing up)."""
    return float(((b - a)[0] * (c - a)[1] - (b - a)[1] * (c - a)[0]) / 2)


def in_floor(x: float, y: float) -> bool:
    """Whether (x, y) is on one of the scene's floor triangles."""
    v = np.asarray(SCENE.floor_vertices)[:, :2]
    p = np.array([x, y])
    for i, j, k in SCENE.floor_faces:
        parts = [triangle_area(a, b, p) for a, b in ((v[i], v[j]), (v[j], v[k]), (v[k], v[i]))]
        if min(parts) >= -1e-12:
            return True
    return False


def test_the_corridor_count_is_what_the_presets_say() -> None:
    assert {"l-shape", "figure-8", "narrow-passage"} <= set(CORRIDORS)


@pytest.mark.parametrize("name", sorted(CORRIDORS))
def test_each_wall_segment_is_a_wall_box_standing_on_it(name: str) -> None:
    scene = static_scene(load_world(name).config)
    walls = scene.wall_segments
    assert walls is not None and len(scene.walls) == len(walls) > 8
    for box, (x0, y0, x1, y1) in zip(scene.walls, walls, strict=True):
        assert box.center[:2] == pytest.approx(((x0 + x1) / 2, (y0 + y1) / 2))
        assert box.size[0] == pytest.approx(math.hypot(x1 - x0, y1 - y0) + 0.04)
        assert box.yaw_rad == pytest.approx(math.atan2(y1 - y0, x1 - x0))


@pytest.mark.parametrize("name", sorted(CORRIDORS))
def test_the_floor_is_the_corridor_facing_up(name: str) -> None:
    scene = static_scene(load_world(name).config)
    geo = scene.geometry
    assert isinstance(geo, CorridorGeometry)
    v = np.asarray(scene.floor_vertices)
    assert not v[:, 2].any()
    areas = [triangle_area(v[i, :2], v[j, :2], v[k, :2]) for i, j, k in scene.floor_faces]
    assert min(areas) > 0  # counter-clockwise from above: facing +z
    # Every corner is a right angle: a segment's mitred quadrilateral is its length x width.
    expected = float(np.dot(geo.leg_lengths_m, geo.widths_m))
    assert sum(areas) == pytest.approx(expected)


def test_the_l_shapes_floor_covers_the_corridor_and_not_its_inside_corner() -> None:
    assert in_floor(*GEO.start_pose[:2])
    assert in_floor(*GEO.stopline_point)
    assert in_floor(7.4, 0.6) and in_floor(3.6, 3.0)  # a left corner and a right one
    assert not in_floor(5.0, 4.5)  # beside the L, beyond the walls
    assert not in_floor(2.0, 2.0)  # inside the L


def test_every_obstacle_is_shown_and_the_trolley_moves_with_the_tick() -> None:
    layout = episode_layout(L_SHAPE, GEO, 5, 0)
    assert SCENE.obstacle_count == len(layout.obstacles) == 2
    moving = [i for i, p in enumerate(layout.obstacles) if p.speed_mps > 0]
    assert len(moving) == 1
    frames = [scene_frame(SCENE, view(episode_tick=t), layout) for t in (0, 5, 10)]
    for f in frames:
        assert len(f.obstacle_positions) == 2
        assert f.obstacle_visible and f.obstacle_position == f.obstacle_positions[0]
    still = 1 - moving[0]
    assert frames[0].obstacle_positions[still] == frames[2].obstacle_positions[still]
    path = [np.asarray(f.obstacle_positions[moving[0]][:2]) for f in frames]
    p = layout.obstacles[moving[0]]
    for t, at in zip((0, 5, 10), path, strict=True):
        assert tuple(at) == pytest.approx(GEO.obstacle_at(p, t * L_SHAPE.dt_s))
    assert np.linalg.norm(path[2] - path[0]) > 0.05


def test_a_side_sonar_ray_ends_at_the_wall_beside_it() -> None:
    # On segment 0 (along +x, walls at y = 0 and y = 1.2), 0.2 m left of the centre line:
    # the left sonar (90 degrees) reads to the left wall, the right one (-90) to the right.
    x, y = 2.0, 0.8
    ranges = sonar_ranges(SCENE, x, y, 0.0, [])
    mount = SCENE.sonar_mount_m
    angles = [math.degrees(a) for a in SCENE.sonar_angles_rad]
    left, right = angles.index(90.0), angles.index(-90.0)
    assert ranges[left] == pytest.approx(1.2 - (y + mount), abs=1e-9)
    assert ranges[right] == pytest.approx(y - mount, abs=1e-9)
    # Where the ray ends lies on a wall segment of the track.
    ex, ey = x, y + mount + ranges[left]
    on = [
        w
        for w in GEO.walls
        if abs((w[2] - w[0]) * (ey - w[1]) - (w[3] - w[1]) * (ex - w[0])) < 1e-9
    ]
    assert on and all(min(w[0], w[2]) <= ex <= max(w[0], w[2]) for w in on)


def test_sonar_rays_match_what_the_robot_senses_on_a_corridor_within_its_noise() -> None:
    world = CorridorWorld(L_SHAPE)
    noise = L_SHAPE.robot.sonar_noise_m
    for episode in range(2):
        world.reset(11, episode)
        for i in range(150):
            world.apply(MotorCommand(0.45, 0.4 * math.sin(i / 11)))
            frame = world.step()
            boxes = [b for c in world.obstacle_centers() if (b := obstacle_box(SCENE, c))]
            mine = sonar_ranges(SCENE, frame.x, frame.y, frame.heading_rad, boxes)
            assert np.abs(np.asarray(mine) - frame.channels[:8]).max() <= 6 * noise, (episode, i)


def test_the_3d_view_sends_every_wall_and_an_obstacle_box_each() -> None:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        Renderer(server, SCENE, L_SHAPE, lambda _: None)
        buffer = server._websock_server.get_message_buffer()  # viser internals
        names = {getattr(m, "name", None) for m in buffer.message_from_id.values()}
    finally:
        server.stop()
    walls = {n for n in names if isinstance(n, str) and n.startswith("/track/walls/")}
    assert len(walls) == len(GEO.walls)
    assert {"/track/floor", "/obstacle", "/obstacle_1"} <= names


def test_a_view_moving_to_the_ring_drops_the_corridors_extra_walls_and_obstacles() -> None:
    ring = WorldConfig()
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        renderer = Renderer(server, SCENE, L_SHAPE, lambda _: None)
        renderer.use_world(ring)
        buffer = server._websock_server.get_message_buffer()  # viser internals
        sent = list(buffer.message_from_id.values())
    finally:
        server.stop()
    # What a browser connecting now is sent, in order: each node's last word.
    last: dict[str, str] = {}
    for m in sent:
        name = getattr(m, "name", None)
        if isinstance(name, str):
            last[name] = type(m).__name__
    shown = {n for n, kind in last.items() if "Remove" not in kind}
    walls = {n for n in shown if n.startswith("/track/walls/")}
    assert len(walls) == len(static_scene(ring).walls) == 8
    assert "/obstacle" in shown and "/obstacle_1" not in shown
