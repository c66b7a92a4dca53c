"""viser's own server behind the gate: whom it answers, how much the gate relays to it.

The end-to-end check (every socket of a live `srlab serve`) is test_listening_sockets.py;
here each layer is checked alone, on the app with its 3D view.
"""

from __future__ import annotations

import asyncio
import base64
import logging
import os
from pathlib import Path

import pytest
from apphelpers import client_for, settings_for
from viserpage import PROTOCOL, camera_message, page_socket, viewer_of

from bench.liveserver import free_port
from server.viewer import upstream

pytestmark = pytest.mark.anyio
WAIT_S = 60.0
"""A bound for a hung view, not a speed test."""


async def until(check: object, what: str) -> None:
    deadline = asyncio.get_running_loop().time() + WAIT_S
    while not check():  # type: ignore[operator]
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.02)


async def exchange(port: int, raw: bytes, head_only: bool = False) -> bytes:
    """What `127.0.0.1:port` answers `raw` with: until it closes, or its answer's head."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(raw)
        await writer.drain()
        async with asyncio.timeout(WAIT_S):
            return await (reader.readuntil(b"\r\n\r\n") if head_only else reader.read())
    finally:
        writer.close()


def handshake(port: int) -> bytes:
    key = base64.b64encode(os.urandom(16)).decode()
    lines = [
        "GET / HTTP/1.1",
        f"Host: 127.0.0.1:{port}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Key: {key}",
        "Sec-WebSocket-Version: 13",
        f"Sec-WebSocket-Protocol: {PROTOCOL}",
    ]
    return ("\r\n".join(lines) + "\r\n\r\n").encode()


async def first_line(port: int, raw: bytes) -> bytes:
    return await exchange(port, raw, head_only=True)


async def test_only_a_socket_through_the_gate_becomes_a_viewer(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (_, app):
        viewer = viewer_of(app)
        server = viewer.server
        loop = server._websock_server._background_event_loop
        assert loop is not None

        async def unguard() -> None:
            found = upstream.websockets_server(server.get_port())
            inner = getattr(found.process_request, "srlab_inner", None)
            assert inner is not None, "viser's server is not guarded"
            found.process_request = inner

        # Were viser's server ever reached past its guard, the viewer still makes no session.
        asyncio.run_coroutine_threadsafe(unguard(), loop).result(WAIT_S)
        async with page_socket(server.get_port()) as direct:
            await direct.send(camera_message())
            async with asyncio.timeout(WAIT_S):
                await direct.wait_closed()
            assert direct.close_code == 1008, direct.close_reason
        assert not viewer.sessions
        # Through the gate, the same page's socket becomes a viewer.
        async with page_socket(viewer.port) as socket:
            await socket.send(camera_message())
            await until(lambda: viewer.sessions, "the gate's socket's session")


async def test_viser_refuses_a_socket_that_did_not_come_through_the_gate(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (_, app):
        viewer = viewer_of(app)
        behind = viewer.server.get_port()
        assert b" 403 " in await first_line(behind, handshake(behind))
        assert b" 101 " in await first_line(viewer.port, handshake(viewer.port))


async def test_a_pipelined_request_gets_one_answer_and_logs_no_error(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (_, app):
        port = viewer_of(app).port
        request = f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode()
        answered = await exchange(port, request + request)
        assert answered.startswith(b"HTTP/1.1 200 ")
        assert answered.count(b"HTTP/1.1 ") == 1
        # Another connection is served as ever.
        assert (await exchange(port, request)).startswith(b"HTTP/1.1 200 ")
    errors = [r for r in caplog.records if r.levelno >= logging.ERROR]
    assert not errors, [r.getMessage() for r in errors]


async def test_viewers_past_the_cap_get_503_until_one_leaves(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port(), viser_max_viewers=2)
    async with client_for(settings) as (_, app):
        viewer = viewer_of(app)
        port = viewer.port
        page = f"GET /run/3 HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode()
        async with page_socket(port) as first, page_socket(port):
            await first.send(camera_message())
            refused = await first_line(port, handshake(port))
            assert refused.startswith(b"HTTP/1.1 503 ") and b"Retry-After: " in refused
            assert b"SRLAB_VISER_MAX_VIEWERS" in await exchange(port, handshake(port))
            # A page that would open a third socket is told so before it loads.
            assert (await exchange(port, page)).startswith(b"HTTP/1.1 503 ")
            await until(lambda: viewer.sessions, "the first viewer's session")
        await until(lambda: viewer.gate.sockets == 0, "the viewers to leave")
        assert b" 101 " in await first_line(port, handshake(port))
        assert (await exchange(port, page)).startswith(b"HTTP/1.1 200 ")
