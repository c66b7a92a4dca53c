"""`srlab serve`: migrate, then run the service with uvicorn (one worker)."""

from __future__ import annotations

import logging

import uvicorn

from server.config import Settings
from server.main import create_app
from server.persistence import upgrade
from server.tuning import configure_process

log = logging.getLogger("srlab.serve")


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
    uvicorn.run(
        app,
        host=settings.host,
        port=settings.port,
        workers=1,
        log_level="info",
        proxy_headers=False,
        timeout_graceful_shutdown=5,
    )
    return 0
