"""`srlab serve`: migrate, then run the service with uvicorn (one worker)."""

from __future__ import annotations

import contextlib
import logging
import socket

import uvicorn
from fastapi import FastAPI

from server.config import Settings
from server.main import create_app
from server.persistence import upgrade
from server.tuning import configure_process

log = logging.getLogger("srlab.serve")
STARTUP_FAILURE = 3
"""uvicorn's exit code when the server could not start."""


def serve(host: str | None = None, port: int | None = None) -> int:
    """Serve until interrupted; runs are interrupted cleanly and stay resumable."""
    overrides: dict[str, object] = {}
    if host is not None:
        overrides["host"] = host
    if port is not None:
        overrides["port"] = port
    settings = Settings(**overrides)  # type: ignore[arg-type]
    settings.check()
    upgrade(settings.database_url)
    configure_process()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    app = create_app(settings)
    # One worker: the runs' state lives in this process.
    config = uvicorn.Config(
        app,
        host=settings.host,
        port=settings.port,
        workers=1,
        log_level="info",
        proxy_headers=False,
        timeout_graceful_shutdown=5,
    )
    server = _Server(config, app)
    with contextlib.suppress(KeyboardInterrupt):
        server.run()
    # As uvicorn.run: a server that never started (a failed lifespan, a taken port) is an
    # error.
    return 0 if server.started else STARTUP_FAILURE


class _Server(uvicorn.Server):
    """uvicorn that ends the runs' live event streams as its shutdown begins.

    uvicorn waits for open connections before the app's lifespan ends the runs, and an
    event stream stays open until its run ends: without this it would be cancelled after
    the grace period, with a traceback.
    """

    def __init__(self, config: uvicorn.Config, app: FastAPI) -> None:
        super().__init__(config)
        self._app = app

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        state = getattr(self._app.state, "srlab", None)
        if state is not None:
            state.engines.close_streams()
        await super().shutdown(sockets)
