"""A run's or a study's export as one zip (docs/export.md).

The files `srlab export` and `srlab study export` write. Both routes are the organiser's:
they hold what participants did.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

from fastapi import HTTPException, Query, status
from fastapi.responses import FileResponse
from starlette.background import BackgroundTask
from starlette.concurrency import run_in_threadpool

from server.api.access import Organiser
from server.api.deps import EnginesDep, StoreDep
from server.api.errors import ErrorPublic
from server.api.routes.runs import RunId
from server.api.routes.studies import StudiesDep, StudyName, settle_study
from server.api.routing import resource_router
from server.export import MinariMissingError, export_run, export_study, zip_folder

router = resource_router("/runs/{run_id}/export", tag="runs")
study_router = resource_router("/studies/{name}/export", tag="studies")
MinariQuery = Annotated[
    bool, Query(description="also a Minari dataset of each run's episodes (srlab[minari])")
]
RESPONSES: dict[int | str, dict[str, Any]] = {
    200: {"content": {"application/zip": {}}, "description": "the export, zipped"},
    409: {"model": ErrorPublic, "description": "a Minari export without srlab[minari]"},
}


def _zipped(name: str, write: Callable[[Path], object]) -> tuple[Path, Path]:
    """`write(folder)`'s files zipped under `name/` in a new temporary folder.

    Returns (the zip, the temporary folder, for the caller to remove once sent).
    """
    work = Path(tempfile.mkdtemp(prefix="srlab-export-"))
    try:
        write(work / name)
        return zip_folder(work / name, work / f"srlab-{name}.zip", name), work
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise


async def _answer(name: str, write: Callable[[Path], object]) -> FileResponse:
    """The zip of what `write` writes, removed once sent; 409 for Minari without the extra."""
    try:
        path, work = await run_in_threadpool(_zipped, name, write)
    except MinariMissingError as e:
        raise HTTPException(status.HTTP_409_CONFLICT, str(e)) from None
    return FileResponse(
        path,
        media_type="application/zip",
        filename=path.name,
        background=BackgroundTask(shutil.rmtree, work, ignore_errors=True),
    )


@router.get("", response_class=FileResponse, responses=RESPONSES, dependencies=[Organiser])
async def export_run_zip(
    run_id: RunId, store: StoreDep, minari: MinariQuery = False
) -> FileResponse:
    """The run's reward log and episodes (JSON Lines and CSV), network and manifest, zipped.

    The files sit under `run-{id}/`, as `srlab export` writes them; a running run's export
    holds what is stored so far. The organiser's: a participant's token gets 403.
    """

    def write(folder: Path) -> object:
        return export_run(store, run_id, folder, minari=minari)

    return await _answer(f"run-{run_id}", write)


@study_router.get("", response_class=FileResponse, responses=RESPONSES, dependencies=[Organiser])
async def export_study_zip(
    name: StudyName,
    store: StoreDep,
    studies: StudiesDep,
    engines: EnginesDep,
    minari: MinariQuery = False,
) -> FileResponse:
    """The study's export, zipped under `study-{name}/`, as `srlab study export` writes it.

    A folder per participant with a run (named by their pseudonym: their run's export), the
    study-wide reward log and episodes, and `study.json`. Never a recruiter's id.
    """
    await settle_study(name, studies, store, engines)  # each status as of now

    def write(folder: Path) -> object:
        return export_study(store, studies, name, folder, minari=minari)

    return await _answer(f"study-{name}", write)
