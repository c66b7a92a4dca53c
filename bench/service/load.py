"""The open-loop load generator: requests on a fixed-rate grid, the mixed traffic, its figures."""

from __future__ import annotations

import argparse
import asyncio
import math
import random
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import quote

from bench.figures import ms, percentile
from bench.service.clients import Client
from bench.service.cpu import CpuMeter


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
