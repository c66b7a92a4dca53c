"""The HTTP service under load: tick pacing, reward acknowledgement and GET throughput.

Run as ``.venv/bin/python -m bench.service`` (about 3.5 minutes; ``--seconds 10
--seconds-get 5`` for a quick check). It starts ``srlab serve`` itself on 127.0.0.1 (a free
port, a temporary SQLite database, the reward rate limit raised so that the load generator
is not refused), waits for /api/health, runs a short uncounted realtime run (the process's
first run pays one-off costs), and measures in one run:

1. a realtime ``rp`` run at 20 Hz for ``--seconds`` (default 60) with no load, then another
   one while an open-loop load generator sends 200 requests/s of mixed traffic (60% reads,
   20% association edits on a network made for the bench, 20% rewards to the running run;
   ``--mix`` changes the shares): tick lateness p99 and max and overruns from each run's
   live figures side by side, the requests sent and their errors, latency by request kind
   and over time, and the client-side reward acknowledgement latency (goals: lateness p99
   <= 5 ms, max <= 25 ms, 0 overruns, 0 errors, ack p99 <= 20 ms);
2. GET /api/runs/{id} of a live realtime run at 1,000 requests/s for ``--seconds-get``
   (default 20), open loop: achieved requests/s, p50/p99 latency, errors, the client's own
   CPU (goal: >= 1,000 req/s at p99 <= 10 ms); then ``wrk`` (closed loop, as fast as the
   server answers) as a second measurement when it is installed.

With ``--part day`` (or by default after 1-2) it starts a second server and measures a long
day's bounds, each side by side in that run:

D1. GET /api/runs/{id} of a realtime run ``--old-ticks`` (200,000) ticks old, aged at
   1000 Hz, alternating with a fresh one's: p99 old / fresh (goal: <= 1.5);
D2. a run with ``--episodes`` (10,000) stored episodes (one real episode's row copied,
   written before the server starts): GET .../episodes?limit=50 and .../episodes/{n}
   (goal: p99 <= 20 ms), and a missing episode's 404s;
D3. ``--streams`` (500) clients of a 20 Hz run's event stream: how many are refused (503),
   and the run's overruns while the accepted ones read (goal: 0);
D4. ``--runs`` (32) realtime runs at 20 Hz under ``--rate`` req/s of mixed load spread over
   them for ``--seconds``: tick lateness p99 and max (worst run) and overruns over all runs
   (goals: <= 5 ms, <= 25 ms, 0).

With ``--part engines`` it measures D3 and D4 with the engines on the service's loop
(``SRLAB_ENGINES=local``) and in a process of their own (``SRLAB_ENGINES=process``,
`server/runtime/process.py`), a fresh server for each, alternated ``--rounds`` times,
and prints them side by side (medians over the rounds). ``--part costs`` measures what a
request of each kind in D4's mix costs the server in CPU, one at a time, and what the mix
at ``--rate`` would cost it in cores. ``--engines`` picks the placement of every other
part's servers (default: the engines' process, as ``srlab serve``).

Open loop: every request has a scheduled send time on a fixed-rate grid, whether earlier
ones were answered or not, and its latency counts from that time; a slow answer cannot hide
the requests that would have queued behind it (no coordinated omission). A request not
answered within ``--timeout`` of leaving (waiting for a free connection included) counts
as an error. The client is a small HTTP/1.1 keep-alive client on asyncio streams: on two
cores httpx.AsyncClient (``--client httpx``) cannot send 1,000 requests/s itself. CPU
shares of the client, the server and the rest of the machine are printed with each load,
since other work on the machine skews every figure.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import importlib.util
import itertools
import json
import math
import os
import random
import re
import resource
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Coroutine, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, Protocol
from urllib.parse import quote

from bench.figures import percentile

ROOT = Path(__file__).resolve().parents[1]
HOST = "127.0.0.1"
REWARD_LIMIT = 100_000
"""SRLAB_REWARD_RATE_PER_S and SRLAB_REWARD_BURST for the bench's server (defaults 20, 40)."""
EDIT_PAIRS = 8
"""Associations the edits spread over."""
NETWORK_BASE = "innate"

# --------------------------------------------------------------------------- HTTP clients


class Client(Protocol):
    """What the load generator needs of an HTTP client."""

    name: str

    async def request(self, method: str, path: str, body: Any = None) -> tuple[int, bytes]:
        """Send one request; its status and body."""
        ...

    async def warm(self) -> None:
        """Open every connection of the pool."""
        ...

    async def aclose(self) -> None:
        """Close every connection."""
        ...


IDLE_S = 2.0
"""A pooled connection idle longer is reopened: uvicorn closes idle ones after 5 s."""


@dataclass
class _Conn:
    reader: asyncio.StreamReader
    writer: asyncio.StreamWriter
    used: float = field(default_factory=time.monotonic)

    def close(self) -> None:
        self.writer.close()


class RawClient:
    """HTTP/1.1 keep-alive over a pool of asyncio streams; a request waits for a free one.

    Tens of microseconds per request where httpx needs about a millisecond, which on two
    cores decides whether the client or the server is measured.
    """

    name = "raw asyncio streams"

    def __init__(self, port: int, connections: int, timeout_s: float) -> None:
        self._port = port
        self._timeout_s = timeout_s
        self._size = connections
        self._idle: asyncio.Queue[_Conn | None] = asyncio.Queue()
        for _ in range(connections):
            self._idle.put_nowait(None)  # opened when first used
        self._host_header = f"Host: {HOST}:{port}\r\n"

    def _message(self, method: str, path: str, body: Any) -> bytes:
        head = f"{method} {path} HTTP/1.1\r\n{self._host_header}"
        data = b""
        if body is not None:
            data = json.dumps(body).encode()
            head += "Content-Type: application/json\r\n"
        if body is not None or method in ("POST", "PUT"):
            head += f"Content-Length: {len(data)}\r\n"
        return head.encode() + b"\r\n" + data

    async def _open(self) -> _Conn:
        reader, writer = await asyncio.open_connection(HOST, self._port)
        return _Conn(reader, writer)

    @staticmethod
    async def _exchange(conn: _Conn, message: bytes) -> tuple[int, bytes, bool]:
        conn.writer.write(message)
        return await _read_response(conn.reader)

    async def request(self, method: str, path: str, body: Any = None) -> tuple[int, bytes]:
        """Send one request on a free connection (a fresh one if the server closed it).

        The timeout covers the wait for a free connection too: a request that waited that
        long in all would be given up by a real client.
        """
        message = self._message(method, path, body)
        async with asyncio.timeout(self._timeout_s):
            conn = await self._idle.get()
            try:
                if conn is not None and time.monotonic() - conn.used > IDLE_S:
                    conn.close()
                    conn = None
                reused = conn is not None
                if conn is None:
                    conn = await self._open()
                try:
                    status, payload, keep = await self._exchange(conn, message)
                except (asyncio.IncompleteReadError, ConnectionError) as e:
                    # A kept-alive connection the server closed before reading the request:
                    # send it again on a new one, as HTTP clients do.
                    partial = isinstance(e, asyncio.IncompleteReadError) and e.partial
                    if not reused or partial:
                        raise
                    conn.close()
                    conn = None
                    conn = await self._open()
                    status, payload, keep = await self._exchange(conn, message)
                conn.used = time.monotonic()
                if not keep:
                    conn.close()
                    conn = None
                return status, payload
            except BaseException:
                if conn is not None:
                    conn.close()
                    conn = None
                raise
            finally:
                self._idle.put_nowait(conn)

    async def warm(self) -> None:
        """Open every connection with a GET /api/health on each."""
        await asyncio.gather(*(self.request("GET", "/api/health") for _ in range(self._size)))

    async def aclose(self) -> None:
        """Close the idle connections (all of them, once the load is over)."""
        while not self._idle.empty():
            conn = self._idle.get_nowait()
            if conn is not None:
                conn.close()
                with contextlib.suppress(OSError):
                    await conn.writer.wait_closed()


async def _read_response(reader: asyncio.StreamReader) -> tuple[int, bytes, bool]:
    """Status, body and whether the connection stays open."""
    head = await reader.readuntil(b"\r\n\r\n")
    lines = head.decode("latin-1").split("\r\n")
    status = int(lines[0].split(" ", 2)[1])
    headers: dict[str, str] = {}
    for line in lines[1:]:
        key, _, value = line.partition(":")
        headers[key.strip().lower()] = value.strip()
    keep = headers.get("connection", "").lower() != "close"
    if "content-length" in headers:
        return status, await reader.readexactly(int(headers["content-length"])), keep
    if headers.get("transfer-encoding", "").lower() == "chunked":
        parts = []
        while True:
            size = int((await reader.readuntil(b"\r\n")).split(b";")[0], 16)
            chunk = await reader.readexactly(size + 2)
            if size == 0:
                break
            parts.append(chunk[:-2])
        return status, b"".join(parts), keep
    return status, await reader.read(), False


class HttpxClient:
    """httpx.AsyncClient with a keep-alive pool (HTTP/1.1), for comparison."""

    name = "httpx.AsyncClient"

    def __init__(self, port: int, connections: int, timeout_s: float) -> None:
        import httpx

        self._size = connections
        self._timeout_s = timeout_s
        self._client = httpx.AsyncClient(
            base_url=f"http://{HOST}:{port}",
            limits=httpx.Limits(max_connections=connections, max_keepalive_connections=connections),
            timeout=timeout_s,
        )

    async def request(self, method: str, path: str, body: Any = None) -> tuple[int, bytes]:
        """Send one request (the timeout covers the wait for a connection too)."""
        async with asyncio.timeout(self._timeout_s):
            r = await self._client.request(method, path, json=body)
        return r.status_code, r.content

    async def warm(self) -> None:
        """Open the connections of the pool."""
        await asyncio.gather(
            *(self._client.get("/api/health") for _ in range(self._size)),
            return_exceptions=True,
        )

    async def aclose(self) -> None:
        """Close the pool."""
        await self._client.aclose()


# --------------------------------------------------------------------------- the load


@dataclass(frozen=True)
class Request:
    """One request of a load: `kind` groups it in the results."""

    kind: str
    method: str
    path: str
    body: Any = None


@dataclass(frozen=True)
class Sample:
    """One request's outcome; status 0: no response (the exception is in `error`)."""

    kind: str
    status: int
    latency_s: float
    """From the request's scheduled send time to its full response."""
    at_s: float
    """Its scheduled send time, from the load's start."""
    error: str = ""

    @property
    def ok(self) -> bool:
        """A 2xx answer."""
        return 200 <= self.status < 300


@dataclass
class Load:
    """What an open-loop load sent and got back."""

    rate: float
    seconds: float
    samples: list[Sample] = field(default_factory=list)
    lag_s: list[float] = field(default_factory=list)
    """How late the generator dispatched each request after its scheduled time."""
    wall_s: float = 0.0
    """From the first scheduled send to the last answer."""
    cpu: str = ""
    """Who used the CPU meanwhile."""
    errors_seen: dict[tuple[str, str], str] = field(default_factory=dict)
    """An example answer per (kind, what went wrong)."""

    @property
    def errors(self) -> int:
        """Non-2xx answers and requests without one."""
        return sum(not s.ok for s in self.samples)

    def latencies(self, kind: str | None = None) -> list[float]:
        """Latencies of the 2xx answers (of one kind)."""
        return [s.latency_s for s in self.samples if s.ok and (kind is None or s.kind == kind)]


async def open_loop(
    client: Client,
    rate: float,
    seconds: float,
    plan: Callable[[int], Request],
    server_pid: int,
) -> Load:
    """Send `plan(i)` at `t0 + i / rate` for `seconds`, whatever the answers; wait for all."""
    load = Load(rate, seconds)
    total = max(1, round(rate * seconds))
    tasks: set[asyncio.Task[None]] = set()

    t0 = time.perf_counter() + 0.005

    async def one(req: Request, scheduled: float) -> None:
        try:
            status, body = await client.request(req.method, req.path, req.body)
        except Exception as e:  # timeouts, resets: counted, never fatal
            what = type(e).__name__
            late = time.perf_counter() - scheduled
            load.samples.append(Sample(req.kind, 0, late, scheduled - t0, what))
            load.errors_seen.setdefault((req.kind, what), str(e)[:200])
            return
        sample = Sample(req.kind, status, time.perf_counter() - scheduled, scheduled - t0)
        load.samples.append(sample)
        if not sample.ok:
            load.errors_seen.setdefault(
                (req.kind, str(status)), body[:200].decode(errors="replace")
            )

    meter = CpuMeter(server_pid)
    i = 0
    while i < total:
        now = time.perf_counter()
        while i < total and t0 + i / rate <= now:
            scheduled = t0 + i / rate
            load.lag_s.append(now - scheduled)
            task = asyncio.create_task(one(plan(i), scheduled))
            tasks.add(task)
            task.add_done_callback(tasks.discard)
            i += 1
        if i < total:
            await asyncio.sleep(max(0.0, t0 + i / rate - time.perf_counter()))
    while tasks:
        await asyncio.gather(*tasks)
    load.wall_s = time.perf_counter() - t0
    load.cpu = meter.report()
    return load


@dataclass(frozen=True)
class EditTarget:
    """Where the edits go: a network made for the bench and pairs a PUT may change."""

    network: str
    template: str
    """The PUT path, e.g. /api/networks/{name}/associations/{stimulus}/{behaviour}."""
    pairs: tuple[tuple[str, str], ...]

    def path(self, stimulus: str, behaviour: str) -> str:
        """The PUT path of one association."""
        values = iter((self.network, stimulus, behaviour))
        return re.sub(r"\{[^}]+\}", lambda _: quote(next(values), safe=""), self.template)


@dataclass(frozen=True)
class Mix:
    """Shares of reads, association edits and rewards in the mixed load."""

    reads: float = 60.0
    edits: float = 20.0
    rewards: float = 20.0

    @classmethod
    def parse(cls, text: str) -> Mix:
        """From "READS,EDITS,REWARDS", e.g. "60,20,20"."""
        try:
            reads, edits, rewards = (float(x) for x in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not READS,EDITS,REWARDS") from None
        if min(reads, edits, rewards) < 0 or reads + edits + rewards <= 0:
            raise argparse.ArgumentTypeError("the shares must be >= 0 and not all 0")
        return cls(reads, edits, rewards)

    def describe(self, edits: bool) -> str:
        """The mix in words, in percent."""
        total = self.reads + self.edits + self.rewards
        r, e, w = (100 * x / total for x in (self.reads, self.edits, self.rewards))
        if edits or e == 0:
            return f"{r:.0f}% reads, {e:.0f}% edits, {w:.0f}% rewards"
        return f"{r + e:.0f}% reads ({e:.0f}% instead of edits), {w:.0f}% rewards"


def mixed(run_id: int, edits: EditTarget | None, mix: Mix, seed: int) -> Callable[[int], Request]:
    """Reads, association edits and rewards to `run_id` in `mix`'s shares, drawn at random.

    Reads are GET /api/runs/{id}, its /ltm and /rewards and /api/stimuli in equal shares.
    Without edit endpoints, the edits' share reads the run's network instead.
    """
    rng = random.Random(seed)
    run = f"/api/runs/{run_id}"
    reads = [
        Request("GET /api/runs/{id}", "GET", run),
        Request("GET /api/runs/{id}/ltm", "GET", f"{run}/ltm"),
        Request("GET /api/runs/{id}/rewards", "GET", f"{run}/rewards"),
        Request("GET /api/stimuli", "GET", "/api/stimuli"),
    ]
    fallback = Request("GET /api/runs/{id}/network", "GET", f"{run}/network")
    total = mix.reads + mix.edits + mix.rewards

    def plan(i: int) -> Request:
        x = rng.random() * total
        if x < mix.reads:
            return reads[min(len(reads) - 1, int(x / mix.reads * len(reads)))]
        if x < mix.reads + mix.edits:
            if edits is None:
                return fallback
            stimulus, behaviour = rng.choice(edits.pairs)
            body = {"strength": round(rng.random(), 3), "source": "dp", "locked": False}
            return Request("PUT association", "PUT", edits.path(stimulus, behaviour), body)
        body = {"value": round(rng.uniform(-1.0, 1.0), 3), "note": "bench"}
        return Request("POST /api/runs/{id}/rewards", "POST", f"{run}/rewards", body)

    return plan


# --------------------------------------------------------------------------- the server


def free_port() -> int:
    """A port nobody listens on now."""
    with socket.socket() as s:
        s.bind((HOST, 0))
        port: int = s.getsockname()[1]
        return port


def cpu_seconds(pid: int) -> float | None:
    """User plus system CPU time of a running process (Linux), None if unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def tree_cpu_seconds(pid: int) -> float | None:
    """`cpu_seconds` of a process and every process under it (its store and engines' ones)."""
    parents: dict[int, int] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        parents[int(stat.parent.name)] = int(fields[1])
    tree, grew = {pid}, True
    while grew:
        below = {child for child, parent in parents.items() if parent in tree} - tree
        tree |= below
        grew = bool(below)
    own = cpu_seconds(pid)
    if own is None:
        return None
    return own + sum(cpu_seconds(p) or 0.0 for p in tree - {pid})


def machine_busy_s() -> float | None:
    """CPU time the whole machine spent busy, summed over its cores (Linux)."""
    try:
        fields = Path("/proc/stat").read_text().splitlines()[0].split()
    except (OSError, IndexError):
        return None
    user, nice, system, _idle, _iowait, irq, softirq, steal = map(int, fields[1:9])
    return (user + nice + system + irq + softirq + steal) / os.sysconf("SC_CLK_TCK")


class CpuMeter:
    """Who used the CPU from now on: the bench, the server and the rest of the machine.

    The server's share is its process's and those it started (the store's, the engines').

    The bench counts the children it waited for (wrk); other work on the machine skews
    every figure, so it is shown too.
    """

    def __init__(self, server_pid: int) -> None:
        self._pid = server_pid
        self._started = time.perf_counter()
        self._client = self._client_s()
        self._server = tree_cpu_seconds(server_pid)
        self._machine = machine_busy_s()

    @staticmethod
    def _client_s() -> float:
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        return time.process_time() + children.ru_utime + children.ru_stime

    def client_share(self) -> float:
        """The bench's CPU since the start, as a share of one core."""
        return (self._client_s() - self._client) / (time.perf_counter() - self._started)

    def report(self, client: str = "client") -> str:
        """Each one's share of one core since the start."""
        wall = time.perf_counter() - self._started
        mine = self._client_s() - self._client
        server1, machine1 = tree_cpu_seconds(self._pid), machine_busy_s()
        parts = [f"{client} {mine / wall:.0%}"]
        server = None
        if self._server is not None and server1 is not None:
            server = server1 - self._server
            parts.append(f"server {server / wall:.0%}")
        if self._machine is not None and machine1 is not None and server is not None:
            rest = max(0.0, machine1 - self._machine - server - mine)
            parts.append(f"rest of the machine {rest / wall:.0%}")
        return f"{', '.join(parts)} of one core ({os.cpu_count()} cores)"


@dataclass
class Server:
    """`srlab serve` in a subprocess with its own database and log."""

    folder: Path
    port: int = field(default_factory=free_port)
    proc: subprocess.Popen[bytes] | None = None
    env: dict[str, str] = field(default_factory=lambda: {"SRLAB_VISER_PORT": str(free_port())})
    """More SRLAB_* settings (by default the 3D view on a free port, not on 8080)."""
    placement: ClassVar[str] = "process"
    """Where servers tick their runs unless `env` says (``--engines``)."""
    extra: ClassVar[dict[str, str]] = {}
    """Settings for every server (``--env``), before `env`'s own."""

    @property
    def log(self) -> Path:
        """Its stdout and stderr: uvicorn's access log and the service's own."""
        return self.folder / "server.log"

    @property
    def url(self) -> str:
        """Its database."""
        return f"sqlite:///{self.folder / 'bench.db'}"

    def start(self) -> None:
        """Start it; it migrates the database first."""
        env = {k: v for k, v in os.environ.items() if not k.startswith("SRLAB_")}
        env.update(
            **placement_env(self.placement),
            SRLAB_DATABASE_URL=self.url,
            SRLAB_HOST=HOST,
            SRLAB_PORT=str(self.port),
            SRLAB_REWARD_RATE_PER_S=str(REWARD_LIMIT),
            SRLAB_REWARD_BURST=str(REWARD_LIMIT),
        )
        env.update(self.extra)
        env.update(self.env)
        script = Path(sys.executable).with_name("srlab")
        command = [str(script)] if script.exists() else [sys.executable, "-m", "server.cli"]
        with self.log.open("wb") as out:
            self.proc = subprocess.Popen(
                [*command, "serve", "--host", HOST, "--port", str(self.port)],
                cwd=ROOT,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,  # a Ctrl-C of the bench reaches it only through stop()
            )

    @property
    def pid(self) -> int:
        """Its process id."""
        assert self.proc is not None
        return self.proc.pid

    def exited(self) -> int | None:
        """Its exit code once it ended."""
        return None if self.proc is None else self.proc.poll()

    def stop(self) -> int | None:
        """SIGINT (uvicorn's graceful shutdown: runs are interrupted), then wait; kill late."""
        if self.proc is None:
            return None
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode

    def tail(self, lines: int = 30) -> str:
        """The end of its log."""
        try:
            return "\n".join(self.log.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""


async def wait_healthy(client: Client, server: Server, timeout_s: float) -> dict[str, Any]:
    """Poll /api/health until it answers 200."""
    end = time.monotonic() + timeout_s
    while True:
        if server.exited() is not None:
            raise RuntimeError(f"srlab serve exited with {server.exited()}:\n{server.tail()}")
        with contextlib.suppress(OSError, asyncio.TimeoutError, asyncio.IncompleteReadError):
            status, body = await client.request("GET", "/api/health")
            if status == 200:
                health: dict[str, Any] = json.loads(body)
                return health
        if time.monotonic() > end:
            raise RuntimeError(f"no healthy srlab serve after {timeout_s:g} s:\n{server.tail()}")
        await asyncio.sleep(0.2)


async def call(client: Client, method: str, path: str, body: Any = None) -> Any:
    """A set-up call that must succeed; its JSON."""
    status, payload = await client.request(method, path, body)
    if not 200 <= status < 300:
        raise RuntimeError(f"{method} {path} answered {status}: {payload[:300].decode()}")
    return json.loads(payload) if payload else None


async def start_run(client: Client, hz: float) -> int:
    """Create and start a realtime rp run; returns once it is ticking."""
    run = await call(client, "POST", "/api/runs", {"condition": "rp", "mode": "realtime", "hz": hz})
    run_id = int(run["id"])
    await call(client, "POST", f"/api/runs/{run_id}/start")
    for _ in range(500):
        state = await call(client, "GET", f"/api/runs/{run_id}")
        if state["status"] == "running":
            return run_id
        if state["status"] not in ("created",):
            raise RuntimeError(f"run {run_id} is {state['status']}: {state.get('error')}")
        await asyncio.sleep(0.002)
    raise RuntimeError(f"run {run_id} did not start")


async def stop_run(client: Client, run_id: int) -> None:
    """Stop a run (best effort: a run that already ended is fine)."""
    with contextlib.suppress(RuntimeError, TimeoutError, OSError, asyncio.IncompleteReadError):
        await call(client, "POST", f"/api/runs/{run_id}/stop")


async def recover(client: Client, limit_s: float) -> float | None:
    """Seconds until /api/health answers within 50 ms again (None: not within `limit_s`).

    After an overload the server still works off what it accepted; the next measurement
    waits for that.
    """
    started = time.perf_counter()
    while time.perf_counter() - started < limit_s:
        sent = time.perf_counter()
        with contextlib.suppress(TimeoutError, OSError, asyncio.IncompleteReadError):
            status, _ = await client.request("GET", "/api/health")
            if status == 200 and time.perf_counter() - sent < 0.05:
                return time.perf_counter() - started
        await asyncio.sleep(0.5)
    return None


async def edit_target(client: Client, seed: int) -> tuple[EditTarget | None, str]:
    """A network to edit, from what /openapi.json offers now; or None and why not."""
    paths: dict[str, dict[str, Any]] = (await call(client, "GET", "/openapi.json"))["paths"]
    put = next(
        (
            p
            for p, ops in paths.items()
            if "put" in ops
            and re.fullmatch(r"/api/networks/\{[^}]+\}/associations/\{[^}]+\}/\{[^}]+\}", p)
        ),
        None,
    )
    if "post" not in paths.get("/api/networks", {}) or put is None:
        return None, (
            "no POST /api/networks and PUT /api/networks/{name}/associations/{stimulus}/"
            "{behaviour} in /openapi.json"
        )
    name = f"bench-{os.getpid()}"
    status, body = await client.request(
        "POST", "/api/networks", {"name": name, "base": NETWORK_BASE}
    )
    if not 200 <= status < 300:
        return None, f"POST /api/networks answered {status}: {body[:200].decode()}"
    locked = set()
    with contextlib.suppress(ValueError):
        for a in _associations(json.loads(body)):
            if a.get("locked"):
                locked.add((a["stimulus"], a["behaviour"]))
    stimuli = [s["name"] for s in await call(client, "GET", "/api/stimuli")]
    behaviours = [b["name"] for b in await call(client, "GET", "/api/behaviours")]
    candidates = [(s, b) for s in stimuli for b in behaviours if (s, b) not in locked]
    random.Random(seed).shuffle(candidates)
    target = EditTarget(name, put, ())
    pairs: list[tuple[str, str]] = []
    refused: Counter[int] = Counter()
    for s, b in candidates[: EDIT_PAIRS * 5]:
        status, _ = await client.request(
            "PUT", target.path(s, b), {"strength": 0.5, "source": "dp", "locked": False}
        )
        if 200 <= status < 300:
            pairs.append((s, b))
            if len(pairs) == EDIT_PAIRS:
                break
        else:
            refused[status] += 1
    if not pairs:
        return None, f"every trial PUT was refused ({dict(refused)})"
    return EditTarget(name, put, tuple(pairs)), ""


def _associations(doc: Any) -> Iterator[dict[str, Any]]:
    """Every dict with stimulus and behaviour anywhere in a JSON document."""
    if isinstance(doc, dict):
        if "stimulus" in doc and "behaviour" in doc:
            yield doc
        for v in doc.values():
            yield from _associations(v)
    elif isinstance(doc, list):
        for v in doc:
            yield from _associations(v)


# --------------------------------------------------------------------------- wrk


@dataclass(frozen=True)
class Wrk:
    """A wrk run's figures."""

    rate: float
    requests: int
    p50_s: float | None
    p99_s: float | None
    non2xx: int
    socket_errors: int
    cpu: str


def _duration(text: str) -> float:
    m = re.fullmatch(r"([\d.]+)(us|ms|s|m)", text)
    if m is None:
        raise ValueError(text)
    return float(m[1]) * {"us": 1e-6, "ms": 1e-3, "s": 1.0, "m": 60.0}[m[2]]


def run_wrk(port: int, path: str, seconds: float, connections: int, server_pid: int) -> Wrk | str:
    """Run wrk with one thread (the other core serves); its figures, or what went wrong."""
    exe = shutil.which("wrk")
    if exe is None:
        return "wrk not installed"
    meter = CpuMeter(server_pid)
    done = subprocess.run(
        [
            exe,
            "-t1",
            f"-c{connections}",
            f"-d{max(1, round(seconds))}s",
            "--latency",
            f"http://{HOST}:{port}{path}",
        ],
        capture_output=True,
        text=True,
        timeout=seconds + 60,
        check=False,
    )
    cpu = meter.report("wrk")
    out = done.stdout
    rate = re.search(r"Requests/sec:\s+([\d.]+)", out)
    total = re.search(r"(\d+) requests in", out)
    if done.returncode != 0 or rate is None or total is None:
        return f"wrk failed ({done.returncode}): {(done.stderr or out).strip()[:300]}"
    pct = dict(re.findall(r"^\s+(\d+)%\s+(\S+)$", out, re.MULTILINE))
    non2xx = re.search(r"Non-2xx or 3xx responses:\s+(\d+)", out)
    sock = re.search(r"Socket errors: connect (\d+), read (\d+), write (\d+), timeout (\d+)", out)
    return Wrk(
        rate=float(rate[1]),
        requests=int(total[1]),
        p50_s=_duration(pct["50"]) if "50" in pct else None,
        p99_s=_duration(pct["99"]) if "99" in pct else None,
        non2xx=int(non2xx[1]) if non2xx else 0,
        socket_errors=sum(int(x) for x in sock.groups()) if sock else 0,
        cpu=cpu,
    )


# --------------------------------------------------------------------------- figures


def ms(x: float | None, width: int = 8) -> str:
    if x is None or math.isnan(x):
        return f"{'-':>{width}}   "
    return f"{x * 1000:{width}.2f} ms"


def live_ms(live: dict[str, Any] | None, key: str) -> float | None:
    value = None if live is None else live.get(key)
    return None if value is None else float(value) / 1000


def print_load(load: Load) -> None:
    answered = sum(s.status != 0 for s in load.samples)
    print(
        f"  requests sent              {len(load.samples):10,}   ({load.rate:g}/s for "
        f"{load.seconds:g} s, open loop)"
    )
    print(f"  answered                   {answered:10,}")
    print(f"  errors (non-2xx, failed)   {load.errors:10,}   (goal: 0)")
    for (kind, what), example in sorted(load.errors_seen.items()):
        n = sum(1 for s in load.samples if s.kind == kind and (s.error or str(s.status)) == what)
        print(f"    {n:6,} x {what} on {kind}: {example}")
    print(
        f"  {'by kind (2xx latency)':<34}{'count':>7}{'errors':>8}{'p50':>12}{'p99':>12}{'max':>12}"
    )
    for kind in sorted({s.kind for s in load.samples}):
        lat = load.latencies(kind)
        count = sum(1 for s in load.samples if s.kind == kind)
        errors = sum(1 for s in load.samples if s.kind == kind and not s.ok)
        row = f"    {kind:<30}{count:7,}{errors:8,}"
        for v in (percentile(lat, 50), percentile(lat, 99), max(lat, default=math.nan)):
            row += f"{'-' if math.isnan(v) else f'{v * 1000:.2f} ms':>12}"
        print(row)
    print(
        f"  generator lag p99 / max    {ms(percentile(load.lag_s, 99))} / "
        f"{ms(max(load.lag_s, default=math.nan), 1)}   (how late requests left the client)"
    )
    print(f"  CPU: {load.cpu}")


_ACCESS = re.compile(r'"([A-Z]+) (\S+) HTTP/[\d.]+" (\d{3})')


def print_log(log: Path) -> None:
    """The server's view: responses by status, and any 5xx, error or traceback lines."""
    text = log.read_text(errors="replace") if log.exists() else ""
    statuses: Counter[str] = Counter()
    bad: list[str] = []
    for line in text.splitlines():
        m = _ACCESS.search(line)
        if m is not None:
            statuses[m[3]] += 1
            if m[3].startswith("5"):
                bad.append(line.strip())
        elif re.search(r"\b(ERROR|CRITICAL|Traceback|Exception)\b", line):
            bad.append(line.strip())
    counts = ", ".join(f"{k}: {v:,}" for k, v in sorted(statuses.items()))
    print(f"server log: {sum(statuses.values()):,} responses logged ({counts or 'none'})")
    fives = sum(v for k, v in statuses.items() if k.startswith("5"))
    print(f"  5xx responses              {fives:10,}")
    print(f"  error/traceback lines      {sum(1 for b in bad if not _ACCESS.search(b)):10,}")
    for line in bad[:15]:
        print(f"    {line[:200]}")
    if len(bad) > 15:
        print(f"    ... and {len(bad) - 15} more")


# --------------------------------------------------------------------------- the bench


def make_client(kind: str, port: int, connections: int, timeout_s: float) -> Client:
    if kind == "httpx":
        return HttpxClient(port, connections, timeout_s)
    return RawClient(port, connections, timeout_s)


WINDOWS = 6
"""The mixed load's figures over time, in this many windows."""
CONTROL_TIMEOUT_S = 180.0
"""How long set-up and control calls, and reads of a run's figures, may take."""


async def watch(
    port: int, run_id: int, seconds: float, timeout_s: float
) -> list[dict[str, Any] | None]:
    """The run (its status and live figures) at the end of each window.

    It reads on a connection of its own; None where no answer came within `timeout_s`.
    """
    client = RawClient(port, 1, timeout_s)
    lives: list[dict[str, Any] | None] = []
    start = time.perf_counter()
    try:
        for k in range(1, WINDOWS + 1):
            await asyncio.sleep(max(0.0, start + k * seconds / WINDOWS - time.perf_counter()))
            try:
                status, body = await client.request("GET", f"/api/runs/{run_id}")
                lives.append(json.loads(body) if status == 200 else None)
            except (OSError, TimeoutError, asyncio.IncompleteReadError, ValueError, KeyError):
                lives.append(None)
    finally:
        await client.aclose()
    return lives


def print_over_time(load: Load, runs: list[dict[str, Any] | None]) -> None:
    """Requests and ticks per window: whether the service keeps up or falls behind."""
    width = load.seconds / WINDOWS
    edges = [k * width for k in range(WINDOWS + 1)]
    heads = "".join(f"{f'{a:.3g}-{b:.3g} s':>12}" for a, b in itertools.pairwise(edges))
    print(f"  {'over time':<27}{heads}")
    sent, errors, p99s = "", "", ""
    for a, b in itertools.pairwise(edges):
        window = [x for x in load.samples if a <= x.at_s < b]
        lat = [x.latency_s for x in window if x.ok]
        sent += f"{len(window):12,}"
        errors += f"{sum(not x.ok for x in window):12,}"
        p = percentile(lat, 99)
        p99s += f"{'-' if math.isnan(p) else f'{p * 1000:.1f} ms':>12}"
    ticks, before = "", 0
    for run in runs:
        t = None if run is None else int(run["live"]["ticks_run"])
        ticks += f"{'?' if t is None else f'{t - before:,}':>12}"
        before = t if t is not None else before
    print(f"    {'requests sent':<25}{sent}")
    print(f"    {'errors':<25}{errors}")
    print(f"    {'2xx latency p99':<25}{p99s}")
    print(f"    {'ticks run':<25}{ticks}")


def whole_ms(*lives: dict[str, Any] | None) -> bool:
    """Whether every lateness figure is a whole number of milliseconds."""
    values = [
        float(v)
        for live in lives
        if live is not None
        for v in (live.get("lateness_p99_ms"), live.get("lateness_max_ms"))
        if v is not None
    ]
    return bool(values) and all(abs(v - round(v)) < 1e-6 for v in values)


async def bench(args: argparse.Namespace, server: Server) -> None:
    client = make_client(args.client, server.port, args.connections, args.timeout)
    # Set-up, run control and figures go on connections of their own, and are patient:
    # an overloaded server still answers them eventually.
    control = RawClient(server.port, 2, CONTROL_TIMEOUT_S)
    try:
        health = await wait_healthy(control, server, args.startup_timeout)
        await client.warm()
        print(
            f"srlab serve {health['version']} on {HOST}:{server.port} (pid {server.pid}, one "
            f"uvicorn worker), {health['database']} at {server.url}"
        )
        print(
            f"reward rate limit raised so the load generator is not refused: "
            f"SRLAB_REWARD_RATE_PER_S={REWARD_LIMIT}, SRLAB_REWARD_BURST={REWARD_LIMIT} "
            "(defaults 20/s, burst 40)"
        )
        print(
            f"client: {client.name}, {args.connections} keep-alive connections, "
            f"{args.loop_name} event loop; machine: {os.cpu_count()} cores, load average "
            f"{os.getloadavg()[0]:.2f} before the bench"
        )
        edits, why = await edit_target(control, args.seed)
        if edits is not None:
            print(
                f"edits: PUT {edits.template} on network {edits.network!r} (a copy of "
                f"{NETWORK_BASE}), {len(edits.pairs)} unlocked associations, random strengths"
            )
        else:
            print(
                f"edits unavailable: {why}; their share is sent as reads of "
                "GET /api/runs/{id}/network instead"
            )

        # 0. the process's first run pays one-off costs (numba's cache, first episode)
        if args.warmup_run > 0:
            first_id = await start_run(control, args.hz)
            await asyncio.sleep(args.warmup_run)
            first = (await call(control, "GET", f"/api/runs/{first_id}"))["live"]
            await stop_run(control, first_id)
            print(
                f"0. warm-up: the server's first run (run {first_id}, {args.warmup_run:g} s, "
                f"not counted): lateness max {ms(live_ms(first, 'lateness_max_ms'), 1)}, "
                f"overruns {first['overruns']}"
            )

        # 1. realtime pacing, alone and under mixed load
        quiet_id = await start_run(control, args.hz)
        meter = CpuMeter(server.pid)
        await asyncio.sleep(args.seconds)
        quiet = (await call(control, "GET", f"/api/runs/{quiet_id}"))["live"]
        quiet_cpu = meter.report()
        await stop_run(control, quiet_id)
        busy_id = await start_run(control, args.hz)
        plan = mixed(busy_id, edits, args.mix, args.seed)
        watcher = asyncio.create_task(watch(server.port, busy_id, args.seconds, CONTROL_TIMEOUT_S))
        load = await open_loop(client, args.rate, args.seconds, plan, server.pid)
        runs = await watcher
        # The run's figures at the end of the load (read by the watcher), else now.
        busy_run = runs[-1] or await call(control, "GET", f"/api/runs/{busy_id}")
        busy = busy_run["live"]
        await stop_run(control, busy_id)
        recovered = await recover(control, CONTROL_TIMEOUT_S)
        acks = load.latencies("POST /api/runs/{id}/rewards")

        print(
            f"1. realtime rp at {args.hz:g} Hz, {args.seconds:g} s each "
            f"(runs {quiet_id} and {busy_id}):"
        )
        print(f"  {'':<27}{'no load':>13}{f'{args.rate:g} req/s mixed':>22}")
        print(f"  ticks run                  {quiet['ticks_run']:10,}   {busy['ticks_run']:16,}")
        for label, key, goal in (
            ("tick lateness p99", "lateness_p99_ms", "<= 5 ms"),
            ("tick lateness max", "lateness_max_ms", "<= 25 ms"),
            ("reward ack p99 (server)", "reward_ack_p99_ms", ""),
        ):
            tail = f"   (goal: {goal})" if goal else ""
            print(f"  {label:<27}{ms(live_ms(quiet, key))}   {ms(live_ms(busy, key), 13)}{tail}")
        print(
            f"  overruns                   {quiet['overruns']:10}   {busy['overruns']:16}   "
            "(goal: 0)"
        )
        if whole_ms(quiet, busy):
            print(
                "  (every lateness figure is a whole ms: the server's loop clock ticks in ms,"
                " as uvloop's does)"
            )
        if busy_run["status"] != "running":
            print(f"  the loaded run ended as {busy_run['status']}: {busy_run['error']}")
        print(f"  CPU with no load: {quiet_cpu}")
        print(
            f"  mixed load ({args.mix.describe(edits is not None)}; reads and rewards to run "
            f"{busy_id}):"
        )
        print_load(load)
        print_over_time(load, runs)
        print(f"  reward ack p50 (client)    {ms(percentile(acks, 50))}")
        print(f"  reward ack p99 (client)    {ms(percentile(acks, 99))}   (goal: <= 20 ms)")
        if recovered is None:
            print(f"  the server was still busy {CONTROL_TIMEOUT_S:g} s after the load ended")
        elif recovered > 1.0:
            print(
                f"  the server answered /api/health within 50 ms again {recovered:.0f} s after "
                "the load ended (working off what it had accepted)"
            )

        # 2. GET throughput of a live run
        live_id = await start_run(control, args.hz)
        path = f"/api/runs/{live_id}"

        def get(_: int) -> Request:
            return Request("GET", "GET", path)

        if args.warmup > 0:
            await open_loop(client, args.get_rate, args.warmup, get, server.pid)
        gets = await open_loop(client, args.get_rate, args.seconds_get, get, server.pid)
        during = (await call(control, "GET", path))["live"]
        lat = gets.latencies()
        print(
            f"2. GET {path} (a live realtime run), target {args.get_rate:,.0f} req/s for "
            f"{args.seconds_get:g} s after {args.warmup:g} s of warm-up:"
        )
        print(f"  {client.name}, open loop, {args.connections} connections:")
        print(f"  requests sent              {len(gets.samples):10,}")
        print(f"  achieved (2xx / s)         {len(lat) / gets.wall_s:10,.0f}   (goal: >= 1,000)")
        print(f"  latency p50                {ms(percentile(lat, 50))}")
        print(f"  latency p99                {ms(percentile(lat, 99))}   (goal: <= 10 ms)")
        print(f"  latency max                {ms(max(lat, default=math.nan))}")
        print(f"  errors                     {gets.errors:10,}   (goal: 0)")
        for (kind, what), example in sorted(gets.errors_seen.items()):
            print(f"    {what} on {kind}: {example}")
        print(
            f"  generator lag p99 / max    {ms(percentile(gets.lag_s, 99))} / "
            f"{ms(max(gets.lag_s, default=math.nan), 1)}   (how late requests left the client)"
        )
        print(f"  CPU: {gets.cpu}")
        print(
            f"  run {live_id} meanwhile: lateness p99 "
            f"{ms(live_ms(during, 'lateness_p99_ms'), 1)}, max "
            f"{ms(live_ms(during, 'lateness_max_ms'), 1)}, overruns {during['overruns']}"
        )
        if args.no_wrk:
            print("  wrk: skipped (--no-wrk)")
        else:
            w = await asyncio.to_thread(
                run_wrk, server.port, path, args.seconds_get, args.connections, server.pid
            )
            if isinstance(w, str):
                print(f"  {w}")
            else:
                print(
                    f"  wrk, closed loop (each connection sends when answered), 1 thread, "
                    f"{args.connections} connections, {args.seconds_get:g} s:"
                )
                print(f"  requests                   {w.requests:10,}")
                print(f"  requests/s                 {w.rate:10,.0f}")
                print(f"  latency p50                {ms(w.p50_s)}")
                print(
                    f"  latency p99                {ms(w.p99_s)}   (at saturation, closed "
                    "loop: not the open-loop p99)"
                )
                print(
                    f"  errors                     {w.non2xx + w.socket_errors:10,}   "
                    f"({w.non2xx} non-2xx, {w.socket_errors} socket errors)"
                )
                print(f"  CPU: {w.cpu}")
        await stop_run(control, live_id)
    finally:
        await client.aclose()
        await control.aclose()


# --------------------------------------------------------------------------- a long day


def store_episodes(url: str, episodes: int) -> int:
    """A finished run with `episodes` stored episodes, written before the server starts.

    One real episode (an `innate` run's first, with its trace) is run in-process and its row
    copied under every other number: the reads cost what real episodes' do, without
    running millions of ticks first.
    """
    from sqlalchemy import insert

    from core.engine import RunEngine
    from core.ports import Mode, RunSpec
    from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade
    from server.persistence.orm import EpisodeRow, RunRow

    upgrade(url)
    engine = make_engine(url)
    sessions = make_sessionmaker(engine)
    store = SqlAlchemyRunStore(sessions)
    run = RunEngine.create(RunSpec("innate", seed=1, episodes=1, mode=Mode.FAST), store)
    asyncio.run(run.run())
    first = store.episode(run.run_id, 0)
    assert first is not None
    with sessions.begin() as s:
        for start in range(1, episodes, 1000):
            rows = [
                {
                    "run_id": run.run_id, "episode": n, "outcome": first.outcome,
                    "cause": first.cause, "ticks": first.ticks,
                    "start_tick": n * first.ticks, "rewards": first.rewards,
                    "trace": first.trace,
                }
                for n in range(start, min(episodes, start + 1000))
            ]  # fmt: skip
            s.execute(insert(EpisodeRow), rows)
        s.get_one(RunRow, run.run_id).episodes_done = episodes
    engine.dispose()
    return run.run_id


async def timed_gets(client: Client, paths: list[str]) -> tuple[list[float], Counter[int]]:
    """GET each path in turn (closed loop, one at a time): latencies of the 2xx, statuses."""
    latencies: list[float] = []
    statuses: Counter[int] = Counter()
    for path in paths:
        sent = time.perf_counter()
        status, _ = await client.request("GET", path)
        statuses[status] += 1
        if 200 <= status < 300:
            latencies.append(time.perf_counter() - sent)
    return latencies, statuses


async def open_streams(
    port: int, run_id: int, n: int
) -> tuple[list[asyncio.Task[int]], Counter[int]]:
    """`n` clients of the run's event stream; the accepted ones keep reading (tasks)."""
    statuses: Counter[int] = Counter()
    readers: list[asyncio.Task[int]] = []

    async def one() -> None:
        try:
            reader, writer = await asyncio.open_connection(HOST, port)
        except OSError:
            statuses[0] += 1
            return
        path = f"/api/runs/{run_id}/events?tick_hz=2"
        writer.write(f"GET {path} HTTP/1.1\r\nHost: {HOST}:{port}\r\n\r\n".encode())
        try:
            line = await asyncio.wait_for(reader.readline(), 30)
            status = int(line.split()[1]) if line else 0
        except (TimeoutError, OSError, ValueError, IndexError):
            status = 0
        statuses[status] += 1
        if status != 200:
            writer.close()
            return

        async def drain() -> int:
            got = 0
            with contextlib.suppress(OSError, asyncio.CancelledError):
                while chunk := await reader.read(65536):
                    got += len(chunk)
            writer.close()
            return got

        readers.append(asyncio.create_task(drain()))

    await asyncio.gather(*(one() for _ in range(n)))
    return readers, statuses


async def day(args: argparse.Namespace, server: Server, episodes_run: int) -> None:
    """The long day's figures: an old run's reads, 10,000 episodes, 500 streams, 32 runs."""
    control = RawClient(server.port, 2, CONTROL_TIMEOUT_S)
    reads = RawClient(server.port, 1, args.timeout)
    health = await wait_healthy(control, server, args.startup_timeout)
    print(
        f"A long day: srlab serve {health['version']} on {HOST}:{server.port}, "
        f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}"
    )
    rng = random.Random(args.seed)

    # D2. a run with stored episodes: a page of 50 and one episode with its trace.
    n = args.episodes
    base = f"/api/runs/{episodes_run}/episodes"
    await timed_gets(reads, [f"{base}?limit=50"] * 20)  # warm
    pages, page_status = await timed_gets(
        reads, [f"{base}?limit=50&offset={rng.randrange(0, n - 50)}" for _ in range(args.samples)]
    )
    ones, one_status = await timed_gets(
        reads, [f"{base}/{rng.randrange(n)}" for _ in range(args.samples)]
    )
    _, missing_status = await timed_gets(reads, [f"{base}/{n + 7}"] * 200)
    print(
        f"D2. a run with {n:,} stored episodes (run {episodes_run}), {args.samples} GETs "
        "each, one at a time:"
    )
    for label, values, answers in (
        ("GET .../episodes?limit=50", pages, page_status),
        ("GET .../episodes/{n}", ones, one_status),
        ("GET .../episodes/{missing}", [], missing_status),
    ):
        figures = (
            f"p50 {ms(percentile(values, 50))}  p99 {ms(percentile(values, 99))}  "
            f"max {ms(max(values))}   (goal: p99 <= 20 ms)"
            if values
            else ""
        )
        print(f"  {label:<28}{figures}   statuses {dict(answers)}")

    # D1. an old run: it ages at the fastest realtime rate, then side by side with a fresh one.
    old_id = await start_run(control, 1000.0)
    aged_from = time.perf_counter()
    while True:
        state = await call(control, "GET", f"/api/runs/{old_id}")
        if state["ticks"] >= args.old_ticks or state["status"] != "running":
            break
        await asyncio.sleep(1.0)
    aged_s = time.perf_counter() - aged_from
    fresh_id = await start_run(control, 1000.0)
    await asyncio.sleep(1.0)
    paths = [f"/api/runs/{r}" for _ in range(args.samples) for r in (old_id, fresh_id)]
    old_l: list[float] = []
    fresh_l: list[float] = []
    for path in paths:  # alternating: both see the same machine
        lat, _ = await timed_gets(reads, [path])
        (old_l if path.endswith(f"/{old_id}") else fresh_l).extend(lat)
    old_state = await call(control, "GET", f"/api/runs/{old_id}")
    fresh_state = await call(control, "GET", f"/api/runs/{fresh_id}")
    await stop_run(control, old_id)
    await stop_run(control, fresh_id)
    ratio = percentile(old_l, 99) / percentile(fresh_l, 99)
    print(
        f"D1. GET /api/runs/{{id}} of a run {old_state['ticks']:,} ticks old (aged "
        f"{aged_s:.0f} s at 1000 Hz) and of one {fresh_state['ticks']:,} ticks old, "
        f"{args.samples} each, alternating:"
    )
    print(f"  old   p50 {ms(percentile(old_l, 50))}  p99 {ms(percentile(old_l, 99))}")
    print(f"  fresh p50 {ms(percentile(fresh_l, 50))}  p99 {ms(percentile(fresh_l, 99))}")
    print(f"  p99 old / fresh {ratio:.2f}   (goal: <= 1.5)")
    await recover(control, 30)

    await event_streams(args, server, control)
    await recover(control, 30)
    await control.aclose()
    await reads.aclose()
    await many_runs(args, server)


async def event_streams(
    args: argparse.Namespace, server: Server, control: RawClient
) -> dict[str, float]:
    """D3: ``--streams`` clients of a realtime run's event stream; its figures."""
    run_id = await start_run(control, args.hz)
    await asyncio.sleep(1.0)
    before = (await call(control, "GET", f"/api/runs/{run_id}"))["live"]
    readers, statuses = await open_streams(server.port, run_id, args.streams)
    await asyncio.sleep(args.stream_seconds)
    after = (await call(control, "GET", f"/api/runs/{run_id}"))["live"]
    await stop_run(control, run_id)  # the streams end with the run
    got = await asyncio.gather(*readers)
    overruns = after["overruns"] - before["overruns"]
    print(
        f"D3. {args.streams} clients of one {args.hz:g} Hz run's event stream for "
        f"{args.stream_seconds:g} s (run {run_id}): answers {dict(sorted(statuses.items()))}, "
        f"{sum(got) / 1024:.0f} KiB read by the accepted ones"
    )
    print(
        f"  while they were open: overruns {overruns} "
        f"(goal: 0), lateness max over the run {ms(live_ms(after, 'lateness_max_ms'), 1)}, "
        f"p99 {ms(live_ms(after, 'lateness_p99_ms'), 1)}"
    )
    return {
        "overruns": float(overruns),
        "max_ms": (live_ms(after, "lateness_max_ms") or 0.0) * 1000,
        "p99_ms": (live_ms(after, "lateness_p99_ms") or 0.0) * 1000,
    }


async def compare_engines(args: argparse.Namespace, folder: Path) -> None:
    """D3 and D4 with the engines in each of `PLACEMENTS`, alternated.

    Each round starts a fresh `srlab serve` per placement (`placement_env`), so all of
    them see the same machine within minutes of each other.
    """
    rows: dict[str, list[dict[str, float]]] = {p: [] for p in PLACEMENTS}
    for k in range(args.rounds):
        for placement in PLACEMENTS:
            server = Server(folder / f"{placement}-{k}")
            server.folder.mkdir(parents=True)
            server.env["SRLAB_MAX_RUNS"] = str(args.runs + 4)
            server.env.update(placement_env(placement))
            server.start()
            try:
                print(f"\n== round {k + 1}, engines on {placement_name(placement)} ==")
                control = RawClient(server.port, 2, CONTROL_TIMEOUT_S)
                await wait_healthy(control, server, args.startup_timeout)
                d3 = await event_streams(args, server, control)
                await recover(control, 30)
                await control.aclose()
                d4 = await many_runs(args, server)
                rows[placement].append({**{f"d3_{key}": v for key, v in d3.items()}, **d4})
            finally:
                server.stop()
    print(f"\nD3 and D4 side by side, {args.rounds} round(s), medians over rounds:")
    print(f"  {'':44}" + "".join(f"{placement_name(p):>22}" for p in PLACEMENTS))
    for key, label in (
        ("d3_overruns", "D3 overruns (goal 0)"),
        ("d3_max_ms", "D3 lateness max, ms"),
        ("p99_worst_ms", "D4 lateness p99 worst run, ms (goal 5)"),
        ("p99_median_ms", "D4 lateness p99 median run, ms"),
        ("max_ms", "D4 lateness max worst run, ms (goal 25)"),
        ("overruns", "D4 overruns, all runs (goal 0)"),
        ("request_p99_ms", "D4 requests p99, ms"),
        ("errors", "D4 request errors"),
    ):
        cells = [statistics.median(r[key] for r in rows[p]) for p in PLACEMENTS]
        print(f"  {label:<44}" + "".join(f"{c:>22.2f}" for c in cells))


async def request_costs(args: argparse.Namespace, server: Server) -> None:
    """``--part costs``: the server's CPU per request of each kind in D4's mix.

    Sent one at a time on one connection, ``--samples`` of each kind after 20 uncounted,
    to a realtime run at ``--hz``; the server's CPU counts the processes it started. Then
    what ``--rate`` requests/s of the mix would cost it, in cores: above what the machine
    has left beside the ticks, D4's load cannot be served on time.
    """
    control = RawClient(server.port, 1, CONTROL_TIMEOUT_S)
    await wait_healthy(control, server, args.startup_timeout)
    run_id = await start_run(control, args.hz)
    edits, why = await edit_target(control, args.seed)
    if edits is None:
        print(f"costs: no edits ({why})")
    plan = mixed(run_id, edits, args.mix, args.seed)
    drawn = [plan(i) for i in range(20_000)]
    share = {k: n / len(drawn) for k, n in Counter(r.kind for r in drawn).items()}
    cores = 0.0
    print(f"server CPU per request, one at a time, {args.samples} of each kind:")
    for kind in sorted(share):
        requests = [r for r in drawn if r.kind == kind][: args.samples + 20]
        warm, counted = requests[:20], requests[20:]
        for r in warm:
            await control.request(r.method, r.path, r.body)
        before, started = tree_cpu_seconds(server.pid), time.perf_counter()
        statuses = Counter([(await control.request(r.method, r.path, r.body))[0] for r in counted])
        after, wall = tree_cpu_seconds(server.pid), time.perf_counter() - started
        if before is None or after is None:
            raise SystemExit("costs: the server's CPU time cannot be read (/proc)")
        cpu_ms = (after - before) / len(counted) * 1000
        cores += args.rate * share[kind] * cpu_ms / 1000
        print(
            f"  {kind:28} {cpu_ms:6.2f} ms CPU, {wall / len(counted) * 1000:6.2f} ms "
            f"wall; {share[kind]:4.0%} of the mix; statuses {dict(sorted(statuses.items()))}"
        )
    print(f"the mix at {args.rate:g} requests/s: {cores:.2f} cores of the server's CPU")
    await stop_run(control, run_id)


async def one_run_part(args: argparse.Namespace, server: Server) -> None:
    """``--part runs``: D4 alone."""
    await many_runs(args, server)


PLACEMENTS = ("loop", "process")
"""Where a server's engines tick: the service's loop, a process of their own."""


def placement_env(placement: str) -> dict[str, str]:
    """The settings that put a server's engines there."""
    return {
        "SRLAB_ENGINES": "process" if placement == "process" else "local",
    }


def placement_name(placement: str) -> str:
    """How the comparison names where the engines tick."""
    return "the service's loop" if placement == "loop" else "their own process"


async def many_runs(args: argparse.Namespace, server: Server) -> dict[str, float]:
    """D4: ``--runs`` realtime runs under mixed load (``--part runs`` runs it alone)."""
    control = RawClient(server.port, 2, CONTROL_TIMEOUT_S)
    await wait_healthy(control, server, args.startup_timeout)
    # D4. many realtime runs under mixed load.
    ids = [await start_run(control, args.hz) for _ in range(args.runs)]
    edits, _ = await edit_target(control, args.seed)
    plans = [mixed(r, edits, args.mix, args.seed + k) for k, r in enumerate(ids)]
    client = make_client(args.client, server.port, args.connections, args.timeout)
    await client.warm()
    load = await open_loop(
        client, args.rate, args.seconds, lambda i: plans[i % len(plans)](i), server.pid
    )
    states = [await call(control, "GET", f"/api/runs/{r}") for r in ids]
    failed = [s for s in states if s["status"] == "failed"]
    lives = [s["live"] for s in states if s["live"] is not None]
    for r in ids:
        await stop_run(control, r)
    if failed:
        print(f"D4. {len(failed)} of {args.runs} runs FAILED: {failed[0]['error']}")
    if not lives:
        raise SystemExit("D4: no run reported live figures")
    p99s = [live_ms(x, "lateness_p99_ms") or 0.0 for x in lives]
    maxes = [live_ms(x, "lateness_max_ms") or 0.0 for x in lives]
    overruns = sum(int(x["overruns"]) for x in lives)
    ticks = sum(int(x["ticks_run"]) for x in lives)
    print(
        f"D4. {args.runs} realtime rp runs at {args.hz:g} Hz under {args.rate:g} req/s mixed "
        f"({args.mix.describe(edits is not None)}) for {args.seconds:g} s: {ticks:,} ticks"
    )
    print(
        f"  tick lateness p99: worst run {ms(max(p99s))}, median run "
        f"{ms(percentile(p99s, 50))}   (goal: <= 5 ms)"
    )
    print(f"  tick lateness max: worst run {ms(max(maxes))}   (goal: <= 25 ms)")
    print(f"  overruns over all runs {overruns}   (goal: 0)")
    print(
        f"  requests {len(load.samples):,}, errors {load.errors}, p99 "
        f"{ms(percentile(load.latencies(), 99))}; {load.cpu}"
    )
    if isinstance(client, RawClient):
        await client.aclose()
    await control.aclose()
    return {
        "p99_worst_ms": max(p99s) * 1000,
        "p99_median_ms": percentile(p99s, 50) * 1000,
        "max_ms": max(maxes) * 1000,
        "overruns": float(overruns),
        "request_p99_ms": percentile(load.latencies(), 99) * 1000,
        "errors": float(load.errors),
    }


def loop_runner(choice: str) -> tuple[Callable[[Coroutine[Any, Any, None]], None], str]:
    """How to run the bench's coroutine: on uvloop when asked or available, else asyncio."""
    if choice == "asyncio" or (choice == "auto" and importlib.util.find_spec("uvloop") is None):
        return asyncio.run, "asyncio"
    import uvloop

    return uvloop.run, "uvloop"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="each realtime run (60)")
    parser.add_argument("--seconds-get", type=float, default=20.0, help="GET throughput (20)")
    parser.add_argument("--hz", type=float, default=20.0, help="realtime tick rate (20)")
    parser.add_argument("--rate", type=float, default=200.0, help="mixed load req/s (200)")
    parser.add_argument("--get-rate", type=float, default=1000.0, help="GET req/s (1000)")
    parser.add_argument("--connections", type=int, default=32, help="client pool (32)")
    parser.add_argument("--warmup", type=float, default=1.0, help="GET warm-up seconds (1)")
    parser.add_argument(
        "--warmup-run",
        type=float,
        default=2.0,
        help="seconds of a first, uncounted realtime run (2; 0: none)",
    )
    parser.add_argument(
        "--mix",
        type=Mix.parse,
        default=Mix(),
        metavar="READS,EDITS,REWARDS",
        help="shares of the mixed load (60,20,20)",
    )
    parser.add_argument("--timeout", type=float, default=10.0, help="per request (10 s)")
    parser.add_argument("--startup-timeout", type=float, default=60.0)
    parser.add_argument("--seed", type=int, default=0, help="of the traffic mix")
    parser.add_argument(
        "--client",
        choices=["raw", "httpx"],
        default="raw",
        help="raw asyncio streams (default) or httpx.AsyncClient",
    )
    parser.add_argument("--loop", choices=["auto", "asyncio", "uvloop"], default="auto")
    parser.add_argument("--no-wrk", action="store_true", help="skip the wrk measurement")
    parser.add_argument("--server-log", type=Path, help="keep the server's log here")
    parser.add_argument(
        "--part",
        choices=["all", "load", "day", "runs", "engines", "costs"],
        default="all",
        help="the load figures (1-2), the long day's (D1-D4), both (default), D4 alone, "
        "D3 and D4 with the engines on the service's loop and in their own process, or "
        "the server's CPU per request of each kind in D4's mix",
    )
    parser.add_argument("--rounds", type=int, default=2, help="--part engines' rounds (2)")
    parser.add_argument(
        "--env",
        action="append",
        default=[],
        metavar="SRLAB_NAME=VALUE",
        help="a setting for every server the bench starts (repeatable), e.g. "
        "SRLAB_STORE_PROCESS=false",
    )
    parser.add_argument(
        "--engines",
        choices=list(PLACEMENTS),
        default="process",
        help="where the servers tick their runs: the service's loop (SRLAB_ENGINES=local) "
        "or a process of their own (SRLAB_ENGINES=process, the default, as srlab serve); "
        "--part engines runs both",
    )
    parser.add_argument("--episodes", type=int, default=10_000, help="D2's stored episodes")
    parser.add_argument("--old-ticks", type=int, default=200_000, help="D1's old run's age")
    parser.add_argument("--samples", type=int, default=1000, help="GETs per D1/D2 figure")
    parser.add_argument("--streams", type=int, default=500, help="D3's stream clients")
    parser.add_argument("--stream-seconds", type=float, default=15.0, help="D3's length")
    parser.add_argument("--runs", type=int, default=32, help="D4's realtime runs")
    args = parser.parse_args()
    if min(args.seconds, args.seconds_get, args.hz, args.rate, args.get_rate) <= 0:
        parser.error("durations and rates must be positive")
    if args.connections < 1 or args.warmup < 0 or args.warmup_run < 0:
        parser.error("--connections must be at least 1, --warmup(-run) not negative")
    if args.episodes <= 50 or min(args.old_ticks, args.samples, args.streams, args.runs) < 1:
        parser.error("--episodes must be over 50; --old-ticks, --samples, --streams, --runs >= 1")
    if bad := [item for item in args.env if not item.startswith("SRLAB_") or "=" not in item]:
        parser.error(f"--env takes SRLAB_NAME=VALUE, not {bad[0]!r}")

    # SIGTERM ends the bench as Ctrl-C does: through the finally that stops the server.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    with tempfile.TemporaryDirectory(prefix="srlab-bench-") as tmp:
        Server.placement = args.engines
        Server.extra = dict(item.split("=", 1) for item in args.env)
        server = Server(Path(tmp))
        started = time.perf_counter()
        try:
            runner, args.loop_name = loop_runner(args.loop)
            if args.part in ("all", "load"):
                server.start()
                runner(bench(args, server))
            if args.part in ("all", "day"):
                if server.proc is not None:
                    server.stop()
                    print_log(server.log)
                    server = Server(Path(tmp) / "day")
                server.folder.mkdir(exist_ok=True)
                server.env["SRLAB_MAX_RUNS"] = str(args.runs + 4)
                episodes_run = store_episodes(server.url, args.episodes)
                server.start()
                runner(day(args, server, episodes_run))
            if args.part == "engines":
                runner(compare_engines(args, Path(tmp) / "engines"))
            if args.part == "runs":
                server.env["SRLAB_MAX_RUNS"] = str(args.runs + 4)
                server.start()
                runner(one_run_part(args, server))
            if args.part == "costs":
                server.start()
                runner(request_costs(args, server))
        finally:
            code = server.stop()
            if server.proc is not None:
                print(
                    f"srlab serve stopped (SIGINT), exit code {code}; "
                    f"bench took {time.perf_counter() - started:.0f} s"
                )
                print_log(server.log)
                if args.server_log is not None:
                    shutil.copyfile(server.log, args.server_log)
                    print(f"server log kept in {args.server_log}")


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        sys.exit("bench.service: interrupted")
