"""What the robot knows by name: stimuli, behaviours, logical sensors."""

from __future__ import annotations

from fastapi import APIRouter

from server.api.deps import StateDep
from server.schemas import BehaviourPublic, SensorPublic, StimulusPublic

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
    """Every logical sensor as declared in data."""
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
        )
        for s in state.catalog.sensors
    ]
