"""Corridor tracks of any shape: walls, progress, sensing, moving obstacles; the ring unchanged."""

from __future__ import annotations

import dataclasses
import hashlib
import math
import struct

import numpy as np
import pytest

from core.run.conditions import get_condition
from core.run.simulation import Simulation
from core.sim import _kernel as k
from core.sim.channels import Channel
from core.sim.corridor import CorridorConfig, CorridorGeometry, PlacedObstacle, seeded_area
from core.sim.corridor_world import CorridorWorld
from core.sim.render import TopDown
from core.sim.sensing import INF
from core.sim.world import MotorCommand, PymunkWorld, make_world
from core.sim.worlds import load_world, with_settings


def corridor(name: str, sonar_noise_m: float | None = None) -> CorridorWorld:
    config = load_world(name).config
    if sonar_noise_m is not None:
        robot = dataclasses.replace(config.robot, sonar_noise_m=sonar_noise_m)
        config = dataclasses.replace(config, robot=robot)
    world = make_world(config)
    assert isinstance(world, CorridorWorld)
    return world


def geometry(name: str) -> CorridorGeometry:
    track = load_world(name).config.track
    assert isinstance(track, CorridorConfig)
    return CorridorGeometry.build(track)


def edges(points: list[tuple[float, float]]) -> set[frozenset[tuple[float, float]]]:
    return {frozenset((points[i], points[(i + 1) % len(points)])) for i in range(len(points))}


def test_the_walls_of_an_l_shape_are_its_two_mitred_outlines() -> None:
    geo = geometry("l-shape")
    walls = {
        frozenset(((round(a, 6), round(b, 6)), (round(c, 6), round(d, 6))))
        for a, b, c, d in geo.walls
    }
    outer = [(0.0, 0.0), (8.0, 0.0), (8.0, 3.6), (4.2, 3.6), (4.2, 6.0), (0.0, 6.0)]
    inner = [(1.2, 1.2), (6.8, 1.2), (6.8, 2.4), (3.0, 2.4), (3.0, 4.8), (1.2, 4.8)]
    assert walls == edges(outer) | edges(inner)
    assert geo.lap_length_m == pytest.approx(23.2)
    assert list(geo.outer_box) == [0.0, 0.0, 8.0, 6.0]


def test_a_narrow_passage_is_as_wide_as_its_file_says_with_steps_either_end() -> None:
    geo = geometry("narrow-passage")
    x, y = geo.point_on_leg(3, 0.8, 0.0)  # the passage's middle
    up = k.walls_hit(x, y, 0.0, 1.0, geo.walls)
    down = k.walls_hit(x, y, 0.0, -1.0, geo.walls)
    assert up + down == pytest.approx(0.7)
    x, y = geo.point_on_leg(2, 1.0, 0.0)  # before it, full width
    assert k.walls_hit(x, y, 0.0, 1.0, geo.walls) + k.walls_hit(
        x, y, 0.0, -1.0, geo.walls
    ) == pytest.approx(1.2)
    across = [abs(w[3] - w[1]) for w in geo.walls if w[0] == pytest.approx(w[2])]
    steps = [round(float(d), 6) for d in across if d < 1.0]  # not the 3.8 m side walls
    assert steps == [0.25] * 4


def test_a_ray_meets_a_known_segment_where_geometry_says() -> None:
    wall = np.array([2.0, -1.0, 2.0, 1.0])
    assert k.ray_segment(0.0, 0.0, 1.0, 0.0, wall) == pytest.approx(2.0)
    d = 1 / math.sqrt(2)
    long_wall = np.array([2.0, -3.0, 2.0, 3.0])
    assert k.ray_segment(0.0, 0.0, d, d, long_wall) == pytest.approx(2 * math.sqrt(2))
    assert k.ray_segment(0.0, 0.0, -1.0, 0.0, wall) >= INF  # behind the ray
    assert k.ray_segment(0.0, 0.0, 0.0, 1.0, wall) >= INF  # parallel
    assert k.ray_segment(0.0, 0.0, 1 / math.sqrt(1.25), 0.5 / math.sqrt(1.25), wall) < INF
    assert k.ray_segment(0.0, 0.0, d, d, wall) >= INF  # passes above its end


def test_the_sonars_read_the_passage_walls_and_predict_them() -> None:
    world = corridor("narrow-passage", sonar_noise_m=0.0)
    geo = geometry("narrow-passage")
    world.reset(0, 0)
    x, y = geo.point_on_leg(3, 0.8, 0.1)
    frame = world.place(x, y, geo.heading_of_leg(3), None)
    mount = world.config.robot.sonar_mount_m
    left, right = frame.channels[Channel.SONAR_0], frame.channels[Channel.SONAR_5]
    assert left == pytest.approx(0.35 - 0.1 - mount)
    assert right == pytest.approx(0.35 + 0.1 - mount)
    assert frame.channels[Channel.SONAR_0_RESIDUAL] == pytest.approx(0.0)
    assert frame.channels[Channel.LATERAL_OFFSET_M] == pytest.approx(0.1)


@pytest.mark.parametrize(("leg", "heading"), [(0, 0.0), (3, -math.pi / 2)])
def test_progress_follows_the_leg_the_robot_is_on_through_a_crossing(
    leg: int, heading: float
) -> None:
    world = corridor("figure-8")
    geo = world.geometry
    world.reset(0, 0)
    crossing = 3.0 if leg == 0 else 4.0  # the crossing's distance along each straight
    x, y = geo.point_on_leg(leg, crossing - 1.5, 0.0)
    frame = world.place(x, y, heading, None)
    progress = [float(frame.channels[Channel.PROGRESS_M])]
    legs = {int(frame.channels[Channel.LEG])}
    for _ in range(60):  # 2.7 m at 0.45 m/s: through the crossing and 1.2 m past it
        world.apply(MotorCommand(0.45, 0.0))
        frame = world.step()
        assert frame.collision is None
        progress.append(float(frame.channels[Channel.PROGRESS_M]))
        legs.add(int(frame.channels[Channel.LEG]))
    assert legs == {leg}
    steps = np.diff(progress)
    assert steps.min() > 0.04 and steps.max() < 0.05
    assert progress[-1] - progress[0] == pytest.approx(60 * 0.045, abs=0.01)


def test_a_moving_obstacle_is_where_its_path_says_at_every_tick() -> None:
    placed = PlacedObstacle(0, 1.0, 0.2, low_m=1.0, high_m=3.0, speed_mps=0.5, phase_m=0.0)
    assert [placed.along_at(t) for t in (0, 2, 4, 6, 8, 9)] == [1.0, 2.0, 3.0, 2.0, 1.0, 1.5]

    def run() -> list[tuple[float, float]]:
        world = corridor("l-shape")
        world.reset(3, 1)
        trolley = world.layout.obstacles[1]
        assert trolley.speed_mps == 0.2
        out = []
        for tick in range(1, 80):
            world.apply(MotorCommand(0.0, 0.0))
            world.step()
            centre = world.obstacle_centers()[1]
            expected = world.geometry.point_on_leg(
                0, trolley.along_at(tick * world.config.dt_s), trolley.lateral_m
            )
            assert centre == pytest.approx(expected)
            body = world._obstacle_bodies[1].position  # the physics agrees with the path
            assert (body.x, body.y) == pytest.approx(expected, abs=1e-6)
            out.append(centre)
        return out

    first = run()
    assert first == run()
    assert len({round(x, 6) for x, _ in first}) > 50  # it moved


def test_a_moving_obstacle_runs_into_a_robot_standing_on_its_path() -> None:
    world = corridor("l-shape")
    world.reset(3, 1)
    trolley = world.layout.obstacles[1]
    middle = (trolley.low_m + trolley.high_m) / 2
    x, y = world.geometry.point_on_leg(0, middle, trolley.lateral_m)
    world._pose(x, y, math.pi / 2)  # across its path, where it passes twice a cycle
    hits = []
    for _ in range(int(2 * (trolley.high_m - trolley.low_m) / 0.2 / 0.1) + 1):
        world.apply(MotorCommand(0.0, 0.0))
        hits.append(world.step().collision)
    assert "obstacle" in hits


def test_seeded_obstacles_keep_out_of_corners_crossings_passages_and_paths() -> None:
    for name in ("l-shape", "figure-8", "narrow-passage"):
        world = corridor(name)
        geo = geometry(name)
        area = seeded_area(geo)
        full = float(geo.widths_m.max())
        for episode in range(150):
            world.reset(7, episode)
            for p in world.layout.obstacles:
                if p.speed_mps > 0:
                    continue
                assert geo.widths_m[p.segment] == full
                assert any(
                    s == p.segment and lo <= p.along_m <= hi for s, lo, hi in area.spans()
                ), (name, p)
                assert abs(p.lateral_m) <= area.lateral_m[p.segment]
    first = corridor("figure-8")
    again = corridor("figure-8")
    assert first.reset(5, 2) and again.reset(5, 2)
    assert first.layout == again.layout


def test_the_new_presets_lap_without_touching_a_wall() -> None:
    """The expert, no obstacle in the way: each world's corners are turned and laps counted."""
    for name in ("l-shape", "figure-8", "narrow-passage"):
        config = load_world(name).config
        track = config.track
        assert isinstance(track, CorridorConfig)
        clear = dataclasses.replace(config, track=dataclasses.replace(track, obstacles=()))
        sim = Simulation(get_condition("expert"), 0, world_config=clear)
        sim.reset()
        while not (s := sim.tick().snapshot).done:
            pass
        assert s.outcome is not None and s.outcome.value == "success", (name, s.cause)


def test_a_corridor_world_draws_and_refuses_noisy_perception() -> None:
    world = corridor("l-shape")
    world.reset(0, 0)
    frame = TopDown(world.geometry, world.config).draw(
        world.geometry.start_pose, None, world.layout.signal_phases[0][0], world.obstacle_centers()
    )
    assert frame.shape == (6 * 64, 8 * 64, 3)
    assert len({tuple(c) for c in frame.reshape(-1, 3)}) > 5
    noisy = with_settings(load_world("l-shape").config, (("perception.camera_miss_rate", 0.2),))
    with pytest.raises(ValueError, match="noisy perception is available on the rectangular ring"):
        make_world(noisy)


MAIN_TRACE_HASHES = {
    ("classic", "kp"): "2b4ca4144b24d732",
    ("soft-obstacle", "rp"): "b4bc0a7ee8c84a72",
    ("crossed-sonar", "dp"): "3d08e6d52f1a69f0",
}
"""Three episodes of seed 1 on each ring preset, hashed by the code before corridor tracks."""


@pytest.mark.parametrize(("world", "condition"), sorted(MAIN_TRACE_HASHES))
def test_the_ring_presets_run_bit_for_bit_as_before(world: str, condition: str) -> None:
    config = load_world(world).config
    assert isinstance(make_world(config), PymunkWorld)
    sim = Simulation(get_condition(condition), 1, world_config=config)
    h = hashlib.sha256()
    for _ in range(3):
        sim.reset()
        while True:
            s = sim.tick().snapshot
            h.update(struct.pack("<3d2i", s.x, s.y, s.heading_rad, s.behaviour, int(s.lamp)))
            if s.done:
                break
    assert h.hexdigest()[:16] == MAIN_TRACE_HASHES[(world, condition)]
