"""A corridor track of any shape in pymunk: `CorridorWorld`.

Also its episodes' layouts and where its obstacles are at a time; `core.sim.corridor` is
its geometry, `core.sim.world` the ring's world it builds on.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pymunk

from core.sim.corridor import CorridorConfig, CorridorGeometry, PlacedObstacle, place_obstacles
from core.sim.types import EpisodeLayout, Geometry, MotorCommand, SensorFrame, WorldConfig
from core.sim.world import (
    _OBSTACLE,
    _ROBOT,
    _WALL,
    PymunkWorld,
    _sensing_vector,
    _set_position,
    _set_velocity,
    _signal_phases,
)

__all__ = ["CorridorWorld", "corridor_layout", "corridor_legs", "obstacle_places", "obstacles_at"]


def corridor_layout(
    config: WorldConfig, geometry: CorridorGeometry, seed: int, episode: int
) -> EpisodeLayout:
    """`episode_layout` on a corridor track: every obstacle, then the lamp's cycle."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, episode, 1]))
    placed = tuple(place_obstacles(geometry, rng))
    first = placed[0] if placed else None
    return EpisodeLayout(
        obstacle_center=None if first is None else geometry.obstacle_at(first, 0.0),
        obstacle_leg=-1 if first is None else first.segment,
        signal_phases=_signal_phases(config, rng),
        obstacles=placed,
    )


def obstacle_places(
    geometry: Geometry, layout: EpisodeLayout
) -> Callable[[float], list[tuple[float, float]]]:
    """Where every obstacle of an episode is, as a function of the time into it (seconds).

    The ring's one obstacle stands; a corridor track's move as `CorridorWorld` moves them,
    so a view of a stored episode puts them where the run had them. Each obstacle's line is
    worked out once: a call costs about a microsecond an obstacle.
    """
    if not isinstance(geometry, CorridorGeometry):
        still = [] if layout.obstacle_center is None else [layout.obstacle_center]
        return lambda time_s: list(still)
    lines = []
    for p in layout.obstacles:
        bx, by = geometry.point_on_leg(p.segment, 0.0, p.lateral_m)
        dx, dy = (float(v) for v in geometry.directions[p.segment])
        lines.append((p, bx, by, dx, dy))

    def places(time_s: float) -> list[tuple[float, float]]:
        out = []
        for p, bx, by, dx, dy in lines:
            a = p.along_at(time_s)
            out.append((bx + dx * a, by + dy * a))
        return out

    return places


def obstacles_at(
    geometry: Geometry, layout: EpisodeLayout, time_s: float
) -> list[tuple[float, float]]:
    """Where every obstacle of an episode is `time_s` seconds into it (the ring: its one)."""
    return obstacle_places(geometry, layout)(time_s)


class CorridorWorld(PymunkWorld):
    """`PymunkWorld` on a corridor track of any shape (`core.sim.corridor`).

    The walls are the geometry's segments; each obstacle is a box, static where it stands
    still and kinematic where it moves (its position a function of the tick alone, so an
    episode replays exactly). Sensing is `core.sim._kernel.sense_corridor`.
    """

    def __init__(self, config: WorldConfig) -> None:
        track = config.track
        if not isinstance(track, CorridorConfig):
            raise TypeError("CorridorWorld needs a corridor track (CorridorConfig)")
        if not config.perception.exact:
            raise ValueError(
                "noisy perception is available on the rectangular ring only, not on "
                "a corridor track"
            )
        self.config = config
        geo = CorridorGeometry.build(track)
        self.geometry = self._corridor = geo
        self._build_space(geo)
        size = track.obstacle.size_m
        self._obstacle_bodies: list[pymunk.Body] = []
        for p in track.obstacles:
            kind = pymunk.Body.KINEMATIC if p.rule == "moving" else pymunk.Body.STATIC
            body = pymunk.Body(body_type=kind)
            body.position = (-100.0 - 2 * len(self._obstacle_bodies), -100.0)
            shape = pymunk.Poly.create_box(body, (size, size))
            shape.collision_type = _OBSTACLE
            self._space.add(body, shape)
            self._obstacle_bodies.append(body)
        self._space.on_collision(_ROBOT, _WALL, begin=self._on_wall)
        self._space.on_collision(_ROBOT, _OBSTACLE, begin=self._on_obstacle)
        g = _sensing_vector(config, geo)
        self._tick_state(g)
        self._legs = corridor_legs(geo)
        self._walls = np.ascontiguousarray(geo.walls)
        self._leg_state = np.array([-1.0])
        self._boxes = np.zeros((max(len(track.obstacles), 1), 4))
        self._n_obstacles = 0
        self._placed: tuple[PlacedObstacle, ...] = ()
        self._moving = False
        self._paths: list[tuple[int, PlacedObstacle, float, float, float, float]] = []
        self._half_size = track.obstacle.size_m / 2
        self._corridor_sense: Callable[..., None] | None = None
        self._perception = None

    def reset(self, seed: int, episode: int) -> SensorFrame:
        """Start episode `episode` of the run seeded `seed`; return the first frame."""
        layout = corridor_layout(self.config, self._corridor, seed, episode)
        self._layout = layout
        self._rng = np.random.default_rng(np.random.SeedSequence([seed, episode, 2]))
        self._refill_noise()
        self._reset_beacon(seed, episode)
        x, y, th = self._corridor.start_pose
        self._pose(x, y, th)
        self._tick = 0
        self._placed = layout.obstacles
        self._moving = any(p.speed_mps > 0 for p in layout.obstacles)
        self._paths = [self._path(i, p) for i, p in enumerate(layout.obstacles) if p.speed_mps > 0]
        self._move_obstacles(0.0)
        self._phase_index = 0
        self._lamp, self._phase_left = layout.signal_phases[0]
        frame = self._sense(violation=False)
        self._front_to_line = float(frame.channels[28])
        return frame

    def place(
        self, x: float, y: float, heading_rad: float, obstacle: tuple[float, float] | None
    ) -> SensorFrame:
        """Put the robot at a pose and one obstacle at a centre (None: no obstacle).

        As `PymunkWorld.place`: the episode's other obstacles are taken away.
        """
        self._pose(x, y, heading_rad)
        self._placed = ()
        self._moving = False
        for body in self._obstacle_bodies:
            body.position = (-100.0, -100.0)
            self._space.reindex_shapes_for_body(body)
        self._n_obstacles = 0
        if obstacle is not None:
            self._put_obstacle(0, obstacle)
            self._n_obstacles = 1
        frame = self._sense(violation=False)
        self._front_to_line = float(frame.channels[28])
        return frame

    def _pose(self, x: float, y: float, th: float) -> None:
        self._body.position = (x, y)
        self._body.angle = th
        self._body.velocity = (0.0, 0.0)
        self._body.angular_velocity = 0.0
        self._space.reindex_shapes_for_body(self._body)
        self._track[:] = 0.0
        self._leg_state[0] = -1.0
        self._command = MotorCommand(0.0, 0.0)
        self._hit = None

    def _put_obstacle(self, i: int, center: tuple[float, float]) -> None:
        ox, oy = center
        half = self.config.track.obstacle.size_m / 2
        self._boxes[i] = (ox - half, oy - half, ox + half, oy + half)
        if i < len(self._obstacle_bodies):
            body = self._obstacle_bodies[i]
            body.position = center
            self._space.reindex_shapes_for_body(body)

    def _path(
        self, i: int, p: PlacedObstacle
    ) -> tuple[int, PlacedObstacle, float, float, float, float]:
        """A moving obstacle's path as plain numbers, for the tick path.

        Its index, itself, where distance 0 along its segment is on its line, and the line's
        direction.
        """
        bx, by = self._corridor.point_on_leg(p.segment, 0.0, p.lateral_m)
        dx, dy = (float(v) for v in self._corridor.directions[p.segment])
        return i, p, bx, by, dx, dy

    def _move_obstacles(self, time_s: float) -> None:
        """Every obstacle where it is `time_s` into the episode, standing still."""
        for i, p in enumerate(self._placed):
            self._put_obstacle(i, self._corridor.obstacle_at(p, time_s))
            self._obstacle_bodies[i].velocity = (0.0, 0.0)
        self._n_obstacles = len(self._placed)

    def step(self) -> SensorFrame:
        """Advance one tick as `PymunkWorld.step`, the moving obstacles moving with it.

        A moving obstacle starts the step where it is at this tick, with the velocity that
        takes it to where it is at the next; the reading after the step sees it there.
        """
        if self._moving:
            dt = self._dt
            now_s = self._tick * dt
            half = self._half_size
            for i, p, bx, by, dx, dy in self._paths:
                a0 = p.along_at(now_s)
                a1 = p.along_at(now_s + dt)
                body = self._obstacle_bodies[i]
                # A kinematic body's shapes are reindexed by every step: no reindex here.
                _set_position(body, (bx + dx * a0, by + dy * a0))
                _set_velocity(body, (dx * (a1 - a0) / dt, dy * (a1 - a0) / dt))
                x1, y1 = bx + dx * a1, by + dy * a1
                self._boxes[i] = (x1 - half, y1 - half, x1 + half, y1 + half)
        return super().step()

    def obstacle_centers(self) -> list[tuple[float, float]]:
        """Where the obstacles are now (for pictures and views)."""
        return [((b[0] + b[2]) / 2, (b[1] + b[3]) / 2) for b in self._boxes[: self._n_obstacles]]

    def _read(self, x: float, y: float, th: float, noise: np.ndarray, out: np.ndarray) -> None:
        """The corridor kernel's readings at pose (x, y, th) into `out`."""
        kernel = self._corridor_sense
        if kernel is None:
            from core.sim._kernel import sense_corridor

            kernel = self._corridor_sense = sense_corridor
        kernel(
            x,
            y,
            th,
            self._g,
            self._sonar_angles,
            noise,
            self._boxes,
            self._n_obstacles,
            float(self._lamp),
            1.0 if self._hit else 0.0,
            self._track,
            self._walls,
            self._legs,
            self._leg_state,
            out,
        )


def corridor_legs(geo: CorridorGeometry) -> np.ndarray[Any, np.dtype[np.float64]]:
    """The legs as the corridor kernel reads them (`core.sim._kernel`'s LEG_ columns)."""
    n = len(geo.leg_lengths_m)
    legs = np.zeros((n, 8))
    legs[:, 0:2] = geo.starts_xy
    legs[:, 2:4] = geo.directions
    legs[:, 4] = geo.leg_lengths_m
    legs[:, 5] = geo.leg_start_m
    legs[:, 6] = geo.setbacks_m[:, 1]
    legs[:, 7] = geo.left_corner
    return legs
