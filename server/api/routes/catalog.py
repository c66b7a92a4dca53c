"""What the robot knows by name: stimuli, behaviours, logical sensors; and the worlds."""

from __future__ import annotations

from typing import Any

from pydantic import JsonValue

from core.brain.catalog import Stimulus, sensor_definitions
from core.run.conditions import CONDITIONS
from core.sim.worlds import default_world, load_world, world_names
from server.api.deps import StateDep
from server.api.routing import resource_router
from server.schemas import (
    BehaviourPublic,
    ConditionPublic,
    SensorDefinitionPublic,
    SensorPublic,
    StimulusPublic,
    WorldPublic,
)

router = resource_router(tag="catalog")

_MEANINGS = {
    "Left": "the robot is left of its lane's centre line (more than 0.2 m)",
    "Middle": "the robot is within 0.2 m of its lane's centre line",
    "Right": "the robot is right of its lane's centre line (more than 0.2 m)",
    "Corner": "a corner of the track is coming up",
    "LeftWall": "a wall is close on the robot's left (sonar)",
    "RightWall": "a wall is close on the robot's right (sonar)",
    "Red": "the lamp is red and the stop line is 0.2-0.8 m ahead (camera)",
    "Yellow": "the lamp is yellow and the stop line is 0.2-0.8 m ahead (camera)",
    "Green": "the lamp is green and the stop line is 0.2-0.8 m ahead (camera)",
    "SonarObstacleLeft": "an echo on the left that the map of the walls does not explain",
    "SonarObstacleFront": "an echo dead ahead (both central sonars) that is not a wall",
    "SonarObstacleRight": "an echo on the right that the map of the walls does not explain",
    "Collision": "the bumper is pressed",
    "BeaconRed": "the stop line's beacon, heard only near the line, says red",
    "BeaconYellow": "the stop line's beacon, heard only near the line, says yellow",
    "BeaconGreen": "the stop line's beacon, heard only near the line, says green",
}
_LANE = {"L": "left", "M": "middle", "R": "right"}
_SIDE = {"L": "left", "M": "ahead (middle)", "R": "right"}


def _meaning(s: Stimulus) -> str:
    """A stimulus in words: the camera's Obstacle_<lane>_<side> of Fig. 10 by its name."""
    parts = s.name.split("_")
    if len(parts) == 3 and parts[0] == "Obstacle" and parts[1] in _LANE and parts[2] in _SIDE:
        return (
            f"robot in the {_LANE[parts[1]]} lane, obstacle {_SIDE[parts[2]]}, "
            "within 1.5 m of the camera"
        )
    return _MEANINGS.get(s.name, "")


def _rule(s: Stimulus) -> str:
    """The stimulus's rule as its data file's conditions, OR of ANDs."""
    return " or ".join(
        " and ".join(" ".join(str(x) for x in c.as_data()) for c in conj) for conj in s.rule
    )


@router.get("/stimuli")
async def list_stimuli(state: StateDep) -> list[StimulusPublic]:
    """Every stimulus the logical sensors emit, with its meaning and its rule."""
    return [
        StimulusPublic(
            name=s.name,
            sensor=s.sensor,
            objective=s.objective,
            level=s.level,
            priority=s.priority,
            description=_meaning(s),
            rule=_rule(s),
        )
        for s in state.catalog.stimuli
    ]


@router.get("/conditions")
async def list_conditions() -> list[ConditionPublic]:
    """The conditions a run may name (`condition`), with what each means."""
    return [
        ConditionPublic(
            name=c.name,
            description=c.description,
            network=c.network,
            learning=c.learning,
            kp=c.kp,
            trainer=c.trainer or "",
        )
        for c in CONDITIONS.values()
        if c.agent == "brain"
    ]


@router.get("/behaviours")
async def list_behaviours(state: StateDep) -> list[BehaviourPublic]:
    """Every behaviour (motor primitive) with its motion vector."""
    dt = 0.1
    return [
        BehaviourPublic(
            name=b.name,
            family=b.family,
            mode=b.mode,
            speed_mps=b.speed_mps,
            turn_dps=b.turn_dps,
            ticks=b.ticks,
            motion=b.motion_vector(dt),
        )
        for b in state.catalog.behaviours
    ]


@router.get("/sensors")
async def list_sensors(state: StateDep) -> list[SensorPublic]:
    """Every logical sensor as declared in data, under the default sensor definition."""
    return [SensorPublic.model_validate(s, from_attributes=True) for s in state.catalog.sensors]


@router.get("/sensor-definitions")
def list_sensor_definitions() -> list[SensorDefinitionPublic]:
    """The sensor definitions a run may name (`sensors`), the default first.

    A definition is one meaning of the rules of the sensors that have several: the same
    stimuli, other conditions for them.
    """
    definitions = sensor_definitions()
    default = next(iter(definitions), None)
    return [
        SensorDefinitionPublic(name=name, description=text, default=name == default)
        for name, text in definitions.items()
    ]


def _json(value: Any) -> JsonValue:
    """A data file's value as JSON (TOML's tables and arrays are dicts and lists)."""
    if isinstance(value, dict):
        return {str(k): _json(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_json(v) for v in value]
    if value is None or isinstance(value, str | int | float | bool):
        return value
    return str(value)


@router.get("/worlds")
def list_worlds() -> list[WorldPublic]:
    """The world presets a run may name (`world`), the default first."""
    default = default_world()
    out = []
    for name in world_names():
        preset = load_world(name)
        overrides = _json(dict(preset.overrides))
        assert isinstance(overrides, dict)
        out.append(
            WorldPublic(
                name=preset.name,
                description=preset.description,
                reasons=preset.reasons,
                overrides=overrides,
                default=name == default,
            )
        )
    return out
