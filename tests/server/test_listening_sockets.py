"""Every socket `srlab serve` listens on refuses other sites, and none is printed but its own.

A page on another loopback origin found viser's own port (ephemeral, behind the 3D view's
gate) by a `fetch(no-cors)` scan, opened viser's websocket there and rewarded and re-paced
runs. So this asks the kernel which TCP sockets the whole process tree listens on (the
service and the engines' process: whatever they opened, not a
list of ports written here) and sends each a websocket handshake from another origin and
a request with a foreign Host: none may answer 101 or 2xx. The service's output (stdout
and stderr) must name no port but the API's and the view's.
"""

from __future__ import annotations

import base64
import os
import socket
import sys
from collections.abc import Callable
from pathlib import Path

import pytest
import viser
from liveharness import listening
from reliability_report import record

from bench.liveserver import LiveServer, stop_server

pytestmark = pytest.mark.slow
FOREIGN = "http://127.0.0.2:8000"
"""Another origin on this machine's loopback, as the attacking page's was."""
ANSWER_S = 30.0
"""A bound for a hung socket, not a speed test: silence counts as a refusal."""


def _connectable(host: str) -> str:
    return {"0.0.0.0": "127.0.0.1", "::": "::1"}.get(host, host)


def _netloc(host: str, port: int) -> str:
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def status(address: tuple[str, int], lines: list[str]) -> str:
    """The status line a socket answers a GET / with these header lines ('' for none)."""
    host, port = address
    raw = "\r\n".join(["GET / HTTP/1.1", *lines]) + "\r\n\r\n"
    with socket.create_connection((_connectable(host), port), timeout=ANSWER_S) as s:
        s.sendall(raw.encode())
        try:
            return s.makefile("rb").readline().decode("latin-1").strip()
        except (TimeoutError, ConnectionError):
            return ""


def code(status_line: str) -> str:
    """The status code of a status line ('' for none)."""
    parts = status_line.split(" ")
    return parts[1] if len(parts) > 1 else ""


def handshake(address: tuple[str, int], origin: str) -> str:
    """The status line of a websocket handshake from `origin`, with the socket's own Host."""
    key = base64.b64encode(os.urandom(16)).decode()
    return status(
        address,
        [
            f"Host: {_netloc(_connectable(address[0]), address[1])}",
            "Upgrade: websocket",
            "Connection: Upgrade",
            f"Sec-WebSocket-Key: {key}",
            "Sec-WebSocket-Version: 13",
            f"Sec-WebSocket-Protocol: viser-v{viser.__version__}",
            f"Origin: {origin}",
        ],
    )


def test_every_listening_socket_refuses_other_sites_and_foreign_hosts(
    start_server: Callable[..., LiveServer], tmp_path: Path
) -> None:
    log = tmp_path / "serve.log"
    # stdout too: viser printed its port there.
    command = ["sh", "-c", f'exec "{sys.executable}" -m server.cli serve 1>&2']
    server = start_server(tmp_path / "sockets.db", command=command, log=log)
    view_port = server.client.get("/api/health").json()["viser_port"]
    sockets = listening(server.process.pid)
    ports = {port for _, port in sockets}
    # The check must see them all: the API, the view, and viser behind it at least.
    assert {server.port, view_port} < ports, sockets
    answers = {
        address: (
            handshake(address, FOREIGN),
            status(address, [f"Host: evil.example:{address[1]}"]),
        )
        for address in sorted(sockets)
    }
    record(
        "every socket `srlab serve` listens on",
        f"the {len(sockets)} listening TCP sockets of its process tree, found in /proc: a "
        f"websocket handshake from {FOREIGN} and a GET with Host: evil.example",
        "; ".join(f"port {a[1]}: {w or '-'}, {g or '-'}" for a, (w, g) in answers.items()),
    )
    for address, (upgraded, got) in answers.items():
        assert code(upgraded) != "101", (address, upgraded)
        assert not code(got).startswith("2"), (address, got)
    # viser's own port answers nobody but the gate: not even viser's own page, whose socket
    # is same-origin there (a foreign page can open that page in a window of its own).
    for port in ports - {server.port, view_port}:
        behind = ("127.0.0.1", port)
        assert code(handshake(behind, f"http://127.0.0.1:{port}")) == "403", port
        assert code(status(behind, [f"Host: 127.0.0.1:{port}"])) == "403", port
    # Not because nothing answers: the view's own page and socket still open.
    view = ("127.0.0.1", view_port)
    assert code(handshake(view, f"http://127.0.0.1:{view_port}")) == "101"
    assert code(status(view, [f"Host: 127.0.0.1:{view_port}"])) == "200"
    said = stop_server(server)
    for port in ports - {server.port, view_port}:
        assert f":{port}" not in said, f"the output names port {port}:\n{said[-3000:]}"
