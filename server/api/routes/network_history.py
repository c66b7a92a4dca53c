"""A stored network's history and its document: versions, diffs, revert, export.

Every change to a network makes a version (`server.api.routes.networks`); these routes
read them, compare two, make an old one current again, and give the network as a file
POST /api/networks/import takes.
"""

from __future__ import annotations

import re
from typing import Annotated, cast

from fastapi import Path, Query, Response

from core.brain.catalog import Source
from server.api.deps import NetworksDep, WriteGuard
from server.api.errors import ErrorPublic
from server.api.routes.network_common import (
    CONFLICT,
    NOT_FOUND,
    STALE,
    Expected,
    Force,
    Live,
    Note,
    Service,
    StoredName,
    answers,
    association_public,
    set_etag,
    written_public,
)
from server.api.routes.runs import Limit, Offset
from server.api.routing import resource_router
from server.schemas import (
    NETWORK_FORMAT,
    AssociationChangePublic,
    AssociationCreate,
    NetworkDiffPublic,
    NetworkDocument,
    NetworkRevert,
    NetworkSnapshotPublic,
    NetworkVersionPublic,
    NetworkVersionsPublic,
    NetworkWritten,
)

router = resource_router("/networks", tag="networks")


@router.get("/{name}/versions", responses=NOT_FOUND)
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
        associations=[association_public(p) for p in snap.associations],
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
        added=[association_public(c.after) for c in changes if c.before is None and c.after],
        removed=[association_public(c.before) for c in changes if c.after is None and c.before],
        changed=[
            AssociationChangePublic(
                stimulus=c.stimulus,
                behaviour=c.behaviour,
                before=association_public(c.before),
                after=association_public(c.after),
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
        **CONFLICT,
        **STALE,
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
    with answers():
        written = await service.revert(
            name, body.version, force=force, note=note, expected=expected, live=live
        )
    set_etag(response, written.edit.network)
    return written_public(written.edit.network, written.live_runs)


@router.get("/{name}/export", responses=NOT_FOUND)
def export_network(name: StoredName, networks: NetworksDep, response: Response) -> NetworkDocument:
    """The network as a document POST /api/networks/import takes, as a file to save."""
    n = networks.get(name)
    set_etag(response, n)
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
