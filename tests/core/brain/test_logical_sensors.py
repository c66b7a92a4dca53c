"""Logical sensors: the data-declared rules classify constructed channel vectors."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace

import pytest
from fakes import channel_list

from core.brain.catalog import Catalog, RuleCondition
from core.brain.sensors import StimulusDetector, compile_detector
from core.sim.channels import Channel
from core.sim.robot import RobotConfig
from core.sim.track import ObstacleConfig, TrackConfig
from core.sim.world import MotorCommand, PymunkWorld, WorldConfig

C = Channel


def names(
    catalog: Catalog, detector: StimulusDetector, values: Mapping[Channel, float]
) -> set[str]:
    return {catalog.stimuli[i].name for i in detector(channel_list(values))}


def test_neutral_channels_give_middle_only(catalog: Catalog, detector: StimulusDetector) -> None:
    assert names(catalog, detector, {}) == {"Middle"}


@pytest.mark.parametrize(
    ("offset", "expected"),
    [
        (0.3, "Left"),
        (0.2000001, "Left"),
        (0.2, "Middle"),
        (0.0, "Middle"),
        (-0.2, "Middle"),
        (-0.2000001, "Right"),
        (-0.3, "Right"),
    ],
)
def test_position_sensor_splits_the_corridor_in_thirds(
    catalog: Catalog, detector: StimulusDetector, offset: float, expected: str
) -> None:
    assert names(catalog, detector, {C.LATERAL_OFFSET_M: offset}) == {expected}


def test_corner_pending_gives_corner(catalog: Catalog, detector: StimulusDetector) -> None:
    assert names(catalog, detector, {C.CORNER_PENDING: 1.0}) == {"Middle", "Corner"}


def test_bumper_gives_collision(catalog: Catalog, detector: StimulusDetector) -> None:
    assert names(catalog, detector, {C.BUMPER: 1.0}) == {"Middle", "Collision"}


@pytest.mark.parametrize(("color", "expected"), [(1, "Red"), (2, "Yellow"), (3, "Green")])
def test_lamp_near_the_stop_line_gives_its_colour(
    catalog: Catalog, detector: StimulusDetector, color: int, expected: str
) -> None:
    seen = {C.LAMP_COLOR: float(color), C.STOPLINE_AHEAD_M: 0.5}
    assert names(catalog, detector, seen) == {"Middle", expected}


@pytest.mark.parametrize(
    ("color", "stopline"), [(0, 0.5), (1, 0.1), (1, 0.2), (1, 0.8), (1, 0.9), (1, 99.0)]
)
def test_lamp_away_from_the_stop_zone_or_unseen_gives_nothing(
    catalog: Catalog, detector: StimulusDetector, color: int, stopline: float
) -> None:
    seen = {C.LAMP_COLOR: float(color), C.STOPLINE_AHEAD_M: stopline}
    assert names(catalog, detector, seen) == {"Middle"}


LANES = {"L": 0.21, "M": 0.0, "R": -0.21}
SIDES = {"L": 0.06, "M": 0.0, "R": -0.06}


@pytest.mark.parametrize("lane", list(LANES))
@pytest.mark.parametrize("side", list(SIDES))
def test_camera_obstacle_in_the_path_gives_lane_by_side(
    path_catalog: Catalog, path_detector: StimulusDetector, lane: str, side: str
) -> None:
    robot, obstacle = LANES[lane], SIDES[side]
    seen = {
        C.LATERAL_OFFSET_M: robot,
        C.OBSTACLE_VISIBLE: 1.0,
        C.OBSTACLE_DISTANCE_M: 1.0,
        C.OBSTACLE_OFFSET_M: obstacle,
        C.OBSTACLE_LATERAL_M: obstacle - robot,
    }
    position = {"L": "Left", "M": "Middle", "R": "Right"}[lane]
    assert names(path_catalog, path_detector, seen) == {position, f"Obstacle_{lane}_{side}"}


@pytest.mark.parametrize(
    "change",
    [
        {C.OBSTACLE_DISTANCE_M: 1.5},
        {C.OBSTACLE_DISTANCE_M: 99.0},
        {C.OBSTACLE_LATERAL_M: 0.3},
        {C.OBSTACLE_LATERAL_M: -0.35},
        {C.OBSTACLE_OFFSET_M: 99.0, C.OBSTACLE_LATERAL_M: 99.0},
    ],
)
def test_camera_obstacle_far_or_out_of_the_path_gives_nothing(
    path_catalog: Catalog, path_detector: StimulusDetector, change: Mapping[Channel, float]
) -> None:
    seen = {
        C.OBSTACLE_DISTANCE_M: 1.0,
        C.OBSTACLE_OFFSET_M: 0.0,
        C.OBSTACLE_LATERAL_M: 0.0,
        **change,
    }
    assert names(path_catalog, path_detector, seen) == {"Middle"}


VIEWS = {"L": 0.5, "M": 0.0, "R": -0.5}


@pytest.mark.parametrize("lane", list(LANES))
@pytest.mark.parametrize("view", list(VIEWS))
def test_paper_camera_obstacle_is_lane_by_third_of_the_view(
    paper_catalog: Catalog, paper_detector: StimulusDetector, lane: str, view: str
) -> None:
    """Fig. 10: the robot's lane x where the obstacle appears in the camera's view, whether
    or not it is in the robot's path."""
    catalog, detector = paper_catalog, paper_detector
    assert catalog.definition == "paper"
    seen = {
        C.LATERAL_OFFSET_M: LANES[lane],
        C.OBSTACLE_VISIBLE: 1.0,
        C.OBSTACLE_DISTANCE_M: 1.2,
        C.OBSTACLE_IMAGE_X: VIEWS[view],
        C.OBSTACLE_OFFSET_M: 0.3,
        C.OBSTACLE_LATERAL_M: 0.5,  # not in the path: the paper's stimuli do not ask
    }
    position = {"L": "Left", "M": "Middle", "R": "Right"}[lane]
    assert names(catalog, detector, seen) == {position, f"Obstacle_{lane}_{view}"}


@pytest.mark.parametrize(
    "change",
    [
        {C.OBSTACLE_VISIBLE: 0.0, C.OBSTACLE_IMAGE_X: 99.0},  # tracked, but out of view
        {C.OBSTACLE_DISTANCE_M: 1.6},
    ],
)
def test_paper_camera_obstacle_out_of_view_or_far_gives_nothing(
    paper_catalog: Catalog, paper_detector: StimulusDetector, change: Mapping[Channel, float]
) -> None:
    catalog, detector = paper_catalog, paper_detector
    seen = {
        C.OBSTACLE_VISIBLE: 1.0,
        C.OBSTACLE_DISTANCE_M: 1.0,
        C.OBSTACLE_IMAGE_X: 0.0,
        C.OBSTACLE_OFFSET_M: 0.0,
        C.OBSTACLE_LATERAL_M: 0.0,
        **change,
    }
    assert names(catalog, detector, seen) == {"Middle"}


@pytest.mark.parametrize("lane", list(LANES))
@pytest.mark.parametrize("view", list(VIEWS))
def test_each_paper_camera_stimulus_fires_in_a_constructed_pose(
    paper_catalog: Catalog, paper_detector: StimulusDetector, lane: str, view: str
) -> None:
    """Robot and obstacle placed in the pymunk world: the camera kernel's image position
    and the position sensor's lane give the stimulus the placement means."""
    world = PymunkWorld(QUIET_WITH_OBSTACLE)
    world.reset(seed=0, episode=0)
    geo = world.geometry
    lateral = {"L": 0.3, "M": 0.0, "R": -0.3}[lane]
    along = 2.0
    x, y = geo.point_on_leg(0, along, lateral)
    # The obstacle 1.2 m ahead, at the image position's bearing: centre of the view, or
    # 15 degrees to a side (the view is 50 degrees wide, so its outer thirds start at 8.3).
    bearing = math.radians({"L": 15.0, "M": 0.0, "R": -15.0}[view])
    distance = 1.2 - world.config.robot.camera_offset_m
    camera = (x + world.config.robot.camera_offset_m, y)
    obstacle = (camera[0] + distance * math.cos(bearing), camera[1] + distance * math.sin(bearing))
    frame = world.place(x, y, 0.0, obstacle)
    fired = {paper_catalog.stimuli[i].name for i in paper_detector(frame.channels.tolist())}
    assert f"Obstacle_{lane}_{view}" in fired
    assert frame.channels[C.OBSTACLE_IMAGE_X] == pytest.approx(
        {"L": 0.6, "M": 0.0, "R": -0.6}[view], abs=1e-9
    )


def test_a_rule_may_compare_two_channels() -> None:
    """["sonar_0", ">", "sonar_5"]: "the left side is freer", written as data."""
    from core.brain.catalog import parse_sensors
    from core.brain.sensors import compile_detector as compile_rules

    spec = {
        "name": "freer_side",
        "objective": "avoid_wall",
        "stimuli": [
            {"name": "LeftFreer", "when": [["sonar_0", ">", "sonar_5"]]},
            {"name": "RightFreer", "when": [["sonar_5", ">=", "sonar_0"], ["sonar_5", ">", 0.5]]},
        ],
    }
    sensors, stimuli = parse_sensors([spec])
    cat = Catalog(stimuli, (), sensors)
    detect = compile_rules(cat)
    left = channel_list({C.SONAR_0: 1.0, C.SONAR_5: 0.4})
    right = channel_list({C.SONAR_0: 0.4, C.SONAR_5: 1.0})
    equal = channel_list({C.SONAR_0: 0.4, C.SONAR_5: 0.4})
    assert [stimuli[i].name for i in detect(left)] == ["LeftFreer"]
    assert [stimuli[i].name for i in detect(right)] == ["RightFreer"]
    assert detect(equal) == []
    assert stimuli[0].rule[0][0].as_data() == ["sonar_0", ">", "sonar_5"]


@pytest.mark.parametrize(
    ("sonars", "expected"),
    [
        ({C.SONAR_2: 0.5, C.SONAR_3: 0.5}, {"SonarObstacleFront"}),
        ({C.SONAR_2: 0.5}, {"SonarObstacleLeft"}),
        ({C.SONAR_3: 0.5}, {"SonarObstacleRight"}),
        ({C.SONAR_1: 0.4}, {"SonarObstacleLeft"}),
        ({C.SONAR_4: 0.4}, {"SonarObstacleRight"}),
        ({C.SONAR_1: 0.4, C.SONAR_4: 0.4}, {"SonarObstacleLeft", "SonarObstacleRight"}),
        ({C.SONAR_2: 0.7, C.SONAR_3: 0.7}, set()),
        ({C.SONAR_1: 0.5}, set()),
    ],
)
def test_sonar_echo_shorter_than_the_map_gives_sonar_obstacles(
    catalog: Catalog,
    detector: StimulusDetector,
    sonars: Mapping[Channel, float],
    expected: set[str],
) -> None:
    # A residual of 3 - reading: the map says the nearest wall is out of range.
    seen = {c: v for s, r in sonars.items() for c, v in ((s, r), (Channel(s + 8), 3.0 - r))}
    assert names(catalog, detector, seen) == {"Middle", *expected}


def test_short_echo_that_the_map_explains_is_not_an_obstacle(
    catalog: Catalog, detector: StimulusDetector
) -> None:
    seen = {C.SONAR_2: 0.5, C.SONAR_3: 0.5, C.SONAR_2_RESIDUAL: 0.05, C.SONAR_3_RESIDUAL: 0.0}
    assert names(catalog, detector, seen) == {"Middle"}


@pytest.mark.parametrize(
    ("sonars", "expected"),
    [
        ({C.SONAR_0: 0.05}, "LeftWall"),
        ({C.SONAR_1: 0.1}, "LeftWall"),
        ({C.SONAR_5: 0.05}, "RightWall"),
        ({C.SONAR_4: 0.1}, "RightWall"),
    ],
)
def test_close_wall_echo_gives_a_wall_stimulus(
    catalog: Catalog, detector: StimulusDetector, sonars: Mapping[Channel, float], expected: str
) -> None:
    assert names(catalog, detector, sonars) == {"Middle", expected}


def test_close_echo_with_a_large_residual_is_not_a_wall(
    catalog: Catalog, detector: StimulusDetector
) -> None:
    seen = {C.SONAR_0: 0.05, C.SONAR_0_RESIDUAL: 0.5, C.SONAR_5: 0.09}
    assert names(catalog, detector, seen) == {"Middle"}


def test_every_stimulus_is_reachable_by_some_vector(
    catalog: Catalog, detector: StimulusDetector
) -> None:
    # Guard against a rule that no channel vector satisfies: each stimulus's first
    # alternative, made true condition by condition, must fire it.
    for s in catalog.stimuli:
        values = channel_list()
        for c in s.rule[0]:
            delta = {"<": -0.01, "<=": 0.0, ">": 0.01, ">=": 0.0, "==": 0.0, "!=": 1.0}[c.op]
            values[c.channel] = c.value + delta
        # Conditions on the same channel (a band) take the band's midpoint.
        by_channel: dict[int, list[float]] = {}
        for c in s.rule[0]:
            by_channel.setdefault(c.channel, []).append(c.value)
        for ch, bounds in by_channel.items():
            if len(bounds) == 2:
                values[ch] = sum(bounds) / 2
        assert s.id in detector(values), s.name


QUIET = WorldConfig(
    track=TrackConfig(obstacle=ObstacleConfig(enabled=False)),
    robot=RobotConfig(sonar_noise_m=0.0),
)
QUIET_WITH_OBSTACLE = WorldConfig(robot=RobotConfig(sonar_noise_m=0.0))


def test_world_start_pose_gives_middle_only(catalog: Catalog, detector: StimulusDetector) -> None:
    world = PymunkWorld(QUIET)
    frame = world.reset(seed=0, episode=0)
    assert {catalog.stimuli[i].name for i in detector(frame.channels.tolist())} == {"Middle"}


def test_world_veering_left_gives_left(catalog: Catalog, detector: StimulusDetector) -> None:
    world = PymunkWorld(QUIET)
    frame = world.reset(seed=0, episode=0)
    seen: list[set[str]] = []
    for _ in range(30):
        turn = math.radians(45) if frame.heading_rad < 0.6 else 0.0
        world.apply(MotorCommand(0.45, turn))
        frame = world.step()
        seen.append({catalog.stimuli[i].name for i in detector(frame.channels.tolist())})
        if frame.channels[C.LATERAL_OFFSET_M] > 0.25:
            break
    assert frame.collision is None
    assert seen[0] == {"Middle"}
    assert seen[-1] == {"Left"}


def test_world_driving_into_the_corner_gives_corner(
    catalog: Catalog, detector: StimulusDetector
) -> None:
    world = PymunkWorld(QUIET)
    frame = world.reset(seed=0, episode=0)
    ticks = 0
    while frame.channels[C.CORNER_PENDING] < 0.5 and ticks < 200:
        world.apply(MotorCommand(0.45, 0.0))
        frame = world.step()
        ticks += 1
    assert frame.collision is None
    # Leg 0's corner centre is 4.8 m along; the zone starts 0.1 m before it.
    assert frame.x == pytest.approx(world.geometry.vertices[0][0] - 0.1, abs=0.05)
    assert {catalog.stimuli[i].name for i in detector(frame.channels.tolist())} == {
        "Middle",
        "Corner",
    }


def test_world_obstacle_ahead_gives_a_camera_obstacle_stimulus(
    path_catalog: Catalog, path_detector: StimulusDetector
) -> None:
    catalog, detector = path_catalog, path_detector
    # Find an episode whose obstacle sits on leg 0 near the centre line, then drive at it.
    world = PymunkWorld(WorldConfig(robot=RobotConfig(sonar_noise_m=0.0)))
    for episode in range(200):
        frame = world.reset(seed=1, episode=episode)
        center = world.layout.obstacle_center
        if world.layout.obstacle_leg == 0 and center is not None and abs(center[1] - 0.6) < 0.04:
            break
    else:
        pytest.fail("no centred obstacle on leg 0 in 200 episodes")
    fired: set[str] = set()
    while frame.collision is None and frame.x < center[0] - 0.5:
        world.apply(MotorCommand(0.3, 0.0))
        frame = world.step()
        fired |= {catalog.stimuli[i].name for i in detector(frame.channels.tolist())}
    assert "Obstacle_M_M" in fired
    assert "SonarObstacleFront" in fired


def test_stale_channels_release_nothing(catalog: Catalog, detector: StimulusDetector) -> None:
    assert detector([math.nan] * len(Channel)) == []


@pytest.mark.parametrize("other", [-1, int(C.SONAR_1)])
def test_a_not_equal_rule_is_false_on_a_stale_channel(catalog: Catalog, other: int) -> None:
    rule = ((RuleCondition(int(C.SONAR_0), "!=", 1.0, other),),)
    stimulus = replace(catalog.stimuli[0], rule=rule)
    detect = compile_detector(replace(catalog, stimuli=(stimulus,)))
    fresh = [0.0] * len(Channel)
    fresh[C.SONAR_1] = 1.0
    assert detect(fresh) == [stimulus.id]
    for stale in (C.SONAR_0, C.SONAR_1):
        if other < 0 and stale == C.SONAR_1:
            continue
        channels = list(fresh)
        channels[stale] = math.nan
        assert detect(channels) == []
