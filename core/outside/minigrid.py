"""MiniGrid's Dynamic-Obstacles as named channels: the channels mapping of ``minigrid-dynamic``.

The agent sees a 7x7 egocentric view (``obs["image"]``, indexed ``[x, y]``): it stands at
(3, 6) facing towards y = 0, so the cell ahead is (3, 5), the one on its left (2, 6).
Balls move one cell at random every step; stepping forward into a ball (or a wall) that is
in the cell ahead ends the episode with a reward of -1, reaching the goal with
``1 - 0.9 * steps / max_steps``.

Channels (cells counted on the view's grid; 99 when nothing is seen):

- ``front_ball``, ``front_wall``: 1 when the cell ahead holds a ball / a wall (the
  adjacent-cell reflex's channels);
- ``left_free``, ``right_free``: 1 when the cell on that side is empty (or the goal);
- ``ball_ahead_cells``: rows ahead of the nearest ball in the agent's own column (1 is the
  cell ahead);
- ``ball_left_cells``, ``ball_right_cells``: rows ahead of the nearest ball in the column
  just left / right of the agent's (1 is diagonally ahead);
- ``goal_visible``, ``goal_ahead_cells`` (rows ahead, 0 its own row), ``goal_side_cells``
  (columns, + = left).

Actions: ``left``, ``right``, ``forward`` (MiniGrid's 0, 1, 2).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt

from core.outside.world import StepResult
from core.sim.types import MotorCommand

CHANNELS: tuple[str, ...] = (
    "front_ball",
    "front_wall",
    "left_free",
    "right_free",
    "ball_ahead_cells",
    "ball_left_cells",
    "ball_right_cells",
    "goal_visible",
    "goal_ahead_cells",
    "goal_side_cells",
)
ACTIONS: tuple[str, ...] = ("left", "right", "forward")
EMPTY, WALL, BALL, GOAL = 1, 2, 6, 8
"""MiniGrid's object indices (``minigrid.core.constants.OBJECT_TO_IDX``)."""
AGENT_X, AGENT_Y = 3, 6
NONE = 99.0


def _nearest_ahead(kinds: npt.NDArray[Any], column: int, start: int) -> float:
    """Rows ahead of the nearest ball in `column`, from `start` rows ahead on (99: none)."""
    for k in range(start, AGENT_Y + 1):
        if kinds[column, AGENT_Y - k] == BALL:
            return float(k)
    return NONE


def channels_of(image: npt.NDArray[Any]) -> list[float]:
    """The channels of one observation's 7x7x3 image."""
    kinds = np.asarray(image)[:, :, 0]
    ahead = int(kinds[AGENT_X, AGENT_Y - 1])
    left = int(kinds[AGENT_X - 1, AGENT_Y])
    right = int(kinds[AGENT_X + 1, AGENT_Y])
    goal = np.argwhere(kinds == GOAL)
    if len(goal):
        gx, gy = goal[0]
        goal_ch = [1.0, float(AGENT_Y - gy), float(AGENT_X - gx)]
    else:
        goal_ch = [0.0, NONE, NONE]
    return [
        float(ahead == BALL),
        float(ahead == WALL),
        float(left in (EMPTY, GOAL)),
        float(right in (EMPTY, GOAL)),
        _nearest_ahead(kinds, AGENT_X, 1),
        _nearest_ahead(kinds, AGENT_X - 1, 1),
        _nearest_ahead(kinds, AGENT_X + 1, 1),
        *goal_ch,
    ]


class DynamicObstacles:
    """The Gymnasium environment behind the channels mapping."""

    def __init__(self, options: Mapping[str, Any]) -> None:
        import gymnasium as gym
        import minigrid  # noqa: F401  (registers MiniGrid's environments)

        kwargs = {k: v for k, v in options.items() if k not in ("env", "folder")}
        self.env = gym.make(str(options.get("env", "MiniGrid-Dynamic-Obstacles-8x8-v0")), **kwargs)

    def reset(self, seed: int) -> list[float]:
        """Start an episode from `seed`."""
        obs, _ = self.env.reset(seed=seed)
        return channels_of(obs["image"])

    def step(self, action: str, wheels: MotorCommand) -> StepResult:
        """Run one of `ACTIONS`."""
        obs, reward, terminated, truncated, _ = self.env.step(ACTIONS.index(action))
        r = float(reward)
        outcome = None
        if terminated:
            outcome = "success" if r > 0.0 else "collision"
        elif truncated:
            outcome = "timeout"
        return StepResult(channels_of(obs["image"]), r, outcome)

    def close(self) -> None:
        """Close the environment."""
        self.env.close()


def make(options: Mapping[str, Any]) -> DynamicObstacles:
    """The environment with `options` (``env``, the Gymnasium id, and its keyword arguments)."""
    return DynamicObstacles(options)
