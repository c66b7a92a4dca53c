"""A fake AmigoBot: srlab's pymunk world behind RosAria2's ROS 2 topics (run as a process).

    python tests/ros2/fake_amigobot.py [--world classic] [--hz 20] [--seed 1] [--rate 1]
                                       [--sonar-for-s S] [--lockstep] [--no-obstacle]

It steps a world preset in realtime at `--hz` with the latest Twist taken on `cmd_vel`
(linear.x, angular.z) and publishes what the robot senses, `--rate` times a tick. With
`--lockstep` it is a simulator on a clock of its own instead: it steps one tick for each
Twist it receives, publishes that tick's senses, then its time on `/clock`
(rosgraph_msgs/msg/Clock, as a simulator does for ROS 2's `use_sim_time`), and stamps its
messages with that time; waiting for a Twist it publishes the current senses again every
20 ms (a simulator paused is still there), and after 0.25 s without one it steps a tick
standing still. A test on it then runs at whatever speed the machine allows, tick for tick
as at 20 Hz. `--no-obstacle` leaves the world's obstacle out: with no referee to end the
episode, a robot pressed against the obstacle may back off and drive into it again until the
jitter of a busy machine's message timing frees it, so a lap that must end in time has none.

- `sonar`: sensor_msgs/msg/PointCloud in `base_link`, one echo point per sonar on its axis,
  at the sonar's range beyond its mount (sonars 0-7 as core/sim/channels.py numbers them);
  stops `--sonar-for-s` seconds after the first Twist when given (a sonar fault; seconds
  of its own clock with `--lockstep`);
- `pose`: nav_msgs/msg/Odometry in `odom`, the pose since the start (the odometry frame's
  origin is where the robot stood at the start, as on a robot);
- `bumper`: std_msgs/msg/Bool;
- `camera/detections`: std_msgs/msg/Float32MultiArray, the camera's findings in this order:
  obstacle_visible, obstacle_distance_m, obstacle_lateral_m, obstacle_offset_m,
  obstacle_image_x, lamp_color (the channels of those names).

When its standard input ends it prints one JSON line, {"ticks": ..., "commands": ...}
(Twists received), and exits 0. (Not on SIGTERM: a signal arriving while the sensing kernel's
threads run can abort the process in C++ before Python's handler sees it.)
"""

from __future__ import annotations

import argparse
import json
import math
import queue
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import contextlib

import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point32, Twist
from nav_msgs.msg import Odometry
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.qos import QoSProfile
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud
from std_msgs.msg import Bool, Float32MultiArray

from core.sim.channels import Channel
from core.sim.track import TrackConfig
from core.sim.types import MotorCommand
from core.sim.world import make_world
from core.sim.worlds import load_world

CAMERA = (
    Channel.OBSTACLE_VISIBLE,
    Channel.OBSTACLE_DISTANCE_M,
    Channel.OBSTACLE_LATERAL_M,
    Channel.OBSTACLE_OFFSET_M,
    Channel.OBSTACLE_IMAGE_X,
    Channel.LAMP_COLOR,
)
"""The camera detections message's layout."""


IDLE_S = 0.02
"""With `--lockstep`: how often it publishes its senses again while it waits for a Twist."""
STAND_AFTER_S = 0.25
"""With `--lockstep`: no Twist for this long, it steps a tick standing still (a robot's own
command watchdog), so its clock goes on while nothing drives it (a run paused, between
episodes, at its end)."""


def main() -> int:
    """Run the fake robot until its standard input ends."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="classic")
    parser.add_argument("--hz", type=float, default=20.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--rate", type=int, default=1, help="sensor messages per tick")
    parser.add_argument("--sonar-for-s", type=float, default=math.inf)
    parser.add_argument("--lockstep", action="store_true", help="a tick per Twist, on /clock")
    parser.add_argument("--no-obstacle", action="store_true", help="the world without its obstacle")
    args = parser.parse_args()

    config = replace(load_world(args.world).config, dt_s=1.0 / args.hz)
    if args.no_obstacle:
        track = config.track
        if not isinstance(track, TrackConfig):
            parser.error(f"--no-obstacle takes a rectangular ring's preset, not {args.world!r}")
        config = replace(
            config, track=replace(track, obstacle=replace(track.obstacle, enabled=False))
        )
    world = make_world(config)
    frame = world.reset(args.seed, 0)
    sx, sy, sth = world.geometry.start_pose
    angles = [math.radians(a) for a in config.robot.sonar_angles_deg]
    mount = config.robot.sonar_mount_m
    period = 1.0 / args.hz

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("fake_amigobot")
    qos = QoSProfile(depth=1)
    sonar = node.create_publisher(PointCloud, "sonar", qos)
    pose = node.create_publisher(Odometry, "pose", qos)
    bumper = node.create_publisher(Bool, "bumper", qos)
    camera = node.create_publisher(Float32MultiArray, "camera/detections", qos)
    clock = node.create_publisher(Clock, "/clock", QoSProfile(depth=1))
    commands: queue.Queue[MotorCommand] = queue.Queue()
    received = [0]
    driven_since = [math.inf]
    """When the first Twist came (on its clock): `--sonar-for-s` counts from there."""
    ticks = 0

    def now_s() -> float:
        return ticks * period if args.lockstep else time.monotonic()

    def on_twist(msg: Any) -> None:
        commands.put(MotorCommand(float(msg.linear.x), float(msg.angular.z)))
        if not received[0]:
            driven_since[0] = now_s()
        received[0] += 1

    node.create_subscription(Twist, "cmd_vel", on_twist, QoSProfile(depth=10))
    executor = SingleThreadedExecutor()
    executor.add_node(node)

    def spin() -> None:
        with contextlib.suppress(ExternalShutdownException):
            executor.spin()

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()
    stop = threading.Event()

    def watch_stdin() -> None:
        sys.stdin.read()  # until the end of its input: the test closed it
        stop.set()
        commands.put(MotorCommand(0.0, 0.0))  # wakes a lockstep wait

    threading.Thread(target=watch_stdin, daemon=True).start()

    def publish() -> None:
        c = frame.channels
        if args.lockstep:
            whole = math.floor(ticks * period)
            stamp = Time(sec=whole, nanosec=round((ticks * period - whole) * 1e9))
        else:
            stamp = node.get_clock().now().to_msg()
        if now_s() - driven_since[0] < args.sonar_for_s:
            cloud = PointCloud()
            cloud.header.frame_id = "base_link"
            cloud.header.stamp = stamp
            cloud.points = [
                Point32(x=(mount + c[i]) * math.cos(a), y=(mount + c[i]) * math.sin(a), z=0.0)
                for i, a in enumerate(angles)
            ]
            sonar.publish(cloud)
        bumper.publish(Bool(data=bool(c[Channel.BUMPER] > 0.5)))
        camera.publish(Float32MultiArray(data=[float(c[i]) for i in CAMERA]))
        odom = Odometry()  # last: a tick paced by its stamp finds the others there
        odom.header.frame_id = "odom"
        odom.header.stamp = stamp
        odom.child_frame_id = "base_link"
        dx, dy = frame.x - sx, frame.y - sy
        odom.pose.pose.position.x = math.cos(sth) * dx + math.sin(sth) * dy
        odom.pose.pose.position.y = -math.sin(sth) * dx + math.cos(sth) * dy
        th = frame.heading_rad - sth
        odom.pose.pose.orientation.z = math.sin(th / 2)
        odom.pose.pose.orientation.w = math.cos(th / 2)
        pose.publish(odom)
        if args.lockstep:
            clock.publish(Clock(clock=stamp))

    start = time.monotonic()
    command = MotorCommand(0.0, 0.0)
    waited = 0.0
    while not stop.is_set():
        if args.lockstep:
            try:
                command = commands.get(timeout=IDLE_S)
                waited = 0.0
            except queue.Empty:
                waited += IDLE_S
                if waited < STAND_AFTER_S:
                    publish()  # still here, at the same time
                    continue
                command, waited = MotorCommand(0.0, 0.0), 0.0  # a tick standing still
            if stop.is_set():
                break
            world.apply(command)
            frame = world.step()
            ticks += 1
            for _ in range(args.rate):
                publish()
            continue
        for k in range(args.rate):
            publish()
            deadline = start + (ticks + (k + 1) / args.rate) * period
            stop.wait(max(0.0, deadline - time.monotonic()))
        while not commands.empty():
            command = commands.get_nowait()  # the latest Twist
        world.apply(command)
        frame = world.step()
        ticks += 1
    sys.stdout.write(json.dumps({"ticks": ticks, "commands": received[0]}) + "\n")
    sys.stdout.flush()
    executor.shutdown()
    spinner.join(timeout=5)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
