"""A run's export as one zip: the files `srlab export` writes (docs/export.md)."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Annotated

from fastapi import HTTPException, Query, status
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask
from starlette.concurrency import run_in_threadpool

from core.ports import RunQueries
from server.api.deps import StoreDep
from server.api.errors import ErrorPublic
from server.api.routes.runs import RunId
from server.api.routing import resource_router
from server.export import MinariMissingError, export_run, zip_folder

router = resource_router("/runs/{run_id}/export", tag="runs")


def _zipped(store: RunQueries, run_id: int, minari: bool) -> tuple[Path, Path]:
    """The run's export zipped in a new temporary folder: (the zip, the folder)."""
    work = Path(tempfile.mkdtemp(prefix="srlab-export-"))
    try:
        name = f"run-{run_id}"
        export_run(store, run_id, work / name, minari=minari)
        return zip_folder(work / name, work / f"srlab-{name}.zip", name), work
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise


@router.get(
    "",
    response_class=FileResponse,
    responses={
        200: {"content": {"application/zip": {}}, "description": "the export, zipped"},
        409: {"model": ErrorPublic, "description": "a Minari export without srlab[minari]"},
    },
)
async def export_run_zip(
    run_id: RunId,
    store: StoreDep,
    minari: Annotated[
        bool, Query(description="also a Minari dataset of its episodes (srlab[minari])")
    ] = False,
) -> FileResponse:
    """The run's reward log and episodes (JSON Lines and CSV), network and manifest, zipped.

    The files sit under `run-{id}/`, as `srlab export` writes them; a running run's export
    holds what is stored so far.
    """
    try:
        path, work = await run_in_threadpool(_zipped, store, run_id, minari)
    except MinariMissingError as e:
        raise HTTPException(status.HTTP_409_CONFLICT, str(e)) from None
    return FileResponse(
        path,
        media_type="application/zip",
        filename=path.name,
        background=BackgroundTask(shutil.rmtree, work, ignore_errors=True),
    )
