"""A run: its creation, its state, its memory and network, its episodes and their traces."""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from core.brain.memory import MAX_REACTION_S
from core.engine import HZ_MAX, HZ_MIN
from core.run.conditions import CONDITIONS
from core.sim.robotfile import ROBOT_PREFIX, robot_names, robot_of
from server.schemas.catalog import SENSOR_DEFINITIONS, WORLD_NAMES
from server.schemas.common import Strict, one_of
from server.schemas.networks import AssociationPublic

ENGINE_CONDITIONS = tuple(n for n, c in CONDITIONS.items() if c.agent == "brain")
"""The conditions the engine runs: the data's (``core/data/conditions.toml``), in its order."""
if TYPE_CHECKING:
    EngineCondition = str
else:  # the data's names, for validation and the OpenAPI schema's enum
    EngineCondition = Literal[ENGINE_CONDITIONS]


ROBOT_WORLDS = [f"{ROBOT_PREFIX}{name}" for name in robot_names()]
"""The robots the service knows when it starts, listed in /openapi.json."""

ReactionSeconds = Annotated[float, Field(ge=0.0, le=MAX_REACTION_S)]


class LearningParams(Strict):
    EXAMPLES = ({"eta": 0.2, "epsilon": 0.05},)

    eta: float | None = Field(None, ge=0.0, le=1.0, description="Eq. (1)'s learning rate")
    epsilon: float | None = Field(None, ge=0.0, le=1.0, description="exploration rate")
    synthesize: bool = Field(False, description="KP keeps new behaviours instead of snapping")
    reaction_window_s: tuple[ReactionSeconds, ReactionSeconds] | None = Field(
        None,
        description="[lo, hi] seconds (the two bounds in either order): a trainer's reward "
        "with the tick they saw credits the ticks lo to hi seconds before it (default: the "
        "service's SRLAB_REACTION_WINDOW)",
    )

    @field_validator("reaction_window_s")
    @classmethod
    def _window(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        # A window is the interval between its bounds: no order a schema cannot say.
        return None if v is None else (min(v), max(v))


class RunCreate(Strict):
    EXAMPLES = (
        {"condition": "kp", "seed": 1, "episodes": 2},
        {"condition": "trainer", "mode": "realtime", "hz": 20, "world": "classic"},
    )

    condition: EngineCondition
    seed: int = Field(0, ge=0, le=2**31 - 1)
    episodes: int | None = Field(None, ge=1, le=1_000_000, description="None: until stopped")
    mode: Literal["fast", "realtime"] = "fast"
    hz: float = Field(
        10.0, ge=HZ_MIN, le=HZ_MAX, description="realtime tick rate (ticks per second)"
    )
    network: str | None = Field(
        None,
        max_length=100,
        description="a stored network to start from (default: the condition's)",
    )
    network_version: int | None = Field(
        None,
        ge=1,
        le=2**31 - 1,
        description="start from this version of `network` (GET /api/networks/{name}/versions), "
        "not its current one; live edits do not reach such a run",
    )
    params: LearningParams = Field(default_factory=LearningParams)
    world: str | None = Field(
        None,
        max_length=100,
        description="a world preset of GET /api/worlds (default: the default one), or a "
        "robot's: `ros2:ROBOT` for a robot file of core/data/robots (a realtime run at the "
        "robot's rate, docs/robots.md)",
        json_schema_extra={"enum": [*WORLD_NAMES, *ROBOT_WORLDS, None]},
    )
    sensors: str | None = Field(
        None,
        max_length=100,
        description="a sensor definition of GET /api/sensor-definitions (default: the default one)",
        json_schema_extra={"enum": [*SENSOR_DEFINITIONS, None]},
    )

    # Checked here, not by the enum alone, so that the 422 lists the known names.
    @field_validator("world")
    @classmethod
    def _known_world(cls, value: str | None) -> str | None:
        if value is not None and robot_of(value) is not None:
            robots = [f"{ROBOT_PREFIX}{name}" for name in robot_names()]
            return one_of(value, robots, "robot")
        return one_of(value, WORLD_NAMES, "world")

    @field_validator("sensors")
    @classmethod
    def _known_sensors(cls, value: str | None) -> str | None:
        return one_of(value, SENSOR_DEFINITIONS, "sensor definition")


class EstimatePublic(BaseModel):
    mean: float | None = Field(description="null without data")
    low: float | None = Field(description="95% Student's t interval; null with fewer than 2 seeds")
    high: float | None
    n: int = Field(description="seeds")


class ComparisonPublic(BaseModel):
    episodes: int = Field(
        description="the first episodes of every run the rates are over (at most 1,000)"
    )
    seeds: list[int]
    a: EstimatePublic = Field(description="success rate of runs `a`, over seeds")
    b: EstimatePublic | None = Field(description="of runs `b`, when given")
    diff: EstimatePublic | None = Field(description="a - b, paired by seed, when `b` is given")
    p: float | None = Field(description="two-sided sign-flip p of no difference")
    complete: bool = Field(description="whether every run has ended")


class LiveState(BaseModel):
    tick: int
    episode: int
    hz: float
    ticks_run: int
    lateness_p99_ms: float | None = Field(description="realtime tick lateness, 99th percentile")
    lateness_max_ms: float | None
    overruns: int = Field(description="tick periods skipped because a tick ran late")
    reward_ack_p99_ms: float | None
    ticks_by_origin: dict[str, int] = Field(
        description="ticks run so far by what made their behaviour run: an association's "
        "source (innate, designed, dp, learned, kp, expert), explored, default or commanded"
    )


RunStatusName = Literal[
    "created", "running", "paused", "finished", "stopped", "interrupted", "failed"
]
OutcomeName = Literal["success", "failure"]
CauseName = Literal["wall_collision", "obstacle_collision", "signal_violation", "timeout"]
HowName = Literal["released", "default", "explored", "continued", "commanded"]


class RunPublic(BaseModel):
    id: int
    condition: str
    seed: int
    episodes: int | None
    mode: Literal["fast", "realtime"]
    hz: float
    network: str | None
    params: dict[str, float | bool]
    world: str = Field(description="its world preset ('' if stored before runs kept it)")
    sensors: str = Field(description="its sensor definition ('' if stored before runs kept it)")
    reaction_window_s: tuple[float, float] = Field(
        description="[lo, hi] seconds: a trainer's reward with `tick_seen` credits the ticks "
        "lo to hi seconds before it, at the run's rate (docs/studies.md)"
    )
    status: RunStatusName
    error: str | None
    episodes_done: int
    successes: int
    ticks: int
    live: LiveState | None = Field(
        default=None, description="its live figures while it runs here (null once it has ended)"
    )


class RunRate(Strict):
    """A realtime run's new tick rate."""

    EXAMPLES = ({"hz": 20},)

    hz: float = Field(ge=HZ_MIN, le=HZ_MAX, description="ticks per second")


class ViewChosen(BaseModel):
    """The run the 3D view now shows, and where the view is."""

    run: int
    url: str = Field(description="the 3D view's page, on the host the request was sent to")


class RunsPublic(BaseModel):
    data: list[RunPublic]
    count: int


class ReliabilityPublic(BaseModel):
    stimulus: str
    behaviour: str
    reliability: float


class MemoryPublic(BaseModel):
    data: list[ReliabilityPublic]
    count: int


class RunNetworkPublic(BaseModel):
    data: list[AssociationPublic]
    count: int


class EpisodePublic(BaseModel):
    model_config = ConfigDict(from_attributes=True)  # read from a core or store object

    episode: int
    outcome: OutcomeName
    cause: CauseName | None
    ticks: int
    start_tick: int
    rewards: int


class EpisodesPublic(BaseModel):
    data: list[EpisodePublic]
    count: int


class TraceRowPublic(BaseModel):
    tick: int
    x: float
    y: float
    heading_rad: float
    behaviour: str | None
    how: HowName
    origin: str = Field(
        description="what made the behaviour run: an association's source, explored, "
        "default or commanded ('' in a trace stored before traces kept it)"
    )
    released_by: str | None = Field(description="the stimulus the behaviour answered")
    lamp: int
    stimuli: list[str]
    obstacles: list[list[float]] = Field(
        default_factory=list,
        description="every obstacle's centre [x, y] at that tick, as the run's world placed "
        "and moved them",
    )


class EpisodeDetail(EpisodePublic):
    trace: list[TraceRowPublic]
