"""The 3D view's front door: the cross-site guard in front of viser's port.

viser (1.1) serves its page and its websocket from one `websockets` server and offers no
hook on the handshake (its `process_request` is its own file server), so it listens on an
ephemeral loopback port and this gate listens on the view's public port. The gate reads
each connection's request head, refuses a Host the service does not answer to (DNS
rebinding) and a websocket handshake from another site (the API's rule, `SitePolicy`),
then relays the bytes both ways. The panel's writes travel over that socket, so this is
what keeps a foreign page from rewarding or re-pacing runs through it.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import threading
from http import HTTPStatus

from server.guard import SitePolicy

log = logging.getLogger("srlab.viewer")

HEAD_LIMIT = 16 * 1024
"""Bytes a request head may take (viser's client sends well under 2 KiB)."""
HEAD_TIMEOUT_S = 10.0
"""A client that has not sent its request head by then is dropped (slow clients)."""
CHUNK = 64 * 1024


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


def _response(status: HTTPStatus, detail: str) -> bytes:
    body = json.dumps({"detail": detail}).encode()
    return (
        f"HTTP/1.1 {status.value} {status.phrase}\r\n"
        "Content-Type: application/json\r\n"
        f"Content-Length: {len(body)}\r\n"
        "Connection: close\r\n\r\n"
    ).encode() + body


class Gate:
    """Listens on `host`:`port` on a thread of its own and relays accepted connections.

    `start` raises OSError when the port is taken; `stop` closes it and every relay.
    """

    def __init__(self, host: str, port: int, upstream_port: int, policy: SitePolicy) -> None:
        self.host = host
        self.port = port
        self.upstream_port = upstream_port
        self.policy = policy
        self.refused = 0
        """Requests refused so far (tests and the reliability suite read it)."""
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
        refused = refusal(headers, self.policy)
        if refused is not None:
            self.refused += 1
            status, detail = refused
            log.warning("the 3D view refused a request: %s", detail)
            writer.write(_response(status, detail))
            await writer.drain()
            return
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.upstream_port)
        try:
            up_writer.write(head)
            await asyncio.gather(
                _pipe(reader, up_writer), _pipe(up_reader, writer), return_exceptions=True
            )
        finally:
            up_writer.close()


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
