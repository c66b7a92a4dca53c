"""`srlab serve` with its 3D view: a taken port fails the start, open streams end at exit."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx
from liveharness import servers

from bench.liveserver import ROOT, free_port, start_server, stop_server


def test_a_taken_view_port_stops_srlab_serve_with_a_clear_message(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        env = {
            **os.environ,
            "SRLAB_DATABASE_URL": f"sqlite:///{tmp_path / 'taken.db'}",
            "SRLAB_VISER_PORT": str(port),
        }
        done = subprocess.run(
            [sys.executable, "-m", "server.cli", "serve", "--port", str(free_port())],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
    assert done.returncode != 0
    assert f"port {port} on 127.0.0.1 is taken" in done.stderr
    assert "SRLAB_VISER_PORT" in done.stderr


def test_open_event_streams_end_with_their_run_status_when_the_service_stops(
    tmp_path: Path,
) -> None:
    server = start_server(tmp_path / "streams.db")
    api = server.client
    running = api.post("/api/runs", json={"condition": "expert", "mode": "realtime"}).json()
    api.post(f"/api/runs/{running['id']}/start")
    idle = api.post("/api/runs", json={"condition": "expert", "episodes": 1}).json()
    seen: dict[int, list[str]] = {}

    def follow(run_id: int) -> None:
        lines = seen.setdefault(run_id, [])
        with httpx.stream("GET", f"{server.url}/api/runs/{run_id}/events", timeout=30) as r:
            for line in r.iter_lines():
                lines.append(line)

    readers = [
        threading.Thread(target=follow, args=(run["id"],), daemon=True) for run in (running, idle)
    ]
    for t in readers:
        t.start()
    deadline = time.monotonic() + 10
    while len(seen) < 2 or not all(seen.values()):
        assert time.monotonic() < deadline, "the streams did not start"
        time.sleep(0.05)
    log = stop_server(server)  # a clean shutdown: no traceback, "Application shutdown complete"
    for t in readers:
        t.join(timeout=10)
        assert not t.is_alive()
    for run in (running, idle):
        statuses = [
            json.loads(line[6:])["status"]
            for line in seen[run["id"]]
            if line.startswith("data: ") and '"status"' in line
        ]
        assert statuses, seen[run["id"]]
    # The streams ended as the shutdown began, not cancelled after uvicorn's grace period.
    assert "timeout graceful shutdown exceeded" not in log


def test_requests_viser_cannot_take_are_answered_by_the_gate_and_log_no_traceback(
    tmp_path: Path,
) -> None:
    with servers() as start:  # killed should an assertion fail
        server = start(tmp_path / "requests.db", log=tmp_path / "serve.log")
        port = server.client.get("/api/health").json()["viser_port"]
        page = f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n\r\n".encode()
        answers = {
            raw: _answer(port, raw)
            for raw in (
                page + page,  # pipelined: viser got both, and logged a traceback
                b"POST / HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Length: 2\r\n\r\nhi",
                b"HEAD / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
                b"GET / HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n",
                b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nTransfer-Encoding: chunked\r\n\r\n",
            )
        }
        statuses = [answer.split(b"\r\n", 1)[0].split(b" ")[1:2] for answer in answers.values()]
        assert statuses == [[b"200"], [b"405"], [b"405"], [b"505"], [b"400"]]
        assert answers[page + page].count(b"HTTP/1.1 ") == 1  # one request, one answer
        stop_server(server)  # no traceback in its log


def _answer(port: int, raw: bytes) -> bytes:
    """All a server answers `raw` with, until it closes the connection."""
    with socket.create_connection(("127.0.0.1", port), timeout=60) as s:
        s.sendall(raw)
        received = b""
        while chunk := s.recv(65536):
            received += chunk
        return received
