"""viser's own server, which only the gate may reach.

viser listens on an ephemeral loopback port behind the gate (`server.viewer.gate`). A
browser can reach any loopback port: a page of another loopback origin found viser's by
scanning (a few thousand ports a second) and, past the gate, opened viser's websocket,
rewarded runs and re-paced them. So viser's server answers nobody but the gate.

viser (1.1) serves its page and its websocket with one `websockets` server whose
`process_request` is viser's own file server, and it offers no hook on a request. The
`websockets` server reads `process_request` from its attribute at every request, so
`guard` wraps it there, on viser's event loop, before the gate opens: a request whose
connection does not come from one of the gate's live relays (`admits`, by the address the
relay connects from) gets 403, whatever it asks; a Host the service does not answer to
gets 400 and a websocket from another site 403, as at the gate (defence in depth: the gate
has refused those already). A viser whose server cannot be found so is refused at start:
the 3D view does not run unguarded.

`quiet_start` keeps viser's address out of the log: viser prints a banner with its URL and
`websockets` logs "server listening on" it; only the gate's port is anybody's business.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import json
import logging
from collections.abc import Callable, Iterator
from http import HTTPStatus
from typing import Any

import rich
import viser
from websockets.asyncio.server import Server, ServerConnection
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

from server.guard import SitePolicy
from server.viewer.gate import Peer
from server.viewer.gate import refusal as site_refusal

log = logging.getLogger("srlab.viewer")
GUARD_TIMEOUT_S = 30.0
"""How long `guard` waits for viser's event loop (a bound for a hung viser)."""


class UnguardedViewerError(RuntimeError):
    """viser's server could not be guarded: the 3D view must not start."""


def peer_of(connection: ServerConnection) -> Peer | None:
    """The address a connection comes from, as (host, port), if it is a TCP one."""
    address = connection.remote_address
    if not isinstance(address, tuple) or len(address) < 2:
        return None
    return str(address[0]), int(address[1])


def refusal(
    peer: Peer | None, headers: dict[str, str], admits: Callable[[Peer], bool], policy: SitePolicy
) -> tuple[HTTPStatus, str] | None:
    """Why viser's server refuses a request from `peer` with these headers, or None."""
    if peer is None or not admits(peer):
        return HTTPStatus.FORBIDDEN, "the 3D view is served on its own port only"
    return site_refusal(headers, policy)


def _answer(status: HTTPStatus, detail: str) -> Response:
    body = json.dumps({"detail": detail}).encode()
    headers = Headers(
        [
            ("Content-Type", "application/json"),
            ("Content-Length", str(len(body))),
            ("Connection", "close"),
        ]
    )
    return Response(status.value, status.phrase, headers, body)


def guarded(
    inner: Callable[[ServerConnection, Request], Any] | None,
    admits: Callable[[Peer], bool],
    policy: SitePolicy,
) -> Callable[[ServerConnection, Request], Any]:
    """`inner` (viser's `process_request`, or None) behind the checks of `refusal`."""

    async def process_request(connection: ServerConnection, request: Request) -> Any:
        headers = {name.lower(): value for name, value in request.headers.raw_items()}
        refused = refusal(peer_of(connection), headers, admits, policy)
        if refused is not None:
            status, detail = refused
            log.warning("viser's server refused a request: %s", detail)
            return _answer(status, detail)
        if inner is None:
            return None
        answer = inner(connection, request)
        return await answer if inspect.isawaitable(answer) else answer

    process_request.srlab_inner = inner  # type: ignore[attr-defined]
    return process_request


def _servers_of(coroutine: object) -> Iterator[Server]:
    """The `websockets` servers held by a suspended coroutine or those it awaits."""
    while coroutine is not None:
        frame = getattr(coroutine, "cr_frame", None)
        if frame is not None:
            for value in frame.f_locals.values():
                if isinstance(value, Server):
                    yield value
        coroutine = getattr(coroutine, "cr_await", None)


def websockets_server(port: int) -> Server:
    """The `websockets` server viser listens with on `port`; call on viser's event loop.

    viser keeps it only in a local of the task that serves (`async with serve(...) as
    server: await stop.wait()`): it is found there, by type and by the port it listens on.
    """
    for task in asyncio.all_tasks():
        for server in _servers_of(task.get_coro()):
            if any(sock.getsockname()[1] == port for sock in server.sockets):
                return server
    raise UnguardedViewerError(
        f"viser {viser.__version__}'s server on port {port} was not found, so it could not "
        "be limited to the 3D view's gate; run with SRLAB_VISER=false, or a viser srlab knows"
    )


def guard(server: viser.ViserServer, admits: Callable[[Peer], bool], policy: SitePolicy) -> None:
    """Let only connections `admits` reach viser's server; close any already open.

    Blocking: it waits for viser's event loop. Call it before the gate opens.

    Raises:
        UnguardedViewerError: viser's server could not be found or guarded.
    """
    infra = server._websock_server
    loop = getattr(infra, "_background_event_loop", None)
    if not isinstance(loop, asyncio.AbstractEventLoop):
        raise UnguardedViewerError(
            f"viser {viser.__version__} runs no event loop srlab can reach, so its server "
            "could not be limited to the 3D view's gate; run with SRLAB_VISER=false"
        )

    async def install() -> None:
        found = websockets_server(server.get_port())
        if not hasattr(found.process_request, "srlab_inner"):
            found.process_request = guarded(found.process_request, admits, policy)

    asyncio.run_coroutine_threadsafe(install(), loop).result(GUARD_TIMEOUT_S)
    # Nobody but a scanner can have connected before the guard: the gate is not open yet.
    infra.disconnect_all_clients()


def drop(server: viser.ViserServer, client_id: int) -> None:
    """Close client `client_id`'s websocket (from any thread but viser's)."""
    infra = server._websock_server
    connection = infra._live_connections.get(client_id)
    loop = getattr(infra, "_background_event_loop", None)
    if connection is None or not isinstance(loop, asyncio.AbstractEventLoop):
        return
    with contextlib.suppress(RuntimeError):  # viser's loop closed: the socket is gone too
        asyncio.run_coroutine_threadsafe(connection.close(1008, "not through the gate"), loop)


class _NotListening(logging.Filter):
    """Drops `websockets`' "server listening on" line: viser's address is nobody's business."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith("server listening on")


@contextlib.contextmanager
def quiet_start() -> Iterator[None]:
    """Start viser in this block: its banner and its listening line say nothing.

    viser prints its banner with `rich.print` on the thread that makes the server (this
    one): a capture of rich's console is this thread's only. The log filter stays on
    `websockets.server`'s logger, where only viser's server logs.
    """
    logger = logging.getLogger("websockets.server")
    if not any(isinstance(f, _NotListening) for f in logger.filters):
        logger.addFilter(_NotListening())
    with rich.get_console().capture():
        yield
