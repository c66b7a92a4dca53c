"""The 3D view's front door: the cross-site guard in front of viser's port.

viser (1.1) serves its page and its websocket from one `websockets` server and offers no
hook on the handshake (its `process_request` is its own file server), so it listens on an
ephemeral loopback port and this gate listens on the view's public port. The gate reads
each connection's request head, refuses a Host the service does not answer to (DNS
rebinding) and a websocket handshake from another site (the API's rule, `SitePolicy`),
then relays the bytes both ways. The panel's writes travel over that socket, so this is
what keeps a foreign page from rewarding or re-pacing runs through it. viser's own port
answers only the gate's relays (`server/viewer/upstream.py`): the gate keeps the address
each of its connections to viser comes from (`relay`) from before its first byte until
it ends, and viser's server refuses any other.

Each connection carries one request. The gate answers what viser's server cannot take
itself (a method but GET, a body, another HTTP version, a head its parser refuses: viser
logged a traceback and answered nothing), so viser sees only heads it parses. A page's
request is relayed alone and the connection closed after viser's answer (viser's server
answers one plain request per connection; a second one sent behind the first reached it
before its answer and failed it with a traceback); a websocket is a connection of its own.

The gate also gives the view URLs that name a run, `/run/<id>` (the console's link). viser's
page opens its websocket on its own URL's path (its client drops the query and a trailing
slash), so the socket of a page opened on `/run/7` asks for `/run/7`, the first time and on
every automatic reconnect, a restart of the service included. The gate keeps that run with
the socket's relay (`Relay.run`, found by the address viser sees the socket come from: the
viewer starts that socket's session on the run, and no other's, even when several pages
reconnect at once) and rewrites the path to `/`, which is all viser serves (its page, one
self-contained index.html, and its socket).

Who may watch: a request whose URL carries `?ticket=` (the API's, `server/viewer/passes.py`)
is a page being opened; the gate exchanges the ticket once for a cookie (`VIEW_COOKIE`
and the view's port, HttpOnly, SameSite=Strict, its path the run's URL or `/` for the
organiser's) and sends the browser on to the URL without it (303). From then on the page's
request and its sockets bring that cookie: one for a run (a participant's) is taken on
that run's URL alone (403 elsewhere), and its viewer shows that run read-only. A
request without a good cookie gets the view as it was (anyone who reaches the port
watches), unless the service keeps reads to tokens (`require_pass`): then 401.

At most `max_viewers` websockets are relayed at once: each is a viewer with a renderer
thread of its own, on the service's process (100 of them slowed `/api/health` from 8 to
616 ms). Past it a handshake gets 503 with `Retry-After`, and a page request a short
page that says so and reloads itself, before viser builds anything.

The gate answers a websocket handshake itself (`handshake_answer`: the 101 viser would
send, which depends on the request alone), then hands the request to viser and drops
viser's own 101. viser's client retries a lost connection every second and closes the
attempt still under way each time; viser answers on the service's process, which steps
back for the runs, and on a machine busy with other work that took longer than a second
after a restart, so the page never reconnected. The gate's answer is a header check and a
hash on its own thread. viser's own answer is awaited at most `VISER_ANSWER_S`: the page
must not sit on an open, silent socket it would never retry.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from http import HTTPStatus
from urllib.parse import urlencode

from server.api.guard import SitePolicy
from server.viewer.heads import (
    BAD_HANDSHAKE,
    FULL_RETRY_AFTER_S,
    cookie_values,
    exchanged,
    full_detail,
    full_page,
    handshake_answer,
    parse_head,
    refusal,
    refused,
    response,
    run_path,
    target,
    wants_upgrade,
)
from server.viewer.passes import Pass, Passes, PassRefused

log = logging.getLogger("srlab.viewer")

HEAD_LIMIT = 16 * 1024
"""Bytes a request head may take (viser's client sends well under 2 KiB)."""
HEAD_TIMEOUT_S = 10.0
"""A client that has not sent its request head by then is dropped (slow clients)."""
CHUNK = 64 * 1024
VISER_ANSWER_S = 30.0
"""How long the gate waits for viser's own answer to a handshake it answered already; then
it closes the page's socket, and the page tries again."""
LINGER_S = 2.0
"""After answering a page's request, how long the gate reads (and drops) what the client
still sends before it closes: closing on unread bytes would reset the connection, and the
client could lose the answer."""
MAX_VIEWERS = 16
"""Websockets (viewers) relayed at once, by default (SRLAB_VISER_MAX_VIEWERS)."""
Peer = tuple[str, int]
"""A TCP address as viser sees a connection's far end: (host, port)."""
VIEW_COOKIE = "srlab_view_"
"""The view cookie's name, before the view's port (cookies are kept by host, not port)."""
TICKET = "ticket"
"""The query parameter a page is opened with to exchange its ticket."""


@dataclass(frozen=True)
class Relay:
    """One of the gate's live connections to viser, as viser sees it come in.

    Attributes:
        run: the run its URL names (`/run/<id>`), for a websocket; else None.
        socket: a websocket (a viewer to be), not a page's request.
        granted: what its view cookie allows; None without one (the view as it was).
    """

    run: int | None
    socket: bool
    granted: Pass | None = None


class Gate:
    """Listens on `host`:`port` on a thread of its own and relays accepted connections.

    `relay` tells, from any thread, which of its connections to viser an address is (and
    the run its URL names, and what its view cookie allows: `passes` keeps the tickets and
    cookies; with `require_pass` a request without a good cookie gets 401.

    At most `max_viewers` websockets are relayed at once. `start`
    raises OSError when the port is taken; `stop` closes it and every relay.
    """

    def __init__(
        self,
        host: str,
        port: int,
        upstream_port: int,
        policy: SitePolicy,
        max_viewers: int = MAX_VIEWERS,
        passes: Passes | None = None,
        require_pass: bool = False,
    ) -> None:
        self.host = host
        self.passes = passes or Passes()
        self.require_pass = require_pass
        self.port = port
        self.upstream_port = upstream_port
        self.policy = policy
        self.max_viewers = max_viewers
        self.refused = 0
        """Requests refused so far (tests and the reliability suite read it)."""
        self.turned_away = 0
        """Viewers and pages turned away so far because the view was full."""
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: asyncio.Server | None = None
        self._thread: threading.Thread | None = None
        self._relays: set[asyncio.Task[None]] = set()
        self._sockets = 0
        """Websockets relayed now (counted on the gate's loop alone)."""
        self._full_said = False
        self._lock = threading.Lock()
        self._upstreams: dict[Peer, Relay] = {}
        """The gate's live connections to viser, by the address viser sees them come from."""

    @property
    def viewers(self) -> int:
        """Websockets relayed now (each a viewer, or one to be)."""
        return self._sockets

    def relay(self, peer: Peer) -> Relay | None:
        """The gate's live connection to viser from `peer`, if it is one (any thread)."""
        with self._lock:
            return self._upstreams.get(peer)

    @contextlib.contextmanager
    def _upstream(self, peer: Peer, relay: Relay) -> Iterator[None]:
        with self._lock:
            self._upstreams[peer] = relay
        try:
            yield
        finally:
            with self._lock:
                self._upstreams.pop(peer, None)

    def start(self) -> None:
        """Bind and serve (blocking until bound)."""
        ready = threading.Event()
        failure: list[BaseException] = []

        def main() -> None:
            loop = asyncio.new_event_loop()
            self._loop = loop
            try:
                self._server = loop.run_until_complete(
                    asyncio.start_server(self._accept, self.host, self.port, limit=HEAD_LIMIT)
                )
            except BaseException as e:
                failure.append(e)
                ready.set()
                loop.close()
                return
            sockets = self._server.sockets
            if sockets:
                self.port = sockets[0].getsockname()[1]
            ready.set()
            try:
                loop.run_forever()
            finally:
                loop.run_until_complete(self._close())
                loop.close()

        self._thread = threading.Thread(target=main, name="srlab viewer gate", daemon=True)
        self._thread.start()
        ready.wait()
        if failure:
            raise failure[0]

    def stop(self) -> None:
        """Close the listener and every open relay."""
        loop = self._loop
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(loop.stop)
        if self._thread is not None:
            self._thread.join(timeout=5.0)

    async def _close(self) -> None:
        if self._server is not None:
            self._server.close()
        for task in list(self._relays):
            task.cancel()
        await asyncio.gather(*self._relays, return_exceptions=True)

    async def _accept(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._relays.add(task)
        try:
            await self._serve(reader, writer)
        except (ConnectionError, asyncio.IncompleteReadError, asyncio.LimitOverrunError):
            pass
        except TimeoutError:
            pass
        except asyncio.CancelledError:
            # The gate is closing. End quietly: asyncio's stream callback asks a handler
            # task for its exception and would log a cancelled one as an error.
            pass
        finally:
            self._relays.discard(task)
            writer.close()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        async with asyncio.timeout(HEAD_TIMEOUT_S):
            head = await reader.readuntil(b"\r\n\r\n")
        headers, problem = parse_head(head)
        problem = problem or refusal(headers, self.policy)
        upgrade = wants_upgrade(headers)
        answer = handshake_answer(headers) if upgrade else None
        if problem is None and upgrade and answer is None:
            problem = HTTPStatus.BAD_REQUEST, BAD_HANDSHAKE
        head_only = head.startswith(b"HEAD ")
        upstream_head, run_id = run_path(head)
        granted: Pass | bytes | None = None
        if problem is None:
            try:
                granted = self._granted(head, headers, run_id, upgrade)
            except PassRefused as e:
                problem = e.status, e.detail
        if problem is not None:
            self.refused += 1
            status, detail = problem
            log.warning("the 3D view refused a request: %s", detail)
            writer.write(refused(status, detail, head_only=head_only))
            await writer.drain()
            return
        if isinstance(granted, bytes):  # a ticket exchanged: on to the URL without it
            writer.write(granted)
            await writer.drain()
            return
        if self._sockets >= self.max_viewers:
            await self._turn_away(writer, upgrade, head_only)
            return
        if answer is None:
            await self._page(reader, writer, upstream_head, granted)
            return
        self._sockets += 1  # no await since the check: the count holds
        try:
            await self._socket(reader, writer, upstream_head, answer, run_id, granted)
        finally:
            self._sockets -= 1
            if self._sockets < self.max_viewers:
                self._full_said = False

    @property
    def cookie(self) -> str:
        """The view cookie's name (the view's port in it)."""
        return f"{VIEW_COOKIE}{self.port}"

    def _granted(
        self, head: bytes, headers: dict[str, str], run_id: int | None, upgrade: bool
    ) -> Pass | bytes | None:
        """What the request's view cookie allows (None: no good one), or an answer.

        A page opened with a ticket is answered here: a 303 on to its URL without it,
        setting the cookie.

        Raises:
            PassRefused: a ticket not taken; a cookie for another run; none where one is
                needed.
        """
        path, params = target(head)
        ticket = next((v for k, v in params if k == TICKET), None)
        if ticket is not None:
            if upgrade:
                raise PassRefused(
                    HTTPStatus.BAD_REQUEST,
                    "a 3D view ticket is exchanged by opening the page, not by a websocket",
                )
            value, redeemed = self.passes.redeem(ticket, run_id)
            rest = urlencode([(k, v) for k, v in params if k != TICKET])
            location = path + (f"?{rest}" if rest else "")
            scope = "/" if redeemed.run is None else f"/run/{redeemed.run}"
            return exchanged(location, f"{self.cookie}={value}; Path={scope}")
        found = [self.passes.session(v) for v in cookie_values(headers, self.cookie)]
        granted = next((g for g in found if g is not None), None)
        if granted is not None and granted.run is not None and granted.run != run_id:
            where = "/" if run_id is None else f"run {run_id}"
            raise PassRefused(
                HTTPStatus.FORBIDDEN,
                f"this browser may watch run {granted.run} only in the 3D view, not {where}",
            )
        if granted is None and self.require_pass:
            raise PassRefused(
                HTTPStatus.UNAUTHORIZED,
                "the 3D view here needs a ticket (SRLAB_READS=token): open it from the "
                "console's 3D view link, or a participant's page",
            )
        return granted

    async def _turn_away(
        self, writer: asyncio.StreamWriter, upgrade: bool, head_only: bool
    ) -> None:
        self.turned_away += 1
        if not self._full_said:
            self._full_said = True
            log.warning(
                "the 3D view is full (%d viewers): new ones get 503 until one leaves",
                self.max_viewers,
            )
        retry = (f"Retry-After: {FULL_RETRY_AFTER_S}",)
        status = HTTPStatus.SERVICE_UNAVAILABLE
        if upgrade:
            body = json.dumps({"detail": full_detail(self.max_viewers)}).encode()
            writer.write(response(status, body, headers=retry))
        else:
            page = full_page(self.max_viewers)
            html = "text/html; charset=utf-8"
            writer.write(response(status, page, html, retry, head_only=head_only))
        await writer.drain()

    async def _open_upstream(
        self,
    ) -> tuple[asyncio.StreamReader, asyncio.StreamWriter, Peer]:
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.upstream_port)
        host, port = up_writer.get_extra_info("sockname")[:2]
        return up_reader, up_writer, (str(host), int(port))

    async def _page(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        head: bytes,
        granted: Pass | None,
    ) -> None:
        """Relay one page request and viser's answer; then close (once the client has)."""
        up_reader, up_writer, peer = await self._open_upstream()
        try:
            with self._upstream(peer, Relay(run=None, socket=False, granted=granted)):
                up_writer.write(head)
                async with asyncio.timeout(VISER_ANSWER_S):
                    reply = await up_reader.readuntil(b"\r\n\r\n")
                writer.write(_closing(reply))
                with contextlib.suppress(ConnectionError):
                    # viser's server resets its end once it has answered.
                    while chunk := await up_reader.read(CHUNK):
                        writer.write(chunk)
                        await writer.drain()
        finally:
            up_writer.close()
        await writer.drain()
        if writer.can_write_eof():
            writer.write_eof()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(LINGER_S):
                while await reader.read(CHUNK):
                    pass

    async def _socket(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        head: bytes,
        answer: bytes,
        run_id: int | None,
        granted: Pass | None,
    ) -> None:
        # The page's socket opens now, not when viser (on the service's process, which
        # steps back for the runs) gets to it: viser's client retries every second and
        # closes a handshake still under way, so a busy machine kept a page from ever
        # reconnecting (tests/web/test_viewer.py beside busy processes).
        writer.write(answer)
        up_reader, up_writer, peer = await self._open_upstream()
        try:
            # Known before viser sees a byte of it: viser's server answers only the gate's
            # own connections, and the viewer starts this one on the run its URL names.
            with self._upstream(peer, Relay(run=run_id, socket=True, granted=granted)):
                up_writer.write(head)
                # viser's own 101 (the same one) was answered already; anything else ends
                # the socket, as viser would have. What the page sends meanwhile waits:
                # it reaches viser only once viser has answered.
                async with asyncio.timeout(VISER_ANSWER_S):
                    reply = await up_reader.readuntil(b"\r\n\r\n")
                if reply.split(b" ", 2)[1:2] != [b"101"]:
                    log.warning(
                        "the 3D view's server refused a websocket: %s",
                        reply.split(b"\r\n", 1)[0].decode("latin-1"),
                    )
                    return
                await asyncio.gather(
                    _pipe(reader, up_writer), _pipe(up_reader, writer), return_exceptions=True
                )
        finally:
            up_writer.close()


def _closing(reply: bytes) -> bytes:
    """The head of viser's answer, saying that the connection closes after it."""
    if b"\r\nconnection:" in reply.lower():
        return reply
    return reply[:-2] + b"Connection: close\r\n\r\n"


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    """Copy until end of stream, then half-close the other side."""
    try:
        while chunk := await reader.read(CHUNK):
            writer.write(chunk)
            await writer.drain()
    finally:
        with contextlib.suppress(OSError, RuntimeError):
            if writer.can_write_eof():
                writer.write_eof()
