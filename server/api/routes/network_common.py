"""What the network routes share: parameters, If-Match, answers, the HTTP models' mapping."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Annotated, Any

from fastapi import Depends, Header, Path, Query, Response

from core.networks import ExpectedVersion, ReadOnlyNetworkError, StoredNetwork
from core.ports import NetworkPair
from server.api import etags
from server.api.deps import StateDep
from server.api.errors import ErrorPublic, StalePublic
from server.schemas import AssociationCreate, AssociationPublic, NetworkPublic, NetworkWritten, Text
from server.services.networks import NetworkService

StoredName = Annotated[Text, Path(max_length=100, description="a stored network's name")]
StimulusName = Annotated[Text, Path(max_length=100, description="a stimulus name")]
BehaviourName = Annotated[Text, Path(max_length=100, description="a behaviour name")]
Live = Annotated[
    bool,
    Query(
        description="also apply the change to every running run started from this network, "
        "at its next tick boundary"
    ),
]
Force = Annotated[bool, Query(description="change or remove locked associations too")]
Note = Annotated[Text, Query(max_length=500, description="a note for the network's history")]
_TAG = r'(W/)?("[!#-~]*"|[!#-+\--~]+)'
ENTITY_TAGS = rf"^(\*|{_TAG}([ \t]*,[ \t]*{_TAG})*)$"
"""`If-Match` as HTTP writes it: `*`, or entity tags (`"v3-1a2b..."`, as an ETag gave
them, weak ones `W/"..."`), comma-separated. A tag without its quotes is taken as the
quoted one (a client that dropped them means the same tag)."""

_E = dict[int | str, dict[str, Any]]
NOT_FOUND: _E = {404: {"model": ErrorPublic, "description": "no such network"}}
CONFLICT: _E = {
    409: {
        "model": ErrorPublic,
        "description": "a built-in network (read-only), or a locked association without force",
    }
}
LIVE_RUNS_HEADER = "Srlab-Live-Runs"
VERSION_HEADER = "Srlab-Network-Version"
STALE: _E = {
    412: {
        "model": StalePublic,
        "description": "If-Match or expected_version names a version that is no longer "
        "current: read the network again and reapply the change",
    }
}
ETAG = {
    "ETag": {
        "description": "the network's version as an entity tag, for If-Match",
        "schema": {"type": "string"},
    }
}


async def _expected(
    if_match: Annotated[
        str | None,
        Header(
            max_length=1000,
            pattern=ENTITY_TAGS,
            examples=['"v3-1a2b3c4d5e6f"', "*"],
            description="write only if the network is still at one of these entity tags "
            '(an ETag from a read, e.g. `"v3-1a2b3c4d5e6f"`; `*`: any version); 412 otherwise',
        ),
    ] = None,
    expected_version: Annotated[
        int | None,
        Query(
            ge=1,
            le=2**31 - 1,
            description="write only if the network is still at this version; 412 otherwise",
        ),
    ] = None,
) -> ExpectedVersion | None:
    """What a write expects of the network: If-Match's tags and/or a version."""
    return etags.expected(if_match, expected_version)


Expected = Annotated[ExpectedVersion | None, Depends(_expected)]


async def _service(state: StateDep) -> NetworkService:
    return NetworkService(state.networks, state.engines, state.run_networks)


Service = Annotated[NetworkService, Depends(_service)]


@contextmanager
def answers() -> Iterator[None]:
    """The core's refusals as the API words them: a built-in network names its copy's request."""
    try:
        yield
    except ReadOnlyNetworkError as e:
        name, what = e.network, e.what
        raise ReadOnlyNetworkError(
            name,
            what,
            f"network {name!r} is built in and cannot be {what}: copy it first with "
            f'POST /api/networks {{"name": "my-{name}", "base": "{name}"}} and edit the copy',
        ) from e


def set_etag(response: Response, network: StoredNetwork) -> None:
    """The network's version as the answer's `ETag`, for If-Match."""
    response.headers["ETag"] = etags.etag(network.fingerprint)


def association_public(p: NetworkPair) -> AssociationPublic:
    """An association as the API shows it."""
    return AssociationPublic(
        stimulus=p.stimulus,
        behaviour=p.behaviour,
        strength=p.strength,
        source=p.source,
        locked=p.locked,
    )


def pair_of(a: AssociationCreate) -> NetworkPair:
    """An association of a request body as the store takes it."""
    return NetworkPair(a.stimulus, a.behaviour, a.strength, a.source, a.locked)


def network_public(n: StoredNetwork) -> NetworkPublic:
    """A stored network as the API shows it, with its associations."""
    return NetworkPublic(
        name=n.name,
        description=n.description,
        builtin=n.builtin,
        version=n.version,
        association_count=len(n.associations),
        created_at=n.created_at,
        updated_at=n.updated_at,
        associations=[association_public(p) for p in n.associations],
    )


def written_public(n: StoredNetwork, live_runs: list[int]) -> NetworkWritten:
    """A network as a write left it, with the live runs that got the change."""
    return NetworkWritten(**network_public(n).model_dump(), live_runs=live_runs)
