"""What only the tests ask of a live `srlab serve`, beside `bench.liveserver`.

`bench.liveserver` starts and stops a server (the tests, the benches and scripts/ share
it); here: its child processes and listening sockets as the tests check them, a run's
status polled, and servers started in turn with none left running.
"""

from __future__ import annotations

import ipaddress
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx

from bench.liveserver import LiveServer, family, links, listeners, start_server


def children(pid: int) -> dict[int, str]:
    """The processes whose parent is `pid`, with their command lines (a zombie's is '')."""
    found = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            command = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ")
        except OSError:
            continue
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            found[int(entry)] = command.decode(errors="replace")
    return found


def listening(pid: int) -> set[tuple[str, int]]:
    """The TCP addresses (host, port) that `pid` and its descendants listen on.

    Read from the kernel's tables (`/proc/net/tcp`, `/proc/net/tcp6`) and the processes'
    open files: every listening socket they hold, whoever opened it. Empty where those
    cannot be read (not Linux).
    """
    held = {link for p in family(pid) for link in links(Path(f"/proc/{p}/fd"))}
    return {
        (_address(address), port)
        for address, port, inode in listeners()
        if f"socket:[{inode}]" in held
    }


def _address(hexed: str) -> str:
    """An address as the kernel's TCP tables write it, in text.

    The tables write it in 32-bit words in the machine's byte order: little-endian, as on
    every machine srlab runs on.
    """
    words = bytes.fromhex(hexed)
    raw = b"".join(words[i : i + 4][::-1] for i in range(0, len(words), 4))
    return str(ipaddress.ip_address(raw))


def kill_server(server: LiveServer) -> None:
    """SIGKILL the server if it still runs, and close its client: no check, no leak."""
    server.client.close()
    if server.process.poll() is None:
        server.process.kill()
    server.process.communicate()


@contextmanager
def servers() -> Iterator[Callable[..., LiveServer]]:
    """`start_server`, with every server it started killed on the way out if still running.

    For a test that starts several in turn: one a failed assertion leaves running is not
    left to the garbage collector, whose warnings would fail whichever test runs next.
    """
    started: list[LiveServer] = []

    def start(*args: Any, **kwargs: Any) -> LiveServer:
        server = start_server(*args, **kwargs)
        started.append(server)
        return server

    try:
        yield start
    finally:
        for server in started:
            kill_server(server)


def start_run(api: httpx.Client, **body: Any) -> int:
    """POST /api/runs with `body` (201), then start it (200); its id."""
    r = api.post("/api/runs", json=body)
    assert r.status_code == 201, r.text
    run_id: int = r.json()["id"]
    assert api.post(f"/api/runs/{run_id}/start").status_code == 200
    return run_id


def wait_run(
    api: httpx.Client,
    run_id: int,
    ready: Callable[[dict[str, Any]], bool],
    what: str,
    timeout: float = 60,
) -> dict[str, Any]:
    """Poll a run (GET /api/runs/{id}) until `ready(run)`; `what` names it in the failure."""
    deadline = time.monotonic() + timeout
    run: dict[str, Any] = {}
    while time.monotonic() < deadline:
        r = api.get(f"/api/runs/{run_id}")
        assert r.status_code == 200, f"GET run {run_id}: {r.status_code} {r.text}"
        run = r.json()
        if ready(run):
            return run
        time.sleep(0.05)
    raise AssertionError(f"run {run_id} never {what}: {run}")


def wait_status(api: httpx.Client, run_id: int, status: str, timeout: float = 60) -> dict[str, Any]:
    """Poll a run until it has `status`."""
    return wait_run(api, run_id, lambda run: run["status"] == status, f"became {status}", timeout)


def wait_episodes(api: httpx.Client, run_id: int, n: int, timeout: float = 90) -> dict[str, Any]:
    """Poll a run until it has finished `n` episodes (their rows may still be on their way)."""
    return wait_run(
        api, run_id, lambda run: run["episodes_done"] >= n, f"finished {n} episodes", timeout
    )
