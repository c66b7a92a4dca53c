"""Whether runs can start and store: the database and the engines' process."""

from __future__ import annotations

from importlib.metadata import version

from core.errors import StorageError
from server.api.deps import StateDep
from server.api.routing import resource_router
from server.schemas import Health

router = resource_router(tag="health")


@router.get("/health")
def health(state: StateDep) -> Health:
    """Whether runs can start and store: 200 "ok", or 503 saying what is down.

    The service's database is read; the engines' process is as last heard (`Runs.outage`:
    its death is seen on its pipe), so a poll costs no trip to it. A SQLite file
    deleted or replaced since the service opened it, or its WAL index cut, is a 503 that
    says which: the runs fail with the same error, and no write is taken. It also says
    which data files changed since the service started (it uses them as they were).
    """
    down = []
    dialect = ""
    try:
        dialect = state.database.check()
    except StorageError as e:
        down.append(str(e))
    if (outage := state.engines.outage()) is not None:
        down.append(outage)
    if down:
        raise StorageError("; ".join(down))
    return Health(
        status="ok",
        version=version("srlab"),
        database=dialect,
        runs_active=state.engines.running(),
        viser_port=state.viewer.port if state.viewer is not None else None,
        data_version=state.data.version,
        data_changed=state.data.changed(),
    )
