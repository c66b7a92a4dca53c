"""The world's plain types and the `World` protocol: what the brain and the simulation share.

Nothing here imports pymunk or numba, so the brain can use a `MotorCommand` without loading
the physics; `core.sim.world` holds the pymunk world and re-exports these names.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, Literal, NamedTuple, Protocol

import numpy as np

from core.sim.corridor import CorridorConfig, CorridorGeometry, PlacedObstacle
from core.sim.perception import PerceptionConfig
from core.sim.robot import RobotConfig
from core.sim.track import TrackConfig, TrackGeometry

__all__ = [
    "CollisionKind",
    "EpisodeLayout",
    "Geometry",
    "LampColor",
    "MotorCommand",
    "SensorFrame",
    "World",
    "WorldConfig",
    "build_geometry",
]

CollisionKind = Literal["wall", "obstacle"]

Geometry = TrackGeometry | CorridorGeometry
"""A track's derived geometry: the rectangular ring's or a corridor track's."""


def build_geometry(track: TrackConfig | CorridorConfig) -> Geometry:
    """The geometry of either kind of track."""
    if isinstance(track, CorridorConfig):
        return CorridorGeometry.build(track)
    return TrackGeometry.build(track)


class LampColor(IntEnum):
    """The lamp's colour as the camera channel encodes it (the paper's "Blue" is green)."""

    NONE = 0
    RED = 1
    YELLOW = 2
    GREEN = 3


@dataclass(frozen=True, slots=True)
class WorldConfig:
    """Everything that defines the simulated world.

    Attributes:
        track: the corridor, signal and obstacle: the rectangular ring (`TrackConfig`) or a
            track of any shape from a world file (`CorridorConfig`).
        robot: the AmigoBot.
        perception: how far the robot's estimates are from the truth (exact by default;
            `core.sim.perception`).
        dt_s: the fixed tick, seconds; the physics steps once per tick.
        max_ticks: an episode's time limit in ticks (120 s by default).
    """

    track: TrackConfig | CorridorConfig = field(default_factory=TrackConfig)
    robot: RobotConfig = field(default_factory=RobotConfig)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    dt_s: float = 0.1
    max_ticks: int = 1200

    def __post_init__(self) -> None:
        if self.dt_s <= 0 or self.max_ticks <= 0:
            raise ValueError("dt_s and max_ticks must be positive")

    def absent_physical(self) -> frozenset[str]:
        """Physical sensors a logical sensor may name that this world does not have.

        The stop line's beacon is part of the world, not of the robot: without it the
        `beacon` logical sensor's stimuli never occur.
        """
        return frozenset() if self.track.signal.beacon else frozenset({"beacon"})


class MotorCommand(NamedTuple):
    """Wheel command for one tick: forward speed and turning rate (+ = left)."""

    speed_mps: float
    turn_rad_s: float


@dataclass(frozen=True, slots=True)
class EpisodeLayout:
    """What is random in an episode: where the obstacle is and how the lamp cycles."""

    obstacle_center: tuple[float, float] | None
    obstacle_leg: int
    signal_phases: tuple[tuple[LampColor, int], ...]
    """The lamp's cycle as (colour, ticks), repeated if the episode outlasts it."""
    obstacles: tuple[PlacedObstacle, ...] = ()
    """On a corridor track (`CorridorConfig`), every obstacle and how it moves; the first is
    also `obstacle_center` and `obstacle_leg` at the episode's start."""


class SensorFrame(NamedTuple):
    """All physical readings after a step, plus what the world itself judged.

    `channels` is indexed by `core.sim.channels.Channel`. `collision` and `violation` are the
    referee's view (the robot only knows what its bumper and camera report).
    """

    tick: int
    x: float
    y: float
    heading_rad: float
    channels: np.ndarray[Any, np.dtype[np.float64]]
    lamp: LampColor
    collision: CollisionKind | None
    violation: bool


class World(Protocol):
    """What the brain's simulation needs from a world."""

    config: WorldConfig

    @property
    def geometry(self) -> Geometry:
        """The track's derived geometry."""
        ...

    def reset(self, seed: int, episode: int) -> SensorFrame:
        """Start episode `episode` of the run seeded `seed`; return the first frame."""
        ...

    def apply(self, command: MotorCommand) -> None:
        """Set the wheel command for the next step."""
        ...

    def step(self) -> SensorFrame:
        """Advance one tick and sense."""
        ...

    @property
    def layout(self) -> EpisodeLayout:
        """The current episode's layout."""
        ...
