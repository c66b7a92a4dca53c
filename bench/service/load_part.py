"""``--part load``: a realtime run's pacing alone and under mixed load (1), GET throughput (2)."""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import math
import os
import re
import shutil
import subprocess
import time
from dataclasses import dataclass
from typing import Any

from bench.figures import live_ms, ms, percentile
from bench.service.clients import HOST, RawClient, make_client
from bench.service.cpu import CpuMeter
from bench.service.harness import (
    CONTROL_TIMEOUT_S,
    NETWORK_BASE,
    REWARD_LIMIT,
    Server,
    call,
    edit_target,
    recover,
    start_run,
    stop_run,
    wait_healthy,
)
from bench.service.load import Load, Request, mixed, open_loop, print_load

WINDOWS = 6
"""The mixed load's figures over time, in this many windows."""


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


async def under_load(args: argparse.Namespace, server: Server) -> None:
    """Parts 1 and 2 on `server`, with their set-up and a warm-up run first."""
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
