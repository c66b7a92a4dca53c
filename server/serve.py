"""The service under uvicorn: migrate, then serve with one worker (`srlab serve`)."""

from __future__ import annotations

import contextlib
import errno
import faulthandler
import logging
import os
import socket

import uvicorn
from fastapi import FastAPI
from uvicorn.config import STARTUP_FAILURE

from server.api.timeouts import timed_protocol
from server.config import Settings
from server.main import create_app
from server.persistence import upgrade
from server.runtime.tuning import configure_process

log = logging.getLogger("srlab.serve")

SERVICE_NICE = 10
"""`srlab serve`'s `service_nice`: measured on 2 busy cores (`bench.service`,
docs/benchmarks.md), 10 gave the engines' ticks most of what 19 did, and leaves the service a share
beside other programs at the default priority (19 would leave it almost none)."""


class _Server(uvicorn.Server):
    """uvicorn's server, which interrupts the runs as soon as it starts shutting down.

    uvicorn lets open connections finish before the lifespan's shutdown, and a run's event
    stream ends only when the run does. Without this, one open stream would hold SIGTERM for
    the whole graceful timeout and then be cancelled. Interrupting the runs first ends each
    stream with a last status event, so the service exits within about a tick.
    """

    def __init__(self, config: uvicorn.Config, app: FastAPI) -> None:
        super().__init__(config)
        self._app = app

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        prepare(self._app)
        await super().startup(sockets)  # the lifespan: storage, the engines, resumed runs

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        state = getattr(self._app.state, "srlab", None)  # None: the lifespan never started
        if state is not None:
            state.engines.interrupt_all()
        await super().shutdown(sockets)


def prepare(app: FastAPI) -> None:
    """Work a first request would otherwise do on the event loop, where the runs tick.

    FastAPI builds the OpenAPI document at its first `GET /openapi.json` (or `/docs`):
    180 ms of CPU, during which every run on the service's loop stood still (32 runs
    under load each lost a few periods, `python -m bench.service --engines loop`). Built here,
    before the lifespan starts any run, it is served from memory.
    """
    app.openapi()


def serve(host: str | None = None, port: int | None = None) -> int:
    """Serve until interrupted; runs are interrupted cleanly and stay resumable."""
    overrides: dict[str, object] = {}
    if host is not None:
        overrides["host"] = host
    if port is not None:
        overrides["port"] = port
    # The runs tick in a process of their own (a GIL and a core apart from HTTP and the 3D
    # view: `bench.service`, docs/benchmarks.md), unless the environment
    # keeps them on the service's loop.
    if "SRLAB_ENGINES" not in os.environ:
        overrides["engines"] = "process"
    # With the engines in a process of their own, the ticks come first on a busy machine.
    if "SRLAB_SERVICE_NICE" not in os.environ:
        overrides["service_nice"] = SERVICE_NICE
    settings = Settings.load(**overrides)
    settings.check()
    check_ports(settings)
    upgrade(settings.database_url)
    configure_process()
    # A fault SQLite cannot report (SIGBUS from a truncated WAL index it has mapped, see
    # `SqliteFileGuard`) then leaves a traceback in the log instead of a silent death.
    faulthandler.enable()
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    app = create_app(settings)
    # One worker: the runs' state lives in this process.
    config = uvicorn.Config(
        app,
        host=settings.host,
        port=settings.port,
        workers=1,
        log_level="info",
        # Only a trusted proxy may say who the client is (the rate limit keys on it).
        proxy_headers=bool(settings.forwarded_allow_ips),
        forwarded_allow_ips=settings.forwarded_allow_ips or None,
        timeout_graceful_shutdown=5,
        # Slow clients: an idle kept-alive connection, a request head and a request body
        # each get a deadline (server.api.timeouts), and a head is at most 16 KiB.
        http=timed_protocol(settings.request_timeout_s),
        timeout_keep_alive=5,
        h11_max_incomplete_event_size=16 * 1024,
    )
    server = _Server(config, app)
    with contextlib.suppress(KeyboardInterrupt):
        server.run()
    # As uvicorn.run: a server that never started (a failed lifespan, a taken port) is an
    # error.
    return 0 if server.started else STARTUP_FAILURE


def check_ports(settings: Settings) -> None:
    """Refuse in one line when a port `srlab serve` needs is taken, before anything starts.

    Found at the bind instead, a taken API port stopped the service after the database,
    the runs and the 3D view had started, and a taken 3D view's port failed the lifespan
    with its traceback. A port taken in the moment between this check and the bind still
    fails there.

    Raises:
        OSError: which port, and the setting that chooses another.
    """
    host = settings.host
    ports = [
        (
            settings.port,
            "SRLAB_PORT or --port",
            f"port {settings.port} on {host} is taken (another srlab serve?): set SRLAB_PORT "
            "or --port to a free one",
        )
    ]
    if settings.viser:
        ports.append(
            (
                settings.viser_port,
                "SRLAB_VISER_PORT",
                f"the 3D view's port {settings.viser_port} on {host} is taken: set "
                "SRLAB_VISER_PORT to a free one, or SRLAB_VISER=false to run without the 3D "
                "view",
            )
        )
    for port, setting, taken in ports:
        error = _bind_error(host, port)
        if error is None:
            continue
        if error.errno == errno.EADDRINUSE:
            raise OSError(taken)
        raise OSError(
            f"cannot listen on {host} port {port} (SRLAB_HOST or --host, {setting}): "
            f"{error.strerror or error}"
        )


def _bind_error(host: str, port: int) -> OSError | None:
    """What stops a server from listening on `host` and `port` now, if anything.

    Bound as asyncio's servers bind (uvicorn's and the 3D view's): address reuse on, and
    IPv6 sockets for IPv6 alone; then let go at once.
    """
    try:
        addresses = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
        for family, kind, proto, _, address in addresses:
            with socket.socket(family, kind, proto) as probe:
                probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                if family == socket.AF_INET6:
                    probe.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
                probe.bind(address)
    except OSError as e:
        return e
    return None
