"""viser's own port: it answers the gate's relays and nothing else.

viser (1.1) listens on TCP, on an ephemeral loopback port behind the gate, and a page in a
browser on this machine can find that port by scanning (about 40 s for the whole
ephemeral range) and open viser's websocket past the gate's Host and Origin checks. viser
can listen nowhere else and has no hook on its handshake, so srlab puts one on the
`websockets` server viser serves with: that `Server` reads its `process_request` as each
connection's handler starts, and `guard` puts a check in front of viser's own there. A
connection whose far end is not one of the gate's live connections to viser (the gate
records each before it sends a byte) gets 403; then a foreign Host gets 400 and a
websocket from another site 403, the gate's rule once more; only then does viser answer.

viser keeps that `Server` in no attribute: its `start_server` coroutine holds it while it
serves, suspended on viser's loop. `guard` looks there, on viser's loop, for a value of
websockets' `Server` type (not a name), wraps its `process_request` and closes every
connection made before (their handlers read the unwrapped one). A viser that keeps it
elsewhere gets `UnguardedViewError`: the service does not serve a 3D view it cannot guard.

The port is not printed either (viser's start-up panel, websockets' "server listening"
line): `quietly` keeps both out of the service's output.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
from collections.abc import Awaitable, Callable, Iterator
from http import HTTPStatus

import rich
import viser
from websockets.asyncio.server import Server, ServerConnection
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

from server.api.guard import SitePolicy
from server.viewer.gate import Peer, Relay
from server.viewer.heads import refusal

log = logging.getLogger("srlab.viewer")

FIND_S = 30.0
"""A bound for viser's loop to run `guard`'s look (it is idle at start-up)."""
NOT_THE_GATE = (
    "this port answers the 3D view's gate only: open the view on the view's own port "
    "(GET /api/health names it as viser_port)"
)

ProcessRequest = Callable[[ServerConnection, Request], Awaitable[Response | None] | Response | None]


class UnguardedViewError(RuntimeError):
    """viser's websocket server is not where srlab can guard it."""


class Checked:
    """viser's `process_request` behind the gate-only check (`original` is viser's own)."""

    def __init__(
        self,
        original: ProcessRequest | None,
        relay: Callable[[Peer], Relay | None],
        policy: SitePolicy,
    ) -> None:
        self.original = original
        self.relay = relay
        self.policy = policy
        self.refused = 0
        """Requests refused so far (tests)."""

    def __call__(
        self, connection: ServerConnection, request: Request
    ) -> Awaitable[Response | None] | Response | None:
        """Refuse what did not come through the gate, then let viser answer."""
        address = connection.remote_address
        peer = (str(address[0]), int(address[1])) if isinstance(address, tuple) else None
        if peer is None or self.relay(peer) is None:
            return self._refuse(HTTPStatus.FORBIDDEN, NOT_THE_GATE)
        headers = {k.lower(): v for k, v in request.headers.raw_items()}
        problem = refusal(headers, self.policy)
        if problem is not None:
            return self._refuse(*problem)
        return None if self.original is None else self.original(connection, request)

    def _refuse(self, status: HTTPStatus, detail: str) -> Response:
        self.refused += 1
        log.warning("the 3D view's server refused a request: %s", detail)
        body = json.dumps({"detail": detail}).encode()
        headers = Headers(
            [
                ("Content-Type", "application/json"),
                ("Content-Length", str(len(body))),
                ("Connection", "close"),
            ]
        )
        return Response(status.value, status.phrase, headers, body)


def _servers() -> list[Server]:
    """The websockets servers the tasks of the running loop hold (run on viser's loop)."""
    servers: list[Server] = []
    for task in asyncio.all_tasks():
        frame = getattr(task.get_coro(), "cr_frame", None)
        if frame is not None:
            servers += [v for v in frame.f_locals.values() if isinstance(v, Server)]
    return servers


async def _install(relay: Callable[[Peer], Relay | None], policy: SitePolicy) -> int:
    """On viser's loop: guard every websockets `Server` its tasks hold; how many there are."""
    servers = _servers()
    for server in servers:
        if not isinstance(server.process_request, Checked):
            server.process_request = Checked(server.process_request, relay, policy)
        # Each connection's handler took `process_request` as it started: one made before
        # (nobody could know the port yet, but nothing says so) goes, viewer or not.
        handlers: dict[ServerConnection, object] = getattr(server, "handlers", {})
        early = list(handlers)
        for connection in early:
            connection.transport.abort()
        if early:
            log.warning("the 3D view closed %d connection(s) made before its gate", len(early))
    return len(servers)


async def guard(
    server: viser.ViserServer, relay: Callable[[Peer], Relay | None], policy: SitePolicy
) -> None:
    """Make `server` answer only connections `relay` knows, with a Host and Origin `policy` takes.

    Raises:
        UnguardedViewError: this viser's websocket server was not found.
    """
    found = asyncio.run_coroutine_threadsafe(_install(relay, policy), server.get_event_loop())
    async with asyncio.timeout(FIND_S):
        count = await asyncio.wrap_future(found)
    if count == 0:
        raise UnguardedViewError(
            f"viser {viser.__version__} keeps its websocket server where srlab cannot guard "
            "it, and any page on this machine could then reach the 3D view past its gate: "
            "install the viser that pyproject.toml names, or set SRLAB_VISER=false"
        )


def websocket_servers(server: viser.ViserServer) -> list[Server]:
    """The websockets servers `server` serves with (tests; blocking, not on viser's loop)."""

    async def look() -> list[Server]:
        return _servers()

    return asyncio.run_coroutine_threadsafe(look(), server.get_event_loop()).result(FIND_S)


class ListeningLine(logging.Filter):
    """On websockets' server logger: drops the line that names viser's port."""

    def filter(self, record: logging.LogRecord) -> bool:
        """False for "server listening on ...", else True."""
        return record.msg != "server listening on %s"


@contextlib.contextmanager
def quietly() -> Iterator[None]:
    """Start viser without printing its port (its panel on stdout, websockets' log line)."""
    websockets_log = logging.getLogger("websockets.server")
    if not any(isinstance(f, ListeningLine) for f in websockets_log.filters):
        websockets_log.addFilter(ListeningLine())
    console = rich.get_console()
    before = console.quiet
    console.quiet = True
    try:
        yield
    finally:
        console.quiet = before


__all__ = ["Checked", "UnguardedViewError", "guard", "quietly", "websocket_servers"]
