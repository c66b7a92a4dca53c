"""A real `srlab serve` on loopback, for the end-to-end and browser tests and the scripts."""

from __future__ import annotations

import contextlib
import os
import secrets
import signal
import socket
import subprocess
import sys
import time
from collections import deque
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import httpx

from bench.procs import descendants

ROOT = Path(__file__).resolve().parents[1]


_RECENT: deque[int] = deque(maxlen=256)
"""The ports `free_port` handed out last in this process."""

EPHEMERAL_PORTS = Path("/proc/sys/net/ipv4/ip_local_port_range")


def _below_ephemeral() -> range:
    """Ports below the kernel's ephemeral range (none where it is unknown or starts low)."""
    try:
        low = int(EPHEMERAL_PORTS.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return range(0)
    return range(max(1024, low - 12_000), low)


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on right now.

    It is taken below the ephemeral range, which the kernel draws on for every client
    connection and every bind to port 0: a server restarted on its port finds it free even
    while other processes (pytest-xdist's workers) open connections all the time.

    A port is not handed out twice in a row within one process (the last
    `_RECENT.maxlen` are skipped): a server and its 3D view, asked for one after the
    other before either binds, get two ports.
    """
    candidates = _below_ephemeral()
    for _ in range(50 if candidates else 0):
        port = candidates[secrets.randbelow(len(candidates))]
        if port in _RECENT:
            continue
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
            _RECENT.append(port)
            return port
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        any_port: int = s.getsockname()[1]
        return any_port


@dataclass
class LiveServer:
    """A running `srlab serve` process and an httpx client on it."""

    url: str
    port: int
    database: Path | str
    process: subprocess.Popen[bytes]
    client: httpx.Client
    log: Path | None = None
    """Where its stderr goes, when not to a pipe (long or busy servers: a pipe fills up)."""


STARTUP_S = 240.0
"""How long a server may take to come up: a bound for a hung start, not a speed test (a
start took 47 s on a 2-core machine at load 6; CI's may be slower)."""


TCP_TABLES = (Path("/proc/net/tcp"), Path("/proc/net/tcp6"))
LISTEN = "0A"


def listeners() -> Iterator[tuple[str, int, str]]:
    """Every listening TCP socket in the kernel's tables.

    Each as its address (as the table writes it), its port and its inode.
    """
    for table in TCP_TABLES:
        try:
            lines = table.read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if fields[3] == LISTEN:
                address, port = fields[1].rsplit(":", 1)
                yield address, int(port, 16), fields[9]


def _listening_sockets(port: int) -> set[str]:
    """The inodes of the sockets listening on `port`, from the kernel's TCP tables."""
    return {inode for _, bound, inode in listeners() if bound == port}


def family(pid: int) -> set[int]:
    """`pid` and its descendants (a wrapper command may start the server as a child)."""
    return {pid} | descendants(pid)


def listens_on(pid: int, port: int) -> bool:
    """Whether process `pid` (or a descendant) holds the socket listening on `port`.

    True where the kernel's tables cannot be read (not Linux): the check is then skipped.
    """
    if not TCP_TABLES[0].exists():
        return True
    wanted = {f"socket:[{inode}]" for inode in _listening_sockets(port)}
    return any(links(Path(f"/proc/{p}/fd")) & wanted for p in family(pid))


def links(folder: Path) -> set[str]:
    """What the links in `folder` point to (a process's open files); none if it is gone."""
    links = set()
    with contextlib.suppress(OSError):
        for fd in folder.iterdir():
            with contextlib.suppress(OSError):  # closed meanwhile
                links.add(os.readlink(fd))
    return links


class PortTakenError(AssertionError):
    """Another process listens on the port the server was to take."""


def _wait_healthy(client: httpx.Client, process: subprocess.Popen[bytes], port: int) -> None:
    """Wait until `process` answers on `port`: the answer must come from it.

    A port found free may be taken by another process (another pytest-xdist worker's
    server) before this one binds it; that one's `/api/health` answers first, with its
    own database. So a 200 counts only once `process` holds the listening socket.
    """
    deadline = time.monotonic() + STARTUP_S
    while time.monotonic() < deadline:
        exited = process.poll() is not None
        try:
            answered = not exited and client.get("/api/health").status_code == 200
        except httpx.HTTPError:
            answered = False
        if answered and listens_on(process.pid, port):
            return
        if (exited or answered) and _listening_sockets(port):
            raise PortTakenError(f"another process listens on port {port}")
        if exited:
            raise AssertionError(f"srlab serve exited with {process.returncode}")
        time.sleep(0.2)
    raise AssertionError(f"srlab serve did not come up within {STARTUP_S:g} s")


def start_server(
    database: Path | str,
    port: int | None = None,
    env: dict[str, str] | None = None,
    *,
    command: Sequence[str] | None = None,
    cwd: Path | None = None,
    log: Path | None = None,
    headers: dict[str, str] | None = None,
) -> LiveServer:
    """Start `srlab serve` and wait until it answers.

    `database` is a SQLite file or any SQLAlchemy URL. `command` replaces
    `python -m server.cli serve --port PORT` (the port is in SRLAB_PORT too), `cwd` the
    repository as working directory, `log` the stderr pipe with a file; `headers` go with
    every request of the server's client (e.g. the bearer token).
    """
    for _ in range(PORT_ATTEMPTS - 1 if port is None else 0):
        with contextlib.suppress(PortTakenError):  # try another
            return _start(database, free_port(), env, command, cwd, log, headers)
    return _start(database, port or free_port(), env, command, cwd, log, headers)


PORT_ATTEMPTS = 5
"""How many free ports `start_server` tries when another process takes the one it chose."""


def _start(
    database: Path | str,
    port: int,
    env: dict[str, str] | None,
    command: Sequence[str] | None,
    cwd: Path | None,
    log: Path | None,
    headers: dict[str, str] | None,
) -> LiveServer:
    environment = {
        **os.environ,
        "SRLAB_VISER_PORT": str(free_port()),
        **(env or {}),
        # `database` and `port` win over `env`: the client must find the server there.
        "SRLAB_DATABASE_URL": database if isinstance(database, str) else f"sqlite:///{database}",
        "SRLAB_PORT": str(port),
    }
    argv = command or [sys.executable, "-m", "server.cli", "serve", "--port", str(port)]
    with ExitStack() as files:
        stderr: IO[bytes] | int = (
            files.enter_context(log.open("ab")) if log is not None else subprocess.PIPE
        )
        process = subprocess.Popen(
            list(argv), cwd=cwd or ROOT, env=environment, stdout=subprocess.DEVNULL, stderr=stderr
        )
    url = f"http://127.0.0.1:{port}"
    client = httpx.Client(base_url=url, timeout=10, headers=headers)
    try:
        _wait_healthy(client, process, port)
    except BaseException as e:
        process.kill()
        _, err = process.communicate()
        client.close()
        if not isinstance(e, AssertionError) or isinstance(e, PortTakenError):
            raise
        said = log.read_text(errors="replace") if log is not None else err.decode(errors="replace")
        raise AssertionError(f"{e}; its stderr ends with:\n{said[-3000:]}") from None
    return LiveServer(url, port, database, process, client, log)


def stop_server(server: LiveServer, check: bool = True) -> str:
    """SIGTERM the server and wait; with `check`, assert it shut down cleanly."""
    server.client.close()
    server.process.terminate()
    _, err = server.process.communicate(timeout=30)
    text = server_log(server) if server.log is not None else err.decode(errors="replace")
    if check:
        # uvicorn shuts down cleanly, then re-raises the signal it caught.
        assert server.process.returncode in (0, -signal.SIGTERM), text[-3000:]
        assert "Application shutdown complete" in text, text[-3000:]
        assert "Traceback" not in text, text[-3000:]
    return text


def server_log(server: LiveServer) -> str:
    """What a server started with `log` has written to stderr so far."""
    assert server.log is not None
    return server.log.read_text(errors="replace")


@contextmanager
def live_server(database: Path | str, env: dict[str, str] | None = None) -> Iterator[LiveServer]:
    """`start_server`, then a clean `stop_server` on the way out."""
    server = start_server(database, env=env)
    try:
        yield server
    finally:
        stop_server(server)
