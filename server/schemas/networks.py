"""Stored networks: the DP S-R editor's associations, versions, diffs and files."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    JsonValue,
    StringConstraints,
    WithJsonSchema,
)

from core.brain.catalog import Source, load_catalog
from server.schemas.common import Strict


class AssociationPublic(BaseModel):
    model_config = ConfigDict(from_attributes=True)  # read from a core or store object

    stimulus: str
    behaviour: str
    strength: float
    source: Source
    locked: bool


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
