"""Robot files: which ROS 2 topic feeds which physical-sensor channel, as data.

A robot file (core/data/robots/*.toml, docs/robots.md) names the srlab world preset whose
track is the map, the tick rate, and a `[ros2]` section: the node's name, the command topic,
when the robot counts as lost, and for each sensor topic its message type, the field read,
the frame it must be in, how old its latest message may be, and the channels it feeds in
order. Parsing needs no ROS install; `server.robots.ros2` subscribes to what it describes.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from core.sim.channels import CHANNELS

ODOMETRY = "odometry"
"""The pseudo-channel a pose feeds: x, y and heading, read against the map."""

INSTALL_HINT = "`make install-ros2` installs the srlab[ros2] extra (rclpy and Fast DDS wheels)"

ROBOT_PREFIX = "ros2:"
"""A run's world that names a robot file: ``ros2:NAME`` or ``ros2:PATH.toml``."""


class RobotFileError(ValueError):
    """A robot file that cannot be used: the message names the file, the entry and why."""


@dataclass(frozen=True, slots=True)
class TopicSpec:
    """One sensor topic and the channels it feeds.

    Attributes:
        topic: the ROS 2 topic name.
        type: the message type as ``package/msg/Name``.
        field: the dotted path of the value read in each message ("": the whole message,
            as a `PointCloud2` is read).
        frame: the `header.frame_id` a message must carry ("" when the type has none).
        stale_after_s: a message older than this no longer counts: its channels are stale.
        channels: the channels fed, in the order of the value's elements (`ODOMETRY` for a pose).
    """

    topic: str
    type: str
    field: str
    frame: str
    stale_after_s: float
    channels: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class RobotFile:
    """A robot reached through ROS 2.

    Attributes:
        name: the robot's name.
        world: the world preset whose track is the map odometry is read on.
        hz: the tick rate: the engine paces ticks at it and the brain's dt is its inverse.
        max_ticks: an episode's time limit in ticks.
        connect_timeout_s: how long a reset waits for the first odometry.
        node: the adapter's ROS 2 node name.
        cmd_vel: the topic each tick's wheel command is sent on (`geometry_msgs/msg/Twist`).
        lost_after_s: no message on any topic for this long: the robot is lost and stopped.
        topics: the sensor topics.
        use_sim_time: the robot's clock is the `/clock` topic (a simulator's, as ROS 2's
            `use_sim_time`): messages' ages are read on it, so a simulator that runs slower
            or faster than the wall clock (or in lockstep with the commands) is sensed as
            at its own pace. Losing the robot is still wall-clock silence.
    """

    name: str
    world: str
    hz: float
    max_ticks: int
    connect_timeout_s: float
    node: str
    cmd_vel: str
    lost_after_s: float
    topics: tuple[TopicSpec, ...]
    use_sim_time: bool = False


def _positive(where: str, table: dict[str, Any], key: str, default: float | None = None) -> float:
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise RobotFileError(f"{where}: {key} must be a number, got {value!r}")
    if value <= 0:
        raise RobotFileError(f"{where}: {key} must be positive, got {value!r}")
    return float(value)


def _text(where: str, table: dict[str, Any], key: str, default: str | None = None) -> str:
    value = table.get(key, default)
    if not isinstance(value, str) or (default is None and not value):
        raise RobotFileError(f"{where}: {key} must be a non-empty string, got {value!r}")
    return value


def _topic(where: str, raw: Any) -> TopicSpec:
    if not isinstance(raw, dict):
        raise RobotFileError(f"{where}: must be a table")
    channels = raw.get("channels")
    if not isinstance(channels, list) or not channels:
        raise RobotFileError(f"{where}: channels must be a non-empty list of channel names")
    for c in channels:
        if c != ODOMETRY and c not in CHANNELS:
            raise RobotFileError(
                f"{where}: unknown channel {c!r} (known: {ODOMETRY}, {', '.join(CHANNELS)})"
            )
    if ODOMETRY in channels and len(channels) != 1:
        raise RobotFileError(f"{where}: {ODOMETRY} feeds the whole pose: it stands alone")
    kind = _text(where, raw, "type")
    if kind.count("/") != 2 or kind.split("/")[1] != "msg":
        raise RobotFileError(f"{where}: type must read package/msg/Name, got {kind!r}")
    return TopicSpec(
        _text(where, raw, "topic"),
        kind,
        _text(where, raw, "field", ""),
        _text(where, raw, "frame", ""),
        _positive(where, raw, "stale_after_s"),
        tuple(channels),
    )


def parse_robot_file(text: str, source: str) -> RobotFile:
    """The robot file `text` (named `source` in errors), or `RobotFileError`."""
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise RobotFileError(f"{source}: {e}") from None
    robot = raw.get("robot", {})
    ros2 = raw.get("ros2")
    if not isinstance(robot, dict) or not isinstance(ros2, dict):
        raise RobotFileError(f"{source}: needs a [robot] table and a [ros2] table")
    topics = ros2.get("topic")
    if not isinstance(topics, list) or not topics:
        raise RobotFileError(f"{source}: [ros2] needs at least one [[ros2.topic]]")
    parsed = tuple(_topic(f"{source}: [[ros2.topic]] {i + 1}", t) for i, t in enumerate(topics))
    fed = [c for t in parsed for c in t.channels]
    twice = sorted({c for c in fed if fed.count(c) > 1})
    if twice:
        raise RobotFileError(f"{source}: [ros2]: channels fed by two topics: {', '.join(twice)}")
    if ODOMETRY not in fed:
        raise RobotFileError(f"{source}: [ros2]: no topic feeds {ODOMETRY} (the map needs it)")
    max_ticks = robot.get("max_ticks", 1200)
    if isinstance(max_ticks, bool) or not isinstance(max_ticks, int) or max_ticks <= 0:
        raise RobotFileError(f"{source}: [robot]: max_ticks must be a positive integer")
    return RobotFile(
        _text(f"{source}: [robot]", robot, "name", Path(source).stem),
        _text(f"{source}: [robot]", robot, "world"),
        _positive(f"{source}: [robot]", robot, "hz", 10.0),
        max_ticks,
        _positive(f"{source}: [robot]", robot, "connect_timeout_s", 10.0),
        _text(f"{source}: [ros2]", ros2, "node", "srlab_brain"),
        _text(f"{source}: [ros2]", ros2, "cmd_vel", "cmd_vel"),
        _positive(f"{source}: [ros2]", ros2, "lost_after_s", 0.5),
        parsed,
        _flag(f"{source}: [ros2]", ros2, "use_sim_time"),
    )


def _flag(where: str, table: dict[str, Any], key: str) -> bool:
    value = table.get(key, False)
    if not isinstance(value, bool):
        raise RobotFileError(f"{where}: {key} must be true or false, got {value!r}")
    return value


def robots_dir() -> Path:
    """The folder of robot files: ``robots`` in srlab's data folder (``SRLAB_DATA_DIR``)."""
    from core.brain.catalog import data_dir

    return data_dir() / "robots"


def robot_names() -> list[str]:
    """The robot files in `robots_dir`, by name."""
    return sorted(p.stem for p in robots_dir().glob("*.toml"))


def robot_of(world: str) -> str | None:
    """The robot file a run's world names (``ros2:NAME``), or None for a simulated world."""
    return world[len(ROBOT_PREFIX) :] if world.startswith(ROBOT_PREFIX) else None


def load_robot_file(name: str) -> RobotFile:
    """A robot file by name (core/data/robots/NAME.toml) or by path (ending in ``.toml``)."""
    path = Path(name) if name.endswith(".toml") else robots_dir() / f"{name}.toml"
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        known = ", ".join(robot_names()) or "none"
        raise RobotFileError(f"unknown robot {name!r}: no file {path} (known: {known})") from None
    except OSError as e:
        raise RobotFileError(f"{path}: {e.strerror or e}") from None
    return parse_robot_file(text, str(path))
