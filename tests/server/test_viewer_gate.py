"""The 3D view's URLs that name a run (`/run/<id>`): the gate's rewrite and its choice.

A page opened on `/run/<id>` opens its websocket on that path again at every reconnect (a
restart of the service included): the gate rewrites it to viser's `/` and chooses the run
for the session viser opens. The real page across a real restart is
tests/web/test_viewer.py.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import os
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from pathlib import Path

import httpx
import pytest
from apphelpers import client_for, settings_for
from viserpage import camera_message, page_socket, viewer_of
from websockets.asyncio.client import ClientConnection, connect
from websockets.exceptions import ConnectionClosed
from websockets.typing import Subprotocol

from bench.liveserver import free_port
from server.guard import SitePolicy
from server.viewer import Viewer
from server.viewer import gate as gate_module
from server.viewer.app import Session
from server.viewer.gate import Gate, Peer, handshake_answer, run_path

pytestmark = pytest.mark.anyio
WAIT_S = 60.0
"""A bound for a hung view, not a speed test."""


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
    lines = ["Upgrade: websocket", "Connection: Upgrade", f"Sec-WebSocket-Key: {key}"]
    if origin is not None:
        lines.append(f"Origin: {origin}")
    return head(target, *lines)


@asynccontextmanager
async def gate_before(
    upstream: Callable[[asyncio.StreamReader, asyncio.StreamWriter], Awaitable[None]],
    on_run: Callable[[int, Peer], None] | None = None,
) -> AsyncIterator[Gate]:
    """A gate on loopback in front of a server that handles each connection with `upstream`."""
    fake = await asyncio.start_server(upstream, "127.0.0.1", 0)
    policy = SitePolicy.of(["127.0.0.1"], [])
    gate = Gate("127.0.0.1", 0, fake.sockets[0].getsockname()[1], policy, on_run=on_run)
    await asyncio.to_thread(gate.start)
    try:
        yield gate
    finally:
        await asyncio.to_thread(gate.stop)
        fake.close()


@asynccontextmanager
async def gate_on_a_fake_viser(
    on_run: Callable[[int, Peer], None],
) -> AsyncIterator[tuple[Gate, list[tuple[bytes, Peer]]]]:
    """A gate in front of a server that records each request head and its sender, then 200."""
    heads: list[tuple[bytes, Peer]] = []

    async def upstream(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        host, port = writer.get_extra_info("peername")[:2]
        heads.append((await reader.readuntil(b"\r\n\r\n"), (host, port)))
        writer.write(b"HTTP/1.1 200 OK\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
        await writer.drain()
        writer.close()

    async with gate_before(upstream, on_run) as gate:
        yield gate, heads


async def send(port: int, raw: bytes) -> bytes:
    """The status line the gate answers `raw` with."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        writer.write(raw)
        await writer.drain()
        async with asyncio.timeout(WAIT_S):
            return await reader.readline()
    finally:
        writer.close()


async def test_the_gate_names_a_websockets_run_and_relays_it_to_slash() -> None:
    named: list[tuple[int, Peer]] = []
    async with gate_on_a_fake_viser(lambda run_id, peer: named.append((run_id, peer))) as (
        gate,
        heads,
    ):
        assert b" 200 " in await send(gate.port, handshake("/run/7"))
        relayed, sender = heads[-1]
        assert relayed.startswith(b"GET / HTTP/1.1\r\n")
        # With the address viser sees the socket come from: the viewer keys the run by it.
        assert named == [(7, sender)]
        # The page itself: viser's page at /, and no choice (only its socket chooses).
        assert b" 200 " in await send(gate.port, head("/run/8/"))
        assert heads[-1][0].startswith(b"GET / HTTP/1.1\r\n") and len(named) == 1
        # Other paths, and a bogus or huge id, pass as they are and choose nothing.
        for target in ("/editor", "/run/7x", "/run/" + "9" * 40):
            assert b" 200 " in await send(gate.port, handshake(target))
            assert heads[-1][0].startswith(f"GET {target} HTTP/1.1\r\n".encode())
        assert len(named) == 1
        # A socket the guard refuses chooses nothing, and reaches no viser.
        count = len(heads)
        assert b" 403 " in await send(gate.port, handshake("/run/9", "http://127.0.0.1:9999"))
        assert len(heads) == count and len(named) == 1 and gate.refused == 1


async def test_a_failing_choice_still_opens_the_view() -> None:
    def fail(run_id: int, peer: Peer) -> None:
        raise RuntimeError(f"cannot choose {run_id}")

    async with gate_on_a_fake_viser(fail) as (gate, heads):
        assert b" 200 " in await send(gate.port, handshake("/run/3"))
        assert heads[-1][0].startswith(b"GET / HTTP/1.1\r\n")


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
    # Not a handshake the gate can answer: viser answers it (with its error).
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

    async with gate_before(upstream) as gate:
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


async def until(check: Callable[[], object], what: str) -> None:
    deadline = asyncio.get_running_loop().time() + WAIT_S
    while not check():
        if asyncio.get_running_loop().time() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.02)


async def start_run(client: httpx.AsyncClient, start: bool = True, **body: object) -> int:
    r = await client.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    run_id = int(r.json()["id"])
    if start:
        assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
    return run_id


async def becomes_viewer(viewer: Viewer, socket: ClientConnection) -> Session:
    """Send the page's first camera message, which makes viser call the socket a viewer."""
    before = set(viewer.sessions)
    await socket.send(camera_message())
    await until(lambda: set(viewer.sessions) - before, "the socket's viewer session")
    (client_id,) = set(viewer.sessions) - before
    return viewer.sessions[client_id]


@asynccontextmanager
async def watching(viewer: Viewer, path: str) -> AsyncIterator[Session]:
    """A page's viewer on the view's `path`; its session ends on the way out."""
    async with page_socket(viewer.port, path) as socket:
        yield await becomes_viewer(viewer, socket)
    await until(lambda: not viewer.sessions, "the viewer's session to end")


def shows(session: Session, run_id: int) -> bool:
    return session.controller.state.run_id == run_id


@pytest.mark.slow
async def test_a_socket_on_a_runs_url_shows_that_run_again_after_a_restart(
    tmp_path: Path,
) -> None:
    port = free_port()
    settings = settings_for(tmp_path, viser=True, viser_port=port)
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        chosen = await start_run(client, condition="kp", mode="realtime", hz=20, seed=1)
        newest = await start_run(client, condition="delayed", mode="realtime", hz=20)
        # On /, a viewer follows the newest running run.
        async with watching(viewer, "/") as session:
            await until(lambda: shows(session, newest), f"run {newest}, the newest")
        # On /run/<chosen>, and again on the next socket (a reconnect), the chosen run, live.
        for _ in range(2):
            async with watching(viewer, f"/run/{chosen}/") as session:
                await until(lambda: shows(session, chosen), f"run {chosen}, the URL's")
                assert session.controller.state.mode == "live"
                # The view looks for runs every second: it stays put (a bound, not a speed).
                await asyncio.sleep(2.5)
                assert shows(session, chosen)
        later = await start_run(client, start=False, condition="delayed")  # the newest stored
    # A restart: the page's socket reconnects on its own URL, to a new service where
    # another run is live and newer; it is given its run back, not the newest.
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        assert (await client.post(f"/api/runs/{later}/start")).status_code == 200
        async with watching(viewer, f"/run/{chosen}") as session:
            await until(lambda: shows(session, chosen), f"run {chosen} after the restart")
            await asyncio.sleep(2.5)
            assert shows(session, chosen)
            live = session.controller.state.live
            assert live is not None and live.status == "interrupted"
        await client.post(f"/api/runs/{later}/stop")


async def test_pages_reconnecting_together_each_get_their_own_run(tmp_path: Path) -> None:
    port = free_port()
    settings = settings_for(tmp_path, viser=True, viser_port=port)
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        one, two, newest = [
            await start_run(client, start=False, condition="delayed") for _ in range(3)
        ]
        # Both sockets are open before either becomes a viewer (viser waits for a page's
        # first camera message), as when pages reconnect at the same moment after a
        # restart; the second to connect becomes a viewer first.
        async with (
            page_socket(viewer.port, f"/run/{one}") as first,
            page_socket(viewer.port, f"/run/{two}") as second,
            page_socket(viewer.port, "/") as plain,
        ):
            two_session = await becomes_viewer(viewer, second)
            one_session = await becomes_viewer(viewer, first)
            plain_session = await becomes_viewer(viewer, plain)
            await until(lambda: shows(two_session, two), f"run {two} on its page")
            await until(lambda: shows(one_session, one), f"run {one} on its page")
            # A page on / takes no page's run: it shows the newest run.
            await until(lambda: shows(plain_session, newest), f"run {newest} on /")
        await until(lambda: not viewer.sessions, "the sessions to end")
        # The console's way still works: POST /view, then a page on /.
        assert (await client.post(f"/api/runs/{one}/view")).status_code == 200
        async with watching(viewer, "/") as session:
            await until(lambda: shows(session, one), f"run {one}, chosen by POST /view")
        # The console posts and opens /run/<id>: that choice is used up by this page.
        assert (await client.post(f"/api/runs/{two}/view")).status_code == 200
        async with watching(viewer, f"/run/{two}") as session:
            await until(lambda: shows(session, two), f"run {two}, chosen and named")
        async with watching(viewer, "/") as session:
            await until(lambda: shows(session, newest), f"run {newest}: nothing left chosen")
