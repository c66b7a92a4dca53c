"""Sonar readings against the analytic distance to the track's walls."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.sim import _kernel as k
from core.sim.channels import Channel
from core.sim.robot import RobotConfig
from core.sim.track import ObstacleConfig, TrackConfig
from core.sim.types import Geometry
from core.sim.world import MotorCommand, PymunkWorld, WorldConfig

Segment = tuple[tuple[float, float], tuple[float, float]]

QUIET = WorldConfig(
    track=TrackConfig(obstacle=ObstacleConfig(enabled=False)),
    robot=RobotConfig(sonar_noise_m=0.0),
)


def ray_to_segment(ox: float, oy: float, dx: float, dy: float, segment: Segment) -> float | None:
    """Distance along the ray (o, d) to a segment, by Cramer's rule; None if it misses."""
    (ax, ay), (bx, by) = segment
    ex, ey = bx - ax, by - ay
    den = dx * ey - dy * ex
    if abs(den) < 1e-15:
        return None
    wx, wy = ax - ox, ay - oy
    t = (wx * ey - wy * ex) / den
    u = (wx * dy - wy * dx) / den
    if t < 0.0 or not 0.0 <= u <= 1.0:
        return None
    return t


def expected_sonars(
    geometry: Geometry,
    robot: RobotConfig,
    x: float,
    y: float,
    heading: float,
    extra: list[Segment] | None = None,
) -> list[float]:
    """Each sonar's distance from its mount point to the nearest segment, capped at range."""
    segments = geometry.wall_segments() + (extra or [])
    out = []
    for deg in robot.sonar_angles_deg:
        a = heading + math.radians(deg)
        dx, dy = math.cos(a), math.sin(a)
        ox, oy = x + robot.sonar_mount_m * dx, y + robot.sonar_mount_m * dy
        hits = [t for s in segments if (t := ray_to_segment(ox, oy, dx, dy, s)) is not None]
        out.append(min([*hits, robot.sonar_range_m]))
    return out


def box_segments(box: tuple[float, float, float, float]) -> list[Segment]:
    x0, y0, x1, y1 = box
    c = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
    return [(c[i], c[(i + 1) % 4]) for i in range(4)]


def kernel_channels(
    world: PymunkWorld,
    x: float,
    y: float,
    heading: float,
    obstacle: tuple[float, float, float, float] | None = None,
) -> np.ndarray[tuple[int], np.dtype[np.float64]]:
    """Run the sensing kernel at a pose with zero noise and the world's geometry.

    The geometry vector is the one `PymunkWorld` built, so its wiring is checked too.
    """
    geo = world.geometry
    out = k.empty_channels()
    k.sense(
        x,
        y,
        heading,
        world._g,
        np.radians(np.asarray(world.config.robot.sonar_angles_deg, dtype=np.float64)),
        np.zeros(8),
        np.asarray(obstacle if obstacle is not None else (0.0, 0.0, 0.0, 0.0), dtype=np.float64),
        obstacle is not None,
        0.0,
        0.0,
        np.zeros(4),
        geo.vertices,
        geo.directions,
        geo.leg_lengths_m,
        geo.leg_start_m,
        out,
    )
    return out


@pytest.fixture(scope="module")
def world() -> PymunkWorld:
    return PymunkWorld(QUIET)


def test_start_pose_side_sonars_read_the_corridor_half_width(world: PymunkWorld) -> None:
    frame = world.reset(seed=0, episode=0)
    x, y, heading = world.geometry.start_pose
    assert (frame.x, frame.y, frame.heading_rad) == pytest.approx((x, y, heading))
    # The start pose is on the centre line of a 1.2 m corridor: 0.6 - 0.14 to either wall.
    assert frame.channels[Channel.SONAR_0] == pytest.approx(0.46, abs=1e-9)
    assert frame.channels[Channel.SONAR_5] == pytest.approx(0.46, abs=1e-9)
    expected = expected_sonars(world.geometry, world.config.robot, x, y, heading)
    assert frame.channels[:8].tolist() == pytest.approx(expected, abs=1e-9)


POSES = [
    (1.8, 0.6, 0.0),
    (1.8, 0.6, 0.7),
    (3.0, 0.35, -0.4),
    (5.4, 0.6, math.pi / 4),
    (5.5, 2.0, math.pi / 2),
    (5.6, 3.5, 2.5),
    (3.0, 3.4, math.pi),
    (0.6, 3.4, -2.0),
    (0.4, 2.0, -math.pi / 2),
    (0.6, 0.6, 0.0),
    (4.0, 0.9, 3.0),
]


@pytest.mark.parametrize(("x", "y", "heading"), POSES)
def test_kernel_sonars_match_the_analytic_wall_distance(
    world: PymunkWorld, x: float, y: float, heading: float
) -> None:
    out = kernel_channels(world, x, y, heading)
    expected = expected_sonars(world.geometry, world.config.robot, x, y, heading)
    assert out[:8].tolist() == pytest.approx(expected, abs=1e-9)
    assert np.abs(out[8:16]).max() < 1e-12


def corridor_pose() -> st.SearchStrategy[tuple[float, float, float]]:
    """A pose with the robot's centre at least 0.16 m inside the corridor."""
    margin = 0.16

    def inside(p: tuple[float, float, float]) -> bool:
        x, y, _ = p
        in_outer = margin <= x <= 6.0 - margin and margin <= y <= 4.0 - margin
        in_island = 1.2 - margin < x < 4.8 + margin and 1.2 - margin < y < 2.8 + margin
        return in_outer and not in_island

    return st.tuples(st.floats(0.0, 6.0), st.floats(0.0, 4.0), st.floats(-math.pi, math.pi)).filter(
        inside
    )


@settings(deadline=None, max_examples=200)
@given(pose=corridor_pose())
def test_kernel_sonars_match_the_analytic_wall_distance_anywhere(
    world: PymunkWorld, pose: tuple[float, float, float]
) -> None:
    x, y, heading = pose
    out = kernel_channels(world, x, y, heading)
    expected = expected_sonars(world.geometry, world.config.robot, x, y, heading)
    assert out[:8].tolist() == pytest.approx(expected, abs=1e-9)


def test_world_frames_match_the_analytic_wall_distance_while_driving(world: PymunkWorld) -> None:
    world.reset(seed=3, episode=0)
    robot = world.config.robot
    commands = [MotorCommand(0.45, 0.0)] * 5 + [MotorCommand(0.3, 0.8)] * 5
    commands += [MotorCommand(0.3, -1.2)] * 6 + [MotorCommand(-0.2, 0.4)] * 4
    for command in commands:
        world.apply(command)
        frame = world.step()
        assert frame.collision is None
        expected = expected_sonars(world.geometry, robot, frame.x, frame.y, frame.heading_rad)
        assert frame.channels[:8].tolist() == pytest.approx(expected, abs=1e-9)
        assert np.abs(frame.channels[8:16]).max() < 1e-12


def test_obstacle_in_front_reads_short_with_a_large_residual(world: PymunkWorld) -> None:
    x, y, heading = 2.0, 0.6, 0.0
    box = (2.6, 0.45, 2.9, 0.75)  # 0.6 m ahead, straddling the centre line
    out = kernel_channels(world, x, y, heading, obstacle=box)
    expected = expected_sonars(
        world.geometry, world.config.robot, x, y, heading, extra=box_segments(box)
    )
    assert out[:8].tolist() == pytest.approx(expected, abs=1e-9)
    for sonar in (Channel.SONAR_2, Channel.SONAR_3):
        # The box's near face is 0.6 m ahead of the centre; the sonar is 12 deg off the axis.
        assert out[sonar] == pytest.approx(0.6 / math.cos(math.radians(12)) - 0.14, abs=1e-9)
        assert out[sonar + 8] > 0.15
    for sonar in (Channel.SONAR_0, Channel.SONAR_5, Channel.SONAR_6, Channel.SONAR_7):
        assert abs(out[sonar + 8]) < 1e-12


def test_residual_is_zero_without_an_obstacle_or_with_one_behind(
    world: PymunkWorld,
) -> None:
    out = kernel_channels(world, 2.5, 0.6, 0.0)
    assert np.abs(out[8:16]).max() < 1e-12
    # Behind the robot the obstacle may echo on the rear sonars, never on the front six.
    out = kernel_channels(world, 2.5, 0.6, 0.0, obstacle=(0.8, 0.45, 1.0, 0.75))
    assert np.abs(out[8:14]).max() < 1e-12


def test_readings_saturate_at_the_sonar_range(world: PymunkWorld) -> None:
    # Sonar 2 (12 deg left) pointed straight down leg 0: over 5 m of corridor, range 3 m.
    out = kernel_channels(world, 0.6, 0.6, -math.radians(12))
    assert out[Channel.SONAR_2] == world.config.robot.sonar_range_m
    assert out[Channel.SONAR_2_RESIDUAL] == 0.0
    assert out[Channel.SONAR_3] < world.config.robot.sonar_range_m


def test_sonar_noise_is_seeded_and_clipped() -> None:
    noisy = replace(QUIET, robot=RobotConfig(sonar_noise_m=0.05))
    a, b = PymunkWorld(noisy), PymunkWorld(noisy)
    fa, fb = a.reset(5, 2), b.reset(5, 2)
    assert fa.channels.tolist() == fb.channels.tolist()
    exact = expected_sonars(a.geometry, noisy.robot, fa.x, fa.y, fa.heading_rad)
    diff = fa.channels[:8] - np.asarray(exact)
    assert 0.0 < np.abs(diff).max() < 0.5
    assert (fa.channels[:8] >= 0.0).all()
    assert (fa.channels[:8] <= noisy.robot.sonar_range_m).all()
    assert a.reset(6, 2).channels[:8].tolist() != fa.channels[:8].tolist()
