"""The FastAPI service: `create_app(settings)` builds everything, its lifespan owns the runs."""

from __future__ import annotations

import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from importlib.metadata import version
from pathlib import Path

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse
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
from server.api import ROUTERS, contract, docs, etags
from server.api.asgi import cut_off, send_error
from server.api.contract import operation_id
from server.api.guard import CrossSiteGuard, SitePolicy
from server.api.methods import ApiMethods
from server.api.routing import add_routes
from server.api.strictjson import StrictJson
from server.api.timeouts import BodyTimeout
from server.bootstrap import service
from server.config import Settings
from server.persistence.networks import StaleVersionError
from server.persistence.storage import StorageFactory, open_storage
from server.runtime import TooManyRunsError

log = logging.getLogger("srlab.server")
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


def create_app(settings: Settings | None = None, storage: StorageFactory = open_storage) -> FastAPI:
    """The srlab service for `settings` (the environment's by default).

    `storage` opens what it stores into (`server.bootstrap`): SQLAlchemy on the settings'
    database unless a test gives another.
    """
    settings = settings or Settings()
    settings.check()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        async with service(settings, storage) as state:
            app.state.srlab = state
            yield

    app = FastAPI(
        title="srlab",
        summary="Behaviour-based control and learning with knowledge propagation",
        version=version("srlab"),
        lifespan=lifespan,
        generate_unique_id_function=operation_id,
        docs_url=None,  # FastAPI's pages load from a CDN: server.api.docs serves its own
        redoc_url=None,
    )
    add_routes(app, ROUTERS)
    docs.install(app)
    contract.install(app, token_needed=settings.writes_need_token)

    async def core_error(request: Request, exc: Exception) -> JSONResponse:
        if isinstance(exc, StaleVersionError):
            return etags.stale(exc)
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
    app.add_middleware(ApiMethods, routes=lambda: app.routes)
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
