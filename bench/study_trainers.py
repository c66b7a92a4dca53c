"""The simulated trainers of `bench.studies`: asyncio clients in a process of their own.

Each follows its own run's event stream with its participant's token, rewards a
human-like delay after a tick it saw, and now and then reads another participant's run
(which must answer 403); `worker` runs them all from a spec file and writes their tallies.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import os
import random
import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from bench.figures import percentile
from bench.service.clients import HOST, RawClient

HZ = 10.0
"""A participant's run ticks at this rate (`server.api.routes.studies.PARTICIPANT_HZ`)."""
ACK_P95_GOAL_S = 0.050
LATENESS_GOAL_SHARE = 0.10
"""Tick lateness p99 of the worst run, as a share of the tick period."""
PRESS_HZ = (1.0, 3.0)
"""A trainer presses at a rate of their own in this range."""
REACTION_S = (0.2, 1.0)
"""How long after a tick they saw a trainer presses."""
FOREIGN_EVERY_S = 5.0
"""A trainer tries another participant's run about this often."""
TICK_HZ = 10
"""The console's event stream asks for every tick at 10 Hz (`web/js/console/stream.js`)."""
TIMEOUT_S = 30.0
"""A request not answered within this counts as a connection error."""
PROGRESS_S = 5.0
SERVICE_NICE = 10
"""`srlab serve`'s nice for the service's process; the trainers' process takes it too."""
MARKER = "bench-mark"


@dataclass(frozen=True)
class Trainer:
    """One simulated trainer: where their service is, their token, run, and a foreign run."""

    index: int
    port: int
    token: str
    run: int
    foreign: int


@dataclass
class Tally:
    """What one trainer saw."""

    acks_s: list[float] = field(default_factory=list)
    markers: list[str] = field(default_factory=list)
    """Every reward sent, acknowledged or not."""
    acked: dict[str, str] = field(default_factory=dict)
    """Marker: the uid its 202 carried."""
    refused: int = 0
    """429s."""
    other: Counter[int] = field(default_factory=Counter)
    """Other statuses of rewards."""
    errors: int = 0
    """Connection errors and timeouts (rewards, reads, the stream)."""
    foreign_tries: int = 0
    foreign_read: int = 0
    """A 2xx to another participant's run."""
    foreign_other: int = 0
    """Neither 2xx nor 403."""
    ticks: int = 0
    polls: int = 0


def _rng(seed: int, index: int) -> random.Random:
    return random.Random(seed * 1_000_003 + index)


class Seen(asyncio.Event):
    """Set at each tick event a trainer's stream brings; `at`: when the newest came."""

    at: float = -math.inf

    def set(self) -> None:
        """A tick came now."""
        self.at = time.perf_counter()
        super().set()


async def _sse(trainer: Trainer, seen: Seen, tally: Tally, stop: asyncio.Event) -> None:
    """Follow the run's event stream as EventSource does; set `seen` at each tick."""
    while not stop.is_set():
        try:
            reader, writer = await asyncio.open_connection(HOST, trainer.port)
        except OSError:
            tally.errors += 1
            await asyncio.sleep(1.0)
            continue
        try:
            writer.write(
                f"GET /api/runs/{trainer.run}/events?tick_hz={TICK_HZ} HTTP/1.1\r\n"
                f"Host: {HOST}:{trainer.port}\r\nAccept: text/event-stream\r\n"
                f"Authorization: Bearer {trainer.token}\r\n\r\n".encode()
            )
            head = await reader.readuntil(b"\r\n\r\n")
            if b" 200 " not in head.split(b"\r\n", 1)[0]:
                tally.errors += 1
                await asyncio.sleep(1.0)
                continue
            buffer = b""
            while not stop.is_set():
                size = int((await reader.readuntil(b"\r\n")).split(b";")[0], 16)
                chunk = await reader.readexactly(size + 2)
                if size == 0:
                    break
                buffer += chunk[:-2]
                *events, buffer = buffer.split(b"\n\n")
                for event in events:
                    if event.startswith(b"event: tick"):
                        tally.ticks += 1
                        seen.set()
        except (OSError, asyncio.IncompleteReadError, asyncio.LimitOverrunError, ValueError):
            if not stop.is_set():
                tally.errors += 1
        finally:
            writer.close()


async def _reward(client: RawClient, trainer: Trainer, tally: Tally, mark: str, v: float) -> None:
    tally.markers.append(mark)
    body = {"value": v, "note": f"{MARKER} {mark}"}
    sent = time.perf_counter()
    try:
        status, payload = await client.request("POST", f"/api/runs/{trainer.run}/rewards", body)
    except (OSError, TimeoutError, asyncio.IncompleteReadError):
        tally.errors += 1
        return
    took = time.perf_counter() - sent
    if status == 202:
        tally.acks_s.append(took)
        tally.acked[mark] = json.loads(payload)["uid"]
    elif status == 429:
        tally.refused += 1
    else:
        tally.other[status] += 1


async def _foreign(client: RawClient, trainer: Trainer, tally: Tally) -> None:
    tally.foreign_tries += 1
    try:
        status, _ = await client.request("GET", f"/api/runs/{trainer.foreign}")
    except (OSError, TimeoutError, asyncio.IncompleteReadError):
        tally.errors += 1
        return
    if 200 <= status < 300:
        tally.foreign_read += 1
    elif status != 403:
        tally.foreign_other += 1


async def _poll(client: RawClient, trainer: Trainer, tally: Tally) -> None:
    """The console's poll: the run, its memory, its network."""
    for path in ("", "/memory", "/network"):
        try:
            await client.request("GET", f"/api/runs/{trainer.run}{path}")
            tally.polls += 1
        except (OSError, TimeoutError, asyncio.IncompleteReadError):
            tally.errors += 1


async def _trainer(
    trainer: Trainer, seconds: float, seed: int, poll_s: float, tally: Tally
) -> None:
    rng = _rng(seed, trainer.index)
    headers = {"Authorization": f"Bearer {trainer.token}"}
    # A browser opens up to six connections to a host: the stream holds one.
    client = RawClient(trainer.port, 3, TIMEOUT_S, headers=headers)
    stop = asyncio.Event()
    seen = Seen()
    stream = asyncio.create_task(_sse(trainer, seen, tally, stop))
    tasks: set[asyncio.Task[None]] = set()

    def spawn(coro: Any) -> None:
        task = asyncio.create_task(coro)
        tasks.add(task)
        task.add_done_callback(tasks.discard)

    gap = 1.0 / rng.uniform(*PRESS_HZ)
    start = time.perf_counter()
    end = start + seconds
    next_press = start + rng.uniform(0, gap)
    next_foreign = start  # one at the first press, then now and then
    next_poll = start + rng.uniform(0, poll_s) if poll_s > 0 else math.inf
    k = 0
    try:
        while True:
            await asyncio.sleep(max(0.0, next_press - time.perf_counter()))
            reaction = rng.uniform(*REACTION_S)
            if time.perf_counter() - seen.at > reaction + 1.0:  # nothing seen lately: look
                seen.clear()
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(1.0):
                        await seen.wait()
                await asyncio.sleep(reaction)
            now = time.perf_counter()
            if now >= end:
                break
            next_press = max(now, next_press + gap * rng.uniform(0.7, 1.3))
            value = rng.choice((1.0, 0.5, -0.5, -1.0))
            spawn(_reward(client, trainer, tally, f"{trainer.index}:{k}:{seed}", value))
            k += 1
            if now >= next_foreign:
                next_foreign = now + rng.uniform(0, 2 * FOREIGN_EVERY_S)
                spawn(_foreign(client, trainer, tally))
            if now >= next_poll:
                next_poll = now + poll_s
                spawn(_poll(client, trainer, tally))
        if tasks:
            await asyncio.wait(set(tasks))
    finally:
        stop.set()
        stream.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await stream
        await client.aclose()


async def _progress(tallies: list[Tally], seconds: float) -> None:
    started = time.perf_counter()
    before = 0
    while True:
        await asyncio.sleep(PROGRESS_S)
        acks = [a for t in tallies for a in t.acks_s]
        recent = acks[before:] if before <= len(acks) else []
        before = len(acks)
        p95 = percentile(recent, 95)
        print(
            f"  {time.perf_counter() - started:5.0f}/{seconds:g} s: "
            f"{sum(len(t.markers) for t in tallies):7,} rewards sent, {len(acks):7,} acknowledged"
            f" (p95 of the last {PROGRESS_S:g} s {p95 * 1000:7.1f} ms), "
            f"{sum(t.refused for t in tallies):,} 429s, {sum(t.errors for t in tallies):,} "
            f"connection errors, {sum(t.ticks for t in tallies):,} ticks seen",
            flush=True,
        )


async def trainers(spec: dict[str, Any]) -> list[Tally]:
    """Run every trainer of `spec` for its seconds; what each saw."""
    people = [Trainer(**t) for t in spec["trainers"]]
    tallies = [Tally() for _ in people]
    progress = asyncio.create_task(_progress(tallies, spec["seconds"]))
    try:
        await asyncio.gather(
            *(
                _trainer(t, spec["seconds"], spec["seed"], spec["poll"], tally)
                for t, tally in zip(people, tallies, strict=True)
            )
        )
    finally:
        progress.cancel()
    return tallies


def worker(spec_path: Path, out_path: Path) -> None:
    """The trainers' process: read the spec, run them, write their tallies."""
    spec = json.loads(spec_path.read_text())
    # The browsers it stands for are elsewhere: it takes no precedence over the service,
    # which `srlab serve` renices by SRLAB_SERVICE_NICE (10).
    os.nice(max(0, SERVICE_NICE - os.nice(0)))
    tallies = asyncio.run(trainers(spec))
    out_path.write_text(json.dumps([{**asdict(t), "other": dict(t.other)} for t in tallies]))
