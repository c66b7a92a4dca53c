"""Stored networks and their associations: the DP S-R editor's operations.

Built-in networks (innate, dp, kp, expert: the knowledge sets srlab ships) are read-only;
copy one with `POST /api/networks {"name": ..., "base": ...}` and edit the copy. Every
change makes a new version of the network (see `/versions`); a change that changes
nothing makes none. A locked association changes only with `force=true`. With
`live=true` a write also reaches every running run started from the network, at its next
tick boundary; without it running robots are untouched. The history (versions, diffs,
revert) and the export are `network_history`'s.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Any

from fastapi import HTTPException, Query, Response, status
from fastapi.exceptions import RequestValidationError
from starlette.concurrency import run_in_threadpool as io

from core.brain.catalog import Catalog
from core.ports import NetworkRepository
from server.api import etags
from server.api.deps import NetworksDep, StateDep, WriteGuard
from server.api.errors import ErrorPublic
from server.api.routes.network_common import (
    CONFLICT,
    ETAG,
    LIVE_RUNS_HEADER,
    NOT_FOUND,
    STALE,
    VERSION_HEADER,
    BehaviourName,
    Expected,
    Force,
    Live,
    Note,
    Service,
    StimulusName,
    StoredName,
    answers,
    association_public,
    network_public,
    pair_of,
    set_etag,
    written_public,
)
from server.api.routing import resource_router
from server.schemas import (
    AssociationCreate,
    AssociationUpdate,
    AssociationWritten,
    NetworkAssociationsPublic,
    NetworkCreate,
    NetworkDocument,
    NetworkName,
    NetworkPublic,
    NetworksPublic,
    NetworkSummaryPublic,
    NetworkWritten,
)
from server.services.networks import Written

router = resource_router("/networks", tag="networks")

MAX_NETWORKS = 1000
"""The most networks of their own users keep (besides the built-in ones): GET
/api/networks answers every one, so their number bounds what it costs."""


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
        associations=[pair_of(a) for a in body.associations],
        note=note,
    )
    return network_public(created)


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
        **STALE,
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
    with answers():
        written = await service.import_network(
            target,
            [pair_of(a) for a in body.associations],
            description=body.description,
            replace=replace,
            force=force,
            note=note,
            expected=expected,
            live=live,
        )
    if not written.edit.created:
        response.status_code = status.HTTP_200_OK
    set_etag(response, written.edit.network)
    return written_public(written.edit.network, written.live_runs)


@router.get("/{name}", responses={**NOT_FOUND, 200: {"headers": ETAG}})
def get_network(name: StoredName, networks: NetworksDep, response: Response) -> NetworkPublic:
    """A network with its associations and version (its `ETag`, for If-Match)."""
    n = networks.get(name)
    set_etag(response, n)
    return network_public(n)


@router.delete(
    "/{name}",
    status_code=status.HTTP_204_NO_CONTENT,
    response_class=Response,
    dependencies=[WriteGuard],
    responses={
        **NOT_FOUND,
        409: {"model": ErrorPublic, "description": "a built-in network"},
        **STALE,
    },
)
async def delete_network(name: StoredName, service: Service, expected: Expected) -> Response:
    """Delete a network and its history; built-in networks cannot be deleted.

    Runs started from it keep the copy they started with; live edits no longer reach them.
    """
    with answers():
        await service.delete(name, expected=expected)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.get("/{name}/associations", responses={**NOT_FOUND, 200: {"headers": ETAG}})
def list_associations(
    name: StoredName, networks: NetworksDep, response: Response
) -> NetworkAssociationsPublic:
    """A network's associations, in catalogue order (its `ETag`, for If-Match)."""
    n = networks.get(name)
    set_etag(response, n)
    data = [association_public(p) for p in n.associations]
    return NetworkAssociationsPublic(data=data, count=len(data), version=n.version)


def _association_written(written: Written, stimulus: str, behaviour: str) -> AssociationWritten:
    n, live_runs = written.edit.network, written.live_runs
    pair = next(p for p in n.associations if (p.stimulus, p.behaviour) == (stimulus, behaviour))
    return AssociationWritten(
        **association_public(pair).model_dump(),
        network=n.name,
        version=n.version,
        live_runs=live_runs,
    )


@router.post(
    "/{name}/associations",
    status_code=status.HTTP_201_CREATED,
    dependencies=[WriteGuard],
    responses={
        **NOT_FOUND,
        409: {
            "model": ErrorPublic,
            "description": "the network has this pair already (PUT changes it), "
            "or it is built in (read-only)",
        },
        **STALE,
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
    with answers():
        written = await service.add_association(
            name, pair_of(body), note=note, expected=expected, live=live
        )
    set_etag(response, written.edit.network)
    return _association_written(written, body.stimulus, body.behaviour)


@router.put(
    "/{name}/associations/{stimulus}/{behaviour}",
    dependencies=[WriteGuard],
    responses={
        404: {"model": ErrorPublic, "description": "no such network, stimulus or behaviour"},
        **CONFLICT,
        **STALE,
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
    with answers():
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
    set_etag(response, written.edit.network)
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
        **CONFLICT,
        **STALE,
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
    with answers():
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
