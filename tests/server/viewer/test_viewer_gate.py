"""The 3D view's gate: what it lets through to viser, and how; viser's port behind it.

The gate relays a page's request alone and answers itself what viser's server cannot take;
it keeps at most `max_viewers` sockets. A page opened on `/run/<id>` opens its websocket
on that path again at every reconnect (a restart of the service included): the gate
rewrites it to viser's `/` and keeps the run with the socket's relay, for the session
viser opens. viser's own port answers the gate's relays alone, and a socket that got past
that still gets no session. The real page across a real restart is
tests/web/test_viewer.py; every listening socket of a live `srlab serve`,
tests/server/test_listening_sockets.py.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any

import pytest
from gatehelpers import WAIT_S, until
from websockets.asyncio.client import connect as ws_connect
from websockets.exceptions import ConnectionClosed, InvalidStatus
from websockets.typing import Subprotocol

from server.api.guard import SitePolicy
from server.viewer import gate as gate_module
from server.viewer.gate import MAX_VIEWERS, Gate, Peer, Relay
from server.viewer.heads import handshake_answer, run_path

pytestmark = pytest.mark.anyio


def head(target: str, *headers: str) -> bytes:
    """A GET request head for `target` with these header lines."""
    return (
        "\r\n".join([f"GET {target} HTTP/1.1", "Host: 127.0.0.1", *headers]) + "\r\n\r\n"
    ).encode()


@pytest.mark.parametrize(
    ("target", "rewritten", "run"),
    [
        ("/run/7", "/", 7),
        ("/run/7/", "/", 7),
        ("/run/12?darkMode", "/?darkMode", 12),
        ("/run/123456789012345678", "/", 123456789012345678),  # 18 digits: the longest
    ],
)
def test_a_runs_path_is_rewritten_to_visers_page_and_names_the_run(
    target: str, rewritten: str, run: int
) -> None:
    assert run_path(head(target, "Upgrade: websocket")) == (
        head(rewritten, "Upgrade: websocket"),
        run,
    )


@pytest.mark.parametrize(
    "target",
    [
        "/",
        "/?run/7",
        "/run/",
        "/run",
        "/runs/7",
        "/run/7/x",
        "/x/run/7",
        "/run/-1",
        "/run/+7",
        "/run/7a",
        "/run/1e3",
        "/run/%37",
        "/run/٣",  # an Arabic-Indic digit: digits are ASCII only
        "/run/" + "9" * 19,  # huge: no run
        "/run/" + "9" * 5000,
        "http://127.0.0.1/run/7",  # absolute form: passed on as it is
    ],
)
def test_any_other_path_passes_unchanged(target: str) -> None:
    raw = head(target, "Upgrade: websocket")
    assert run_path(raw) == (raw, None)


def test_a_malformed_request_line_passes_unchanged() -> None:
    for raw in (
        b"\r\n\r\n",
        b"GET /run/7\r\nHost: x\r\n\r\n",  # no version
        b"GET  /run/7 HTTP/1.1\r\n\r\n",  # two spaces
        b"GET /run/7 HTTP/1.1 extra\r\n\r\n",
        b"\xff\xfe /run/\xff HTTP/1.1\r\n\r\n",
    ):
        assert run_path(raw) == (raw, None)
    # Only the request line is read: a header that looks like a run path is left alone.
    raw = head("/", "Referer: http://127.0.0.1:8080/run/7")
    assert run_path(raw) == (raw, None)


def handshake(target: str, origin: str | None = None) -> bytes:
    """A websocket handshake's head for `target`, from `origin` if given."""
    key = base64.b64encode(os.urandom(16)).decode()
    lines = [
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Key: {key}",
        "Sec-WebSocket-Version: 13",
    ]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    return head(target, *lines)


Upstream = Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]]


def connect(url: str, **kwargs: Any) -> ws_connect:
    """A websocket client of the gate; the fake viser behind it answers no closing
    handshake, so a close waits 1 s for it, not websockets' 10."""
    return ws_connect(url, close_timeout=1, **kwargs)


@asynccontextmanager
async def gate_before(
    upstream: Callable[[Gate], Upstream], max_viewers: int = MAX_VIEWERS
) -> AsyncIterator[Gate]:
    """A gate on loopback in front of a server that handles each connection with `upstream`
    (made for the gate, which it may ask about its relays)."""
    gates: list[Gate] = []

    async def handle(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await upstream(gates[0])(reader, writer)

    fake = await asyncio.start_server(handle, "127.0.0.1", 0)
    policy = SitePolicy.of(["127.0.0.1"], [])
    gate = Gate("127.0.0.1", 0, fake.sockets[0].getsockname()[1], policy, max_viewers=max_viewers)
    gates.append(gate)
    await asyncio.to_thread(gate.start)
    try:
        yield gate
    finally:
        await asyncio.to_thread(gate.stop)
        fake.close()


@dataclass
class Seen:
    """A request as a fake viser got it: its head, its sender, what the gate said of the
    sender then, and whatever came after the head."""

    head: bytes
    sender: Peer
    relay: Relay | None
    rest: bytes = b""
    ended: bool = False
    """The gate closed this connection (`rest` is all it sent)."""


SWITCH = b"HTTP/1.1 101 Switching Protocols\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\r\n"


@asynccontextmanager
async def gate_on_a_fake_viser(
    max_viewers: int = MAX_VIEWERS,
) -> AsyncIterator[tuple[Gate, list[Seen]]]:
    """A gate in front of a server that records each request, then answers as viser does:
    a handshake with 101 (then holds the socket until the gate closes it), a page with 200
    and the end of its side."""
    seen: list[Seen] = []

    def upstream(gate: Gate) -> Upstream:
        async def answer(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
            host, port = writer.get_extra_info("peername")[:2]
            request = await reader.readuntil(b"\r\n\r\n")
            seen.append(Seen(request, (host, port), gate.relay((host, port))))
            if b"\r\nUpgrade: websocket" in request:
                writer.write(SWITCH)
            else:
                writer.write(b"HTTP/1.1 200 OK\r\nContent-Length: 2\r\n\r\nok")
                writer.write_eof()
            with contextlib.suppress(ConnectionError):
                seen[-1].rest = await reader.read()  # until the gate closes
            seen[-1].ended = True
            writer.close()

        return answer

    async with gate_before(upstream, max_viewers) as gate:
        yield gate, seen


async def exchange(port: int, raw: bytes) -> bytes:
    """All the gate answers `raw` with, until it closes (a socket opened: its 101)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(raw)
        await writer.drain()
        async with asyncio.timeout(WAIT_S):
            answer = await reader.readuntil(b"\r\n\r\n")
            if answer.startswith(b"HTTP/1.1 101 "):
                return answer
            return answer + await reader.read()
    finally:
        writer.close()


async def send(port: int, raw: bytes) -> bytes:
    """The status line the gate answers `raw` with."""
    return (await exchange(port, raw)).split(b"\r\n", 1)[0] + b"\r\n"


async def test_the_gate_keeps_a_websockets_run_with_its_relay_and_relays_it_to_slash() -> None:
    async with gate_on_a_fake_viser() as (gate, seen):
        assert b" 101 " in await send(gate.port, handshake("/run/7"))
        await until(lambda: len(seen) == 1, "the socket to reach viser")
        # The address viser sees the socket come from is the gate's, known with its run
        # before viser got a byte: the viewer starts the session on it.
        assert seen[-1].head.startswith(b"GET / HTTP/1.1\r\n")
        assert seen[-1].relay == Relay(run=7, socket=True)
        # The page itself: viser's page at /, and no run (only its socket chooses).
        assert b" 200 " in await send(gate.port, head("/run/8/"))
        assert seen[-1].head.startswith(b"GET / HTTP/1.1\r\n")
        assert seen[-1].relay == Relay(run=None, socket=False)

        # Other paths, and a bogus or huge id, pass as they are and name no run.
        def reached(line: bytes) -> Callable[[], bool]:
            return lambda: seen[-1].head.startswith(line)

        for target in ("/editor", "/run/7x", "/run/" + "9" * 40):
            assert b" 101 " in await send(gate.port, handshake(target))
            await until(reached(f"GET {target} ".encode()), target)
            assert seen[-1].relay == Relay(run=None, socket=True)
        # A socket the guard refuses names nothing, and reaches no viser.
        count = len(seen)
        assert b" 403 " in await send(gate.port, handshake("/run/9", "http://127.0.0.1:9999"))
        assert len(seen) == count and gate.refused == 1
        # A relay is known while it lasts, and no longer.
        await until(lambda: gate.viewers == 0, "the sockets to end")
        assert all(gate.relay(s.sender) is None for s in seen)


async def test_a_page_request_goes_alone_and_its_connection_closes_after_the_answer() -> None:
    async with gate_on_a_fake_viser() as (gate, seen):
        page = head("/")
        # Two requests back to back (pipelined), and more bytes: viser gets the first
        # alone, and the client one answer that says the connection closes.
        answer = await exchange(gate.port, page + page + b"x" * 100_000)
        assert answer.count(b"HTTP/1.1") == 1 and answer.endswith(b"\r\n\r\nok")
        assert b"\r\nConnection: close\r\n" in answer
        await until(lambda: seen and seen[0].ended, "the gate to close its side")
        assert [(s.head, s.rest) for s in seen] == [(page, b"")]


@pytest.mark.parametrize(
    ("raw", "status"),
    [
        (b"POST / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 2\r\n\r\nhi", b" 405 "),
        (b"HEAD / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n", b" 405 "),
        (b"GET / HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n", b" 505 "),
        (b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 2\r\n\r\nhi", b" 400 "),
        (b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nTransfer-Encoding: chunked\r\n\r\n", b" 400 "),
        (b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nno colon\r\n\r\n", b" 400 "),
        (b"GET /\r\nHost: 127.0.0.1\r\n\r\n", b" 400 "),
        (b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n\r\n", b" 400 "),
        (
            b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: websocket\r\n"
            b"Sec-WebSocket-Version: 8\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n",
            b" 400 ",
        ),
    ],
)
async def test_the_gate_answers_what_visers_server_cannot_take(raw: bytes, status: bytes) -> None:
    # viser's server logged a traceback for each and answered nothing.
    async with gate_on_a_fake_viser() as (gate, seen):
        answer = await exchange(gate.port, raw)
        assert status in answer.split(b"\r\n", 1)[0]
        assert b'{"detail": ' in answer or raw.startswith(b"HEAD ")
        assert not seen and gate.refused == 1


@pytest.mark.slow  # the refused handshake's close waits out the client's close timeout
async def test_past_max_viewers_a_socket_and_a_page_get_503_and_retry_after() -> None:
    async with gate_on_a_fake_viser(max_viewers=2) as (gate, seen):
        url = f"ws://127.0.0.1:{gate.port}/"
        async with connect(url) as one, connect(url):
            with pytest.raises(InvalidStatus) as refused:
                await connect(url)
            turned = refused.value.response
            assert turned.status_code == 503 and turned.headers["Retry-After"] == "5"
            assert "SRLAB_VISER_MAX_VIEWERS" in json.loads(turned.body)["detail"]
            # A page opened now says so, and tries again by itself.
            page = await exchange(gate.port, head("/run/3"))
            assert page.startswith(b"HTTP/1.1 503 ") and b"\r\nRetry-After: 5\r\n" in page
            assert b"The 3D view is full" in page and b'http-equiv="refresh"' in page
            assert gate.turned_away == 2 and len(seen) == 2  # viser got neither
            await one.close()
            await until(lambda: gate.viewers < 2, "a viewer to leave")
            async with connect(url):
                assert gate.viewers == 2
        await until(lambda: gate.viewers == 0, "the viewers to leave")


def test_the_gate_answers_a_handshake_as_viser_would() -> None:
    # RFC 6455's own example key and answer.
    headers = {
        "upgrade": "websocket",
        "sec-websocket-key": "dGhlIHNhbXBsZSBub25jZQ==",
        "sec-websocket-version": "13",
        "sec-websocket-protocol": "chat, viser-v1.1.1, viser-v0",
    }
    answer = handshake_answer(headers)
    assert answer is not None
    assert answer.startswith(b"HTTP/1.1 101 Switching Protocols\r\n")
    assert b"\r\nSec-WebSocket-Accept: s3pPLMBiTxaQ9kYGzzhZRbK+xOo=\r\n" in answer
    # viser's choice: the first `viser-v` offered; none offered, none chosen.
    assert b"\r\nSec-WebSocket-Protocol: viser-v1.1.1\r\n" in answer
    plain = handshake_answer({**headers, "sec-websocket-protocol": "chat"})
    assert plain is not None and b"Sec-WebSocket-Protocol" not in plain
    # Not a handshake the gate can answer: the gate refuses it (400).
    for broken in (
        {"sec-websocket-version": "8"},
        {"sec-websocket-key": "not base64!"},
        {"sec-websocket-key": base64.b64encode(b"short").decode()},
    ):
        assert handshake_answer({**headers, **broken}) is None


@asynccontextmanager
async def gate_on_a_slow_viser(
    status: bytes,
) -> AsyncIterator[tuple[Gate, asyncio.Event]]:
    """A gate in front of a server that answers a handshake only once the event is set:
    `status` then one text frame ("hello")."""
    answer_now = asyncio.Event()

    async def upstream(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        await reader.readuntil(b"\r\n\r\n")
        await answer_now.wait()
        # The gate may have let go meanwhile (a refusal, no answer in time).
        with contextlib.suppress(ConnectionError):
            # The gate answered the page already: what it reads here is dropped on a 101.
            writer.write(b"HTTP/1.1 " + status + b"\r\nUpgrade: websocket\r\n\r\n")
            writer.write(b"\x81\x05hello")  # a final, unmasked text frame
            await writer.drain()
            # The page's close frame (or the gate's end): answered with one, as viser
            # would, so the page does not wait out its close timeout.
            await reader.read(1)
            writer.write(b"\x88\x02\x03\xe8")  # close, 1000
            await writer.drain()
        writer.close()

    async with gate_before(lambda _: upstream) as gate:
        try:
            yield gate, answer_now
        finally:
            answer_now.set()


async def test_a_page_socket_opens_before_viser_answers_then_carries_visers_frames() -> None:
    # viser's client gives a handshake one second before it closes it and tries again: the
    # gate answers at once, whenever viser (on a busy service) gets to its own answer.
    async with gate_on_a_slow_viser(b"101 Switching Protocols") as (gate, answer_now):
        url = f"ws://127.0.0.1:{gate.port}/run/4"
        async with asyncio.timeout(WAIT_S):
            async with connect(url, subprotocols=[Subprotocol("viser-v1.1.1")]) as socket:
                assert socket.subprotocol == "viser-v1.1.1"
                assert not answer_now.is_set()  # open, and viser has not answered yet
                answer_now.set()
                assert await socket.recv() == "hello"


async def test_a_socket_viser_never_answers_is_closed(monkeypatch: pytest.MonkeyPatch) -> None:
    # The page's socket opened on the gate's answer; a viser that never gives its own must
    # not leave the page on a silent socket (it would never try again).
    monkeypatch.setattr(gate_module, "VISER_ANSWER_S", 0.2)
    async with gate_on_a_slow_viser(b"101 Switching Protocols") as (gate, answer_now):
        url = f"ws://127.0.0.1:{gate.port}/"
        async with asyncio.timeout(WAIT_S):
            async with connect(url, subprotocols=[Subprotocol("viser-v1.1.1")]) as socket:
                with pytest.raises(ConnectionClosed):
                    await socket.recv()
                assert not answer_now.is_set()


async def test_a_socket_viser_refuses_is_closed() -> None:
    async with gate_on_a_slow_viser(b"503 Service Unavailable") as (gate, answer_now):
        url = f"ws://127.0.0.1:{gate.port}/"
        async with asyncio.timeout(WAIT_S):
            async with connect(url, subprotocols=[Subprotocol("viser-v1.1.1")]) as socket:
                answer_now.set()
                with pytest.raises(ConnectionClosed):
                    await socket.recv()


# --- the real view: a socket on /run/<id> gets a session on that run ----------------------
