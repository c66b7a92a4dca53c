"""A live service under overload, and a 50 MB request body.

64 client connections, each sending its next request as soon as the last is answered
(closed loop: as much as the one worker can take), for ``SRLAB_LOAD_SECONDS`` (5 by
default; ``make reliability`` runs 60), while a realtime run ticks at 20 Hz. The mix is
reads of the live run, its reward log and LTM, the run list, health, the catalogue, and
rewards. No request may hang,
meaning go unanswered for 10 s. None may get a 5xx other than a 503 shed. Over a full
minute the run's tick lateness must stay bounded: its p99 within one tick period and its
max within `MAX_LATENESS_MS`. CI's 5 s is only 100 ticks, whose p99 is their worst one or
two, at the mercy of whatever else the machine runs: there the lateness is measured and
reported, and not asserted.

Rewards are checked against what the rate limiter guarantees, whatever the machine's
speed: every loopback connection is one client, so at most ``burst + rate x seconds``
rewards are accepted (202), and every other reward that is answered gets 429 (or a 503
shed). How many 429s there are depends on how fast the machine answers, so it is
reported and not asserted.

A 50 MB body, once with its length declared and once chunked, gets 413 and does not grow
the server's resident memory (VmRSS, and the peak VmHWM, from /proc).
"""

from __future__ import annotations

import asyncio
import math
import os
import random
import socket
import threading
import time
from collections import Counter
from pathlib import Path

import httpx
from harness import rss_kib
from liveharness import wait_status
from reliability_report import count, record

from bench.liveserver import live_server
from bench.service import RawClient

SECONDS = float(os.environ.get("SRLAB_LOAD_SECONDS", "5"))
CONNECTIONS = 64
HZ = 20.0
TIMEOUT_S = 10.0
"""A request unanswered this long is a hang."""
MAX_LATENESS_MS = 250.0
"""The worst tick lateness allowed under overload (5 periods at 20 Hz)."""
BOUNDED_FROM_S = 30.0
"""Loads at least this long assert the lateness bounds."""
BODY_MB = 50
MAX_GROWTH_KIB = 8 * 1024
"""How much a rejected 50 MB body may grow the server's memory (peak included)."""
REWARD_RATE = 20.0
REWARD_BURST = 40
ENV = {
    "SRLAB_MAX_RUNS": "4",
    "SRLAB_REWARD_RATE_PER_S": f"{REWARD_RATE:g}",
    "SRLAB_REWARD_BURST": str(REWARD_BURST),
}


def _trainer_rewards(api: httpx.Client, run_id: int) -> int:
    """How many of the run's logged rewards are this test's (note "load")."""
    found, offset = 0, 0
    while True:
        page = api.get(f"/api/runs/{run_id}/rewards", params={"offset": offset, "limit": 1000})
        rows = page.json()["data"]
        found += sum(1 for r in rows if r["note"] == "load")
        offset += len(rows)
        if not rows or offset >= page.json()["count"]:
            return found


def _plan(run_id: int, rng: random.Random) -> tuple[str, str, str, object]:
    """(kind, method, path, body) of the next request."""
    run = f"/api/runs/{run_id}"
    x = rng.random()
    if x < 0.35:
        return "GET run", "GET", run, None
    if x < 0.50:
        return "GET runs", "GET", "/api/runs", None
    if x < 0.60:
        return "GET rewards", "GET", f"{run}/rewards?limit=50", None
    if x < 0.70:
        return "GET ltm", "GET", f"{run}/ltm", None
    if x < 0.80:
        return "GET health", "GET", "/api/health", None
    if x < 0.85:
        return "GET stimuli", "GET", "/api/stimuli", None
    return "POST reward", "POST", f"{run}/rewards", {"value": rng.choice([-1, 1]), "note": "load"}


def _percentile(values: list[float], q: float) -> float:
    if not values:
        return math.nan
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q / 100 * len(ordered)) - 1))]


async def _overload(
    port: int, run_id: int, seconds: float
) -> tuple[Counter[str], Counter[str], list[float]]:
    """Statuses of every request, statuses of the rewards alone, and the latencies."""
    client = RawClient(port, CONNECTIONS, TIMEOUT_S)
    statuses: Counter[str] = Counter()
    rewards: Counter[str] = Counter()
    latencies: list[float] = []
    end = math.inf  # set once every connection is up: a busy machine may take long to open 64

    async def worker(i: int) -> None:
        rng = random.Random(i)
        while time.monotonic() < end:
            kind, method, path, body = _plan(run_id, rng)
            started = time.monotonic()
            try:
                status, _ = await client.request(method, path, body)
            except TimeoutError:
                statuses["hang"] += 1
                continue
            except (OSError, asyncio.IncompleteReadError) as e:
                statuses[type(e).__name__] += 1
                continue
            latencies.append(time.monotonic() - started)
            statuses[str(status)] += 1
            if kind == "POST reward":
                rewards[str(status)] += 1

    try:
        await client.warm()
        end = time.monotonic() + seconds
        await asyncio.gather(*(worker(i) for i in range(CONNECTIONS)))
    finally:
        await client.aclose()
    return statuses, rewards, latencies


def test_64_connections_of_overload_never_hang_and_ticks_stay_bounded(tmp_path: Path) -> None:
    with live_server(tmp_path / "load.db", env=ENV) as server:
        api = server.client
        created = api.post("/api/runs", json={"condition": "rp", "mode": "realtime", "hz": HZ})
        run_id = created.json()["id"]
        assert api.post(f"/api/runs/{run_id}/start").status_code == 200
        started = time.monotonic()
        statuses, rewards, latencies = asyncio.run(_overload(server.port, run_id, SECONDS))
        wall = time.monotonic() - started
        logged = _trainer_rewards(api, run_id)
        run = api.get(f"/api/runs/{run_id}").json()
        health = api.get("/api/health").status_code
        api.post(f"/api/runs/{run_id}/stop")
        wait_status(api, run_id, "stopped")
    live = run["live"]
    p99, worst = live["lateness_p99_ms"], live["lateness_max_ms"]
    answered = sum(n for k, n in statuses.items() if k.isdigit())
    shed = sum(n for k, n in statuses.items() if k in ("429", "503"))
    errors = {k: n for k, n in statuses.items() if not k.isdigit() or k.startswith("5")}
    errors.pop("503", None)
    record(
        "overload: 64 connections",
        f"64 connections in closed loop for {SECONDS:g} s (reads of a live run, its log and "
        f"LTM, runs, health, catalogue; 15% rewards) while a realtime run ticks at {HZ:g} Hz",
        f"{count(answered)} answered ({answered / wall:,.0f}/s; p50 "
        f"{_percentile(latencies, 50) * 1000:.0f} ms, p99 {_percentile(latencies, 99) * 1000:.0f}"
        f" ms, max {max(latencies, default=0) * 1000:.0f} ms), {count(shed)} shed with 429/503, "
        f"rewards {rewards['202']} accepted and {rewards['429']} limited, "
        f"{statuses['hang']} hung, {sum(errors.values()) - statuses['hang']} errors; "
        f"tick lateness p99 {p99:.1f} ms, max {worst:.1f} ms, {live['overruns']} overruns "
        f"in {count(live['ticks_run'])} ticks"
        + ("" if SECONDS >= BOUNDED_FROM_S else " (bounds not asserted under 30 s)"),
    )
    assert statuses["hang"] == 0, statuses
    assert not errors, statuses
    assert health == 200
    assert run["status"] == "running"
    # The token bucket's guarantee: one client (every loopback connection is one) gets at
    # most `burst` rewards at once plus `rate` a second, the time since the run started
    # (`wall` covers it, and more) counted generously.
    allowed = REWARD_BURST + REWARD_RATE * wall
    assert 0 < rewards["202"] <= allowed, (rewards, allowed)
    assert set(rewards) <= {"202", "429", "503"}, rewards
    assert rewards["202"] == logged, (rewards, logged)  # each 202 is in the log
    if SECONDS >= BOUNDED_FROM_S:
        assert p99 <= 1000 / HZ, live
        assert worst <= MAX_LATENESS_MS, live


def _post_huge(port: int, chunked: bool) -> tuple[int | None, int]:
    """POST a 50 MB body: the status the server answered and how much of it went out."""
    size = BODY_MB * 1024 * 1024
    block = b"x" * 65536
    sent = 0
    with socket.create_connection(("127.0.0.1", port), timeout=TIMEOUT_S) as s:
        framing = "Transfer-Encoding: chunked" if chunked else f"Content-Length: {size}"
        s.sendall(
            f"POST /api/runs HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
            f"Content-Type: application/json\r\n{framing}\r\n\r\n".encode()
        )

        def send() -> None:
            nonlocal sent
            try:
                while sent < size:
                    s.sendall(b"%x\r\n%s\r\n" % (len(block), block) if chunked else block)
                    sent += len(block)
                if chunked:
                    s.sendall(b"0\r\n\r\n")
            except OSError:
                pass  # the server answered and closed the connection

        sender = threading.Thread(target=send)
        sender.start()
        head = b""
        try:
            while b"\r\n\r\n" not in head:
                data = s.recv(65536)
                if not data:
                    break
                head += data
        except OSError:
            pass
        sender.join(TIMEOUT_S)
        assert not sender.is_alive(), "sending the body hung"
    line = head.split(b"\r\n", 1)[0].split()
    return (int(line[1]) if len(line) > 1 else None), sent


def test_a_50_mb_body_gets_413_without_a_memory_spike(tmp_path: Path) -> None:
    with live_server(tmp_path / "body.db") as server:
        pid = server.process.pid
        # Warm the request path first, so that its one-off allocations do not count.
        server.client.post("/api/runs", json={"condition": "kp"})
        rss0, peak0 = rss_kib(pid)
        declared, declared_sent = _post_huge(server.port, chunked=False)
        chunked, chunked_sent = _post_huge(server.port, chunked=True)
        rss1, peak1 = rss_kib(pid)
        health = server.client.get("/api/health").status_code
    record(
        "50 MB request body",
        f"POST a {BODY_MB} MB body to /api/runs, once with Content-Length and once chunked",
        f"413 and 413 after {declared_sent / 2**20:.1f} MB and {chunked_sent / 2**20:.1f} MB "
        f"had gone out; server RSS {rss0 / 1024:.1f} -> {rss1 / 1024:.1f} MiB, peak "
        f"{peak0 / 1024:.1f} -> {peak1 / 1024:.1f} MiB; healthy after",
    )
    assert (declared, chunked) == (413, 413)
    assert health == 200
    assert rss1 - rss0 <= MAX_GROWTH_KIB
    assert peak1 - peak0 <= MAX_GROWTH_KIB
