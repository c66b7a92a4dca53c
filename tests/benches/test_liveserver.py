"""The live-server harness starts the server it says it started.

A port found free can be taken by another process (another pytest-xdist worker's server)
before `srlab serve` binds it. That process then answers `/api/health` with its own
database: a test once got `{"detail":"no run 1"}` from a stranger. The harness counts an
answer only from the process it started, and tries another port when it chose the port.
"""

from __future__ import annotations

import os
import subprocess
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest
from liveharness import servers

import bench.liveserver as liveserver
from bench.liveserver import PortTakenError, listens_on, start_server, stop_server


class _Healthy(BaseHTTPRequestHandler):
    """A stranger that says it is healthy to every GET."""

    def do_GET(self) -> None:
        body = b'{"status": "ok"}'
        self.send_response(200)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture
def stranger() -> Iterator[int]:
    """A port on which another server answers `/api/health` with 200."""
    server = ThreadingHTTPServer(("127.0.0.1", liveserver.free_port()), _Healthy)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield server.server_address[1]
    finally:
        server.shutdown()
        server.server_close()


def test_a_stranger_holds_the_port_it_listens_on_and_we_do_not(stranger: int) -> None:
    assert listens_on(os.getpid(), stranger)
    with subprocess.Popen(["sleep", "30"]) as other:
        try:
            assert not listens_on(other.pid, stranger)
        finally:
            other.kill()


def test_a_port_given_and_taken_by_a_stranger_is_an_error_not_the_stranger(
    stranger: int, tmp_path: Path
) -> None:
    with pytest.raises(PortTakenError, match=f"port {stranger}"):
        start_server(tmp_path / "srlab.db", port=stranger)


@pytest.mark.slow
def test_a_port_chosen_and_taken_by_a_stranger_is_given_up_for_another(
    stranger: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real = liveserver.free_port
    chosen = iter([stranger])
    monkeypatch.setattr(liveserver, "free_port", lambda: next(chosen, None) or real())
    server = start_server(tmp_path / "srlab.db")
    try:
        assert server.port != stranger
        assert listens_on(server.process.pid, server.port)
        assert server.client.get("/api/runs").json()["count"] == 0
    finally:
        stop_server(server)


@pytest.mark.slow
def test_a_server_a_failed_test_leaves_running_is_killed(tmp_path: Path) -> None:
    with pytest.raises(RuntimeError, match="a failed assertion"), servers() as start:
        server = start(tmp_path / "srlab.db")
        assert server.process.poll() is None
        raise RuntimeError("a failed assertion")
    assert server.process.returncode is not None
    assert server.client.is_closed


def test_free_port_does_not_hand_out_a_port_twice_in_a_row() -> None:
    # A server's port and its 3D view's are asked for one after the other, before either
    # binds: with 12,000 candidates, 200 draws would repeat one most of the time.
    ports = [liveserver.free_port() for _ in range(200)]
    assert len(set(ports)) == len(ports)
