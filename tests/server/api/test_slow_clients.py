"""Slow clients against a live `srlab serve` (uvicorn) on loopback: they are cut off.

The deadlines are SRLAB_REQUEST_TIMEOUT_S (1 s here). Nothing asserts how long anything
took: a slow client sends for up to `GIVE_UP_S` (60 times the deadline), and the test
asserts that the server ended it, not when.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator

import pytest
from reliability_report import record

from bench.liveserver import LiveServer, live_server

GIVE_UP_S = 60.0


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    env = {"SRLAB_REQUEST_TIMEOUT_S": "1", "SRLAB_VISER": "false"}
    with live_server(tmp_path_factory.mktemp("slow") / "slow.db", env=env) as s:
        yield s


def connect(server: LiveServer) -> socket.socket:
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=GIVE_UP_S)
    return sock


def test_a_request_head_sent_a_byte_at_a_time_is_cut_off(server: LiveServer) -> None:
    with connect(server) as sock:
        sock.sendall(b"GET /api/health HTTP/1.1\r\nHost: 127.0.0.1\r\nX-Slow: ")
        deadline = time.monotonic() + GIVE_UP_S
        closed = False
        while time.monotonic() < deadline:
            try:
                sock.sendall(b"a")
            except OSError:  # reset or broken pipe: the server closed it
                closed = True
                break
            sock.settimeout(0.1)
            try:
                if sock.recv(1024) == b"":
                    closed = True
                    break
            except TimeoutError:
                pass
            except OSError:  # reset: the server closed it with our bytes unread
                closed = True
                break
        sent = GIVE_UP_S - (deadline - time.monotonic())
        record(
            "a slow request head",
            "a live srlab serve (SRLAB_REQUEST_TIMEOUT_S=1); a request head sent a byte "
            "every 0.1 s",
            f"closed by the server after about {sent:.0f} s (a stalled body got 408)",
        )
        assert closed, f"the server still read a head after {GIVE_UP_S} s"


def test_a_stalled_body_gets_408(server: LiveServer) -> None:
    with connect(server) as sock:
        sock.sendall(
            b"POST /api/runs HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
            b'Content-Length: 100\r\n\r\n{"condition": '
        )
        answer = b""
        while chunk := sock.recv(4096):  # the socket's timeout is GIVE_UP_S
            answer += chunk
    assert answer.startswith(b"HTTP/1.1 408"), answer[:200]
    assert b"did not arrive within 1 s" in answer
    # Nothing was created, and others are served as before.
    assert server.client.get("/api/runs").json()["count"] == 0


def test_an_idle_kept_alive_connection_is_closed(server: LiveServer) -> None:
    with connect(server) as sock:
        sock.sendall(b"GET /api/health HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        answer = b""
        while chunk := sock.recv(4096):  # ends when uvicorn's keep-alive timeout closes it
            answer += chunk
    assert answer.startswith(b"HTTP/1.1 200")


def test_an_event_stream_outlives_the_deadline(server: LiveServer) -> None:
    run = server.client.post("/api/runs", json={"condition": "delayed", "mode": "realtime"})
    run_id = run.json()["id"]
    server.client.post(f"/api/runs/{run_id}/start").raise_for_status()
    try:
        with server.client.stream("GET", f"/api/runs/{run_id}/events?tick_hz=5") as stream:
            ticks = 0
            for line in stream.iter_lines():
                if line == "event: tick":
                    ticks += 1
                    if ticks == 15:  # about 3 s of ticks at 5/s: past the 1 s deadline
                        break
        assert ticks == 15
    finally:
        server.client.post(f"/api/runs/{run_id}/stop")
