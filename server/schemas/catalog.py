"""What the service knows: stimuli, conditions, behaviours, sensors and worlds."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, JsonValue

from core.brain.catalog import sensor_definitions
from core.sim.worlds import world_names


class StimulusPublic(BaseModel):
    name: str
    sensor: str
    objective: str
    level: Literal["low", "high"]
    priority: int
    description: str = Field(
        "",
        description="what the stimulus means, in words (e.g. the robot's lane and where "
        "the obstacle is)",
    )
    rule: str = Field(
        "", description="when the sensor emits it, as its data file's conditions (OR of ANDs)"
    )


class ConditionPublic(BaseModel):
    name: str
    description: str
    network: str = Field(description="the knowledge set it starts from by default")
    learning: bool
    kp: bool = Field(description="whether knowledge propagation runs")
    trainer: str = Field(description="the reward program that runs beside it ('' for none)")


class BehaviourPublic(BaseModel):
    name: str
    family: str
    mode: str
    speed_mps: float
    turn_dps: float
    ticks: int
    motion: tuple[float, float, float] = Field(
        description="displacement forward and left (m) and heading change (rad) over its run"
    )


class SensorPublic(BaseModel):
    model_config = ConfigDict(from_attributes=True)  # read from a core or store object

    name: str
    physical: list[str]
    processing: str
    objective: str
    level: Literal["low", "high"]
    priority: int
    weight: float
    stimuli: list[str]
    definition: str = Field(
        description="the sensor definition its rules are written for, when it has several "
        "(see GET /api/sensor-definitions); '' when it has one set of rules"
    )


class SensorDefinitionPublic(BaseModel):
    """A sensor definition: one meaning of the logical sensors' rules (same stimuli)."""

    name: str
    description: str
    default: bool = Field(description="the definition a run uses when it names none")


class WorldPublic(BaseModel):
    """A world preset: `WorldConfig`'s defaults with some settings changed, and why."""

    name: str
    description: str
    reasons: str = Field(description="why it differs from the defaults, in physical terms")
    overrides: dict[str, JsonValue] = Field(
        description="the settings that differ from the defaults, nested as the world's "
        "configuration is (robot, track, track.obstacle, track.signal)"
    )
    default: bool = Field(description="the world a run uses when it names none")


class SonarPublic(BaseModel):
    """One sonar: where it reads from and along which axis, in the robot's frame."""

    x_m: float
    y_m: float
    angle_rad: float = Field(description="its axis relative to the heading, + = left")


class RunWorldPublic(BaseModel):
    """A run's world as a top-down view draws it: the fixed parts, in metres."""

    world: str = Field(description="its world preset ('' for the default)")
    outer_box: list[float] = Field(
        description="[x0, y0, x1, y1]: the track's outer walls (on a corridor track of any "
        "shape, the walls' bounding box)"
    )
    inner_box: list[float] = Field(
        description="[x0, y0, x1, y1]: the island's walls (on a corridor track of any shape, "
        "an empty box at the bounding box's centre: its walls are `walls`)"
    )
    walls: list[list[float]] = Field(
        description="every wall as a segment [x0, y0, x1, y1], for a track of any shape"
    )
    centre_line: list[list[float]] = Field(
        description="the corridor's centre line, its vertices [x, y] in lap order (closed: "
        "the last joins the first)"
    )
    corridor_widths_m: list[float] = Field(
        description="the corridor's width on each centre-line segment (segment k runs from "
        "vertex k to vertex k + 1)"
    )
    floor: list[list[list[float]]] = Field(
        description="the corridor's floor, a quadrilateral [[x, y] x 4] per centre-line "
        "segment between its mitred walls (at a crossing two overlap)"
    )
    ring: bool = Field(
        description="true: the rectangular ring (`outer_box` and `inner_box` are its walls); "
        "false: a corridor track of any shape (`walls` and `floor` are)"
    )
    corridor_width_m: float
    stopline: list[list[float]] = Field(description="the stop line's two ends, [[x, y], [x, y]]")
    lamp: list[float] = Field(description="[x, y] of the traffic lamp")
    start_pose: list[float] = Field(description="[x, y, heading_rad] of each episode's start")
    robot_length_m: float
    robot_width_m: float
    sonar_range_m: float
    sonars: list[SonarPublic]
    obstacle_size_m: float


WORLD_NAMES: list[JsonValue] = list(world_names())
"""The world presets the service knows, listed in /openapi.json."""
SENSOR_DEFINITIONS: list[JsonValue] = list(sensor_definitions())
"""The sensor definitions the service knows, listed in /openapi.json."""
