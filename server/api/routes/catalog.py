"""What the robot knows by name: stimuli, behaviours, logical sensors; and the worlds."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from pydantic import JsonValue

from core.brain.catalog import sensor_definitions
from core.conditions import CONDITIONS
from core.worlds import default_world, load_world, world_names
from server.api.deps import StateDep
from server.schemas import (
    BehaviourPublic,
    ConditionPublic,
    SensorDefinitionPublic,
    SensorPublic,
    StimulusPublic,
    WorldPublic,
)

router = APIRouter(tags=["catalog"])


@router.get("/stimuli")
def list_stimuli(state: StateDep) -> list[StimulusPublic]:
    """Every stimulus the logical sensors emit."""
    return [
        StimulusPublic(
            name=s.name, sensor=s.sensor, objective=s.objective, level=s.level, priority=s.priority
        )
        for s in state.catalog.stimuli
    ]


@router.get("/conditions")
def list_conditions() -> list[ConditionPublic]:
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
def list_behaviours(state: StateDep) -> list[BehaviourPublic]:
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
def list_sensors(state: StateDep) -> list[SensorPublic]:
    """Every logical sensor as declared in data, under the default sensor definition."""
    return [
        SensorPublic(
            name=s.name,
            physical=list(s.physical),
            processing=s.processing,
            objective=s.objective,
            level=s.level,
            priority=s.priority,
            weight=s.weight,
            stimuli=list(s.stimuli),
            definition=s.definition,
        )
        for s in state.catalog.sensors
    ]


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
