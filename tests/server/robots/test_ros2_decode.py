"""How the ROS 2 adapter reads a message's field, without ROS: values shaped like its messages."""

from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from core.sim.robotfile import load_robot_file
from server.robots.ros2 import Ros2World, decode, yaw

MOUNT = 0.14


def quaternion(heading: float) -> NS:
    return NS(x=0.0, y=0.0, z=math.sin(heading / 2), w=math.cos(heading / 2))


@pytest.mark.parametrize("heading", [0.0, 0.5, -1.2, math.pi - 1e-9, -math.pi / 2])
def test_a_pose_gives_x_y_and_its_heading(heading: float) -> None:
    pose = NS(position=NS(x=1.5, y=-2.0, z=0.0), orientation=quaternion(heading))
    x, y, h = decode(pose, MOUNT)
    assert (x, y) == (1.5, -2.0)
    assert h == pytest.approx(heading)
    assert yaw(quaternion(heading)) == pytest.approx(heading)


def test_points_give_each_echos_range_from_its_sonars_mount() -> None:
    angles = [math.radians(a) for a in (90.0, 12.0, -160.0)]
    ranges = [0.5, 2.75, 0.0]
    points = [
        NS(x=(MOUNT + r) * math.cos(a), y=(MOUNT + r) * math.sin(a), z=0.0)
        for r, a in zip(ranges, angles, strict=True)
    ]
    assert decode(points, MOUNT) == pytest.approx(ranges)


@pytest.mark.parametrize(("kind", "bigendian"), [(7, False), (8, True)])
def test_a_point_cloud2_gives_each_echos_range(kind: int, bigendian: bool) -> None:
    angles = [math.radians(a) for a in (90.0, 12.0, -160.0)]
    ranges = [0.5, 2.75, 0.0]
    scalar = ">" if bigendian else "<"
    scalar += "f4" if kind == 7 else "f8"
    # x, y, z and an intensity the adapter skips: 4 fields a point, padded to 40 bytes.
    points = np.zeros(
        3,
        dtype=np.dtype(
            {
                "names": ["x", "y", "z", "intensity"],
                "formats": [scalar] * 4,
                "offsets": [0, 8, 16, 24],
                "itemsize": 40,
            }
        ),
    )
    points["x"] = [(MOUNT + r) * math.cos(a) for r, a in zip(ranges, angles, strict=True)]
    points["y"] = [(MOUNT + r) * math.sin(a) for r, a in zip(ranges, angles, strict=True)]
    fields = [
        NS(name=n, offset=o, datatype=kind, count=1) for n, o in zip("xyz", (0, 8, 16), strict=True)
    ]
    cloud = NS(
        fields=fields,
        point_step=40,
        width=3,
        height=1,
        is_bigendian=bigendian,
        data=points.tobytes(),
    )
    assert decode(cloud, MOUNT) == pytest.approx(ranges, abs=1e-6)
    assert decode(NS(**{**vars(cloud), "fields": fields[1:]}), MOUNT) == ()  # no x: nothing


def test_numbers_and_bools_give_themselves() -> None:
    assert decode(True, MOUNT) == (1.0,)
    assert decode(False, MOUNT) == (0.0,)
    assert decode(0.25, MOUNT) == (0.25,)
    assert decode([1.0, 99.0, -0.5], MOUNT) == (1.0, 99.0, -0.5)
    assert decode([], MOUNT) == ()


def test_without_the_extra_the_adapter_says_how_to_install_it() -> None:
    try:
        import rclpy  # noqa: F401
    except ImportError:
        pass
    else:
        pytest.skip("the srlab[ros2] extra is installed here")
    with pytest.raises(ImportError, match=r"make install-ros2"):
        Ros2World(load_robot_file("amigobot"))
