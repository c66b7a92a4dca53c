"""Dependencies of the routes: the app's state, and the write guard.

They are coroutines because they do no I/O: FastAPI runs a plain function dependency on a
worker thread, a hand-off there and back for each dependency of each request (about half
of what a cheap request cost, see docs/benchmarks.md). The same goes for route handlers
that only read memory.
"""

from __future__ import annotations

import hmac
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Annotated

from fastapi import Depends, HTTPException, Request, status

from core.brain.catalog import Catalog
from core.ports import NetworkRepository, RunQueries
from server.api.ratelimit import RateLimiter
from server.config import Settings
from server.runtime import Runs
from server.services.datafiles import DataWatch

if TYPE_CHECKING:
    from core.studies import StudyRepository
    from server.persistence.storage import DatabaseProbe
    from server.viewer import Viewer


@dataclass
class AppState:
    """What `create_app`'s lifespan builds and the routes share."""

    settings: Settings
    catalog: Catalog
    database: DatabaseProbe
    store: RunQueries
    networks: NetworkRepository
    engines: Runs
    rewards_limiter: RateLimiter
    viewer: Viewer | None = None
    studies: StudyRepository | None = None
    """Trainer studies (None: this storage keeps none, e.g. the in-memory fakes)."""
    data: DataWatch = field(default_factory=DataWatch)
    """The data files as the service read them at its start, and which changed since."""
    run_networks: dict[int, int | None] = field(default_factory=dict)
    """Runs whose stored network was deleted while they ran here (None), overriding
    `RunSpec.network_id` of the engine's spec."""


async def _state(request: Request) -> AppState:
    state: AppState = request.app.state.srlab
    return state


StateDep = Annotated[AppState, Depends(_state)]


async def _engines(state: StateDep) -> Runs:
    return state.engines


async def _store(state: StateDep) -> RunQueries:
    return state.store


async def _networks(state: StateDep) -> NetworkRepository:
    return state.networks


EnginesDep = Annotated[Runs, Depends(_engines)]
NetworksDep = Annotated[NetworkRepository, Depends(_networks)]
StoreDep = Annotated[RunQueries, Depends(_store)]


def bearer(request: Request) -> str | None:
    """The bearer token the request carries, if any (checked or not)."""
    scheme, _, given = request.headers.get("authorization", "").partition(" ")
    return (given.strip() or None) if scheme.lower() == "bearer" else None


def holds_token(settings: Settings, given: str | None) -> bool:
    """Whether a request carrying `given` has the organiser's rights.

    It has when no token is needed here, or when `given` is `SRLAB_TOKEN` (compared in
    constant time).
    """
    if not settings.writes_need_token:
        return True
    token = settings.token or ""
    return bool(given) and hmac.compare_digest((given or "").encode(), token.encode())


async def require_write(request: Request, state: StateDep) -> None:
    """Writes need `Authorization: Bearer $SRLAB_TOKEN` when the service is reachable."""
    who = request.scope.get("srlab.principal")  # `server.api.access.SCOPE_KEY`
    if who is not None and who.participant is not None:
        return  # a participant's token, already held to their own run (`server.api.access`)
    if not holds_token(state.settings, bearer(request)):
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            "this write needs `Authorization: Bearer <SRLAB_TOKEN>`",
            headers={"WWW-Authenticate": "Bearer"},
        )


WriteGuard = Depends(require_write)
