"""Track geometry: the closed-loop corridor, the traffic signal and the obstacle's placement."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class SignalConfig:
    """The traffic signal: a lamp beside one straight and a stop line across it.

    Attributes:
        leg: the leg (0 bottom, 1 right, 2 top, 3 left, in lap order) that has the signal.
        stopline_fraction: where the stop line crosses that leg's straight part, 0..1.
        lamp_beyond_m: how far past the stop line the lamp stands (a far-side signal, so the
            camera still sees it from the stop zone).
        red_s: range of a red phase's duration, seconds, drawn uniformly per phase.
        green_s: range of a green phase's duration, seconds.
        yellow_s: a yellow phase's duration, seconds. The cycle is red, green, yellow, red.
        beacon: whether an infrared beacon at the stop line broadcasts the phase (the
            `beacon_phase` channel, the `beacon` logical sensor).
        beacon_range_m: how far along the lane either side of the stop line the robot's
            front receiver hears the beacon.
        beacon_period_s: the beacon repeats its message (the phase) this often; each
            episode draws when its first message goes out.
    """

    leg: int = 2
    stopline_fraction: float = 0.5
    lamp_beyond_m: float = 1.5
    red_s: tuple[float, float] = (4.0, 8.0)
    green_s: tuple[float, float] = (4.0, 8.0)
    yellow_s: float = 1.5
    beacon: bool = False
    beacon_range_m: float = 0.12
    beacon_period_s: float = 0.5


@dataclass(frozen=True, slots=True)
class ObstacleConfig:
    """The obstacle: a box placed anywhere on the track's straights each episode.

    Attributes:
        size_m: side of the square box (a carton about the robot's size).
        max_lateral_m: largest offset of its centre from the corridor's centre line; with the
            defaults a gap of at least 0.475 m stays on one side, enough for the 0.28 m robot.
        corner_margin_m: keep-out distance from the corner squares.
        start_clearance_m: keep-out distance ahead of the start pose.
        stopline_clearance_m: keep-out distance either side of the stop line.
        enabled: False removes the obstacle (useful for tests and for teaching).
        echo_range_m: how far away the sonars hear the obstacle's echo. A large, hard,
            flat box echoes like a wall, heard as far as the sonars reach; a small, soft or
            rounded one returns a weak echo that the sonars register only when near, and
            beyond this range they read whatever lies behind it.
        sight_range_m: how far away the camera recognises the obstacle, within the camera's
            own range (`RobotConfig.camera_range_m`, which also bounds the lamp's): a small,
            low-contrast object is made out nearer than a lit lamp.
    """

    size_m: float = 0.25
    max_lateral_m: float = 0.3
    corner_margin_m: float = 0.4
    start_clearance_m: float = 1.5
    stopline_clearance_m: float = 0.6
    enabled: bool = True
    echo_range_m: float = 3.0
    sight_range_m: float = 3.0


@dataclass(frozen=True, slots=True)
class TrackConfig:
    """The closed-loop track: a rectangular ring corridor the robot laps counter-clockwise.

    Defaults give a 15.2 m centre line, so a clean lap at the 0.45 m/s cruise takes about
    340 ticks of 0.1 s plus the corners and any wait at the signal.

    Attributes:
        outer_width_m: outer wall's extent along x.
        outer_height_m: outer wall's extent along y.
        corridor_width_m: distance between the outer and inner walls.
        start_along_m: start pose's distance along leg 0 from the bottom-left corner's centre.
        signal: the traffic signal.
        obstacle: the obstacle's placement.
    """

    outer_width_m: float = 6.0
    outer_height_m: float = 4.0
    corridor_width_m: float = 1.2
    start_along_m: float = 1.2
    signal: SignalConfig = field(default_factory=SignalConfig)
    obstacle: ObstacleConfig = field(default_factory=ObstacleConfig)

    def __post_init__(self) -> None:
        w = self.corridor_width_m
        if w <= 0 or self.outer_width_m <= 3 * w or self.outer_height_m <= 3 * w:
            raise ValueError("the track needs a positive corridor and straights longer than it")
        if not 0 <= self.signal.leg <= 3:
            raise ValueError("signal.leg must be 0..3")


@dataclass(frozen=True, slots=True)
class TrackGeometry:
    """Derived geometry of a `TrackConfig`, as arrays the sensing kernel reads.

    Leg i runs from `vertices[i - 1]` to `vertices[i]` (the centres of the corner squares)
    in direction `directions[i]`; `leg_start_m[i]` is the arc length at its start, measured
    along the centre line from the bottom-left corner's centre.
    """

    config: TrackConfig
    outer_box: FloatArray
    inner_box: FloatArray
    vertices: FloatArray
    directions: FloatArray
    leg_lengths_m: FloatArray
    leg_start_m: FloatArray
    lap_length_m: float
    start_pose: tuple[float, float, float]
    start_progress_m: float
    stopline_point: tuple[float, float]
    lamp_point: tuple[float, float]

    @classmethod
    def build(cls, config: TrackConfig) -> TrackGeometry:
        """Compute the arrays of a track."""
        big_w, big_h, w = config.outer_width_m, config.outer_height_m, config.corridor_width_m
        h = w / 2
        vertices = np.array(
            [[big_w - h, h], [big_w - h, big_h - h], [h, big_h - h], [h, h]], dtype=np.float64
        )
        directions = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
        lengths = np.array([big_w - w, big_h - w, big_w - w, big_h - w], dtype=np.float64)
        starts = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
        start = vertices[3] + directions[0] * config.start_along_m
        sig = config.signal
        leg_from = vertices[(sig.leg - 1) % 4]
        d = directions[sig.leg]
        straight = lengths[sig.leg] - w
        stop = leg_from + d * (h + sig.stopline_fraction * straight)
        normal_right = np.array([d[1], -d[0]])
        lamp = stop + d * sig.lamp_beyond_m + normal_right * (h - 0.05)
        return cls(
            config=config,
            outer_box=np.array([0.0, 0.0, big_w, big_h]),
            inner_box=np.array([w, w, big_w - w, big_h - w]),
            vertices=vertices,
            directions=directions,
            leg_lengths_m=lengths,
            leg_start_m=starts,
            lap_length_m=float(lengths.sum()),
            start_pose=(float(start[0]), float(start[1]), 0.0),
            start_progress_m=config.start_along_m,
            stopline_point=(float(stop[0]), float(stop[1])),
            lamp_point=(float(lamp[0]), float(lamp[1])),
        )

    def wall_segments(self) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        """The eight wall segments: the outer rectangle, then the inner one."""
        segments = []
        for box in (self.outer_box, self.inner_box):
            x0, y0, x1, y1 = (float(v) for v in box)
            corners = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
            segments += [(corners[i], corners[(i + 1) % 4]) for i in range(4)]
        return segments

    def point_on_leg(self, leg: int, along_m: float, lateral_m: float) -> tuple[float, float]:
        """The point `along_m` from leg `leg`'s start, `lateral_m` left of its centre line."""
        d = self.directions[leg]
        p = self.vertices[(leg - 1) % 4] + d * along_m + np.array([-d[1], d[0]]) * lateral_m
        return float(p[0]), float(p[1])

    def heading_of_leg(self, leg: int) -> float:
        """Direction of travel along a leg, radians."""
        d = self.directions[leg]
        return math.atan2(float(d[1]), float(d[0]))
