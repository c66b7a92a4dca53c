"""The FastAPI service: `create_app(settings)` builds everything, its lifespan owns the runs."""

from __future__ import annotations

import asyncio
import gc
import logging
import os
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import version
from pathlib import Path

import anyio.to_thread
from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse
from sqlalchemy import Engine
from starlette.middleware.trustedhost import TrustedHostMiddleware
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from core.errors import (
    CatalogError,
    CoreError,
    LockedAssociationError,
    RunStateError,
    StorageError,
    UnknownNameError,
    UnknownRunError,
)
from core.setup import Setup
from server.api import api_router, contract
from server.api.contract import operation_id
from server.api.deps import AppState
from server.api.methods import ApiMethods
from server.api.strictjson import StrictJson
from server.asgi import cut_off, send_error
from server.config import Settings
from server.engines import EngineManager, TooManyRunsError
from server.guard import CrossSiteGuard, SitePolicy
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker
from server.persistence.db import DatabaseCheck
from server.persistence.networks import SqlAlchemyNetworkRepository, StaleVersionError
from server.persistence.process import StoreProcess
from server.ratelimit import RateLimiter
from server.timeouts import BodyTimeout

log = logging.getLogger("srlab.server")
REQUEST_THREADS = min(32, (os.cpu_count() or 1) + 4)
"""Threads for the routes' blocking work: 6 on two cores, as asyncio's default executor."""
WEB = Path(__file__).resolve().parents[1] / "web"

_STATUS: list[tuple[type[Exception], int]] = [
    (TooManyRunsError, 429),
    (UnknownRunError, 404),
    (UnknownNameError, 404),
    (LockedAssociationError, 409),
    (RunStateError, 409),
    (StorageError, 503),
    (CatalogError, 422),
    (CoreError, 400),
]


class BodyLimit:
    """Answers 413 to a request body over `limit` bytes, before the app reads it."""

    def __init__(self, app: ASGIApp, limit: int) -> None:
        self.app = app
        self.limit = limit

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        """Check the declared length, then count what arrives."""
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        length = dict(scope["headers"]).get(b"content-length")
        if length is not None and (not length.isdigit() or int(length) > self.limit):
            await self._reject(send)
            return
        seen = 0

        async def counted() -> Message:
            nonlocal seen
            message = await receive()
            if message["type"] == "http.request":
                seen += len(message.get("body", b""))
                if seen > self.limit:
                    raise _TooLarge
            return message

        await cut_off(self.app, scope, counted, send, _TooLarge, self._reject)

    async def _reject(self, send: Send) -> None:
        detail = "the request body is larger than the limit (SRLAB_MAX_BODY_BYTES)"
        await send_error(send, 413, detail, [(b"connection", b"close")])


class _TooLarge(Exception):
    pass


def create_app(settings: Settings | None = None) -> FastAPI:
    """The srlab service for `settings` (the environment's by default)."""
    settings = settings or Settings()
    settings.check()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        engine: Engine | None = None
        storage: StoreProcess | None = None
        if settings.store_process:
            storage = await asyncio.to_thread(StoreProcess, settings.database_url)
            store, networks, database = storage.runs, storage.networks, storage.database
        else:
            engine = make_engine(settings.database_url)
            sessions = make_sessionmaker(engine)
            store = SqlAlchemyRunStore(sessions)
            networks = SqlAlchemyNetworkRepository(sessions)
            database = DatabaseCheck(engine)
        catalog = Setup().catalog()  # the default definition's, shared with its runs
        manager = EngineManager(
            store,
            catalog,
            settings.max_runs,
            max_streams=settings.max_streams,
            max_streams_per_run=settings.max_streams_per_run,
        )
        # Load the sensing kernel's machine code now, not in the first run's first tick.
        from starlette.concurrency import run_in_threadpool

        from core.sim.world import PymunkWorld

        await run_in_threadpool(lambda: PymunkWorld().reset(0, 0))
        # Everything loaded so far lives as long as the process: keep it out of the cyclic
        # collector's way, so a full collection does not stall realtime ticks.
        gc.collect()
        gc.freeze()
        # Routes run their database work in threads, which take the GIL from the event loop
        # that paces realtime ticks. Starlette allows 40 at once; under 64 busy connections
        # that delayed ticks by tens of ms. As many as asyncio's own default executor keeps
        # them short (tests/reliability/test_load.py).
        anyio.to_thread.current_default_thread_limiter().total_tokens = REQUEST_THREADS
        # A run stored as running or paused lost its process: it can be resumed from its
        # checkpoint and log.
        store.interrupt_active()
        rewards_limiter = RateLimiter(
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
                store=store,
                catalog=catalog,
                limiter=rewards_limiter,
                writable=not settings.writes_need_token,
                policy=SitePolicy.of(settings.host_names(), settings.editor_origins()),
            )
        app.state.srlab = AppState(
            settings=settings,
            catalog=catalog,
            database=database,
            store=store,
            networks=networks,
            engines=manager,
            rewards_limiter=rewards_limiter,
            viewer=viewer,
        )
        try:
            yield
        finally:
            if viewer is not None:
                await viewer.stop()
            await manager.shutdown()
            if engine is not None:
                engine.dispose()
            if storage is not None:
                await asyncio.to_thread(storage.stop)

    app = FastAPI(
        title="srlab",
        summary="Behaviour-based control and learning with knowledge propagation",
        version=version("srlab"),
        lifespan=lifespan,
        generate_unique_id_function=operation_id,
    )
    app.include_router(api_router)
    contract.install(app, token_needed=settings.writes_need_token)

    async def core_error(request: Request, exc: Exception) -> JSONResponse:
        if isinstance(exc, StaleVersionError):
            body = {"detail": str(exc), "version": exc.current, "etag": exc.etag}
            return JSONResponse(body, status_code=412, headers={"ETag": exc.etag})
        for kind, code in _STATUS:
            if isinstance(exc, kind):
                return JSONResponse({"detail": str(exc)}, status_code=code)
        raise exc  # pragma: no cover - registered for CoreError only

    async def value_error(request: Request, exc: Exception) -> JSONResponse:
        return JSONResponse({"detail": str(exc)}, status_code=422)

    app.add_exception_handler(CoreError, core_error)
    app.add_exception_handler(ValueError, value_error)
    _ = RequestValidationError  # FastAPI answers invalid bodies with 422 naming the field

    hosts = settings.host_names()
    editor = f"http://{settings.host}:{settings.port}"
    app.add_middleware(StrictJson)
    app.add_middleware(ApiMethods, schema=app.openapi)
    app.add_middleware(
        CORSMiddleware,
        allow_origins=[editor, *settings.cors_origins],
        allow_methods=["GET", "POST", "PUT", "DELETE"],
        allow_headers=["Authorization", "Content-Type"],
    )
    # Inside the Host check, so a request is refused for its Host first (DNS rebinding).
    app.add_middleware(CrossSiteGuard, policy=SitePolicy.of(hosts, settings.cors_origins))
    app.add_middleware(TrustedHostMiddleware, allowed_hosts=sorted(hosts))
    app.add_middleware(BodyLimit, limit=settings.max_body_bytes)
    app.add_middleware(BodyTimeout, limit_s=settings.request_timeout_s)
    if WEB.is_dir() and (WEB / "index.html").exists():
        from fastapi.staticfiles import StaticFiles

        app.mount("/", StaticFiles(directory=WEB, html=True), name="web")
    return app
