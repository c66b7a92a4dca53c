"""HTTP/1.1 keep-alive clients for the open-loop load: raw asyncio streams, and httpx to compare."""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from dataclasses import dataclass, field
from typing import Any, Protocol

HOST = "127.0.0.1"
"""Where the bench's servers listen: loopback only."""


class Client(Protocol):
    """What the load generator needs of an HTTP client."""

    name: str

    async def request(self, method: str, path: str, body: Any = None) -> tuple[int, bytes]:
        """Send one request; its status and body."""
        ...

    async def warm(self) -> None:
        """Open every connection of the pool."""
        ...

    async def aclose(self) -> None:
        """Close every connection."""
        ...


IDLE_S = 2.0
"""A pooled connection idle longer is reopened: uvicorn closes idle ones after 5 s."""


@dataclass
class _Conn:
    reader: asyncio.StreamReader
    writer: asyncio.StreamWriter
    used: float = field(default_factory=time.monotonic)

    def close(self) -> None:
        self.writer.close()


class RawClient:
    """HTTP/1.1 keep-alive over a pool of asyncio streams; a request waits for a free one.

    Tens of microseconds per request where httpx needs about a millisecond, which on two
    cores decides whether the client or the server is measured.
    """

    name = "raw asyncio streams"

    def __init__(
        self,
        port: int,
        connections: int,
        timeout_s: float,
        headers: dict[str, str] | None = None,
    ) -> None:
        self._port = port
        self._timeout_s = timeout_s
        self._size = connections
        self._idle: asyncio.Queue[_Conn | None] = asyncio.Queue()
        for _ in range(connections):
            self._idle.put_nowait(None)  # opened when first used
        extra = "".join(f"{k}: {v}\r\n" for k, v in (headers or {}).items())
        self._host_header = f"Host: {HOST}:{port}\r\n{extra}"

    def _message(self, method: str, path: str, body: Any) -> bytes:
        head = f"{method} {path} HTTP/1.1\r\n{self._host_header}"
        data = b""
        if body is not None:
            data = json.dumps(body).encode()
            head += "Content-Type: application/json\r\n"
        if body is not None or method in ("POST", "PUT"):
            head += f"Content-Length: {len(data)}\r\n"
        return head.encode() + b"\r\n" + data

    async def _open(self) -> _Conn:
        reader, writer = await asyncio.open_connection(HOST, self._port)
        return _Conn(reader, writer)

    @staticmethod
    async def _exchange(conn: _Conn, message: bytes) -> tuple[int, bytes, bool]:
        conn.writer.write(message)
        return await _read_response(conn.reader)

    async def request(self, method: str, path: str, body: Any = None) -> tuple[int, bytes]:
        """Send one request on a free connection (a fresh one if the server closed it).

        The timeout covers the wait for a free connection too: a request that waited that
        long in all would be given up by a real client.
        """
        message = self._message(method, path, body)
        async with asyncio.timeout(self._timeout_s):
            conn = await self._idle.get()
            try:
                if conn is not None and time.monotonic() - conn.used > IDLE_S:
                    conn.close()
                    conn = None
                reused = conn is not None
                if conn is None:
                    conn = await self._open()
                try:
                    status, payload, keep = await self._exchange(conn, message)
                except (asyncio.IncompleteReadError, ConnectionError) as e:
                    # A kept-alive connection the server closed before reading the request:
                    # send it again on a new one, as HTTP clients do.
                    partial = isinstance(e, asyncio.IncompleteReadError) and e.partial
                    if not reused or partial:
                        raise
                    conn.close()
                    conn = None
                    conn = await self._open()
                    status, payload, keep = await self._exchange(conn, message)
                conn.used = time.monotonic()
                if not keep:
                    conn.close()
                    conn = None
                return status, payload
            except BaseException:
                if conn is not None:
                    conn.close()
                    conn = None
                raise
            finally:
                self._idle.put_nowait(conn)

    async def warm(self) -> None:
        """Open every connection with a GET /api/health on each."""
        await asyncio.gather(*(self.request("GET", "/api/health") for _ in range(self._size)))

    async def aclose(self) -> None:
        """Close the idle connections (all of them, once the load is over)."""
        while not self._idle.empty():
            conn = self._idle.get_nowait()
            if conn is not None:
                conn.close()
                with contextlib.suppress(OSError):
                    await conn.writer.wait_closed()


async def _read_response(reader: asyncio.StreamReader) -> tuple[int, bytes, bool]:
    """Status, body and whether the connection stays open."""
    head = await reader.readuntil(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split(" ", 2)[1])
    headers: dict[str, str] = {}
    for line in lines[1:]:
        key, _, value = line.partition(":")
        headers[key.strip().lower()] = value.strip()
    keep = headers.get("connection", "").lower() != "close"
    if "content-length" in headers:
        return status, await reader.readexactly(int(headers["content-length"])), keep
    if headers.get("transfer-encoding", "").lower() == "chunked":
        parts = []
        while True:
            size = int((await reader.readuntil(b"\r\n")).split(b";")[0], 16)
            chunk = await reader.readexactly(size + 2)
            if size == 0:
                break
            parts.append(chunk[:-2])
        return status, b"".join(parts), keep
    return status, await reader.read(), False


class HttpxClient:
    """httpx.AsyncClient with a keep-alive pool (HTTP/1.1), for comparison."""

    name = "httpx.AsyncClient"

    def __init__(self, port: int, connections: int, timeout_s: float) -> None:
        import httpx

        self._size = connections
        self._timeout_s = timeout_s
        self._client = httpx.AsyncClient(
            base_url=f"http://{HOST}:{port}",
            limits=httpx.Limits(max_connections=connections, max_keepalive_connections=connections),
            timeout=timeout_s,
        )

    async def request(self, method: str, path: str, body: Any = None) -> tuple[int, bytes]:
        """Send one request (the timeout covers the wait for a connection too)."""
        async with asyncio.timeout(self._timeout_s):
            r = await self._client.request(method, path, json=body)
        return r.status_code, r.content

    async def warm(self) -> None:
        """Open the connections of the pool."""
        await asyncio.gather(
            *(self._client.get("/api/health") for _ in range(self._size)),
            return_exceptions=True,
        )

    async def aclose(self) -> None:
        """Close the pool."""
        await self._client.aclose()


def make_client(kind: str, port: int, connections: int, timeout_s: float) -> Client:
    if kind == "httpx":
        return HttpxClient(port, connections, timeout_s)
    return RawClient(port, connections, timeout_s)
