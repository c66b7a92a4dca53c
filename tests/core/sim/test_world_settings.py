"""World settings a phase diagram varies: the camera's range for the obstacle, the cruise speed,
and settings over a preset by dotted path."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from core.brain.catalog import Catalog
from core.brain.motor import Motor, cruise_scale
from core.errors import CatalogError
from core.run.conditions import get_condition
from core.run.runner import run
from core.run.setup import Setup
from core.run.simulation import Simulation
from core.sim.channels import Channel
from core.sim.robot import RobotConfig
from core.sim.track import ObstacleConfig, TrackConfig
from core.sim.world import PymunkWorld, WorldConfig


def facing_obstacle(sight_range_m: float, ahead_m: float) -> list[float]:
    """The channels of a robot on the signal's straight, the obstacle `ahead_m` in front and
    the lamp in view."""
    world = PymunkWorld(
        WorldConfig(track=TrackConfig(obstacle=ObstacleConfig(sight_range_m=sight_range_m)))
    )
    world.reset(0, 0)
    geo = world.geometry
    leg = world.config.track.signal.leg
    heading = geo.heading_of_leg(leg)
    lamp_x = geo.lamp_point[0]
    dx, dy = math.cos(heading), math.sin(heading)
    x, y = lamp_x - 2.0 * dx, geo.stopline_point[1]  # the lamp about 2 m ahead
    camera = world.config.robot.camera_offset_m
    obstacle = (x + (camera + ahead_m) * dx, y + (camera + ahead_m) * dy)
    return list(world.place(x, y, heading, obstacle).channels)


def test_the_camera_makes_the_obstacle_out_only_within_its_sight_range() -> None:
    assert facing_obstacle(3.0, 1.2)[Channel.OBSTACLE_VISIBLE] == 1.0
    assert facing_obstacle(1.0, 1.2)[Channel.OBSTACLE_VISIBLE] == 0.0
    assert facing_obstacle(1.0, 0.8)[Channel.OBSTACLE_VISIBLE] == 1.0


def test_the_lamp_is_seen_from_the_cameras_range_whatever_the_obstacles_sight_range() -> None:
    assert facing_obstacle(3.0, 1.2)[Channel.LAMP_COLOR] != 0.0
    assert facing_obstacle(0.5, 1.2)[Channel.LAMP_COLOR] != 0.0


def test_the_cruise_speed_scales_the_forward_primitives_only(catalog: Catalog) -> None:
    assert cruise_scale(catalog, RobotConfig()) == 1.0  # exactly: the default world unchanged
    motor = Motor(catalog, 2.0, math.radians(150), 0.1, cruise_scale(catalog, RobotConfig(
        cruise_speed_mps=0.6)))  # fmt: skip
    speeds = {}
    for name in ("goforward1", "goforward3", "goforward5", "leftturn90", "back"):
        motor.start(catalog.behaviour(name).id, [0.0] * 32)
        speeds[name] = motor.command([0.0] * 32).speed_mps
    assert speeds["goforward3"] == pytest.approx(0.6)
    assert speeds["goforward1"] == pytest.approx(0.2)
    assert speeds["goforward5"] == pytest.approx(1.0)  # the world clips it to the top speed
    assert speeds["leftturn90"] == catalog.behaviour("leftturn90").speed_mps
    assert speeds["back"] == catalog.behaviour("back").speed_mps


def test_a_faster_cruise_drives_the_robot_farther_in_the_same_ticks() -> None:
    def progress(cruise: float) -> float:
        config = WorldConfig(
            track=TrackConfig(obstacle=ObstacleConfig(enabled=False)),
            robot=RobotConfig(cruise_speed_mps=cruise),
        )
        sim = Simulation(get_condition("reflexes"), 0, world_config=config)
        x0 = sim.reset().x
        for _ in range(20):
            snapshot = sim.tick().snapshot
        return snapshot.x - x0

    assert progress(0.6) / progress(0.45) == pytest.approx(0.6 / 0.45, rel=0.02)


def test_a_cruise_above_the_top_speed_is_refused() -> None:
    with pytest.raises(ValueError, match="cruise_speed_mps"):
        RobotConfig(cruise_speed_mps=0.8)


def test_a_setup_changes_its_presets_settings_by_dotted_path() -> None:
    base = Setup("soft-obstacle")
    moved = replace(base, world_settings=(("track.obstacle.echo_range_m", 0.6),))
    assert base.world_config().track.obstacle.echo_range_m == 0.3
    config = moved.world_config()
    assert config.track.obstacle.echo_range_m == 0.6
    assert config == replace(
        base.world_config(),
        track=replace(base.world_config().track, obstacle=replace(
            base.world_config().track.obstacle, echo_range_m=0.6)),
    )  # fmt: skip


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ((("track.obstacle.echo", 0.6),), "world.track.obstacle: unknown setting 'echo'"),
        ((("robot.cruise_speed_mps", "fast"),), "world.robot.cruise_speed_mps must be a number"),
        ((("robot.cruise_speed_mps", 0.9),), "cruise_speed_mps must be positive and at most"),
        ((("dt_s.x", 1.0),), "world.dt_s must be a number"),
    ],
)
def test_a_bad_world_setting_is_a_clear_error_naming_it(
    settings: tuple[tuple[str, float], ...], message: str
) -> None:
    with pytest.raises(CatalogError, match=message):
        Setup(world_settings=settings)


def test_an_episode_runs_in_the_setups_world() -> None:
    """The sonars hear the obstacle from farther away: the reflexes avoid it more often."""

    def successes(echo: float) -> int:
        setup = Setup("soft-obstacle", signal="given", world_settings=(
            ("track.obstacle.echo_range_m", echo),))  # fmt: skip
        condition = setup.condition(get_condition("reflexes"))
        sim = Simulation(condition, 3, world_config=setup.world_config())
        summary = run(condition, 3, 12, simulation=sim)
        return sum(e.outcome.value == "success" for e in summary.episodes)

    assert successes(3.0) > successes(0.1)
