"""The simulated robot world: a pymunk AmigoBot on a closed-loop corridor track."""

from core.sim.channels import CHANNELS, Channel
from core.sim.robot import RobotConfig
from core.sim.track import ObstacleConfig, SignalConfig, TrackConfig, TrackGeometry
from core.sim.world import (
    EpisodeLayout,
    LampColor,
    MotorCommand,
    PymunkWorld,
    SensorFrame,
    World,
    WorldConfig,
)

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
