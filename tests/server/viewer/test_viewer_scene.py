"""The 3D view's pure mapping from ticks to scene updates: positions, colours, visibility."""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import replace

import numpy as np
import pytest
import viser
from viser._messages import EnableLightsMessage, EnvironmentMapMessage, HemisphereLightMessage

from core.sim.types import build_geometry
from core.sim.world import EpisodeLayout, LampColor, MotorCommand, PymunkWorld, WorldConfig
from server.viewer.render import Renderer
from server.viewer.scene import (
    DIM,
    FLOOR_COLOR,
    GREEN,
    KP_COLOR,
    RED,
    STOPLINE_COLOR,
    YELLOW,
    TickView,
    Trail,
    contrast_ratio,
    decision_markdown,
    obstacle_box,
    range_color,
    robot_body_mesh,
    robot_outline,
    scene_frame,
    sonar_ranges,
    static_scene,
    trail_of,
    why,
    yaw_quaternion,
)

WORLD = WorldConfig()
SCENE = static_scene(WORLD)
GEO = build_geometry(WORLD.track)


def view(**kw: object) -> TickView:
    base: dict[str, object] = {
        "run_id": 1, "episode": 0, "tick": 1, "episode_tick": 1, "x": 2.0, "y": 0.6,
        "heading_rad": 0.0, "lamp": LampColor.RED,
    }  # fmt: skip
    base.update(kw)
    return TickView(**base)  # type: ignore[arg-type]


def rotate(q: tuple[float, float, float, float], v: tuple[float, float, float]) -> np.ndarray:
    """Rotate v by the unit quaternion q = (w, x, y, z)."""
    w, x, y, z = q
    r = np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
    out: np.ndarray = r @ np.asarray(v)
    return out


NO_OBSTACLE = EpisodeLayout(None, -1, ((LampColor.GREEN, 1),))


@pytest.mark.parametrize("heading", [0.0, 0.7, math.pi / 2, -2.5, math.pi])
def test_the_robot_stands_at_its_pose_and_faces_its_heading(heading: float) -> None:
    frame = scene_frame(SCENE, view(x=3.5, y=2.75, heading_rad=heading), NO_OBSTACLE)
    assert frame.robot_position == (3.5, 2.75, 0.0)
    forward = rotate(frame.robot_wxyz, (1.0, 0.0, 0.0))
    assert forward == pytest.approx([math.cos(heading), math.sin(heading), 0.0], abs=1e-12)
    assert math.fsum(c * c for c in frame.robot_wxyz) == pytest.approx(1.0)


def test_sonar_rays_match_what_the_robot_senses_within_its_noise() -> None:
    world = PymunkWorld(WORLD)
    noise = WORLD.robot.sonar_noise_m
    for episode in range(3):
        frame = world.reset(7, episode)
        box = obstacle_box(SCENE, world.layout.obstacle_center)
        for i in range(120):
            world.apply(MotorCommand(0.45, 0.5 * math.sin(i / 9)))
            frame = world.step()
            mine = sonar_ranges(SCENE, frame.x, frame.y, frame.heading_rad, [box] if box else [])
            sensed = frame.channels[:8]
            assert np.abs(np.asarray(mine) - sensed).max() <= 6 * noise, (episode, i)


def test_sonar_rays_see_the_obstacle_only_when_the_episode_has_one() -> None:
    # Straight at the obstacle, half a metre ahead: the two front sonars (+-12 degrees)
    # hit its near face.
    center = (2.5, 0.6)
    layout = EpisodeLayout(center, 0, ((LampColor.GREEN, 1),))
    with_box = scene_frame(SCENE, view(x=2.0, y=0.6, heading_rad=0.0), layout)
    without = scene_frame(SCENE, view(x=2.0, y=0.6, heading_rad=0.0), NO_OBSTACLE)
    half = SCENE.obstacle_size_m / 2
    c = math.cos(math.radians(12))
    for k in (2, 3):
        mount_x = 2.0 + SCENE.sonar_mount_m * c
        expected = (center[0] - half - mount_x) / c
        assert with_box.sonar_ranges_m[k] == pytest.approx(expected, abs=1e-9)
        assert without.sonar_ranges_m[k] > with_box.sonar_ranges_m[k] + 1.0
    assert with_box.obstacle_visible and with_box.obstacle_position == (2.5, 0.6, half)
    assert not without.obstacle_visible


def test_sonar_segments_run_from_each_mount_along_its_axis_for_its_range() -> None:
    frame = scene_frame(SCENE, view(), NO_OBSTACLE)
    assert len(frame.sonar_points) == len(frame.sonar_colors) == 8
    for (start, end), a, r, (mx, my) in zip(
        frame.sonar_points,
        SCENE.sonar_angles_rad,
        frame.sonar_ranges_m,
        SCENE.sonar_origins,
        strict=True,
    ):
        assert start[:2] == pytest.approx((mx, my))
        assert end[0] - start[0] == pytest.approx(r * math.cos(a))
        assert end[1] - start[1] == pytest.approx(r * math.sin(a))
        assert start[2] == end[2] > 0


def test_ray_colours_go_from_red_when_close_to_green_at_range() -> None:
    top = SCENE.sonar_range_m
    assert range_color(0.0, top) == RED
    assert range_color(top, top) == GREEN
    assert range_color(top / 3, top) == YELLOW
    # Past yellow the red fades monotonically; green never fades with range.
    beyond = [range_color(float(r), top) for r in np.linspace(top / 3, top, 30)]
    assert [c[0] for c in beyond] == sorted((c[0] for c in beyond), reverse=True)
    assert range_color(0.1, top)[1] < range_color(0.5, top)[1] < range_color(0.9, top)[1]
    # What the colour says follows the range: a near ray is redder than a far one.
    frame = scene_frame(SCENE, view(x=1.8, y=0.6, heading_rad=0.0), NO_OBSTACLE)
    near = min(range(8), key=lambda k: frame.sonar_ranges_m[k])
    far = max(range(8), key=lambda k: frame.sonar_ranges_m[k])
    assert frame.sonar_colors[near][0] >= frame.sonar_colors[far][0]
    assert frame.sonar_colors[near][1] < frame.sonar_colors[far][1]


@pytest.mark.parametrize(
    ("lamp", "lit"),
    [(LampColor.RED, 0), (LampColor.YELLOW, 1), (LampColor.GREEN, 2), (LampColor.NONE, None)],
)
def test_only_the_lamps_current_colour_is_lit(lamp: LampColor, lit: int | None) -> None:
    bulbs = scene_frame(SCENE, view(lamp=lamp), NO_OBSTACLE).bulbs
    for k, color in enumerate(bulbs):
        assert color == ((RED, YELLOW, GREEN)[k] if k == lit else DIM)


def test_a_kp_made_behaviour_is_highlighted_and_labelled() -> None:
    plain = scene_frame(SCENE, view(behaviour="leftturn30", how="released"), NO_OBSTACLE)
    kp = scene_frame(SCENE, view(behaviour="leftturn30", how="released", kp=True), NO_OBSTACLE)
    assert not plain.kp and plain.behaviour_label == "leftturn30"
    assert kp.kp and kp.behaviour_label == "leftturn30 (KP)"
    assert KP_COLOR != DIM
    text = decision_markdown(view(behaviour="leftturn30", how="released", kp=True), "live", "")
    assert "KP-made" in text and "leftturn30" in text


def test_a_participants_panel_says_nothing_that_tells_their_condition() -> None:
    v = view(behaviour="leftturn30", how="released", origin="kp", released_by="Corner", kp=True)
    assert "(kp)" in why(v) and "KP-made" in decision_markdown(v, "live", "")
    assert why(v, blind=True) == "released by `Corner`"
    blind = decision_markdown(v, "live", "", blind=True)
    assert "Behaviour: `leftturn30` (released by `Corner`)" in blind
    assert "KP" not in blind and "kp" not in blind


def test_a_participants_view_does_not_mark_a_kp_made_behaviour() -> None:
    from server.viewer.state import LiveInfo, ViewState

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        renderer = Renderer(server, SCENE, WORLD, lambda _: None)
        live = LiveInfo(1, "", 3, "running", True, 20.0, True)
        tick = view(behaviour="leftturn30", how="released", kp=True)
        renderer.draw(ViewState(clients=1, run_id=1, live=live, only=1), [tick], 0.0)
        assert (renderer._label.text, renderer._kp.visible) == ("leftturn30", False)
        renderer.draw(ViewState(clients=1, run_id=1, live=live), [tick], 0.0)  # the organiser's
        assert (renderer._label.text, renderer._kp.visible) == ("leftturn30 (KP)", True)
    finally:
        server.stop()


def test_the_panel_names_stimuli_behaviour_episode_tick_and_successes() -> None:
    v = view(
        episode=4, tick=1234, episode_tick=87, stimuli=("Middle", "Red"), behaviour="stop",
        how="released", successes=2, episodes_done=4,
    )  # fmt: skip
    text = decision_markdown(v, "live", "**Decision**")
    for part in ("**Decision**", "Episode **4**", "tick **1234**", "`Middle`", "`Red`", "`stop`"):
        assert part in text
    assert "**2** of 4 episodes" in text
    assert "Replay" not in text
    assert "Replay" in decision_markdown(v, "replay", "")
    assert "No tick" in decision_markdown(None, "live", "")


@pytest.mark.parametrize(
    ("how", "origin", "released_by", "text"),
    [
        ("released", "kp", "Obstacle_M_M", "released by `Obstacle_M_M` (kp)"),
        ("continued", "designed", "Corner", "continued, released by `Corner` (designed)"),
        ("default", "default", "Obstacle_L_M", "default, answering `Obstacle_L_M`"),
        ("default", "default", None, "default"),
        ("explored", "explored", None, "explored"),
        ("released", "", None, "released"),  # a trace stored before traces kept origins
    ],
)
def test_the_panel_says_what_made_the_behaviour_run(
    how: str, origin: str, released_by: str | None, text: str
) -> None:
    v = view(behaviour="leftturn30", how=how, origin=origin, released_by=released_by)
    assert why(v) == text
    assert f"Behaviour: `leftturn30` ({text})" in decision_markdown(v, "live", "")


def test_walls_stand_just_outside_the_corridor_they_bound() -> None:
    assert len(SCENE.walls) == 8
    ox0, oy0, ox1, oy1 = SCENE.outer_box
    ix0, iy0, ix1, iy1 = SCENE.inner_box
    for wall in SCENE.walls:
        x, y, z = wall.center
        assert wall.size[2] == pytest.approx(2 * z)
        # No wall's box reaches into the corridor, where the robot drives.
        half_t = wall.size[1] / 2
        inside_x = ix0 <= x <= ix1
        inside_y = iy0 <= y <= iy1
        if inside_x and inside_y:  # an inner wall: inside the island
            assert min(x - ix0, ix1 - x, y - iy0, iy1 - y) == pytest.approx(half_t)
        else:  # an outer wall: outside the outer rectangle
            assert max(ox0 - x, x - ox1, oy0 - y, y - oy1) == pytest.approx(half_t)


def test_the_stop_line_crosses_the_signal_leg_at_the_worlds_stop_line() -> None:
    sx, sy = GEO.stopline_point
    assert SCENE.stopline.center[:2] == (sx, sy)
    assert SCENE.stopline.size[1] == WORLD.track.corridor_width_m
    d = GEO.directions[WORLD.track.signal.leg]
    assert math.cos(SCENE.stopline.yaw_rad) == pytest.approx(d[0])
    assert math.sin(SCENE.stopline.yaw_rad) == pytest.approx(d[1])
    assert SCENE.lamp_position[:2] == GEO.lamp_point


def test_the_floor_is_the_ring_between_the_walls_facing_up() -> None:
    v = np.asarray(SCENE.floor_vertices)
    area = 0.0
    for a, b, c in SCENE.floor_faces:
        normal_z = np.cross(v[b] - v[a], v[c] - v[a])[2]
        assert normal_z > 0
        area += normal_z / 2
    ox0, oy0, ox1, oy1 = SCENE.outer_box
    ix0, iy0, ix1, iy1 = SCENE.inner_box
    assert area == pytest.approx((ox1 - ox0) * (oy1 - oy0) - (ix1 - ix0) * (iy1 - iy0))


def test_the_robot_body_is_a_closed_shell_of_the_amigobots_size() -> None:
    vertices, faces = robot_body_mesh(WORLD.robot)
    edges: Counter[tuple[int, ...]] = Counter()
    for a, b, c in faces:
        for e in ((a, b), (b, c), (c, a)):
            edges[tuple(sorted(e))] += 1
    assert set(edges.values()) == {2}  # watertight: every edge joins two faces
    xs = [p[0] for p in vertices]
    ys = [p[1] for p in vertices]
    assert max(xs) - min(xs) == pytest.approx(WORLD.robot.length_m)
    assert max(ys) - min(ys) == pytest.approx(WORLD.robot.width_m)
    outline = robot_outline(WORLD.robot)
    assert outline[0][0] == outline[-1][0] == -WORLD.robot.length_m / 2  # a flat back


def test_the_trail_grows_thinned_and_starts_afresh_each_episode() -> None:
    trail = Trail(min_step_m=0.05)
    assert trail.add(view(x=0.0, y=0.0))
    assert not trail.add(view(x=0.01, y=0.0))  # too close to keep
    assert trail.add(view(x=0.06, y=0.0))
    assert trail.points == [(0.0, 0.0), (0.06, 0.0)]
    assert trail.add(view(episode=1, x=5.0, y=5.0))
    assert trail.points == [(5.0, 5.0)]
    assert trail.add(view(run_id=2, episode=1, x=5.0, y=5.0))  # another run: another trail
    last = trail_of([view(x=0.1 * i, y=0.0) for i in range(10)], 0.05).points[-1]
    assert last[0] == pytest.approx(0.9) and last[1] == 0.0


def test_yaw_quaternions_are_unit_and_about_z() -> None:
    for yaw in np.linspace(-math.pi, math.pi, 13):
        w, x, y, z = yaw_quaternion(float(yaw))
        assert (x, y) == (0.0, 0.0)
        assert w * w + z * z == pytest.approx(1.0)
        assert 2 * math.atan2(z, w) == pytest.approx(float(yaw))


def test_a_realtime_frame_drawn_later_than_half_a_tick_is_dropped() -> None:
    from server.viewer.render import late
    from server.viewer.state import LiveInfo, ViewState

    live = LiveInfo(1, "kp", 3, "running", True, 20.0, True)
    state = ViewState(clients=1, run_id=1, live=live)
    assert not late(state, 0.001)
    assert not late(state, 0.024)
    assert late(state, 0.026)  # half of 50 ms
    assert not late(replace(state, live=replace(live, hz=10.0)), 0.026)
    # Nothing to protect: a fast run, a paused one, a replay.
    assert not late(replace(state, live=replace(live, realtime=False)), 1.0)
    assert not late(replace(state, live=replace(live, status="paused")), 1.0)
    assert not late(replace(state, mode="replay"), 1.0)


def test_the_stop_line_stands_out_on_the_floor() -> None:
    # Defect 10: the white line on light grey was hard to see. WCAG's 3:1 for graphics.
    assert contrast_ratio(STOPLINE_COLOR, FLOOR_COLOR) >= 3.0
    assert contrast_ratio((0, 0, 0), (255, 255, 255)) == pytest.approx(21.0)


def test_the_scene_is_lit_without_an_environment_map_or_shadows() -> None:
    # An environment map made every frame cost a software renderer (CI's Chromium, a
    # machine without a GPU) about 1.7 CPU-seconds: an open view kept two cores busy.
    # Read from viser's message buffer, what a browser that connects is sent.
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        Renderer(server, SCENE, WORLD, lambda _: None)
        buffer = server._websock_server.get_message_buffer()  # viser internals
        sent = list(buffer.message_from_id.values())
    finally:
        server.stop()
    environment = [m for m in sent if isinstance(m, EnvironmentMapMessage)]
    lights = [m for m in sent if isinstance(m, EnableLightsMessage)]
    assert environment and environment[-1].hdri_data is None
    assert lights and (lights[-1].enabled, lights[-1].cast_shadow) == (True, False)
    sky = [m for m in sent if isinstance(m, HemisphereLightMessage)]
    assert sky and sky[-1].props.intensity > 0
