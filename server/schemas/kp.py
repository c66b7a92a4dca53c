"""Knowledge propagation's inspector: RSTM, percepts and each KP association's provenance."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field


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
