"""Liveness of the service and its database."""

from __future__ import annotations

from importlib.metadata import version

from server.api.deps import StateDep
from server.api.routing import resource_router
from server.schemas import Health

router = resource_router(tag="health")


@router.get("/health")
def health(state: StateDep) -> Health:
    """Whether the service answers and its database does (503 when it does not).

    A SQLite file deleted or replaced since the service opened it, or its WAL index cut,
    is a 503 that says which: the runs fail with the same error, and no write is taken.
    """
    dialect = state.database.check()
    return Health(
        status="ok",
        version=version("srlab"),
        database=dialect,
        runs_active=state.engines.running(),
        viser_port=state.viewer.port if state.viewer is not None else None,
    )
