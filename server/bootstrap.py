"""The composition root: what the service is made of, built in one place.

`create_app`'s lifespan calls `service(settings, storage)`: storage first (SQLAlchemy in
this process, or in a store process as `srlab serve` runs it), then the runs' manager
(`server.runtime`: the runs' host on this process's event loop, or in a process of its
own), the reward rate limiter and the 3D view over it. Tests give
another `storage` factory, e.g. the in-memory fakes of `tests/fakes/`, and drive the
same routes and engines.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio.to_thread

from core.run.setup import Setup
from server.api.deps import AppState
from server.api.guard import SitePolicy
from server.api.ratelimit import RateLimiter
from server.config import Settings
from server.persistence.storage import StorageFactory, open_storage
from server.runtime import open_runs
from server.runtime.tuning import step_back, warm_up
from server.services.datafiles import DataWatch
from server.services.studies import StudyWatch


async def _cancelled(task: asyncio.Task[None]) -> None:
    """Cancel `task` and wait until it has ended (its cancellation is not ours to raise)."""
    task.cancel()
    await asyncio.wait([task])


DATA_LOOK_EVERY_S = 5.0
"""How often the service looks whether its data files changed (a warning in the log)."""


async def _watch_data(data: DataWatch) -> None:
    while True:
        await asyncio.sleep(DATA_LOOK_EVERY_S)
        await asyncio.to_thread(data.changed)


REQUEST_THREADS = min(32, (os.cpu_count() or 1) + 4)
"""Threads for the routes' blocking work: 6 on two cores, as asyncio's default executor."""


@asynccontextmanager
async def service(
    settings: Settings, storage: StorageFactory = open_storage
) -> AsyncIterator[AppState]:
    """Everything the routes share, for as long as the service runs; then a clean stop.

    On the way out: the 3D view closes, every run is interrupted at a tick boundary (and
    stays resumable), then storage closes after the runs' last writes.
    """
    if settings.engines == "process" and storage is not open_storage:
        # The engines' process opens its own, from the settings: it would not be this one.
        raise ValueError("SRLAB_ENGINES=process opens storage by SRLAB_DATABASE_URL only")
    opened = await asyncio.to_thread(storage, settings)
    async with contextlib.AsyncExitStack() as stack:
        # Undone in reverse: the 3D view, the runs, the engines' process, then storage.
        stack.push_async_callback(asyncio.to_thread, opened.close)
        catalog = Setup().catalog()  # the default definition's, shared with its runs
        data = await asyncio.to_thread(DataWatch)  # the data files as read now
        looking = asyncio.create_task(_watch_data(data), name="data files")
        stack.push_async_callback(_cancelled, looking)
        watch = None if opened.studies is None else StudyWatch(opened.studies)
        if watch is not None:  # its last look comes after the runs' shutdown
            stack.push_async_callback(watch.flush)
        manager = await open_runs(settings, opened.runs, stack)
        if watch is not None:
            watch.attach(manager)
            watching = asyncio.create_task(watch.run(), name="study budgets")
            stack.push_async_callback(_cancelled, watching)
        if settings.engines == "process":
            step_back(settings.service_nice)
        # The kernel only where the runs tick.
        await warm_up(kernel=settings.engines == "local")
        # Routes run their blocking work in threads, which take the GIL from the event loop
        # that paces realtime ticks. Starlette allows 40 at once; under 64 busy connections
        # that delayed ticks by tens of ms. As many as asyncio's own default executor keeps
        # them short (tests/reliability/test_load.py).
        anyio.to_thread.current_default_thread_limiter().total_tokens = REQUEST_THREADS
        # A run stored as running or paused lost its process: it can be resumed from its
        # checkpoint and log.
        await asyncio.to_thread(opened.runs.interrupt_active)
        limiter = RateLimiter(
            settings.reward_rate_per_s,
            settings.reward_burst,
            run_rate=settings.reward_run_rate_per_s,
            run_burst=settings.reward_run_burst,
        )
        viewer = None
        if settings.viser:
            from server.viewer import Viewer

            viewer = await Viewer.start(
                host=settings.host,
                port=settings.viser_port,
                manager=manager,
                store=opened.runs,
                catalog=catalog,
                limiter=limiter,
                writable=not settings.writes_need_token,
                policy=SitePolicy.of(settings.host_names(), settings.editor_origins()),
                max_viewers=settings.viser_max_viewers,
                require_pass=settings.reads == "token",
            )
            stack.push_async_callback(viewer.stop)
        yield AppState(
            settings=settings,
            catalog=catalog,
            database=opened.database,
            store=opened.runs,
            networks=opened.networks,
            engines=manager,
            rewards_limiter=limiter,
            viewer=viewer,
            studies=opened.studies,
            data=data,
        )
