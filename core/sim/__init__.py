"""The simulated robot world: a pymunk AmigoBot on a closed-loop corridor track.

The plain types load eagerly; `PymunkWorld` (pymunk and the numba kernels) loads on first use,
so importing `core.sim.types` or `core.sim.channels` (as the brain does) stays free of physics.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from core.sim.channels import CHANNELS, Channel
from core.sim.robot import RobotConfig
from core.sim.track import ObstacleConfig, SignalConfig, TrackConfig, TrackGeometry
from core.sim.types import (
    EpisodeLayout,
    LampColor,
    MotorCommand,
    SensorFrame,
    World,
    WorldConfig,
)

if TYPE_CHECKING:
    from core.sim.world import PymunkWorld

__all__ = [
    "CHANNELS",
    "Channel",
    "EpisodeLayout",
    "LampColor",
    "MotorCommand",
    "ObstacleConfig",
    "PymunkWorld",
    "RobotConfig",
    "SensorFrame",
    "SignalConfig",
    "TrackConfig",
    "TrackGeometry",
    "World",
    "WorldConfig",
]


def __getattr__(name: str) -> Any:
    if name == "PymunkWorld":
        from core.sim.world import PymunkWorld

        return PymunkWorld
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
