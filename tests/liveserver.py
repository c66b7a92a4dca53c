"""A real `srlab serve` on loopback for end-to-end and browser tests."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@dataclass
class LiveServer:
    """A running `srlab serve` process and an httpx client on it."""

    url: str
    port: int
    database: Path
    process: subprocess.Popen[bytes]
    client: httpx.Client


def _wait_healthy(client: httpx.Client, process: subprocess.Popen[bytes]) -> None:
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise AssertionError(f"srlab serve exited with {process.returncode}")
        try:
            if client.get("/api/health").status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.2)
    raise AssertionError("srlab serve did not come up within 60 s")


def start_server(
    database: Path, port: int | None = None, env: dict[str, str] | None = None
) -> LiveServer:
    """Start `srlab serve` on `database` (a SQLite file) and wait until it answers."""
    port = port or free_port()
    environment = {
        **os.environ,
        "SRLAB_DATABASE_URL": f"sqlite:///{database}",
        "SRLAB_VISER_PORT": str(free_port()),
        **(env or {}),
    }
    process = subprocess.Popen(
        [sys.executable, "-m", "server.cli", "serve", "--port", str(port)],
        cwd=ROOT,
        env=environment,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    url = f"http://127.0.0.1:{port}"
    client = httpx.Client(base_url=url, timeout=10)
    try:
        _wait_healthy(client, process)
    except BaseException:
        process.kill()
        client.close()
        raise
    return LiveServer(url, port, database, process, client)


def stop_server(server: LiveServer, check: bool = True) -> str:
    """SIGTERM the server and wait; with `check`, assert it shut down cleanly."""
    server.client.close()
    server.process.terminate()
    _, err = server.process.communicate(timeout=30)
    text = err.decode(errors="replace")
    if check:
        # uvicorn shuts down cleanly, then re-raises the signal it caught.
        assert server.process.returncode in (0, -signal.SIGTERM), text[-3000:]
        assert "Application shutdown complete" in text, text[-3000:]
        assert "Traceback" not in text, text[-3000:]
    return text


@contextmanager
def live_server(database: Path, env: dict[str, str] | None = None) -> Iterator[LiveServer]:
    """`start_server`, then a clean `stop_server` on the way out."""
    server = start_server(database, env=env)
    try:
        yield server
    finally:
        stop_server(server)


def wait_status(api: httpx.Client, run_id: int, status: str, timeout: float = 60) -> dict[str, Any]:
    """Poll a run until it has `status`."""
    deadline = time.monotonic() + timeout
    run: dict[str, Any] = {}
    while time.monotonic() < deadline:
        run = api.get(f"/api/runs/{run_id}").json()
        if run["status"] == status:
            return run
        time.sleep(0.05)
    raise AssertionError(f"run {run_id} never became {status}: {run}")
