"""The AmigoBot's body and sensors, as parameters."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class RobotConfig:
    """An AmigoBot: differential drive, eight sonars, a forward camera and a bumper.

    Attributes:
        length_m: body length (the AmigoBot is about 0.33 m x 0.28 m).
        width_m: body width.
        mass_kg: body mass.
        max_speed_mps: top wheel speed; commands are clipped to it.
        max_turn_dps: top turning rate, degrees per second.
        sonar_angles_deg: sonar axes relative to the heading, + = left: six fanned across the
            front from +90 to -90 degrees and two at the rear, as on the AmigoBot.
        sonar_mount_m: distance of the sonars from the body's centre (they read from there).
        sonar_range_m: maximum sonar range; farther readings saturate at it.
        sonar_noise_m: standard deviation of the additive Gaussian sonar noise.
        camera_fov_deg: the forward camera's horizontal field of view.
        camera_range_m: how far the camera recognises the lamp and the obstacle.
        camera_offset_m: camera position ahead of the body's centre.
        camera_track_ticks: how long the obstacle logical sensor keeps tracking an obstacle on
            the map after it leaves the camera's view (while it is still ahead).
        align_gain: heading-hold gain of the forward behaviours, 1/s.
        cruise_speed_mps: the speed the robot cruises at when nothing else is released: its
            keep-moving default behaviour's (goforward3, 0.45 m/s in behaviours.toml). Every
            forward primitive's speed is scaled by the same factor (goforward1..5 at 1/3 to
            5/3 of it), up to `max_speed_mps`; turns keep their speeds.
    """

    length_m: float = 0.33
    width_m: float = 0.28
    mass_kg: float = 3.6
    max_speed_mps: float = 0.75
    max_turn_dps: float = 150.0
    sonar_angles_deg: tuple[float, ...] = (90.0, 44.0, 12.0, -12.0, -44.0, -90.0, -160.0, 160.0)
    sonar_mount_m: float = 0.14
    sonar_range_m: float = 3.0
    sonar_noise_m: float = 0.01
    camera_fov_deg: float = 50.0
    camera_range_m: float = 3.0
    camera_offset_m: float = 0.12
    camera_track_ticks: int = 30
    align_gain: float = 2.0
    cruise_speed_mps: float = 0.45

    def __post_init__(self) -> None:
        if len(self.sonar_angles_deg) != 8:
            raise ValueError("the AmigoBot has eight sonars")
        if min(self.length_m, self.width_m, self.mass_kg, self.max_speed_mps) <= 0:
            raise ValueError("body dimensions, mass and top speed must be positive")
        if not 0 < self.cruise_speed_mps <= self.max_speed_mps:
            raise ValueError("cruise_speed_mps must be positive and at most max_speed_mps")

    @property
    def max_turn_rad_s(self) -> float:
        """Top turning rate in radians per second."""
        return math.radians(self.max_turn_dps)
