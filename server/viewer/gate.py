"""The 3D view's front door: the cross-site guard in front of viser's port.

viser (1.1) serves its page and its websocket from one `websockets` server and offers no
hook on the handshake (its `process_request` is its own file server), so it listens on an
ephemeral loopback port and this gate listens on the view's public port. The gate reads
each connection's request head, refuses a Host the service does not answer to (DNS
rebinding) and a websocket handshake from another site (the API's rule, `SitePolicy`),
then relays the bytes both ways. The panel's writes travel over that socket, so this is
what keeps a foreign page from rewarding or re-pacing runs through it.

The gate also gives the view URLs that name a run, `/run/<id>` (the console's link). viser's
page opens its websocket on its own URL's path (its client drops the query and a trailing
slash), so the socket of a page opened on `/run/7` asks for `/run/7`, the first time and on
every automatic reconnect, a restart of the service included. The gate hands such a
socket's run to `on_run`, with the address viser sees the socket come from (the gate's own
end of the relay: the viewer starts that socket's session on the run, and no other's, even
when several pages reconnect at once), and rewrites the path to `/`, which is all viser
serves (its page, one self-contained index.html, and its socket). Only a connection's first
request head is read
(later keep-alive requests are relayed raw); that is enough, since the page needs nothing
but index.html, viser's server answers one plain HTTP request per connection and closes
it, and the websocket is a connection of its own.

The gate answers a websocket handshake itself (`handshake_answer`: the 101 viser would
send, which depends on the request alone), then hands the request to viser and drops
viser's own 101. viser's client retries a lost connection every second and closes the
attempt still under way each time; viser answers on the service's process, which steps
back for the runs, and on a machine busy with other work that took longer than a second
after a restart, so the page never reconnected. The gate's answer is a header check and a
hash on its own thread. viser's own answer is awaited at most `VISER_ANSWER_S`: the page
must not sit on an open, silent socket it would never retry.

The gate keeps the address of each of its live connections to viser (`relays`): viser's
server answers those and nobody else (`server.viewer.upstream`). A plain request is relayed
alone: viser answers one request a connection and closes it, and bytes a client sends after
its first head (a pipelined second request) are not passed on, where they failed viser's
`websockets` server with a traceback. At most `max_sockets` websockets are relayed at once
(each is a viewer, with its own renderer): past that, a handshake or a page's request gets
503 with `Retry-After`.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import logging
import re
import threading
from collections.abc import Callable
from http import HTTPStatus

from websockets.utils import accept_key

from server.guard import SitePolicy

log = logging.getLogger("srlab.viewer")

HEAD_LIMIT = 16 * 1024
"""Bytes a request head may take (viser's client sends well under 2 KiB)."""
HEAD_TIMEOUT_S = 10.0
"""A client that has not sent its request head by then is dropped (slow clients)."""
CHUNK = 64 * 1024
VISER_ANSWER_S = 30.0
"""How long the gate waits for viser's own answer to a handshake it answered already; then
it closes the page's socket, and the page tries again."""
Peer = tuple[str, int]
"""A TCP address as viser sees a connection's far end: (host, port)."""
RETRY_AFTER_S = 10
"""What a request refused for want of a viewer's place is told to wait."""
RUN_PATH = re.compile(r"/run/([0-9]{1,18})/?")
"""A view URL's path that names a run. At most 18 digits: run ids stay below 2**62 (the
API's bound), and a longer or non-digit id is no run but a plain path (viser's 404)."""


def run_path(head: bytes) -> tuple[bytes, int | None]:
    """The request head as viser must get it, and the run its path names, if any.

    `GET /run/7?x HTTP/1.1` becomes `GET /?x HTTP/1.1` and names run 7; any other head
    is returned unchanged, with None.
    """
    line, sep, rest = head.partition(b"\r\n")
    parts = line.split(b" ")
    if len(parts) != 3:
        return head, None
    method, target, version = parts
    path, query, params = target.partition(b"?")
    found = RUN_PATH.fullmatch(path.decode("latin-1"))
    if found is None:
        return head, None
    return b" ".join((method, b"/" + query + params, version)) + sep + rest, int(found[1])


def _parse_head(head: bytes) -> tuple[str, dict[str, str]]:
    """The request line's method and the headers (names lower-case, last one wins)."""
    lines = head.decode("latin-1").split("\r\n")
    method = lines[0].split(" ", 1)[0]
    headers: dict[str, str] = {}
    for line in lines[1:]:
        name, sep, value = line.partition(":")
        if sep:
            headers[name.strip().lower()] = value.strip()
    return method, headers


def refusal(headers: dict[str, str], policy: SitePolicy) -> tuple[HTTPStatus, str] | None:
    """Why the gate refuses a request with these headers, or None to let it through."""
    problem = policy.host_problem(headers.get("host"))
    if problem is not None:
        return HTTPStatus.BAD_REQUEST, problem
    if headers.get("upgrade", "").lower() == "websocket":
        problem = policy.origin_problem(headers, "http")
        if problem is not None:
            return HTTPStatus.FORBIDDEN, problem
    return None


def handshake_answer(headers: dict[str, str]) -> bytes | None:
    """The 101 viser would answer this websocket handshake with, or None if it is not one.

    viser's server (1.1) negotiates no extension (`compression=None`) and picks the first
    subprotocol offered that starts with `viser-v` (its client's version, checked after the
    handshake); so the answer depends on the request's headers alone. A request without
    a well-formed key or version 13 gets None: viser answers it (with its error).
    """
    key = headers.get("sec-websocket-key", "")
    if headers.get("sec-websocket-version") != "13":
        return None
    try:
        if len(base64.b64decode(key, validate=True)) != 16:
            return None
    except ValueError:
        return None
    lines = [
        "HTTP/1.1 101 Switching Protocols",
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Accept: {accept_key(key)}",
    ]
    offered = [p.strip() for p in headers.get("sec-websocket-protocol", "").split(",")]
    chosen = next((p for p in offered if p.startswith("viser-v")), None)
    if chosen is not None:
        lines.append(f"Sec-WebSocket-Protocol: {chosen}")
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


def _response(status: HTTPStatus, detail: str, *extra: str) -> bytes:
    body = json.dumps({"detail": detail}).encode()
    lines = [
        f"HTTP/1.1 {status.value} {status.phrase}",
        "Content-Type: application/json",
        f"Content-Length: {len(body)}",
        *extra,
        "Connection: close",
    ]
    return ("\r\n".join(lines) + "\r\n\r\n").encode() + body


def is_page(head: bytes) -> bool:
    """Whether a request head asks for the view's page (`/` or a run's URL), not a file."""
    line = head.split(b"\r\n", 1)[0].split(b" ")
    if len(line) != 3:
        return False
    path = line[1].partition(b"?")[0]
    return path == b"/" or RUN_PATH.fullmatch(path.decode("latin-1")) is not None


class Gate:
    """Listens on `host`:`port` on a thread of its own and relays accepted connections.

    `on_run` is called (on the gate's thread) with the run of each accepted websocket
    handshake on `/run/<id>` and the address of the gate's connection to viser that will
    carry it, before viser gets it. `relays` tells whether an address is one of the gate's
    live connections to viser (from any thread). `max_sockets` bounds the websockets
    relayed at once (None: no bound). `start` raises OSError when the port is taken; `stop`
    closes it and every relay.
    """

    def __init__(
        self,
        host: str,
        port: int,
        upstream_port: int,
        policy: SitePolicy,
        on_run: Callable[[int, Peer], None] | None = None,
        max_sockets: int | None = None,
    ) -> None:
        self.host = host
        self.port = port
        self.upstream_port = upstream_port
        self.policy = policy
        self.on_run = on_run
        self.max_sockets = max_sockets
        self.refused = 0
        """Requests refused so far (tests and the reliability suite read it)."""
        self.sockets = 0
        """Websockets relayed now (the gate's thread counts them)."""
        self._upstreams: set[Peer] = set()
        self._upstreams_lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: asyncio.Server | None = None
        self._thread: threading.Thread | None = None
        self._relays: set[asyncio.Task[None]] = set()

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

    def relays(self, peer: Peer) -> bool:
        """Whether `peer` is the address of one of the gate's live connections to viser."""
        with self._upstreams_lock:
            return peer in self._upstreams

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
        _, headers = _parse_head(head)
        upgrade = headers.get("upgrade", "").lower() == "websocket"
        refused = refusal(headers, self.policy) or self._full(head, upgrade)
        if refused is not None:
            self.refused += 1
            status, detail = refused
            log.warning("the 3D view refused a request: %s", detail)
            extra = (
                (f"Retry-After: {RETRY_AFTER_S}",)
                if status is HTTPStatus.SERVICE_UNAVAILABLE
                else ()
            )
            writer.write(_response(status, detail, *extra))
            await writer.drain()
            return
        head, run_id = run_path(head)
        # A viewer's place is taken now, before any await: sockets arriving together
        # cannot all pass `_full` on the same count.
        taken = 1 if upgrade else 0
        self.sockets += taken
        try:
            await self._relay(reader, writer, head, headers, run_id if upgrade else None)
        finally:
            self.sockets -= taken

    async def _relay(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        head: bytes,
        headers: dict[str, str],
        run_id: int | None,
    ) -> None:
        """Relay one accepted request to viser: a plain one alone, a websocket both ways."""
        upgrade = headers.get("upgrade", "").lower() == "websocket"
        answer = handshake_answer(headers) if upgrade else None
        if answer is not None:
            # The page's socket opens now, not when viser (on the service's process, which
            # steps back for the runs) gets to it: viser's client retries every second and
            # closes a handshake still under way, so a busy machine kept a page from ever
            # reconnecting (tests/web/test_viewer.py beside busy processes).
            writer.write(answer)
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.upstream_port)
        sockname = up_writer.get_extra_info("sockname")
        peer: Peer = (str(sockname[0]), int(sockname[1]))
        # Known before viser reads a byte from it: viser's server answers no other address.
        with self._upstreams_lock:
            self._upstreams.add(peer)
        try:
            # Past the guard (a foreign page chooses nothing) and before viser sees the
            # handshake, so the choice is there when viser opens the session.
            if run_id is not None:
                self._chose(run_id, peer)
            up_writer.write(head)
            if not upgrade:
                # One request a connection, as viser serves: its answer, then the end.
                await _pipe(up_reader, writer)
                return
            if answer is not None:
                # viser's own 101 (the same one) was answered already; anything else ends
                # the socket, as viser would have.
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
            with self._upstreams_lock:
                self._upstreams.discard(peer)
            up_writer.close()

    def _full(self, head: bytes, upgrade: bool) -> tuple[HTTPStatus, str] | None:
        """A 503 for a viewer's socket or page when `max_sockets` viewers are open."""
        if self.max_sockets is None or self.sockets < self.max_sockets:
            return None
        if not upgrade and not is_page(head):
            return None
        return (
            HTTPStatus.SERVICE_UNAVAILABLE,
            f"the 3D view has {self.sockets} viewers open, the most it serves at once "
            f"(SRLAB_VISER_MAX_VIEWERS): close one, or try again in {RETRY_AFTER_S} s",
        )

    def _chose(self, run_id: int, peer: Peer) -> None:
        if self.on_run is None:
            return
        try:
            self.on_run(run_id, peer)
        except Exception:
            # The view still opens, on the run it would show without the URL's.
            log.exception("the 3D view could not choose run %d", run_id)


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
