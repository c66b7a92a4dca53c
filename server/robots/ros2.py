"""A `World` on a ROS 2 robot: channels from its topics, each tick's command as a Twist.

`Ros2World` has `PymunkWorld`'s protocol (`core.sim.types.World`), so the brain, the
simulation's episodes and the engine's realtime pacing run on it unchanged. A robot file
(`core.sim.robotfile`, docs/robots.md) says which topic feeds which channel of
`core.sim.channels`, so srlab's logical sensors (core/data/sensors.toml) apply as they are.

- **Sensor topics** are read on a thread of their own (an rclpy executor); each keeps only
  its latest message (a queue of one), so a fast publisher leaves no backlog. A tick reads
  the latest message of each topic; one older than its `stale_after_s`, missing, in the wrong
  frame or of the wrong size leaves its channels NaN ("stale"): every comparison a logical
  sensor's rule makes with NaN is false, so it releases nothing on them.
- **Map channels** (lateral offset, heading error, corner, leg, progress, stop line) come
  from odometry read against the track of the robot file's world preset: the robot starts
  each episode at the track's start pose, and the odometry since the episode's reset,
  turned into the map's frame, is the pose srlab's sensing kernel reads the map at. The
  sonars' residuals are the map's expected ranges there minus the ranges measured.
- **Commands**: each tick's wheel command is published on `cmd_vel` as a Twist (linear.x
  m/s, angular.z rad/s); a command that is not finite (the motor read stale odometry) is
  sent as zero. **Losing the robot** (no message on any topic for `lost_after_s`) sends a
  zero Twist at once, from the reading thread, and calls the `on_lost` callbacks; every
  later command is zero too. A moving robot sent no command for `HOLD_PERIODS` ticks (its
  run paused, or between episodes) is sent a zero Twist as well.

**Pacing from the robot's clock**: `RobotPacer` is the engine's realtime clock read off the
robot (its odometry's stamps), so a tick starts as the odometry of its period arrives, and
`latest()` lets the simulation read that message before the brain decides: the command
answers readings a fraction of a millisecond old instead of a period old.

There is no referee on a robot: frames report no collision and no violation; an episode ends
on a full lap by odometry or at the time limit.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import math
import threading
import time
from collections import deque
from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from core.engine.pacing import ON_TIME_S
from core.sim.channels import CHANNELS, Channel
from core.sim.robotfile import INSTALL_HINT, ODOMETRY, RobotFile, TopicSpec
from core.sim.types import EpisodeLayout, LampColor, MotorCommand, SensorFrame
from core.sim.world import make_world
from core.sim.worlds import robot_preset

if TYPE_CHECKING:
    from core.engine.pacing import Wake

MAP_CHANNELS = (
    Channel.LATERAL_OFFSET_M,
    Channel.HEADING_ERROR_RAD,
    Channel.VERTEX_AHEAD_M,
    Channel.CORNER_PENDING,
    Channel.STOPLINE_AHEAD_M,
    Channel.LEG,
    Channel.PROGRESS_M,
    Channel.FRONT_TO_STOPLINE_M,
    Channel.HEADING_RAD,
)
"""The channels read from the map at the odometry's pose."""

_SONARS = slice(Channel.SONAR_0, Channel.SONAR_7 + 1)
_RESIDUALS = slice(Channel.SONAR_0_RESIDUAL, Channel.SONAR_7_RESIDUAL + 1)


LATENCIES_KEPT = 100_000
"""How many commands' latencies a world keeps (the latest): 83 minutes at 20 Hz."""


HOLD_PERIODS = 2
"""A moving robot sent no command for this many tick periods gets a zero Twist."""


class RobotLostError(RuntimeError):
    """The robot sent no odometry in time."""


def message_class(kind: str) -> Any:
    """The rclpy message class of ``package/msg/Name``, or `ValueError` naming it."""
    package, _, name = kind.split("/")
    try:
        return getattr(importlib.import_module(f"{package}.msg"), name)
    except (ImportError, AttributeError):
        raise ValueError(f"unknown ROS 2 message type {kind!r}") from None


def yaw(q: Any) -> float:
    """The heading (rotation about z) of a quaternion with x, y, z, w."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


_CLOUD2_TYPES = {7: "f4", 8: "f8"}
"""`sensor_msgs/msg/PointField` datatypes a `PointCloud2`'s x and y may have: FLOAT32, FLOAT64."""


def _cloud2_points(cloud: Any) -> np.ndarray:
    """A `sensor_msgs/msg/PointCloud2`'s points' x and y (float32 or float64 fields)."""
    fields = {f.name: f for f in cloud.fields}
    if not {"x", "y"} <= fields.keys() or any(
        fields[n].datatype not in _CLOUD2_TYPES for n in "xy"
    ):
        return np.empty((0, 2))
    order = ">" if cloud.is_bigendian else "<"
    dtype = np.dtype(
        {
            "names": ["x", "y"],
            "formats": [order + _CLOUD2_TYPES[fields[n].datatype] for n in "xy"],
            "offsets": [fields[n].offset for n in "xy"],
            "itemsize": cloud.point_step,
        }
    )
    points = np.frombuffer(bytes(cloud.data), dtype=dtype, count=cloud.width * cloud.height)
    return np.stack([points["x"], points["y"]], axis=1).astype(float)


def decode(value: Any, sonar_mount_m: float) -> tuple[float, ...]:
    """The numbers a message's field gives, by its shape.

    A pose (position and orientation): x, y, heading. Points (`geometry_msgs/Point32`, as
    in a `PointCloud`, or a whole `PointCloud2` with float x and y fields): each point's
    range from the sonar's mount, its distance from the robot's centre less
    `sonar_mount_m` (an echo lies on its sonar's axis). A number or a bool: itself. A
    sequence of numbers: them.
    """
    if hasattr(value, "position") and hasattr(value, "orientation"):
        return (float(value.position.x), float(value.position.y), yaw(value.orientation))
    if hasattr(value, "point_step") and hasattr(value, "fields"):
        xy = _cloud2_points(value)
        return tuple(float(r) for r in np.hypot(xy[:, 0], xy[:, 1]) - sonar_mount_m)
    if isinstance(value, bool | int | float):
        return (float(value),)
    items = list(value)
    if items and hasattr(items[0], "x"):
        return tuple(math.hypot(p.x, p.y) - sonar_mount_m for p in items)
    return tuple(float(v) for v in items)


def read_field(msg: Any, path: str) -> Any:
    """The value at a dotted path in a message ("": the message itself)."""
    for part in path.split(".") if path else ():
        msg = getattr(msg, part)
    return msg


class Ros2World:
    """The `World` protocol over a ROS 2 robot described by a robot file.

    Args:
        robot: the robot file.
        clock: seconds, monotonic: the watchdog's, latencies', and message ages' unless the
            robot file says `use_sim_time` (then ages are read on the robot's `/clock`).
    """

    def __init__(self, robot: RobotFile, clock: Callable[[], float] = time.monotonic) -> None:
        try:
            import rclpy
        except ImportError as e:
            raise ImportError(f"{e.name} is not installed: {INSTALL_HINT}") from None
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile
        from rclpy.signals import SignalHandlerOptions

        self.robot = robot
        self.config = robot_preset(robot).config
        self._map = make_world(self.config)
        self.geometry = self._map.geometry
        self._clock = clock
        self._mount = self.config.robot.sonar_mount_m
        self._latest: list[tuple[float, float, tuple[float, ...]] | None] = [None] * len(
            robot.topics
        )
        """Per topic, its latest message: received when (wall clock, age clock), values."""
        self.sim_time = 0.0
        """The robot's `/clock` (with `use_sim_time`): seconds."""
        self._index = [
            (-1,) if t.channels == (ODOMETRY,) else tuple(CHANNELS.index(c) for c in t.channels)
            for t in robot.topics
        ]
        self._odometry = next(i for i, t in enumerate(robot.topics) if t.channels == (ODOMETRY,))
        fed = {c for i in self._index for c in i if c >= 0}
        fed |= {int(c) for c in MAP_CHANNELS} | {int(Channel.PROGRESS_M)}
        fed |= (
            set(range(len(CHANNELS))[_RESIDUALS])
            if fed & set(range(len(CHANNELS))[_SONARS])
            else set()
        )
        self.fed = frozenset(fed)
        """The channels the robot's topics and its map give; every other one stays stale
        (NaN: a world's channel this robot has no sensor for, e.g. `beacon_phase`), so a
        logical sensor over it releases nothing."""
        self._last_any = -math.inf
        self._lost = False
        self.stopped_after_s = math.nan
        """How long after the robot's last message its zero Twist went out, once lost."""
        self._lost_callbacks: list[Callable[[], object]] = []
        self._lock = threading.Lock()
        self.rejected = 0
        """Messages ignored: in the wrong frame or of the wrong size."""
        self.sent = 0
        """Twists published."""
        self.held = 0
        """Zero Twists sent because no command came for `HOLD_PERIODS` ticks."""
        self._commanded_at = -math.inf
        self._moving = False
        self.latencies_s: deque[float] = deque(maxlen=LATENCIES_KEPT)
        """For the latest commands, the age of the newest sensor message each answered."""
        self._used_at = -math.inf
        self.robot_time = 0.0
        """The robot's clock: the stamp of its latest odometry, seconds."""
        self._on_odometry: tuple[Callable[[], object], ...] = ()
        self._tick = 0
        self._origin = (0.0, 0.0, 0.0)
        self._pose = self.geometry.start_pose
        self._progress = 0.0
        self._layout = EpisodeLayout(None, 0, ((LampColor.NONE, robot.max_ticks),))

        from geometry_msgs.msg import Twist

        self._twist = Twist
        self._context = rclpy.Context()
        rclpy.init(context=self._context, signal_handler_options=SignalHandlerOptions.NO)
        self._node = rclpy.create_node(robot.node, context=self._context)
        # Commands are kept 10 deep until delivered (reliable), so a robot whose reader
        # was busy for a tick still gets each; its sensors keep 1, the latest.
        self._cmd = self._node.create_publisher(Twist, robot.cmd_vel, QoSProfile(depth=10))
        for i, t in enumerate(robot.topics):
            self._node.create_subscription(
                message_class(t.type), t.topic, partial(self._receive, i, t), QoSProfile(depth=1)
            )
        if robot.use_sim_time:
            from rclpy.qos import qos_profile_sensor_data
            from rosgraph_msgs.msg import Clock

            self._node.create_subscription(Clock, "/clock", self._tock, qos_profile_sensor_data)
        self._node.create_timer(min(robot.lost_after_s / 4, 0.05), self._watch)
        self._executor = SingleThreadedExecutor(context=self._context)
        self._executor.add_node(self._node)
        self._thread = threading.Thread(target=self._spin, name="ros2-world", daemon=True)
        self._thread.start()

    # --- the reading thread ----------------------------------------------------------

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        with contextlib.suppress(ExternalShutdownException):
            self._executor.spin()

    def _ages_now(self) -> float:
        """The clock message ages are read on: the robot's `/clock` or the wall clock."""
        return self.sim_time if self.robot.use_sim_time else self._clock()

    def _tock(self, msg: Any) -> None:
        self._last_any = self._clock()
        self.sim_time = msg.clock.sec + msg.clock.nanosec * 1e-9

    def _receive(self, i: int, spec: TopicSpec, msg: Any) -> None:
        now = self._clock()
        self._last_any = now
        if spec.frame and getattr(getattr(msg, "header", None), "frame_id", "") != spec.frame:
            self.rejected += 1
            return
        values = decode(read_field(msg, spec.field), self._mount)
        if len(values) != (3 if spec.channels == (ODOMETRY,) else len(spec.channels)):
            self.rejected += 1
            return
        header = getattr(msg, "header", None)
        stamp = None if header is None else header.stamp.sec + header.stamp.nanosec * 1e-9
        # On the robot's clock a message is as old as its stamp says (it may have waited
        # in its queue while this thread was busy); on the wall clock, from its arrival
        # (the robot's wall clock is another machine's).
        aged = stamp if stamp is not None and self.robot.use_sim_time else self._ages_now()
        self._latest[i] = (now, aged, values)
        if i == self._odometry:
            self.robot_time = aged if stamp is None else stamp
            for callback in self._on_odometry:
                callback()

    def _watch(self) -> None:
        self._hold()
        if self._lost or self._clock() - self._last_any <= self.robot.lost_after_s:
            return
        if self._last_any == -math.inf:
            return  # not connected yet: reset() waits for the robot
        self._lost = True
        self._publish(0.0, 0.0)
        self.stopped_after_s = self._clock() - self._last_any
        for callback in self._lost_callbacks:
            callback()

    def _hold(self) -> None:
        """Stop a moving robot (a zero Twist) sent no command for `HOLD_PERIODS` ticks.

        Its run paused, between episodes, or its engine stalled.
        """
        if self._moving and self._ages_now() - self._commanded_at > HOLD_PERIODS / self.robot.hz:
            self._moving = False
            self._publish(0.0, 0.0)
            self.held += 1

    def _publish(self, speed: float, turn: float) -> None:
        msg = self._twist()
        msg.linear.x = speed
        msg.angular.z = turn
        with self._lock:
            self._cmd.publish(msg)
            self.sent += 1

    # --- the World protocol ----------------------------------------------------------

    @property
    def lost(self) -> bool:
        """Whether the robot went silent for `lost_after_s` (it has been sent a zero Twist)."""
        return self._lost

    def on_lost(self, callback: Callable[[], object]) -> None:
        """Call `callback` (on the reading thread) when the robot is lost."""
        self._lost_callbacks.append(callback)

    def listen_odometry(self, callback: Callable[[], object]) -> Callable[[], None]:
        """Call `callback` (on the reading thread) on each odometry; returns its removal."""
        self._on_odometry = (*self._on_odometry, callback)

        def remove() -> None:
            self._on_odometry = tuple(c for c in self._on_odometry if c is not callback)

        return remove

    @property
    def layout(self) -> EpisodeLayout:
        """No layout is known on a robot: no obstacle placed, no lamp cycle."""
        return self._layout

    def reset(self, seed: int, episode: int) -> SensorFrame:
        """Wait for odometry (up to `connect_timeout_s`), take its pose as the start pose."""
        self._map.reset(seed, episode)
        deadline = self._clock() + self.robot.connect_timeout_s
        while self._latest[self._odometry] is None or self._stale(self._odometry):
            if self._clock() > deadline or self._lost:
                raise RobotLostError(
                    f"no odometry on {self.robot.topics[self._odometry].topic!r} "
                    f"within {self.robot.connect_timeout_s:g} s"
                )
            time.sleep(0.01)
        latest = self._latest[self._odometry]
        assert latest is not None
        x, y, heading = latest[2]
        self._origin = (x, y, heading)
        self._tick = 0
        self._progress = 0.0
        return self._sense()

    def apply(self, command: MotorCommand) -> None:
        """Send the wheel command as a Twist now (zero when lost or not finite)."""
        speed, turn = command
        if self._lost or not (math.isfinite(speed) and math.isfinite(turn)):
            speed, turn = 0.0, 0.0
        self._publish(float(speed), float(turn))
        self._commanded_at = self._ages_now()
        self._moving = (speed, turn) != (0.0, 0.0)
        self.latencies_s.append(self._clock() - self._used_at)

    def step(self) -> SensorFrame:
        """The latest readings as a frame (the robot moves by itself: nothing to advance)."""
        self._tick += 1
        return self._sense()

    def latest(self) -> SensorFrame:
        """The latest readings, read again within the tick (`Simulation` calls it first)."""
        return self._sense()

    def close(self) -> None:
        """Stop the robot (a zero Twist) and leave ROS 2."""
        import rclpy

        if not self._context.ok():
            return
        self._publish(0.0, 0.0)
        self._executor.shutdown()
        self._node.destroy_node()
        rclpy.shutdown(context=self._context)
        self._thread.join(timeout=5)

    # --- sensing ---------------------------------------------------------------------

    def _stale(self, i: int, now: float | None = None) -> bool:
        """Whether topic `i` has no message younger than its `stale_after_s` (on the age clock)."""
        latest = self._latest[i]
        if latest is None:
            return True
        return (self._ages_now() if now is None else now) - latest[1] > self.robot.topics[
            i
        ].stale_after_s

    def _map_pose(self, x: float, y: float, th: float) -> tuple[float, float, float]:
        ox, oy, oth = self._origin
        c, s = math.cos(oth), math.sin(oth)
        dx, dy = c * (x - ox) + s * (y - oy), -s * (x - ox) + c * (y - oy)
        sx, sy, sth = self.geometry.start_pose
        c, s = math.cos(sth), math.sin(sth)
        heading = sth + th - oth
        return (
            sx + c * dx - s * dy,
            sy + s * dx + c * dy,
            math.atan2(math.sin(heading), math.cos(heading)),
        )

    def _sense(self) -> SensorFrame:
        now = self._ages_now()
        out = np.full(len(CHANNELS), math.nan)
        newest = -math.inf
        for i, latest in enumerate(self._latest):
            if latest is None or self._stale(i, now):
                continue
            newest = max(newest, latest[0])
            if i != self._odometry:
                out[list(self._index[i])] = latest[2]
        self._used_at = newest
        if not self._stale(self._odometry, now):
            latest = self._latest[self._odometry]
            assert latest is not None
            self._pose = self._map_pose(*latest[2])
            on_map = self._map.place(*self._pose, None).channels
            out[list(MAP_CHANNELS)] = on_map[list(MAP_CHANNELS)]
            out[_RESIDUALS] = on_map[_SONARS] - out[_SONARS]
            self._progress = float(on_map[Channel.PROGRESS_M])
        # The episode's bookkeeping (progress) needs a number: the last one known.
        out[Channel.PROGRESS_M] = self._progress
        lamp = out[Channel.LAMP_COLOR]
        colour = LampColor(int(lamp)) if math.isfinite(lamp) and 0 <= lamp <= 3 else LampColor.NONE
        x, y, heading = self._pose
        return SensorFrame(self._tick, x, y, heading, out, colour, None, False)


class RobotPacer:
    """The engine's realtime clock (`core.engine.pacing.Pacer`) read off the robot.

    `now()` is the stamp of the robot's latest odometry; a sleep ends when odometry stamped
    that much later arrives (or on a wake-up, or when the robot stays silent for
    `lost_after_s` past it). A realtime run at the robot's rate then ticks as each period's
    odometry arrives, whatever the two machines' clocks say. The robot's own timing jitters:
    odometry stamped up to a quarter of a period early counts as on time.
    """

    def __init__(self, world: Ros2World) -> None:
        self._world = world
        self._early_s = 0.25 / world.robot.hz

    def now(self) -> float:
        """The robot's clock, seconds (the latest odometry's stamp, a quarter period on)."""
        return self._world.robot_time + self._early_s

    async def sleep(self, seconds: float, wake: Wake) -> None:
        """Until the robot's clock is `seconds` on, or `wake` is set."""
        if wake.is_set():
            return
        until = self.now() + seconds - ON_TIME_S
        loop = asyncio.get_running_loop()
        fut: asyncio.Future[None] = wake.waiter()

        def check() -> None:
            if not fut.done() and self.now() >= until:
                fut.set_result(None)

        remove = self._world.listen_odometry(lambda: loop.call_soon_threadsafe(check))
        silent = loop.call_later(
            max(0.0, seconds) + self._world.robot.lost_after_s,
            lambda: None if fut.done() else fut.set_result(None),
        )
        try:
            check()
            await fut
        finally:
            silent.cancel()
            remove()
            if not wake.is_set():
                wake.forget(fut)
