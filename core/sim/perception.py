"""Noisy perception: the camera's range and bearing errors, missed detections, odometry drift.

By default the world senses exactly: every stimulus comes from the true pose and the true
obstacle position (the sonars alone are noisy, `RobotConfig.sonar_noise_m`). With any of
`PerceptionConfig`'s settings above 0, `NoisyPerception` turns the exact channels of each
tick into estimates, and every logical sensor (stimulus) is computed from those:

- a **detection** (the camera sees the obstacle this tick) is **missed** with probability
  `camera_miss_rate`: the obstacle is not in view that tick, and its range, lateral and
  offset are what the last detection still tells (for the camera's tracking time), or
  unknown when there was none;
- a detection's **range** is off by a normal error (`camera_range_sd_m`) and its
  **bearing** by another (`camera_bearing_sd_deg`): the obstacle's place in the image
  moves by the bearing error, and its place across the corridor (lateral and offset) by
  the range times the bearing error, the cross-range error of a bearing. Between
  detections the last detection's errors stay with the tracked estimate;
- the robot's own **lateral position** on the map drifts as a random walk with distance
  travelled (`odometry_drift_m`: the standard deviation after 1 m), which moves its
  lateral offset in the corridor and the obstacle's offset, both read on the map through
  it (the obstacle's lateral from the robot is the camera's, and does not drift), and
  the sonars' **residuals**: what the map of the static walls predicts each sonar reads
  is predicted from where the robot believes it is, so a wall read from a drifted pose
  leaves a residual (a phantom obstacle, or a wall taken for none). Only the lateral
  position drifts: the heading and the progress along the track stay exact.

The draws come from a generator of their own per seed and episode, so noise on leaves
every other random stream (layout, lamp, sonar noise, exploration) as it was, and the same
seed and episode give the same noise. All settings at 0 skip this module entirely: the
world is then bit for bit the exact one.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from core.sim.channels import Channel
from core.sim.sensing import G_FOV_HALF, UNSEEN

_VISIBLE = int(Channel.OBSTACLE_VISIBLE)
_DISTANCE = int(Channel.OBSTACLE_DISTANCE_M)
_LATERAL = int(Channel.OBSTACLE_LATERAL_M)
_OFFSET = int(Channel.OBSTACLE_OFFSET_M)
_IMAGE_X = int(Channel.OBSTACLE_IMAGE_X)
_ROBOT_LATERAL = int(Channel.LATERAL_OFFSET_M)
_HEADING = int(Channel.HEADING_RAD)
_HEADING_ERROR = int(Channel.HEADING_ERROR_RAD)


@dataclass(frozen=True, slots=True)
class PerceptionConfig:
    """How far the robot's estimates are from the truth (all 0: exact, the default).

    Attributes:
        camera_range_sd_m: standard deviation of a detection's range error, metres.
        camera_bearing_sd_deg: standard deviation of a detection's bearing error, degrees.
        camera_miss_rate: probability that a tick's detection of the obstacle is missed.
        odometry_drift_m: standard deviation of the robot's lateral position error after
            1 m travelled (a random walk: it grows with the square root of the distance).
    """

    camera_range_sd_m: float = 0.0
    camera_bearing_sd_deg: float = 0.0
    camera_miss_rate: float = 0.0
    odometry_drift_m: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"perception.{f.name} must be 0 or more, got {value!r}")
        if self.camera_miss_rate > 1:
            rate = self.camera_miss_rate
            raise ValueError(f"perception.camera_miss_rate is a probability (0 to 1), got {rate!r}")

    @property
    def exact(self) -> bool:
        """Whether the robot perceives exactly (every setting 0)."""
        return not any(getattr(self, f.name) for f in fields(self))


class NoisyPerception:
    """Turns each tick's exact channels into the robot's estimates (`PerceptionConfig`).

    `g` and `sonar_angles` are the sensing kernel's geometry and sonar axes
    (`core.sim.sensing`), from which the map's prediction of each sonar is recomputed at the
    drifted pose.
    """

    def __init__(
        self,
        config: PerceptionConfig,
        g: np.ndarray[Any, np.dtype[np.float64]],
        sonar_angles: np.ndarray[Any, np.dtype[np.float64]],
        track_ticks: float,
    ) -> None:
        self.config = config
        self._g = g
        self._sonar_angles = sonar_angles
        self._residuals_at: Callable[..., None] | None = None
        self._bearing_to_image = 1.0 / float(g[G_FOV_HALF])
        self._track_ticks = track_ticks
        self._rng = np.random.default_rng(0)
        self._reset_state()

    def _reset_state(self) -> None:
        self._drift = 0.0
        self._last: tuple[float, float] | None = None
        # The last accepted detection's errors, and the ticks since it (None: none yet).
        self._range_error = 0.0
        self._bearing_error = 0.0
        self._since: float | None = None

    def reset(self, seed: int, episode: int) -> None:
        """Start an episode: its own noise stream, no drift, nothing detected yet."""
        self._rng = np.random.default_rng(np.random.SeedSequence([seed, episode, 3]))
        self._reset_state()

    def relocate(self) -> None:
        """The robot was put somewhere: no travel to drift over, the camera's track afresh."""
        self._last = None
        self._since = None

    def apply(self, out: np.ndarray[Any, np.dtype[np.float64]], x: float, y: float) -> None:
        """Make this tick's exact channels `out` the robot's estimates, in place."""
        cfg = self.config
        rng = self._rng
        if cfg.odometry_drift_m > 0.0:
            if self._last is not None:
                travelled = math.hypot(x - self._last[0], y - self._last[1])
                if travelled > 0.0:
                    self._drift += float(
                        rng.normal(0.0, cfg.odometry_drift_m * math.sqrt(travelled))
                    )
            self._last = (x, y)
            out[_ROBOT_LATERAL] += self._drift
            if self._drift != 0.0:
                self._residuals_from_estimate(out, x, y)
        if out[_VISIBLE] > 0.0:
            if cfg.camera_miss_rate > 0.0 and rng.random() < cfg.camera_miss_rate:
                out[_VISIBLE] = 0.0
                out[_IMAGE_X] = UNSEEN
                if self._since is not None:
                    self._since += 1
            else:
                self._range_error = float(rng.normal(0.0, cfg.camera_range_sd_m))
                self._bearing_error = math.radians(
                    float(rng.normal(0.0, cfg.camera_bearing_sd_deg))
                )
                self._since = 0.0
                out[_IMAGE_X] += self._bearing_error * self._bearing_to_image
        elif self._since is not None:
            self._since += 1
        if out[_DISTANCE] >= UNSEEN:
            return
        if self._since is None or self._since > self._track_ticks:
            # Tracked only from detections this module missed: nothing is known.
            out[_DISTANCE] = out[_LATERAL] = out[_OFFSET] = UNSEEN
            return
        distance = out[_DISTANCE]
        cross = distance * self._bearing_error
        out[_DISTANCE] = max(0.0, distance + self._range_error)
        out[_LATERAL] += cross
        out[_OFFSET] += cross + self._drift

    def _residuals_from_estimate(
        self, out: np.ndarray[Any, np.dtype[np.float64]], x: float, y: float
    ) -> None:
        """Each sonar's residual against the map as seen from the drifted pose, in place."""
        if self._residuals_at is None:
            from core.sim._kernel import residuals_at  # numba: loaded with the first reading

            self._residuals_at = residuals_at
        heading = float(out[_HEADING])
        # The corridor's direction (the leg the lateral offset is measured across); the
        # drift moves the believed position along its left normal, as the offset is + left.
        corridor = heading - float(out[_HEADING_ERROR])
        believed_x = x - self._drift * math.sin(corridor)
        believed_y = y + self._drift * math.cos(corridor)
        self._residuals_at(believed_x, believed_y, heading, self._g, self._sonar_angles, out)
