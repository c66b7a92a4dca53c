"""The HTTP API's models: pydantic at the edge only."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from core.conditions import CONDITIONS

EngineCondition = Literal["innate", "delayed", "dp", "rp", "kp", "expert"]
assert set(EngineCondition.__args__) == {  # type: ignore[attr-defined]
    n for n, c in CONDITIONS.items() if c.agent == "brain"
}


class Strict(BaseModel):
    """Unknown fields are an error, not silently ignored."""

    model_config = ConfigDict(extra="forbid")


class Health(BaseModel):
    status: Literal["ok"]
    version: str
    database: str
    runs_active: int


class StimulusPublic(BaseModel):
    name: str
    sensor: str
    objective: str
    level: Literal["low", "high"]
    priority: int


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
    name: str
    physical: list[str]
    processing: str
    objective: str
    level: Literal["low", "high"]
    priority: int
    weight: float
    stimuli: list[str]


class LearningParams(Strict):
    eta: float | None = Field(None, ge=0.0, le=1.0, description="Eq. (1)'s learning rate")
    epsilon: float | None = Field(None, ge=0.0, le=1.0, description="exploration rate")
    synthesize: bool = Field(False, description="KP keeps new behaviours instead of snapping")


class RunCreate(Strict):
    condition: EngineCondition
    seed: int = Field(0, ge=0, le=2**31 - 1)
    episodes: int | None = Field(None, ge=1, le=1_000_000, description="None: until stopped")
    mode: Literal["fast", "realtime"] = "fast"
    hz: float = Field(10.0, gt=0.0, le=1000.0, description="realtime tick rate")
    network: str | None = Field(
        None,
        max_length=100,
        description="a stored network to start from (default: the condition's)",
    )
    params: LearningParams = Field(default_factory=LearningParams)


class LiveState(BaseModel):
    tick: int
    episode: int
    hz: float
    ticks_run: int
    lateness_p99_ms: float | None


class RunPublic(BaseModel):
    id: int
    condition: str
    seed: int
    episodes: int | None
    mode: str
    hz: float
    network: str | None
    params: dict[str, float | bool]
    status: str
    error: str | None
    episodes_done: int
    successes: int
    ticks: int
    live: LiveState | None = None


class RunsPublic(BaseModel):
    data: list[RunPublic]
    count: int


class RewardCreate(Strict):
    value: float = Field(ge=-1.0, le=1.0, description="the reward, -1 (bad) to 1 (good)")
    note: str = Field("", max_length=500)


class RewardAccepted(BaseModel):
    id: int
    tick: int
    episode: int
    value: float


class RewardPublic(BaseModel):
    id: int
    tick: int
    episode: int
    value: float
    source: str
    note: str
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
    stimulus: str
    behaviour: str
    strength: float
    source: str
    locked: bool


class RunNetworkPublic(BaseModel):
    data: list[AssociationPublic]
    count: int


class EpisodePublic(BaseModel):
    episode: int
    outcome: str
    cause: str | None
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
    how: str
    lamp: int
    stimuli: list[str]


class EpisodeDetail(EpisodePublic):
    trace: list[TraceRowPublic]
