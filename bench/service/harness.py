"""`srlab serve` under the bench: the server process, its placement, run control, its log."""

from __future__ import annotations

import asyncio
import contextlib
import json
import os
import random
import re
import signal
import subprocess
import sys
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from bench.liveserver import ROOT, free_port
from bench.service.clients import HOST, Client
from bench.service.load import EditTarget

REWARD_LIMIT = 100_000
"""SRLAB_REWARD_RATE_PER_S and SRLAB_REWARD_BURST for the bench's server (defaults 20, 40)."""
EDIT_PAIRS = 8
"""Associations the edits spread over."""
NETWORK_BASE = "innate"
"""The network the edits' own copy starts from."""
CONTROL_TIMEOUT_S = 180.0
"""How long set-up and control calls, and reads of a run's figures, may take."""


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
