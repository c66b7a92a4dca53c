"""The sensing kernel's layout: the slots of its geometry vector, its constants, its output.

Plain numpy, so a world can be built (a run created, its first checkpoint stored) without
loading numba; the kernel itself (`core.sim._kernel`) loads with the first reading.
"""

from __future__ import annotations

from typing import Any

import numpy as np

INF = 1.0e9
UNSEEN = 99.0

# Layout of the geometry vector `g` the kernel reads (built by PymunkWorld).
G_OUTER = 0  # 4: x0 y0 x1 y1
G_INNER = 4  # 4
G_SONAR_RANGE = 8
G_SONAR_MOUNT = 9
G_FOV_HALF = 10
G_CAMERA_RANGE = 11
G_CAMERA_OFFSET = 12
G_LAMP_X = 13
G_LAMP_Y = 14
G_SIGNAL_LEG = 15
G_STOPLINE_X = 16
G_STOPLINE_Y = 17
G_CORNER_TRIGGER = 18
G_HALF_LENGTH = 19
G_CORRIDOR = 20
G_TRACK_HOLD = 21
G_OBSTACLE_ECHO = 22
G_OBSTACLE_SIGHT = 23  # the camera's range for the obstacle
G_SIZE = 24


def empty_channels() -> np.ndarray[Any, np.dtype[np.float64]]:
    """A channel vector to fill."""
    return np.zeros(33, dtype=np.float64)
