"""ir-sim's differential-drive robot as named channels: the channels mapping of ``irsim-corridor``.

The world is ir-sim's own YAML file (``world`` in the options, beside world.toml): a robot
with a 2D lidar over the half-plane ahead and a field of view (`fov`, `fov_radius`), round
obstacles placed at random, walls, a goal. The brain's wheel command (forward speed, turn
rate) is the robot's action; an episode ends at the goal (success), on a collision, or
after `max_ticks` (timeout).

Channels (metres and degrees, + = left; 99 when nothing is seen):

- ``lidar_front_m``, ``lidar_left_m``, ``lidar_right_m``: the shortest lidar range within
  20 degrees of straight ahead, and between 20 and 60 degrees to each side (the low-level
  sensor: anything close, a wall or an obstacle);
- ``fov_obstacle_m``, ``fov_obstacle_deg``: the gap to the nearest round obstacle inside the
  field of view, and its bearing (the high-level detector: obstacles only, farther away);
- ``goal_distance_m``, ``goal_deg``: where the goal is.
"""

from __future__ import annotations

import contextlib
import io
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from core.outside.world import StepResult
from core.sim.types import MotorCommand

CHANNELS: tuple[str, ...] = (
    "lidar_front_m",
    "lidar_left_m",
    "lidar_right_m",
    "fov_obstacle_m",
    "fov_obstacle_deg",
    "goal_distance_m",
    "goal_deg",
)
ACTIONS: tuple[str, ...] = ()
"""Driven by wheel commands: a behaviour's speed and turn rate are the action."""
NONE = 99.0
FRONT_DEG, SIDE_DEG = 20.0, 60.0


def _wrap_deg(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


def lidar_channels(ranges: Any, angle_min: float, angle_increment: float) -> list[float]:
    """The lidar's front, left and right ranges from one scan."""
    r = np.asarray(ranges, dtype=np.float64)
    angles = np.degrees(angle_min + angle_increment * np.arange(len(r)))
    front = r[np.abs(angles) <= FRONT_DEG]
    left = r[(angles > FRONT_DEG) & (angles <= SIDE_DEG)]
    right = r[(angles < -FRONT_DEG) & (angles >= -SIDE_DEG)]
    return [float(x.min()) if len(x) else NONE for x in (front, left, right)]


def seen_channels(
    pose: tuple[float, float, float], seen: list[tuple[float, float, float]], robot_radius: float
) -> list[float]:
    """The nearest seen obstacle's gap and bearing: `seen` holds (x, y, radius) each."""
    x, y, th = pose
    best = (NONE, NONE)
    for ox, oy, r in seen:
        gap = math.hypot(ox - x, oy - y) - r - robot_radius
        if gap < best[0]:
            bearing = _wrap_deg(math.degrees(math.atan2(oy - y, ox - x) - th))
            best = (gap, bearing)
    return list(best)


def goal_channels(pose: tuple[float, float, float], goal: tuple[float, float]) -> list[float]:
    """The goal's distance and bearing from the robot's pose."""
    x, y, th = pose
    d = math.hypot(goal[0] - x, goal[1] - y)
    return [d, _wrap_deg(math.degrees(math.atan2(goal[1] - y, goal[0] - x) - th))]


class Corridor:
    """An ir-sim environment behind the channels mapping."""

    def __init__(self, options: Mapping[str, Any]) -> None:
        with contextlib.redirect_stdout(io.StringIO()):  # it reports its plot backend
            import irsim
        world = Path(str(options.get("folder", "."))) / str(options.get("world", "world.yaml"))
        self.max_ticks = int(options.get("max_ticks", 300))
        self.env = irsim.make(str(world), display=False, headless=True, log_level="ERROR")
        self.ticks = 0

    def _channels(self) -> list[float]:
        env = self.env
        robot = env.robot
        s = robot.state[:, 0]
        pose = (float(s[0]), float(s[1]), float(s[2]))
        scan = env.get_lidar_scan()
        seen = [
            (float(o.state[0, 0]), float(o.state[1, 0]), float(o.radius))
            for o in env.obstacle_list
            if o.shape == "circle" and robot.fov_detect_object(o)
        ]
        goal = robot.goal[:, 0]
        return [
            *lidar_channels(scan["ranges"], scan["angle_min"], scan["angle_increment"]),
            *seen_channels(pose, seen, float(robot.radius)),
            *goal_channels(pose, (float(goal[0]), float(goal[1]))),
        ]

    def reset(self, seed: int) -> list[float]:
        """A new scene drawn from `seed`."""
        self.env.set_random_seed(seed)
        self.env.reset(random=True)
        self.ticks = 0
        return self._channels()

    def step(self, action: str, wheels: MotorCommand) -> StepResult:
        """Drive at the wheel command for one step."""
        self.env.step([wheels.speed_mps, wheels.turn_rad_s])
        self.ticks += 1
        robot = self.env.robot
        outcome = None
        if robot.collision:
            outcome = "collision"
        elif robot.arrive:
            outcome = "success"
        elif self.ticks >= self.max_ticks:
            outcome = "timeout"
        return StepResult(self._channels(), 1.0 if outcome == "success" else 0.0, outcome)

    def close(self) -> None:
        """Close the environment."""
        with contextlib.redirect_stdout(io.StringIO()):
            self.env.end(0)


def make(options: Mapping[str, Any]) -> Corridor:
    """The environment with `options` (``world``: ir-sim's YAML file; ``max_ticks``)."""
    return Corridor(options)
