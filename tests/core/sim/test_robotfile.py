"""Robot files: the AmigoBot's parses; a bad one is one error naming the file, entry and reason."""

from __future__ import annotations

import pytest

from core.sim.robotfile import ODOMETRY, RobotFileError, load_robot_file, parse_robot_file
from core.sim.worlds import load_world

GOOD = """
[robot]
world = "classic"
hz = 20

[ros2]
[[ros2.topic]]
topic = "pose"
type = "nav_msgs/msg/Odometry"
field = "pose.pose"
frame = "odom"
stale_after_s = 0.2
channels = ["odometry"]
"""


def test_the_amigobots_robot_file_feeds_every_sensor_of_srlab() -> None:
    robot = load_robot_file("amigobot")
    load_world(robot.world)  # a preset that exists
    fed = {c for t in robot.topics for c in t.channels}
    assert ODOMETRY in fed
    assert {f"sonar_{i}" for i in range(8)} | {"bumper", "lamp_color"} <= fed
    assert robot.hz == 20.0
    assert robot.cmd_vel == "cmd_vel"


def test_a_minimal_robot_file_takes_the_defaults() -> None:
    robot = parse_robot_file(GOOD, "mini.toml")
    assert (robot.name, robot.node, robot.cmd_vel, robot.lost_after_s) == (
        "mini",
        "srlab_brain",
        "cmd_vel",
        0.5,
    )
    assert robot.topics[0].frame == "odom"


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            ('channels = ["odometry"]', 'channels = ["sonar_9"]'),
            "[[ros2.topic]] 1: unknown channel 'sonar_9'",
        ),
        (('channels = ["odometry"]', 'channels = ["sonar_0"]'), "no topic feeds odometry"),
        (
            ('channels = ["odometry"]', 'channels = ["odometry", "bumper"]'),
            "odometry feeds the whole pose",
        ),
        (
            ("stale_after_s = 0.2", "stale_after_s = 0"),
            "[[ros2.topic]] 1: stale_after_s must be positive",
        ),
        (("stale_after_s = 0.2", 'stale_after_s = "x"'), "stale_after_s must be a number"),
        (
            ('type = "nav_msgs/msg/Odometry"', 'type = "Odometry"'),
            "type must read package/msg/Name",
        ),
        (("hz = 20", "hz = -1"), "[robot]: hz must be positive"),
        (('world = "classic"', ""), "[robot]: world must be a non-empty string"),
        (("[[ros2.topic]]", "[[ros2.other]]"), "needs at least one [[ros2.topic]]"),
        (("hz = 20", "hz = "), "bad.toml: "),
    ],
)
def test_a_bad_robot_file_names_the_file_the_entry_and_the_reason(
    change: tuple[str, str], message: str
) -> None:
    with pytest.raises(RobotFileError) as e:
        parse_robot_file(GOOD.replace(*change), "bad.toml")
    assert str(e.value).startswith("bad.toml: ")
    assert message in str(e.value)


def test_a_channel_fed_twice_is_an_error() -> None:
    twice = GOOD + GOOD[GOOD.index("[[ros2.topic]]") :]
    with pytest.raises(RobotFileError, match="channels fed by two topics: odometry"):
        parse_robot_file(twice, "twice.toml")


def test_a_missing_robot_file_is_an_error_naming_it() -> None:
    with pytest.raises(RobotFileError, match=r"nosuch\.toml"):
        load_robot_file("nosuch")


def test_use_sim_time_is_a_flag_and_off_by_default() -> None:
    assert parse_robot_file(GOOD, "mini.toml").use_sim_time is False
    on = GOOD.replace("[ros2]\n", "[ros2]\nuse_sim_time = true\n")
    assert parse_robot_file(on, "mini.toml").use_sim_time is True
    with pytest.raises(RobotFileError, match=r"mini\.toml: \[ros2\]: use_sim_time must be true"):
        parse_robot_file(GOOD.replace("[ros2]\n", '[ros2]\nuse_sim_time = "yes"\n'), "mini.toml")


def test_a_robots_world_is_its_maps_preset_at_its_rate() -> None:
    robot = load_robot_file("amigobot")
    preset = load_world("ros2:amigobot")
    assert preset.name == "ros2:amigobot"
    assert preset.config.dt_s == 1.0 / robot.hz
    assert preset.config.max_ticks == robot.max_ticks
    assert preset.config.track == load_world(robot.world).config.track
