"""The adapter reads real rclpy messages: a PointCloud2 as a whole, a Range's number."""

from __future__ import annotations

import math

import numpy as np
import pytest
import ros2_or_skip  # noqa: F401  # before rclpy: skips the module without it
from sensor_msgs.msg import PointCloud2, PointField, Range

from core.sim.robotfile import parse_robot_file
from server.robots.ros2 import decode, read_field

MOUNT = 0.14

ROBOT = """
[robot]
world = "classic"
[ros2]
[[ros2.topic]]
topic = "pose"
type = "nav_msgs/msg/Odometry"
field = "pose.pose"
stale_after_s = 0.2
channels = ["odometry"]
[[ros2.topic]]
topic = "sonar"
type = "sensor_msgs/msg/PointCloud2"
stale_after_s = 0.2
channels = ["sonar_0", "sonar_1"]
"""


def test_a_point_cloud2_is_read_whole_when_the_robot_file_names_no_field() -> None:
    sonar = parse_robot_file(ROBOT, "cloud2.toml").topics[1]
    assert sonar.field == ""
    ranges, angles = [0.4, 1.9], [math.radians(90.0), math.radians(50.0)]
    xyz = np.array(
        [
            [(MOUNT + r) * math.cos(a), (MOUNT + r) * math.sin(a), 0.0]
            for r, a in zip(ranges, angles, strict=True)
        ],
        dtype="<f4",
    )
    cloud = PointCloud2(
        height=1,
        width=2,
        fields=[
            PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
            for i, n in enumerate("xyz")
        ],
        is_bigendian=False,
        point_step=12,
        row_step=24,
        data=xyz.tobytes(),
        is_dense=True,
    )
    assert decode(read_field(cloud, sonar.field), MOUNT) == pytest.approx(ranges, abs=1e-6)


def test_a_range_message_gives_its_range() -> None:
    assert decode(read_field(Range(range=1.25), "range"), MOUNT) == (1.25,)
