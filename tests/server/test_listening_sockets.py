"""Every socket `srlab serve` listens on refuses another site, whatever serves it.

A page of another loopback origin once found viser's own port (behind the 3D view's gate)
by scanning, opened viser's websocket there and rewarded and re-paced runs. The sockets
are found from the processes (the service, its store process, the engines' process and
its store process), not listed by hand: a socket added later is checked too.
"""

from __future__ import annotations

import base64
import os
import socket
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import viser

from bench.liveserver import LiveServer, free_port, listening_ports, server_log, stop_server

pytestmark = pytest.mark.slow
WAIT_S = 60.0
"""A bound for a hung socket, not a speed test."""
FOREIGN = "http://127.0.0.2:8666"
"""Another loopback origin: the attacker's page."""


def answer(port: int, host: str, *headers: str) -> bytes:
    """The status line `127.0.0.1:port` answers a GET of / with this Host and these headers."""
    head = "\r\n".join(["GET / HTTP/1.1", f"Host: {host}", *headers]) + "\r\n\r\n"
    with socket.create_connection(("127.0.0.1", port), timeout=WAIT_S) as conn:
        conn.sendall(head.encode())
        return conn.makefile("rb").readline()


def websocket(port: int, origin: str, host: str | None = None) -> bytes:
    """The status line a websocket handshake from `origin`, as viser's page sends it, gets."""
    key = base64.b64encode(os.urandom(16)).decode()
    return answer(
        port,
        host or f"127.0.0.1:{port}",
        "Upgrade: websocket",
        "Connection: Upgrade",
        f"Sec-WebSocket-Key: {key}",
        "Sec-WebSocket-Version: 13",
        f"Sec-WebSocket-Protocol: viser-v{viser.__version__}",
        f"Origin: {origin}",
    )


def status(line: bytes) -> int:
    return int(line.split(b" ", 2)[1])


@pytest.fixture
def served(tmp_path: Path, start_server: object) -> Iterator[LiveServer]:
    """`srlab serve` as `make run` starts it, its stdout and stderr both in its log."""
    port = free_port()
    # stdout too: viser prints its banner there.
    command = ["bash", "-c", 'exec "$0" -m server.cli serve --port "$1" 1>&2', sys.executable]
    server = start_server(  # type: ignore[operator]
        tmp_path / "srlab.db", port, command=[*command, str(port)], log=tmp_path / "serve.log"
    )
    yield server
    stop_server(server)


def test_every_listening_socket_refuses_a_foreign_host_and_a_foreign_sites_websocket(
    served: LiveServer,
) -> None:
    api = served.port
    view = served.client.get("/api/health").json()["viser_port"]
    ports = listening_ports(served.process.pid)
    hidden = ports - {api, view}
    # The API, the 3D view's gate, and viser's own server behind it (at least).
    assert {api, view} <= ports and hidden, ports
    for port in sorted(ports):
        assert 400 <= status(answer(port, f"evil.example:{port}")) < 500, port
        assert 400 <= status(websocket(port, FOREIGN)) < 500, port
        # DNS rebinding: a foreign name for loopback makes the page same-origin.
        rebound = f"evil.example:{port}"
        assert 400 <= status(websocket(port, f"http://{rebound}", host=rebound)) < 500, port
    # viser's own server answers nobody but the gate: not even its own page, whose socket
    # is same-origin there (a foreign page could open that page in a window of its own).
    for port in hidden:
        assert status(answer(port, f"127.0.0.1:{port}")) == 403, port
        assert status(websocket(port, f"http://127.0.0.1:{port}")) == 403, port
    # Through the gate the view works: its page, and its socket from its page.
    assert status(answer(view, f"127.0.0.1:{view}")) == 200
    assert status(websocket(view, f"http://127.0.0.1:{view}")) == 101
    # viser's address is printed nowhere (its banner, websockets' "listening on").
    said = server_log(served)
    assert "the 3D view is on" in said
    for port in hidden:
        assert str(port) not in said, said
