"""Rewards in, and the run's event stream out (GET /api/runs/{id}/events)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import AwareDatetime, BaseModel, Field

from core.commands import RewardSource
from server.schemas.common import Strict
from server.schemas.runs import CauseName, HowName, OutcomeName, RunStatusName

TickSeen = Annotated[
    int | None,
    Field(
        description="the tick its trainer saw when they pressed (null: the reward credits "
        "every STM record before its boundary, the paper's rule)"
    ),
]
CreditWindow = Annotated[
    tuple[int, int] | None,
    Field(
        description="[first, last]: the ticks a reward with `tick_seen` could credit, its "
        "reaction window before the seen tick (null without `tick_seen`)"
    ),
]


class RewardCreate(Strict):
    EXAMPLES = (
        {"value": 1.0, "note": "a clean pass of the obstacle"},
        {"value": -0.5},
        {"value": -1.0, "tick_seen": 484, "note": "that turn into the wall"},
    )

    value: float = Field(ge=-1.0, le=1.0, description="the reward, -1 (bad) to 1 (good)")
    note: str = Field("", max_length=500)
    tick_seen: int | None = Field(
        None,
        ge=0,
        le=2**53 - 1,  # exact in every JSON reader
        description="the tick the trainer was looking at when they pressed: the reward "
        "credits the run's reaction window before it (docs/studies.md); a tick the run has "
        "reached, in its current episode or the one that ended last (null: every STM "
        "record before the next boundary)",
    )
    episode: int | None = Field(
        None,
        ge=0,
        le=2**31 - 1,
        description="the episode `tick_seen` belongs to (default: the one it lies in)",
    )


class RewardAccepted(BaseModel):
    id: int
    tick: int
    episode: int
    value: float
    uid: str = Field(
        description="the reward's id from its arrival: its 202, its log entry and its event "
        "on the run's stream carry it (the log's `id` is the database's)"
    )
    tick_seen: TickSeen
    window: CreditWindow
    seen_episode: int | None = Field(description="the episode of `tick_seen`")


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
    tick_seen: TickSeen
    window: CreditWindow
    seen_episode: int | None = Field(description="the episode of `tick_seen`")
    applied: bool
    credited: int
    at: AwareDatetime | None = Field(
        description="when the reward log took it (UTC, the database's clock; to the second "
        "on SQLite)"
    )


class RewardsPublic(BaseModel):
    data: list[RewardPublic]
    count: int


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
        None,
        description="the first obstacle's centre [x, y] in metres; null: this episode has none",
    )
    obstacles: list[list[float]] = Field(
        default_factory=list,
        description="every obstacle's centre [x, y] at that tick, the first first (a moving "
        "one where it has moved to)",
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
    tick_seen: TickSeen
    window: CreditWindow


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
