"""The HTTP API's models: pydantic at the edge only."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime
from typing import Annotated, Any, ClassVar, Literal, get_args, get_origin

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    GetJsonSchemaHandler,
    JsonValue,
    StringConstraints,
    ValidationInfo,
    WithJsonSchema,
    field_validator,
)
from pydantic.json_schema import JsonSchemaValue
from pydantic_core import CoreSchema

from core.brain.catalog import Source, load_catalog, sensor_definitions
from core.commands import RewardSource
from core.conditions import CONDITIONS
from core.engine import HZ_MAX, HZ_MIN
from core.text import unstorable
from core.worlds import world_names

EngineCondition = Literal[
    "innate",
    "delayed",
    "dp",
    "dp-rare",
    "rp",
    "trainer",
    "kp",
    "kp-punished",
    "sonar",
    "expert",
    "reflexes",
    "unaware",
]
assert set(EngineCondition.__args__) == {  # type: ignore[attr-defined]
    n for n, c in CONDITIONS.items() if c.agent == "brain"
}


def _kinds(annotation: object) -> set[type]:
    """The plain types among an annotation's (`float | None` -> {float, NoneType})."""
    args = get_args(annotation)
    if not args:
        return {annotation} if isinstance(annotation, type) else set()
    return {t for a in args for t in _kinds(a)} if get_origin(annotation) is not Literal else set()


TEXT_PATTERN = r"^[^\u0000]*$"
"""Text a request may carry, as a JSON Schema pattern: any character but NUL, which
PostgreSQL cannot store (`core.text` holds the rule). Lone surrogates are refused too, but
they are not text at all (no UTF-8 holds one, and most validators' regular expressions
cannot name them), so the pattern leaves them out."""


def _storable(value: str) -> str:
    problem = unstorable(value)
    if problem is not None:
        raise ValueError(problem)
    return value


def _with_text_pattern(schema: JsonSchemaValue) -> None:
    """Give a string schema (or a nullable one's string branch) `TEXT_PATTERN`.

    A schema with its own pattern, enum or constant says more already.
    """
    if {"pattern", "enum", "const"} & schema.keys():
        return
    if schema.get("type") == "string":
        schema["pattern"] = TEXT_PATTERN
    for branch in schema.get("anyOf", ()):
        _with_text_pattern(branch)


class _TextSchema:
    """Annotated metadata: `TEXT_PATTERN` in the JSON schema of the string it marks."""

    def __get_pydantic_json_schema__(
        self, core_schema: CoreSchema, handler: GetJsonSchemaHandler
    ) -> JsonSchemaValue:
        schema = handler(core_schema)
        _with_text_pattern(schema)
        return schema


Text = Annotated[str, AfterValidator(_storable), _TextSchema()]
"""A string the service may store: a query or path parameter's type (a request body's
strings get the same rule from `Strict`). Anything else is a 422 naming the field."""


def _strict_schema(schema: dict[str, Any], model: type) -> None:
    for prop in schema.get("properties", {}).values():
        _with_text_pattern(prop)
    examples = getattr(model, "EXAMPLES", ())
    if examples:
        schema["examples"] = list(examples)


class Strict(BaseModel):
    """A request body: unknown fields are an error, and values are not coerced.

    `"hz": "10"` is a string, not a number, `true` is a boolean, not 1, and `1` is not
    `true`: as JSON Schema reads the document (where 10.0 is an integer, and an integer is
    a number). Floats are finite. Every string field takes `Text`'s rule, declared and
    checked, without saying so: a new field cannot forget it. `EXAMPLES`, when a body has
    them, are its schema's `examples` (the documentation's, and a contract test's first
    cases).
    """

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, json_schema_extra=_strict_schema)
    EXAMPLES: ClassVar[tuple[dict[str, JsonValue], ...]] = ()

    @field_validator("*", mode="before")
    @classmethod
    def _as_json_schema_reads_it(cls, value: object, info: ValidationInfo) -> object:
        assert info.field_name is not None
        kinds = _kinds(cls.model_fields[info.field_name].annotation)
        if kinds & {int, float} and isinstance(value, bool | str):
            raise ValueError(f"a number is needed, not {type(value).__name__} {value!r}")
        if bool in kinds and value is not None and not isinstance(value, bool):
            raise ValueError(f"true or false is needed, not {value!r}")
        if str in kinds and isinstance(value, str):
            _storable(value)
        return value


class Health(BaseModel):
    status: Literal["ok"]
    version: str
    database: str
    runs_active: int
    viser_port: int | None = Field(
        None, description="Port of the 3D view on this host; null when it is not running."
    )


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
    outer_box: list[float] = Field(description="[x0, y0, x1, y1]: the track's outer walls")
    inner_box: list[float] = Field(description="[x0, y0, x1, y1]: the island's walls")
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


class LearningParams(Strict):
    EXAMPLES = ({"eta": 0.2, "epsilon": 0.05},)

    eta: float | None = Field(None, ge=0.0, le=1.0, description="Eq. (1)'s learning rate")
    epsilon: float | None = Field(None, ge=0.0, le=1.0, description="exploration rate")
    synthesize: bool = Field(False, description="KP keeps new behaviours instead of snapping")


def _one_of(value: str | None, known: Sequence[JsonValue], what: str) -> str | None:
    """`value` if it is one of `known` (or empty), else a ValueError listing them."""
    if value and value not in known:
        raise ValueError(f"unknown {what} {value!r} (known: {', '.join(map(str, known))})")
    return value


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
        description="a world preset of GET /api/worlds (default: the default one)",
        json_schema_extra={"enum": [*WORLD_NAMES, None]},
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
        return _one_of(value, WORLD_NAMES, "world")

    @field_validator("sensors")
    @classmethod
    def _known_sensors(cls, value: str | None) -> str | None:
        return _one_of(value, SENSOR_DEFINITIONS, "sensor definition")


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


class RewardCreate(Strict):
    EXAMPLES = ({"value": 1.0, "note": "a clean pass of the obstacle"}, {"value": -0.5})

    value: float = Field(ge=-1.0, le=1.0, description="the reward, -1 (bad) to 1 (good)")
    note: str = Field("", max_length=500)


class RewardAccepted(BaseModel):
    id: int
    tick: int
    episode: int
    value: float
    uid: str = Field(
        description="the reward's id from its arrival: its 202, its log entry and its event "
        "on the run's stream carry it (the log's `id` is the database's)"
    )


class RewardPublic(BaseModel):
    id: int
    tick: int
    episode: int
    value: float
    source: RewardSource
    note: str
    uid: str = Field(
        description="the reward's id from its arrival: its 202, its log entry and its event "
        "on the run's stream carry it (the log's `id` is the database's)"
    )
    applied: bool
    credited: int


class RewardsPublic(BaseModel):
    data: list[RewardPublic]
    count: int


class ReliabilityPublic(BaseModel):
    stimulus: str
    behaviour: str
    reliability: float


class MemoryPublic(BaseModel):
    data: list[ReliabilityPublic]
    count: int


class AssociationPublic(BaseModel):
    model_config = ConfigDict(from_attributes=True)  # read from a core or store object

    stimulus: str
    behaviour: str
    strength: float
    source: Source
    locked: bool


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


class EpisodeDetail(EpisodePublic):
    trace: list[TraceRowPublic]


# --- networks: the DP S-R editor ------------------------------------------------------

NETWORK_NAME = r"^[A-Za-z0-9_-]{1,64}$"
RESERVED_NAMES: list[JsonValue] = ["import"]
"""Names no network may take: `/api/networks/import` is an operation of its own, which
OpenAPI matches before `/api/networks/{name}`."""


def _not_reserved(name: str) -> str:
    if name in RESERVED_NAMES:
        raise ValueError(
            f"{name!r} names an operation (/api/networks/{name}), not a network: choose another"
        )
    return name


NetworkName = Annotated[
    str,
    StringConstraints(pattern=NETWORK_NAME),
    AfterValidator(_not_reserved),
    WithJsonSchema({"type": "string", "pattern": NETWORK_NAME, "not": {"enum": RESERVED_NAMES}}),
]
"""A new network's name: 1-64 letters, digits, '-' and '_', not a reserved one."""
NETWORK_FORMAT: Literal["srlab-network/1"] = "srlab-network/1"
_SHIPPED = load_catalog()
STIMULUS_NAMES: list[JsonValue] = [s.name for s in _SHIPPED.stimuli]
"""The stimuli the service knows (its catalogue), listed in /openapi.json."""
BEHAVIOUR_NAMES: list[JsonValue] = [b.name for b in _SHIPPED.behaviours]
"""The behaviours the service knows (its catalogue), listed in /openapi.json."""
MAX_ASSOCIATIONS = len(STIMULUS_NAMES) * len(BEHAVIOUR_NAMES)
"""The most associations a network body lists: one per S-R pair of the catalogue (a later
one replaces an earlier one of its pair). So many of the shortest take about a third of
the body limit (`SRLAB_MAX_BODY_BYTES`, 64 KiB): a longer list is a 422, not a 413."""


class AssociationCreate(Strict):
    """An S-R association to add: stimulus -> behaviour with a strength, source and lock."""

    EXAMPLES = ({"stimulus": "Red", "behaviour": "stop", "strength": 0.9, "source": "dp"},)

    # The names are listed for clients; the route checks them, naming the field in its 422.
    stimulus: str = Field(
        description="a name of GET /api/stimuli", json_schema_extra={"enum": STIMULUS_NAMES}
    )
    behaviour: str = Field(
        description="a name of GET /api/behaviours", json_schema_extra={"enum": BEHAVIOUR_NAMES}
    )
    strength: float = Field(1.0, ge=0.0, le=1.0, allow_inf_nan=False)
    source: Source = "dp"
    locked: bool = Field(
        False, description="the editor's lock: a locked association changes only with force"
    )


class AssociationUpdate(Strict):
    """New values for an association; an omitted one stays (a new association: 1, dp, no)."""

    EXAMPLES = ({"strength": 0.5}, {"locked": False})

    strength: float | None = Field(None, ge=0.0, le=1.0, allow_inf_nan=False)
    source: Source | None = None
    locked: bool | None = Field(None, description="false unlocks it (with force=true)")


class NetworkCreate(Strict):
    """A new network: a copy of `base` with `associations` over it."""

    EXAMPLES = (
        {"name": "my-dp", "base": "dp", "description": "dp, stopping sooner at red"},
        {
            "name": "mine",
            "base": None,
            "associations": [{"stimulus": "Red", "behaviour": "stop", "strength": 0.9}],
        },
    )

    name: NetworkName = Field(description="1-64 letters, digits, '-' and '_'; unique")
    description: str = Field("", max_length=2000)
    base: str | None = Field(
        "innate", max_length=100, description="the network to copy (null: start empty)"
    )
    associations: list[AssociationCreate] = Field(
        default_factory=list,
        max_length=MAX_ASSOCIATIONS,
        description="added to the base's in order, each replacing any earlier one of its pair",
    )


class NetworkSummaryPublic(BaseModel):
    """A stored network without its associations."""

    name: str
    description: str
    builtin: bool = Field(description="shipped with srlab, read-only: copy it to edit it")
    version: int = Field(description="bumped by every change (see /versions)")
    association_count: int
    created_at: datetime
    updated_at: datetime


class NetworksPublic(BaseModel):
    """Every stored network."""

    data: list[NetworkSummaryPublic]
    count: int


class NetworkPublic(NetworkSummaryPublic):
    """A stored network with its associations, in catalogue order."""

    associations: list[AssociationPublic]


class NetworkWritten(NetworkPublic):
    """A network as a write left it."""

    live_runs: list[int] = Field(
        description="ids of the running runs started from this network that got the change "
        "(live=true only)"
    )


class NetworkAssociationsPublic(BaseModel):
    """A network's associations, in catalogue order."""

    data: list[AssociationPublic]
    count: int
    version: int


class AssociationWritten(AssociationPublic):
    """An association as a write left it, with its network's version."""

    network: str
    version: int = Field(description="the network's version after the write")
    live_runs: list[int] = Field(
        description="ids of the running runs started from this network that got the change "
        "(live=true only)"
    )


class NetworkVersionPublic(BaseModel):
    """One entry of a network's edit history."""

    version: int
    created_at: datetime
    note: str
    association_count: int


class NetworkVersionsPublic(BaseModel):
    """A network's edit history, oldest first."""

    data: list[NetworkVersionPublic]
    count: int


class NetworkSnapshotPublic(BaseModel):
    """A network as it was at one version."""

    name: str
    version: int
    created_at: datetime
    note: str
    description: str
    associations: list[AssociationPublic]
    association_count: int


class AssociationChangePublic(BaseModel):
    """An association that changed between two versions."""

    stimulus: str
    behaviour: str
    before: AssociationPublic
    after: AssociationPublic


class NetworkDiffPublic(BaseModel):
    """What changed from one version of a network to another."""

    name: str
    from_version: int
    to_version: int
    added: list[AssociationPublic]
    removed: list[AssociationPublic]
    changed: list[AssociationChangePublic]


class NetworkRevert(Strict):
    """The version to make current again."""

    EXAMPLES = ({"version": 1},)

    version: int = Field(ge=1, le=2**31 - 1)


class NetworkDocument(Strict):
    """A network as a file: what GET .../export gives and POST /api/networks/import takes."""

    EXAMPLES = (
        {
            "format": "srlab-network/1",
            "name": "imported",
            "description": "",
            "associations": [
                {"stimulus": "Corner", "behaviour": "leftturn90", "source": "innate"},
                {"stimulus": "Red", "behaviour": "stop", "strength": 0.9},
            ],
        },
    )

    format: Literal["srlab-network/1"] = Field(description="the document's format and version")
    name: NetworkName = Field(description="1-64 letters, digits, '-' and '_'")
    description: str = Field("", max_length=2000)
    associations: list[AssociationCreate] = Field(
        max_length=MAX_ASSOCIATIONS,
        description="in order, each replacing any earlier one of its pair",
    )


# --- the event stream (GET /api/runs/{id}/events) -------------------------------------


class CompetitorEvent(BaseModel):
    behaviour: str | None
    stimulus: str
    value: float


class CompetitionEvent(BaseModel):
    threshold: float
    strategy: str
    values: list[CompetitorEvent] = Field(description="strongest first, at most 8")


class TickEvent(BaseModel):
    """`event: tick`: a snapshot (throttled to tick_hz)."""

    episode: int
    tick: int
    episode_tick: int
    x: float
    y: float
    heading_rad: float
    stimuli: list[str]
    behaviour: str | None
    how: HowName
    origin: str
    released_by: str | None
    lamp: Literal["none", "red", "yellow", "green"]
    progress_m: float
    sonar_m: list[float] = Field(
        default_factory=list,
        description="the sonars' readings of that tick, sonar 0 first (their mounts and "
        "axes are in GET /api/runs/{id}/world)",
    )
    obstacle: list[float] | None = Field(
        None, description="the obstacle's centre [x, y] in metres; null: this episode has none"
    )
    competition: CompetitionEvent | None = None


class CreditEvent(BaseModel):
    tick: int
    stimulus: str
    behaviour: str | None
    d_k: int
    before: float
    after: float


class RewardEvent(BaseModel):
    """`event: reward`: a reward applied, with the STM records it credited (at most 200)."""

    tick: int
    episode: int
    value: float
    source: RewardSource
    note: str
    credits: list[CreditEvent]
    credited: int
    uid: str = Field(
        description="the reward's id from its arrival: its 202, its log entry and its event "
        "on the run's stream carry it (the log's `id` is the database's)"
    )


class EpisodeEvent(BaseModel):
    """`event: episode`: an episode ended."""

    episode: int
    outcome: OutcomeName
    cause: CauseName | None
    ticks: int


class AssociationEvent(BaseModel):
    """`event: association`: an association joined or left the behaviour network."""

    change: Literal["promoted", "demoted"]
    stimulus: str
    behaviour: str | None
    reliability: float


class StatusEvent(BaseModel):
    """`event: status`: the run's status (first event; the stream ends after the last)."""

    status: RunStatusName
    error: str | None = None
    run: int | None = Field(None, description="in the first event only")


STREAM_EVENTS: dict[str, type[BaseModel]] = {
    "tick": TickEvent,
    "reward": RewardEvent,
    "episode": EpisodeEvent,
    "association": AssociationEvent,
    "status": StatusEvent,
}
"""The event stream's events by name, described in /openapi.json."""


class RstmRecordPublic(BaseModel):
    """A low-level response the RSTM recorded while a camera stimulus was perceived."""

    tick: int
    camera_stimulus: str
    sonar_stimulus: str
    behaviour: str


class RstmPublic(BaseModel):
    """One high-level logical sensor's RSTM: what the next reward will reason over."""

    sensor: str
    records: list[RstmRecordPublic]


class KpPerceptPublic(BaseModel):
    """The camera stimulus last perceived for an objective.

    Sonar responses up to `window_ticks` after `tick` are recorded against it.
    """

    objective: str
    camera_stimulus: str
    tick: int
    open: bool = Field(description="whether the window is still open at the run's tick")


class KpSourcePublic(BaseModel):
    """A source S0_i -> B_i of a reasoning, with the heading B_i drives to."""

    tick: int
    sonar_stimulus: str
    behaviour: str
    heading_deg: float


class KpProvenancePublic(BaseModel):
    """How one reward's reasoningKPM made the association: sources, vector sum, snap."""

    after_tick: int = Field(description="the last tick before the reward that reasoned")
    sources: list[KpSourcePublic]
    sum_x: float = Field(description="vector sum of the sources' unit headings, along")
    sum_y: float = Field(description="the same, across (+ = left)")
    heading_deg: float = Field(description="the direction of the vector sum")
    speed_mps: float = Field(description="the sources' mean speed")
    nearest: str = Field(description="the primitive whose heading is nearest the sum")
    nearest_heading_deg: float
    behaviour: str
    resolution: Literal["snapped", "synthesized", "reused"]


class RltmPointPublic(BaseModel):
    """One Eq. (1) step of the pair's RLTM reliability."""

    model_config = ConfigDict(from_attributes=True)  # read from a core or store object

    after_tick: int
    reward: float
    before: float
    after: float


class KpRunSpanPublic(BaseModel):
    """Ticks first..last (inclusive) where the association ran as a ``kp`` association."""

    first_tick: int
    last_tick: int


class KpAssociationPublic(BaseModel):
    """An S1 -> B pair knowledge propagation made, with how it came to be."""

    stimulus: str
    behaviour: str
    reliability: float = Field(description="its RLTM reliability now")
    in_network: bool = Field(description="whether it is in the run's behaviour network")
    synthesized: bool = Field(description="whether B is a behaviour KP synthesised")
    provenance: list[KpProvenancePublic] = Field(
        description="the latest reasonings that gave it, oldest first (live runs only)"
    )
    history: list[RltmPointPublic] = Field(description="its RLTM steps, oldest first")
    runs: list[KpRunSpanPublic] = Field(description="where it ran, oldest first")
    reasoned: int = Field(description="rewards that reasoned it, in this engine's life")
    ran_ticks: int = Field(description="ticks it ran, in this engine's life")


class KpPublic(BaseModel):
    """A run's knowledge propagation: RSTM now and every KP-made association's provenance.

    `kp` is false for a run whose condition does not propagate (`reason` says so). `live`
    is false for a run not running here: the RSTM and provenance are kept in the running
    engine only, so such a run answers its stored RLTM and network with `reason`.
    """

    run: int
    condition: str
    kp: bool
    live: bool
    reason: str | None = None
    tick: int | None = None
    window_ticks: int | None = None
    rstm: list[RstmPublic] = Field(default_factory=list)
    percepts: list[KpPerceptPublic] = Field(default_factory=list)
    associations: list[KpAssociationPublic] = Field(default_factory=list)
    count: int = 0
    insert_threshold: float | None = Field(
        None, description="the RLTM reliability at which a KP pair joins the behaviour network"
    )
