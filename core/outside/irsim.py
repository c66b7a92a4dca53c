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
from functools import lru_cache
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


@lru_cache(maxsize=8)
def _sectors(n: int, angle_min: float, angle_increment: float) -> tuple[slice, slice, slice]:
    """The beams of the front, left and right sectors (beams run from right to left)."""
    angles = np.degrees(angle_min + angle_increment * np.arange(n)) + 1e-9

    def span(mask: Any) -> slice:
        idx = np.flatnonzero(mask)
        return slice(int(idx[0]), int(idx[-1]) + 1) if len(idx) else slice(0, 0)

    front = span(np.abs(angles) <= FRONT_DEG + 2e-9)
    left = span((angles > FRONT_DEG + 2e-9) & (angles <= SIDE_DEG + 2e-9))
    right = span((angles < -FRONT_DEG) & (angles >= -SIDE_DEG))
    return front, left, right


def lidar_channels(ranges: Any, angle_min: float, angle_increment: float) -> list[float]:
    """The lidar's front, left and right ranges from one scan."""
    r = ranges.tolist() if isinstance(ranges, np.ndarray) else list(ranges)
    return [
        min(r[sector]) if sector.stop > sector.start else NONE
        for sector in _sectors(len(r), float(angle_min), float(angle_increment))
    ]


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
        self._robot: Any = None
        self._round: list[tuple[Any, float]] = []
        self._radius = 0.0
        self._goal = (0.0, 0.0)

    def _channels(self) -> list[float]:
        robot = self._robot
        s = robot.state
        pose = (float(s[0, 0]), float(s[1, 0]), float(s[2, 0]))
        scan = robot.get_lidar_scan()
        seen = [
            (float(o.state[0, 0]), float(o.state[1, 0]), r)
            for o, r in self._round
            if robot.fov_detect_object(o)
        ]
        return [
            *lidar_channels(scan["ranges"], scan["angle_min"], scan["angle_increment"]),
            *seen_channels(pose, seen, self._radius),
            *goal_channels(pose, self._goal),
        ]

    def reset(self, seed: int) -> list[float]:
        """A new scene drawn from `seed`."""
        env = self.env
        env.set_random_seed(seed)
        env.reset(random=True)
        self.ticks = 0
        robot = self._robot = env.robot
        self._round = [(o, float(o.radius)) for o in env.obstacle_list if o.shape == "circle"]
        self._radius = float(robot.radius)
        goal = robot.goal[:, 0]
        self._goal = (float(goal[0]), float(goal[1]))
        return self._channels()

    def step(self, action: str, wheels: MotorCommand) -> StepResult:
        """Drive at the wheel command for one step."""
        self.env.step([wheels.speed_mps, wheels.turn_rad_s])
        self.ticks += 1
        robot = self._robot
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
