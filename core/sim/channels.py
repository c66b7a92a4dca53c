"""Names and indices of the physical sensor channels a logical sensor can read."""

from enum import IntEnum


class Channel(IntEnum):
    """Index of each physical channel in a `SensorFrame.channels` array.

    Sonars are numbered like the AmigoBot's: 0 (+90 deg, left) to 5 (-90 deg, right) across
    the front, 6 and 7 at the rear. A sonar reads the distance from its mount point (on a
    circle of `RobotConfig.sonar_mount_m` around the body's centre) to the nearest surface
    along its axis (noisy); its residual is how much shorter that is than the
    map of the static walls predicts, so a large residual means "not a wall".
    """

    SONAR_0 = 0
    SONAR_1 = 1
    SONAR_2 = 2
    SONAR_3 = 3
    SONAR_4 = 4
    SONAR_5 = 5
    SONAR_6 = 6
    SONAR_7 = 7
    SONAR_0_RESIDUAL = 8
    SONAR_1_RESIDUAL = 9
    SONAR_2_RESIDUAL = 10
    SONAR_3_RESIDUAL = 11
    SONAR_4_RESIDUAL = 12
    SONAR_5_RESIDUAL = 13
    SONAR_6_RESIDUAL = 14
    SONAR_7_RESIDUAL = 15
    LATERAL_OFFSET_M = 16
    """Odometry on the map: signed distance from the corridor's centre line, + = left."""
    HEADING_ERROR_RAD = 17
    """Heading minus the corridor direction, + = pointing left of it."""
    VERTEX_AHEAD_M = 18
    """Distance along the current leg to the next corner's centre."""
    CORNER_PENDING = 19
    """1 while the robot is in a corner zone and has not yet turned into the next leg."""
    OBSTACLE_VISIBLE = 20
    """Camera: 1 while the obstacle is in view. Distance, lateral and offset are also given
    for a while after it leaves the view, from its tracked position on the map."""
    OBSTACLE_DISTANCE_M = 21
    """Camera: range to the obstacle, or 99 when it is not seen."""
    OBSTACLE_LATERAL_M = 22
    """Camera + odometry: the obstacle's offset across the corridor from the robot, + = left
    (so |value| < clearance means it is in the robot's path); 99 unseen."""
    LAMP_COLOR = 23
    """Camera: 0 lamp not seen, 1 red, 2 yellow, 3 green."""
    STOPLINE_AHEAD_M = 24
    """Distance from the robot's centre to the stop line ahead, or 99."""
    BUMPER = 25
    """1 when the bumper touched something during the last step."""
    LEG = 26
    PROGRESS_M = 27
    """Arc length of the robot's projection on the track's centre line, from the start."""
    FRONT_TO_STOPLINE_M = 28
    """Signed distance from the robot's front to the stop line, or 99 off the signal leg."""
    OBSTACLE_OFFSET_M = 29
    """Camera + odometry: the obstacle's offset from the corridor's centre line, + = left."""
    HEADING_RAD = 30
    """Odometry: the robot's heading in the map frame."""
    OBSTACLE_IMAGE_X = 31
    """Camera: where the obstacle's centre appears across the image, from -1 (right edge)
    to +1 (left edge): its bearing off the camera's axis over half the field of view;
    99 while it is not in view."""
    BEACON_PHASE = 32
    """The stop line's beacon (a world with `track.signal.beacon`): the signal's phase, 1
    red, 2 yellow, 3 green, in the last message the front receiver heard while within
    `beacon_range_m` of the line (the beacon repeats it every `beacon_period_s`); 0 out of
    its range, before its first message there, and in a world without a beacon."""


CHANNELS: tuple[str, ...] = tuple(c.name.lower() for c in Channel)
"""Channel names as logical-sensor data files spell them."""
