"""The pymunk world: track walls, the AmigoBot, the traffic signal and the obstacle."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, cast

import numpy as np
import pymunk

from core.sim import sensing
from core.sim.channels import Channel
from core.sim.perception import NoisyPerception
from core.sim.track import TrackConfig, TrackGeometry
from core.sim.types import (
    CollisionKind,
    EpisodeLayout,
    Geometry,
    LampColor,
    MotorCommand,
    SensorFrame,
    World,
    WorldConfig,
)

__all__ = [
    "CollisionKind",
    "EpisodeLayout",
    "LampColor",
    "MotorCommand",
    "PymunkWorld",
    "SensorFrame",
    "World",
    "WorldConfig",
    "episode_layout",
    "make_world",
]
"""The world's plain types live in `core.sim.types`; they are re-exported here."""

_ROBOT, _WALL, _OBSTACLE = 1, 2, 3
_BEACON_PHASE = int(Channel.BEACON_PHASE)
_FRONT_TO_LINE = int(Channel.FRONT_TO_STOPLINE_M)


def episode_layout(
    config: WorldConfig, geometry: Geometry, seed: int, episode: int
) -> EpisodeLayout:
    """Draw an episode's obstacle and lamp cycle from (seed, episode) alone.

    Every condition of an experiment meets the same obstacles and lamp cycles for the same
    seed and episode, whatever happened in earlier episodes (common random numbers).
    """
    if not isinstance(geometry, TrackGeometry):  # a corridor track's: every obstacle
        from core.sim.corridor_world import corridor_layout

        return corridor_layout(config, geometry, seed, episode)
    assert isinstance(config.track, TrackConfig)
    rng = np.random.default_rng(np.random.SeedSequence([seed, episode, 1]))
    track = config.track
    obs = track.obstacle
    half = track.corridor_width_m / 2
    center: tuple[float, float] | None = None
    leg_chosen = -1
    if obs.enabled:
        straights = [
            (
                leg,
                half + obs.corner_margin_m,
                float(geometry.leg_lengths_m[leg]) - half - obs.corner_margin_m,
            )
            for leg in range(4)
        ]
        total = sum(max(hi - lo, 0.0) for _, lo, hi in straights)
        stop_leg = track.signal.leg
        stop_along = _along(geometry, stop_leg, geometry.stopline_point)
        for _ in range(1000):
            leg, along = _pick_on_straights(straights, rng.random() * total)
            lateral = (rng.random() * 2 - 1) * obs.max_lateral_m
            if leg == 0 and -0.3 <= along - track.start_along_m <= obs.start_clearance_m:
                continue
            if leg == stop_leg and abs(along - stop_along) < obs.stopline_clearance_m:
                continue
            center = geometry.point_on_leg(leg, along, lateral)
            leg_chosen = leg
            break
        else:  # pragma: no cover - the keep-outs never cover the whole track
            raise RuntimeError("no place for the obstacle")
    phases = _signal_phases(config, rng)
    return EpisodeLayout(
        obstacle_center=center,
        obstacle_leg=leg_chosen,
        signal_phases=phases,
    )


def _signal_phases(
    config: WorldConfig, rng: np.random.Generator
) -> tuple[tuple[LampColor, int], ...]:
    """An episode's lamp cycle, drawn from `rng` after the obstacles."""
    sig = config.track.signal
    per_s = 1.0 / config.dt_s
    n = 64
    reds = np.maximum(1, np.rint(rng.uniform(*sig.red_s, n) * per_s)).astype(int).tolist()
    greens = np.maximum(1, np.rint(rng.uniform(*sig.green_s, n) * per_s)).astype(int).tolist()
    yellow = max(1, round(sig.yellow_s * per_s))
    phases: list[tuple[LampColor, int]] = []
    for red, green in zip(reds, greens, strict=True):
        phases += [(LampColor.RED, red), (LampColor.GREEN, green), (LampColor.YELLOW, yellow)]
    shift = int(rng.integers(len(phases) // 2))
    return tuple(phases[shift:] + phases[:shift])


def _pick_on_straights(straights: list[tuple[int, float, float]], u: float) -> tuple[int, float]:
    """The (leg, along) at distance `u` along the concatenated straights."""
    for leg, lo, hi in straights:
        span = max(hi - lo, 0.0)
        if u <= span:
            return leg, lo + u
        u -= span
    leg, lo, hi = straights[-1]
    return leg, hi


def _along(geometry: TrackGeometry, leg: int, point: tuple[float, float]) -> float:
    start = geometry.vertices[(leg - 1) % 4]
    return float(np.dot(np.asarray(point) - start, geometry.directions[leg]))


# pymunk's Body properties, called directly on the tick path: the same C calls without
# pymunk's attribute-checking `__setattr__` frame (a few microseconds a tick).
def _body_property(name: str) -> property:
    found = vars(pymunk.Body)[name]
    assert isinstance(found, property)
    return found


_get_angle = cast(Callable[[pymunk.Body], float], _body_property("angle").fget)
_get_position = cast(Callable[[pymunk.Body], pymunk.Vec2d], _body_property("position").fget)
_set_position = cast(
    Callable[[pymunk.Body, tuple[float, float]], None], _body_property("position").fset
)
_set_velocity = cast(
    Callable[[pymunk.Body, tuple[float, float]], None], _body_property("velocity").fset
)
_set_angular_velocity = cast(
    Callable[[pymunk.Body, float], None], _body_property("angular_velocity").fset
)


def _sensing_vector(config: WorldConfig, geo: Geometry) -> np.ndarray[Any, np.dtype[np.float64]]:
    """The geometry vector the sensing kernels read (`core.sim.sensing`'s G_ slots)."""
    robot = config.robot
    track = config.track
    g = np.zeros(sensing.G_SIZE)
    g[sensing.G_OUTER : sensing.G_OUTER + 4] = geo.outer_box
    g[sensing.G_INNER : sensing.G_INNER + 4] = geo.inner_box
    g[sensing.G_SONAR_RANGE] = robot.sonar_range_m
    g[sensing.G_SONAR_MOUNT] = robot.sonar_mount_m
    g[sensing.G_FOV_HALF] = math.radians(robot.camera_fov_deg / 2)
    g[sensing.G_CAMERA_RANGE] = robot.camera_range_m
    g[sensing.G_CAMERA_OFFSET] = robot.camera_offset_m
    g[sensing.G_LAMP_X], g[sensing.G_LAMP_Y] = geo.lamp_point
    g[sensing.G_SIGNAL_LEG] = track.signal.leg
    g[sensing.G_STOPLINE_X], g[sensing.G_STOPLINE_Y] = geo.stopline_point
    g[sensing.G_CORNER_TRIGGER] = 0.1
    g[sensing.G_HALF_LENGTH] = robot.length_m / 2
    g[sensing.G_CORRIDOR] = track.corridor_width_m
    g[sensing.G_TRACK_HOLD] = robot.camera_track_ticks
    g[sensing.G_OBSTACLE_ECHO] = track.obstacle.echo_range_m
    g[sensing.G_OBSTACLE_SIGHT] = min(robot.camera_range_m, track.obstacle.sight_range_m)
    return g


class PymunkWorld:
    """The world simulated with pymunk: rigid body contacts, analytic sensing.

    The robot is a dynamic box driven by setting its velocity each step (a differential
    drive without wheel slip); the walls and the obstacle are static. Contacts come from
    pymunk's collision callbacks; sonar, camera and odometry readings from the sensing kernel.
    """

    def __init__(self, config: WorldConfig | None = None) -> None:
        self.config = config or WorldConfig()
        if not isinstance(self.config.track, TrackConfig):
            raise TypeError("a corridor track is a CorridorWorld's (see make_world)")
        self.geometry: Geometry = TrackGeometry.build(self.config.track)
        robot = self.config.robot
        geo = self.geometry
        self._build_space(geo)
        self._obstacle_body = pymunk.Body(body_type=pymunk.Body.STATIC)
        size = self.config.track.obstacle.size_m
        self._obstacle_shape = pymunk.Poly.create_box(self._obstacle_body, (size, size))
        self._obstacle_shape.collision_type = _OBSTACLE
        self._space.add(self._obstacle_body, self._obstacle_shape)
        self._space.on_collision(_ROBOT, _WALL, begin=self._on_wall)
        self._space.on_collision(_ROBOT, _OBSTACLE, begin=self._on_obstacle)

        g = _sensing_vector(self.config, geo)
        self._tick_state(g)
        self._obstacle_box = np.zeros(4)
        self._has_obstacle = False
        self._kernel_sense: Callable[..., None] | None = None
        # Exact perception (the default) skips the estimates entirely: bit for bit as before.
        perception = self.config.perception
        self._perception = (
            None
            if perception.exact
            else NoisyPerception(perception, g, self._sonar_angles, robot.camera_track_ticks)
        )

    def _tick_state(self, g: np.ndarray[Any, np.dtype[np.float64]]) -> None:
        """What the tick path reads and keeps, before the first episode."""
        robot = self.config.robot
        self._track = np.zeros(4)
        self._g = g
        self._sonar_angles = np.radians(np.asarray(robot.sonar_angles_deg, dtype=np.float64))
        self._channels = sensing.empty_channels()
        self._noise = np.zeros((0, 8))
        self._noise_at = 0
        self._rng = np.random.default_rng(0)
        self._command = MotorCommand(0.0, 0.0)
        self._tick = 0
        self._hit: CollisionKind | None = None
        self._phase_index = 0
        self._phase_left = 0
        self._lamp = LampColor.RED
        self._layout = EpisodeLayout(None, -1, ((LampColor.GREEN, 1),))
        self._front_to_line = sensing.UNSEEN
        sig = self.config.track.signal
        self._beacon = sig.beacon
        self._beacon_range = sig.beacon_range_m
        self._beacon_period = max(1, round(sig.beacon_period_s / self.config.dt_s))
        self._beacon_first = 0
        self._beacon_heard = 0.0
        # Constants of the tick path, read once (the config is frozen).
        self._v_max = robot.max_speed_mps
        self._w_max = robot.max_turn_rad_s
        self._dt = self.config.dt_s

    def _build_space(self, geo: Geometry) -> None:
        """The physics space with the track's walls and the robot's body in it."""
        robot = self.config.robot
        self._space = pymunk.Space()
        for a, b in geo.wall_segments():
            seg = pymunk.Segment(self._space.static_body, a, b, 0.01)
            seg.collision_type = _WALL
            self._space.add(seg)
        self._body = pymunk.Body(
            robot.mass_kg, pymunk.moment_for_box(robot.mass_kg, (robot.length_m, robot.width_m))
        )
        self._robot_shape = pymunk.Poly.create_box(self._body, (robot.length_m, robot.width_m))
        self._robot_shape.collision_type = _ROBOT
        self._space.add(self._body, self._robot_shape)

    @property
    def layout(self) -> EpisodeLayout:
        """The current episode's layout."""
        return self._layout

    def _on_wall(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        if self._hit is None:
            self._hit = "wall"

    def _on_obstacle(self, arbiter: pymunk.Arbiter, space: pymunk.Space, data: Any) -> None:
        self._hit = "obstacle"

    def reset(self, seed: int, episode: int) -> SensorFrame:
        """Start episode `episode` of the run seeded `seed`; return the first frame."""
        layout = episode_layout(self.config, self.geometry, seed, episode)
        self._layout = layout
        self._rng = np.random.default_rng(np.random.SeedSequence([seed, episode, 2]))
        self._refill_noise()
        if self._perception is not None:
            self._perception.reset(seed, episode)
        self._reset_beacon(seed, episode)
        x, y, th = self.geometry.start_pose
        self._body.position = (x, y)
        self._body.angle = th
        self._body.velocity = (0.0, 0.0)
        self._body.angular_velocity = 0.0
        self._space.reindex_shapes_for_body(self._body)
        if layout.obstacle_center is None:
            self._has_obstacle = False
            self._obstacle_body.position = (-100.0, -100.0)
        else:
            self._has_obstacle = True
            ox, oy = layout.obstacle_center
            half = self.config.track.obstacle.size_m / 2
            self._obstacle_box[:] = (ox - half, oy - half, ox + half, oy + half)
            self._obstacle_body.position = (ox, oy)
        self._space.reindex_shapes_for_body(self._obstacle_body)
        self._track[:] = 0.0
        self._phase_index = 0
        self._lamp, self._phase_left = layout.signal_phases[0]
        self._command = MotorCommand(0.0, 0.0)
        self._tick = 0
        self._hit = None
        frame = self._sense(violation=False)
        self._front_to_line = float(frame.channels[28])
        return frame

    def place(
        self, x: float, y: float, heading_rad: float, obstacle: tuple[float, float] | None
    ) -> SensorFrame:
        """Put the robot at a pose and the obstacle at a centre (None: no obstacle).

        For constructed situations (the placement probe, tests): call after `reset`, which
        still decides the lamp's cycle and the noise. The robot stands still; the camera's
        tracking of the obstacle starts afresh.
        """
        self._body.position = (x, y)
        self._body.angle = heading_rad
        self._body.velocity = (0.0, 0.0)
        self._body.angular_velocity = 0.0
        self._space.reindex_shapes_for_body(self._body)
        if obstacle is None:
            self._has_obstacle = False
            self._obstacle_body.position = (-100.0, -100.0)
        else:
            self._has_obstacle = True
            ox, oy = obstacle
            half = self.config.track.obstacle.size_m / 2
            self._obstacle_box[:] = (ox - half, oy - half, ox + half, oy + half)
            self._obstacle_body.position = (ox, oy)
        self._space.reindex_shapes_for_body(self._obstacle_body)
        self._track[:] = 0.0
        self._beacon_heard = 0.0
        if self._perception is not None:
            self._perception.relocate()
        self._command = MotorCommand(0.0, 0.0)
        self._hit = None
        frame = self._sense(violation=False)
        self._front_to_line = float(frame.channels[28])
        return frame

    def apply(self, command: MotorCommand) -> None:
        """Set the wheel command for the next step (clipped to the robot's limits)."""
        self._command = command

    def step(self) -> SensorFrame:
        """Advance one tick: drive, step the physics, cycle the lamp, referee, sense."""
        cmd = self._command
        v_max = self._v_max
        v = min(max(cmd.speed_mps, -v_max), v_max)
        w_max = self._w_max
        w = min(max(cmd.turn_rad_s, -w_max), w_max)
        body = self._body
        th = _get_angle(body)
        _set_velocity(body, (v * math.cos(th), v * math.sin(th)))
        _set_angular_velocity(body, w)
        self._hit = None
        self._space.step(self._dt)
        self._tick += 1
        self._phase_left -= 1
        if self._phase_left <= 0:
            phases = self._layout.signal_phases
            self._phase_index = (self._phase_index + 1) % len(phases)
            self._lamp, self._phase_left = phases[self._phase_index]
        frame = self._sense(violation=False)
        front = float(frame.channels[28])
        crossed = self._front_to_line > 0.0 >= front and self._front_to_line < sensing.UNSEEN
        self._front_to_line = front
        if crossed and self._lamp == LampColor.RED:
            return SensorFrame(
                frame.tick,
                frame.x,
                frame.y,
                frame.heading_rad,
                frame.channels,
                frame.lamp,
                frame.collision,
                True,
            )
        return frame

    def _reset_beacon(self, seed: int, episode: int) -> None:
        """When the beacon's first message of the episode comes (a seeded offset)."""
        if self._beacon:  # its own stream: a world without a beacon draws as before
            beacon_rng = np.random.default_rng(np.random.SeedSequence([seed, episode, 3]))
            self._beacon_first = int(beacon_rng.integers(self._beacon_period))
        self._beacon_heard = 0.0

    def _hear_beacon(self, front_to_line: float) -> float:
        """The phase in the beacon's last message heard within its range (0: none)."""
        if abs(front_to_line) > self._beacon_range:
            self._beacon_heard = 0.0
        elif (self._tick - self._beacon_first) % self._beacon_period == 0:
            self._beacon_heard = float(self._lamp)
        return self._beacon_heard

    def _refill_noise(self) -> None:
        self._noise = self._rng.normal(0.0, self.config.robot.sonar_noise_m, (256, 8))
        self._noise_at = 0

    def _load_kernel(self) -> Callable[..., None]:
        """The sensing kernel, loaded with the first reading, not with this module.

        Loading it loads numba (0.3-0.4 s of CPU): a process that builds worlds without
        ticking them (the service creating runs for an engines' process) does without.
        """
        from core.sim._kernel import sense

        self._kernel_sense = sense
        return sense

    def _sense(self, violation: bool) -> SensorFrame:
        if self._noise_at >= len(self._noise):
            self._refill_noise()
        noise = self._noise[self._noise_at]
        self._noise_at += 1
        body = self._body
        pos = _get_position(body)
        th = _get_angle(body)
        out = self._channels
        self._read(pos.x, pos.y, th, noise, out)
        if self._beacon:
            out[_BEACON_PHASE] = self._hear_beacon(float(out[_FRONT_TO_LINE]))
        if self._perception is not None:
            self._perception.apply(out, pos.x, pos.y)
        return SensorFrame(
            self._tick, pos.x, pos.y, th, out.copy(), self._lamp, self._hit, violation
        )

    def _read(self, x: float, y: float, th: float, noise: np.ndarray, out: np.ndarray) -> None:
        """The sensing kernel's readings at pose (x, y, th) into `out` (the ring's kernel)."""
        geo = self.geometry
        kernel_sense = self._kernel_sense or self._load_kernel()
        kernel_sense(
            x,
            y,
            th,
            self._g,
            self._sonar_angles,
            noise,
            self._obstacle_box,
            self._has_obstacle,
            float(self._lamp),
            1.0 if self._hit else 0.0,
            self._track,
            geo.vertices,
            geo.directions,
            geo.leg_lengths_m,
            geo.leg_start_m,
            out,
        )


def make_world(config: WorldConfig) -> PymunkWorld:
    """The pymunk world of a config: the ring's `PymunkWorld` or a `CorridorWorld`."""
    if not isinstance(config.track, TrackConfig):
        from core.sim.corridor_world import CorridorWorld  # it builds on PymunkWorld

        return CorridorWorld(config)
    return PymunkWorld(config)
