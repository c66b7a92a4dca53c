"""A top-down picture of a track of any shape, drawn with numpy alone (Gymnasium's `rgb_array`).

Pure: a frame is a function of the geometry and one pose, so recording a video of an
episode (`gymnasium.wrappers.RecordVideo`) changes nothing in the run.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from core.sim.corridor import CorridorGeometry
from core.sim.types import Geometry
from core.sim.world import LampColor, WorldConfig

Frame = npt.NDArray[np.uint8]

PX_PER_M = 64
"""Resolution: the default 6 x 4 m track is a 384 x 256 frame (multiples of 16, which video
encoders like)."""

_FLOOR = (214, 214, 208)
_OUTSIDE = (120, 120, 120)
_ISLAND = (90, 96, 90)
_WALL = (20, 20, 20)
_OBSTACLE = (150, 95, 40)
_ROBOT = (200, 30, 30)
_HEADING = (255, 255, 255)
_STOPLINE = (250, 250, 250)
_LAMP = {
    LampColor.NONE: (60, 60, 60),
    LampColor.RED: (230, 20, 20),
    LampColor.YELLOW: (240, 200, 20),
    LampColor.GREEN: (20, 190, 60),
}


class TopDown:
    """Draws frames of one track; the static part is drawn once."""

    def __init__(self, geometry: Geometry, config: WorldConfig) -> None:
        self.geometry = geometry
        self.config = config
        x0, y0, x1, y1 = (float(v) for v in geometry.outer_box)
        self._origin = (x0, y0)
        self.width = round((x1 - x0) * PX_PER_M)
        self.height = round((y1 - y0) * PX_PER_M)
        base = np.empty((self.height, self.width, 3), dtype=np.uint8)
        base[:] = _OUTSIDE
        if isinstance(geometry, CorridorGeometry):
            self._fill_corridor(base, geometry)
        else:
            self._fill_box(base, geometry.outer_box, _FLOOR)
            self._fill_box(base, geometry.inner_box, _ISLAND)
        for a, b in geometry.wall_segments():
            self._line(base, a, b, 0.03, _WALL)
        self._stop_line(base)
        self._base = base

    def _px(self, x: float, y: float) -> tuple[float, float]:
        """Pixel coordinates (column, row) of a point on the map; rows grow downwards."""
        return (x - self._origin[0]) * PX_PER_M, self.height - (y - self._origin[1]) * PX_PER_M

    def _fill_box(self, img: Frame, box: npt.ArrayLike, color: tuple[int, int, int]) -> None:
        x0, y0, x1, y1 = (float(v) for v in np.asarray(box))
        c0, r1 = self._px(x0, y0)
        c1, r0 = self._px(x1, y1)
        img[max(0, round(r0)) : max(0, round(r1)), max(0, round(c0)) : max(0, round(c1))] = color

    def _fill_corridor(self, img: Frame, geo: CorridorGeometry) -> None:
        """The floor of a corridor track: each segment's corridor, out to its corners."""
        rows, cols = np.ogrid[: self.height, : self.width]
        x = self._origin[0] + (cols + 0.5) / PX_PER_M
        y = self._origin[1] + (self.height - rows - 0.5) / PX_PER_M
        floor = np.zeros((self.height, self.width), dtype=bool)
        for k in range(len(geo.leg_lengths_m)):
            (sx, sy), (dx, dy) = geo.starts_xy[k], geo.directions[k]
            half = float(geo.widths_m[k]) / 2
            along = (x - sx) * dx + (y - sy) * dy
            lateral = -(x - sx) * dy + (y - sy) * dx
            reach = geo.setbacks_m[k]
            floor |= (
                (np.abs(lateral) <= half)
                & (along >= -reach[0])
                & (along <= geo.leg_lengths_m[k] + reach[1])
            )
        img[floor] = _FLOOR

    def _disc(
        self, img: Frame, x: float, y: float, radius_m: float, color: tuple[int, int, int]
    ) -> None:
        c, r = self._px(x, y)
        rad = radius_m * PX_PER_M
        rows, cols = np.ogrid[: self.height, : self.width]
        img[(rows - r) ** 2 + (cols - c) ** 2 <= rad * rad] = color

    def _line(
        self,
        img: Frame,
        a: tuple[float, float],
        b: tuple[float, float],
        width_m: float,
        color: tuple[int, int, int],
    ) -> None:
        (ca, ra), (cb, rb) = self._px(*a), self._px(*b)
        rows, cols = np.ogrid[: self.height, : self.width]
        dc, dr = cb - ca, rb - ra
        length2 = dc * dc + dr * dr
        t = np.clip(((cols - ca) * dc + (rows - ra) * dr) / length2, 0.0, 1.0) if length2 else 0.0
        dist2 = (cols - (ca + t * dc)) ** 2 + (rows - (ra + t * dr)) ** 2
        half = max(0.5, width_m * PX_PER_M / 2)
        img[dist2 <= half * half] = color

    def _stop_line(self, img: Frame) -> None:
        geo = self.geometry
        leg = self.config.track.signal.leg
        d = geo.directions[leg]
        normal = np.array([-d[1], d[0]])
        half = self.config.track.corridor_width_m / 2
        if isinstance(geo, CorridorGeometry):
            half = float(geo.widths_m[leg]) / 2
        sx, sy = geo.stopline_point
        a = (sx + normal[0] * half, sy + normal[1] * half)
        b = (sx - normal[0] * half, sy - normal[1] * half)
        self._line(img, a, b, 0.04, _STOPLINE)

    def draw(
        self,
        pose: tuple[float, float, float],
        obstacle: tuple[float, float] | None,
        lamp: LampColor,
        more: Sequence[tuple[float, float]] = (),
    ) -> Frame:
        """A frame: the track, the lamp in its colour, the obstacles and the robot."""
        img = self._base.copy()
        lx, ly = self.geometry.lamp_point
        self._disc(img, lx, ly, 0.12, _LAMP[lamp])
        half = self.config.track.obstacle.size_m / 2
        for ox, oy in [*([obstacle] if obstacle is not None else []), *more]:
            self._fill_box(img, (ox - half, oy - half, ox + half, oy + half), _OBSTACLE)
        x, y, th = pose
        robot = self.config.robot
        self._disc(img, x, y, max(robot.length_m, robot.width_m) / 2, _ROBOT)
        tip = (x + math.cos(th) * robot.length_m / 2, y + math.sin(th) * robot.length_m / 2)
        self._line(img, (x, y), tip, 0.04, _HEADING)
        return img
