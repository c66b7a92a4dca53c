"""Stored networks and their associations: the DP S-R editor's operations.

Built-in networks (innate, dp, kp, expert: the knowledge sets srlab ships) are read-only;
copy one with `POST /api/networks {"name": ..., "base": ...}` and edit the copy. Every
change makes a new version of the network (see `/versions`); a change that changes
nothing makes none. A locked association changes only with `force=true`. With
`live=true` a write also reaches every running run started from the network, at its next
tick boundary; without it running robots are untouched.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Annotated, Any, cast

from fastapi import Depends, Header, HTTPException, Path, Query, Response, status
from fastapi.exceptions import RequestValidationError
from starlette.concurrency import run_in_threadpool as io

from core.brain.catalog import Catalog, Source
from core.networks import ExpectedVersion, ReadOnlyNetworkError, StoredNetwork
from core.ports import NetworkPair, NetworkRepository
from server.api import etags
from server.api.deps import NetworksDep, StateDep, WriteGuard
from server.api.errors import ErrorPublic, StalePublic
from server.api.routes.runs import Limit, Offset
from server.api.routing import resource_router
from server.schemas import (
    NETWORK_FORMAT,
    AssociationChangePublic,
    AssociationCreate,
    AssociationPublic,
    AssociationUpdate,
    AssociationWritten,
    NetworkAssociationsPublic,
    NetworkCreate,
    NetworkDiffPublic,
    NetworkDocument,
    NetworkName,
    NetworkPublic,
    NetworkRevert,
    NetworkSnapshotPublic,
    NetworksPublic,
    NetworkSummaryPublic,
    NetworkVersionPublic,
    NetworkVersionsPublic,
    NetworkWritten,
    Text,
)
from server.services.networks import NetworkService, Written

router = resource_router("/networks", tag="networks")

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
MAX_NETWORKS = 1000
"""The most networks of their own users keep (besides the built-in ones): GET
/api/networks answers every one, so their number bounds what it costs."""
_TAG = r'(W/)?("[!#-~]*"|[!#-+\--~]+)'
ENTITY_TAGS = rf"^(\*|{_TAG}([ \t]*,[ \t]*{_TAG})*)$"
"""`If-Match` as HTTP writes it: `*`, or entity tags (`"v3-1a2b..."`, as an ETag gave
them, weak ones `W/"..."`), comma-separated. A tag without its quotes is taken as the
quoted one (a client that dropped them means the same tag)."""

_E = dict[int | str, dict[str, Any]]
_NOT_FOUND: _E = {404: {"model": ErrorPublic, "description": "no such network"}}
_CONFLICT: _E = {
    409: {
        "model": ErrorPublic,
        "description": "a built-in network (read-only), or a locked association without force",
    }
}
LIVE_RUNS_HEADER = "Srlab-Live-Runs"
VERSION_HEADER = "Srlab-Network-Version"
_STALE: _E = {
    412: {
        "model": StalePublic,
        "description": "If-Match or expected_version names a version that is no longer "
        "current: read the network again and reapply the change",
    }
}
_ETAG = {
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
def _answers() -> Iterator[None]:
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


def _tag(response: Response, network: StoredNetwork) -> None:
    response.headers["ETag"] = etags.etag(network.fingerprint)


def _association(p: NetworkPair) -> AssociationPublic:
    return AssociationPublic(
        stimulus=p.stimulus,
        behaviour=p.behaviour,
        strength=p.strength,
        source=p.source,
        locked=p.locked,
    )


def _pair(a: AssociationCreate) -> NetworkPair:
    return NetworkPair(a.stimulus, a.behaviour, a.strength, a.source, a.locked)


def _public(n: StoredNetwork) -> NetworkPublic:
    return NetworkPublic(
        name=n.name,
        description=n.description,
        builtin=n.builtin,
        version=n.version,
        association_count=len(n.associations),
        created_at=n.created_at,
        updated_at=n.updated_at,
        associations=[_association(p) for p in n.associations],
    )


def _written(n: StoredNetwork, live_runs: list[int]) -> NetworkWritten:
    return NetworkWritten(**_public(n).model_dump(), live_runs=live_runs)


def _check_names(
    catalog: Catalog, items: Sequence[AssociationCreate], loc: tuple[str | int, ...], many: bool
) -> None:
    """422 naming the field for stimulus and behaviour names the catalogue lacks."""
    stimuli = {s.name for s in catalog.stimuli}
    behaviours = {b.name for b in catalog.behaviours}
    errors: list[dict[str, Any]] = []
    for i, a in enumerate(items):
        at = (*loc, i) if many else loc
        for field, value, known in (
            ("stimulus", a.stimulus, stimuli),
            ("behaviour", a.behaviour, behaviours),
        ):
            if value not in known:
                errors.append(
                    {
                        "type": "value_error",
                        "loc": (*at, field),
                        "msg": f"unknown {field} {value!r}",
                        "input": value,
                    }
                )
    if errors:
        raise RequestValidationError(errors)


async def _room_for(networks: NetworkRepository, name: str) -> None:
    """409 when a network named `name` would be one more than `MAX_NETWORKS`."""
    own = {x.name for x in await io(networks.summaries) if not x.builtin}
    if len(own) >= MAX_NETWORKS and name not in own:
        raise HTTPException(
            status.HTTP_409_CONFLICT,
            f"there are {len(own):,} networks besides the built-in ones, the most this "
            "service keeps: delete one (DELETE /api/networks/{name}) before making another",
        )


@router.get("")
def list_networks(networks: NetworksDep) -> NetworksPublic:
    """Every stored network, built-in ones first, with its version and size."""
    data = [
        NetworkSummaryPublic(
            name=s.name,
            description=s.description,
            builtin=s.builtin,
            version=s.version,
            association_count=s.association_count,
            created_at=s.created_at,
            updated_at=s.updated_at,
        )
        for s in networks.summaries()
    ]
    return NetworksPublic(data=data, count=len(data))


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    dependencies=[WriteGuard],
    responses={
        404: {"model": ErrorPublic, "description": "no such base network"},
        409: {
            "model": ErrorPublic,
            "description": "the name is taken, or there are 1,000 networks besides the "
            "built-in ones already",
        },
    },
)
async def create_network(
    body: NetworkCreate, service: Service, state: StateDep, note: Note = ""
) -> NetworkPublic:
    """Create an editable network: a copy of `base` (innate by default, null for none).

    This is how a built-in network is edited: copy it and change the copy. 409 once there
    are 1,000 networks besides the built-in ones: delete one first.
    """
    _check_names(state.catalog, body.associations, ("body", "associations"), many=True)
    await _room_for(state.networks, body.name)
    created = await service.create(
        body.name,
        description=body.description,
        base=body.base,
        associations=[_pair(a) for a in body.associations],
        note=note,
    )
    return _public(created)


@router.post(
    "/import",
    status_code=status.HTTP_201_CREATED,
    dependencies=[WriteGuard],
    responses={
        200: {"model": NetworkWritten, "description": "replaced: a new version of the network"},
        409: {
            "model": ErrorPublic,
            "description": "the name is taken (import under another ?name= or ?replace=true), "
            "a built-in network, a locked association without force, or a new network "
            "past the 1,000 kept besides the built-in ones",
        },
        **_STALE,
    },
)
async def import_network(
    body: NetworkDocument,
    response: Response,
    service: Service,
    state: StateDep,
    expected: Expected,
    name: Annotated[
        NetworkName | None, Query(description="store it under this name, not the document's")
    ] = None,
    replace: Annotated[
        bool, Query(description="replace an existing network's associations (a new version)")
    ] = False,
    force: Force = False,
    live: Live = False,
    note: Note = "",
) -> NetworkWritten:
    """Import a document GET .../export gave: 201 as a new network, 200 when replacing one."""
    target = name or body.name
    _check_names(state.catalog, body.associations, ("body", "associations"), many=True)
    await _room_for(state.networks, target)
    with _answers():
        written = await service.import_network(
            target,
            [_pair(a) for a in body.associations],
            description=body.description,
            replace=replace,
            force=force,
            note=note,
            expected=expected,
            live=live,
        )
    if not written.edit.created:
        response.status_code = status.HTTP_200_OK
    _tag(response, written.edit.network)
    return _written(written.edit.network, written.live_runs)


@router.get("/{name}", responses={**_NOT_FOUND, 200: {"headers": _ETAG}})
def get_network(name: StoredName, networks: NetworksDep, response: Response) -> NetworkPublic:
    """A network with its associations and version (its `ETag`, for If-Match)."""
    n = networks.get(name)
    _tag(response, n)
    return _public(n)


@router.delete(
    "/{name}",
    status_code=status.HTTP_204_NO_CONTENT,
    response_class=Response,
    dependencies=[WriteGuard],
    responses={
        **_NOT_FOUND,
        409: {"model": ErrorPublic, "description": "a built-in network"},
        **_STALE,
    },
)
async def delete_network(name: StoredName, service: Service, expected: Expected) -> Response:
    """Delete a network and its history; built-in networks cannot be deleted.

    Runs started from it keep the copy they started with; live edits no longer reach them.
    """
    with _answers():
        await service.delete(name, expected=expected)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get("/{name}/associations", responses={**_NOT_FOUND, 200: {"headers": _ETAG}})
def list_associations(
    name: StoredName, networks: NetworksDep, response: Response
) -> NetworkAssociationsPublic:
    """A network's associations, in catalogue order (its `ETag`, for If-Match)."""
    n = networks.get(name)
    _tag(response, n)
    data = [_association(p) for p in n.associations]
    return NetworkAssociationsPublic(data=data, count=len(data), version=n.version)


def _association_written(written: Written, stimulus: str, behaviour: str) -> AssociationWritten:
    n, live_runs = written.edit.network, written.live_runs
    pair = next(p for p in n.associations if (p.stimulus, p.behaviour) == (stimulus, behaviour))
    return AssociationWritten(
        **_association(pair).model_dump(), network=n.name, version=n.version, live_runs=live_runs
    )


@router.post(
    "/{name}/associations",
    status_code=status.HTTP_201_CREATED,
    dependencies=[WriteGuard],
    responses={
        **_NOT_FOUND,
        409: {
            "model": ErrorPublic,
            "description": "the network has this pair already (PUT changes it), "
            "or it is built in (read-only)",
        },
        **_STALE,
    },
)
async def add_association(
    name: StoredName,
    body: AssociationCreate,
    service: Service,
    state: StateDep,
    response: Response,
    expected: Expected,
    live: Live = False,
    note: Note = "",
) -> AssociationWritten:
    """Add an association the network does not have yet (PUT changes one it has)."""
    _check_names(state.catalog, [body], ("body",), many=False)
    with _answers():
        written = await service.add_association(
            name, _pair(body), note=note, expected=expected, live=live
        )
    _tag(response, written.edit.network)
    return _association_written(written, body.stimulus, body.behaviour)


@router.put(
    "/{name}/associations/{stimulus}/{behaviour}",
    dependencies=[WriteGuard],
    responses={
        404: {"model": ErrorPublic, "description": "no such network, stimulus or behaviour"},
        **_CONFLICT,
        **_STALE,
    },
)
async def put_association(
    name: StoredName,
    stimulus: StimulusName,
    behaviour: BehaviourName,
    body: AssociationUpdate,
    service: Service,
    response: Response,
    expected: Expected,
    force: Force = False,
    live: Live = False,
    note: Note = "",
) -> AssociationWritten:
    """Set an association, adding it if the network lacks it; omitted fields keep their value.

    A locked association changes only with `force=true`; unlocking is `{"locked": false}`
    with `force=true`. With `live=true` running runs get the association as it now is, even
    when the stored network did not change (a way to push a stored edit to them later).
    """
    with _answers():
        written = await service.put_association(
            name,
            stimulus,
            behaviour,
            strength=body.strength,
            source=body.source,
            locked=body.locked,
            force=force,
            note=note,
            expected=expected,
            live=live,
        )
    _tag(response, written.edit.network)
    return _association_written(written, stimulus, behaviour)


@router.delete(
    "/{name}/associations/{stimulus}/{behaviour}",
    status_code=status.HTTP_204_NO_CONTENT,
    response_class=Response,
    dependencies=[WriteGuard],
    responses={
        204: {
            "description": "removed",
            "headers": {
                VERSION_HEADER: {
                    "description": "the network's version after the removal",
                    "schema": {"type": "integer"},
                },
                LIVE_RUNS_HEADER: {
                    "description": "comma-separated ids of the running runs that got the "
                    "removal (live=true only)",
                    "schema": {"type": "string"},
                },
            },
        },
        404: {"model": ErrorPublic, "description": "no such network or association"},
        **_CONFLICT,
        **_STALE,
    },
)
async def remove_association(
    name: StoredName,
    stimulus: StimulusName,
    behaviour: BehaviourName,
    service: Service,
    expected: Expected,
    force: Force = False,
    live: Live = False,
    note: Note = "",
) -> Response:
    """Remove an association; a locked one only with `force=true`."""
    with _answers():
        written = await service.remove_association(
            name, stimulus, behaviour, force=force, note=note, expected=expected, live=live
        )
    network = written.edit.network
    headers = {
        "ETag": etags.etag(network.fingerprint),
        VERSION_HEADER: str(network.version),
        LIVE_RUNS_HEADER: ",".join(map(str, written.live_runs)),
    }
    return Response(status_code=status.HTTP_204_NO_CONTENT, headers=headers)


@router.get("/{name}/versions", responses=_NOT_FOUND)
def list_versions(
    name: StoredName, networks: NetworksDep, offset: Offset = 0, limit: Limit = 100
) -> NetworkVersionsPublic:
    """The network's edit history, oldest first, a page at a time (`count`: all of them).

    Version 1 is how it was made or seeded; the newest page starts at `count - limit`.
    """
    page, total = networks.versions_page(name, offset, limit)
    data = [
        NetworkVersionPublic(
            version=v.version,
            created_at=v.created_at,
            note=v.note,
            association_count=v.association_count,
        )
        for v in page
    ]
    return NetworkVersionsPublic(data=data, count=total)


Version = Annotated[int, Path(ge=1, le=2**31 - 1, description="a version of the network")]


@router.get(
    "/{name}/versions/{version}",
    responses={404: {"model": ErrorPublic, "description": "no such network or version"}},
)
def get_version(name: StoredName, version: Version, networks: NetworksDep) -> NetworkSnapshotPublic:
    """The network as it was at one version."""
    snap = networks.snapshot(name, version)
    return NetworkSnapshotPublic(
        name=snap.name,
        version=snap.version,
        created_at=snap.created_at,
        note=snap.note,
        description=snap.description,
        associations=[_association(p) for p in snap.associations],
        association_count=len(snap.associations),
    )


@router.get(
    "/{name}/diff",
    responses={404: {"model": ErrorPublic, "description": "no such network or version"}},
)
def diff_versions(
    name: StoredName,
    networks: NetworksDep,
    from_version: Annotated[
        int | None,
        Query(alias="from", ge=1, le=2**31 - 1, description="default: the version before `to`"),
    ] = None,
    to_version: Annotated[
        int | None, Query(alias="to", ge=1, le=2**31 - 1, description="default: the current")
    ] = None,
) -> NetworkDiffPublic:
    """The associations added, removed and changed from version `from` to version `to`."""
    to = to_version if to_version is not None else networks.get(name).version
    start = from_version if from_version is not None else max(1, to - 1)
    changes = networks.diff(name, start, to)
    return NetworkDiffPublic(
        name=name,
        from_version=start,
        to_version=to,
        added=[_association(c.after) for c in changes if c.before is None and c.after],
        removed=[_association(c.before) for c in changes if c.after is None and c.before],
        changed=[
            AssociationChangePublic(
                stimulus=c.stimulus,
                behaviour=c.behaviour,
                before=_association(c.before),
                after=_association(c.after),
            )
            for c in changes
            if c.before is not None and c.after is not None
        ],
    )


@router.post(
    "/{name}/revert",
    dependencies=[WriteGuard],
    responses={
        404: {"model": ErrorPublic, "description": "no such network or version"},
        **_CONFLICT,
        **_STALE,
    },
)
async def revert_network(
    name: StoredName,
    body: NetworkRevert,
    service: Service,
    response: Response,
    expected: Expected,
    force: Force = False,
    live: Live = False,
    note: Note = "",
) -> NetworkWritten:
    """Make the network what it was at `version`, as a new version (history is kept).

    Changing or removing locked associations needs `force=true`.
    """
    with _answers():
        written = await service.revert(
            name, body.version, force=force, note=note, expected=expected, live=live
        )
    _tag(response, written.edit.network)
    return _written(written.edit.network, written.live_runs)


@router.get("/{name}/export", responses=_NOT_FOUND)
def export_network(name: StoredName, networks: NetworksDep, response: Response) -> NetworkDocument:
    """The network as a document POST /api/networks/import takes, as a file to save."""
    n = networks.get(name)
    _tag(response, n)
    filename = re.sub(r"[^A-Za-z0-9_-]", "_", n.name) or "network"
    response.headers["Content-Disposition"] = f'attachment; filename="{filename}.json"'
    return NetworkDocument(
        format=NETWORK_FORMAT,
        name=n.name,
        description=n.description,
        associations=[
            AssociationCreate(
                stimulus=p.stimulus,
                behaviour=p.behaviour,
                strength=p.strength,
                source=cast(Source, p.source),
                locked=p.locked,
            )
            for p in n.associations
        ],
    )
