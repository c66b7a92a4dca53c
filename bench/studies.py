"""A trainer study under load: N participants each rewarding their own realtime run.

Run as ``.venv/bin/python -m bench.studies --trainers N [--store sqlite|postgres]
[--seconds S] [--services 2]`` (``--quick``: 4 trainers for 5 s, what the test runs). It
starts ``srlab serve`` (`bench.service.harness.Server`: a temporary SQLite database, or
``--database-url``'s PostgreSQL, else ``.pg/url`` as ``scripts/pg-test-server.sh start``
leaves it) with the cap on running runs and streams above N and the production reward
limits, creates a study with N participants through the API, and has each consent, which
starts their realtime 10 Hz run. Then N simulated trainers, asyncio clients in one process
of their own (as many browsers would be), each with their own token: one event stream of
their run (the console's, ``tick_hz=10``), a reward at 1-3 Hz a human-like delay (0.2-1 s)
after a tick they saw, with ``value``, ``note`` and a unique marker in the note, and now and
then a read of another participant's run, which must answer 403. ``--poll 2`` adds the
console's poll (the run, its memory and network every 2 s).

Afterwards it reads each run's pacing figures (``GET /api/runs/{id}``'s ``live``) and
reward log, and prints beside the goals: acknowledgement p50/p95/p99, the worst run's tick
lateness p99 and the overruns, rewards sent, acknowledged and found in the log (lost,
duplicated by marker or uid), 429s, connection errors, and foreign reads that were not
refused. With ``--services 2`` (PostgreSQL only) two services share the database, each
hosting half the participants' runs. Other work on the machine skews every figure: the
CPU shares and the load average are printed with them.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from bench.figures import percentile
from bench.liveserver import ROOT
from bench.procs import cpu_seconds, descendants, tree_cpu_seconds
from bench.service.clients import RawClient
from bench.service.cpu import CpuMeter
from bench.service.harness import Server, call, print_log, wait_healthy
from bench.study_trainers import (
    ACK_P95_GOAL_S,
    HZ,
    LATENESS_GOAL_SHARE,
    MARKER,
    Trainer,
    worker,
)


@dataclass
class StudyServer(Server):
    """A bench server on a given database (a SQLAlchemy URL), else its own SQLite file."""

    database: str = ""

    @property
    def url(self) -> str:
        """Its database."""
        return self.database or super().url


# The service's side: set-up, and what it logged and measured.


@dataclass(frozen=True)
class Seat:
    """A participant as set up: their token, the service hosting their run, their run."""

    token: str
    port: int
    run: int


async def _consent(client: RawClient, port: int, token: str) -> Seat:
    """Consent as the participant would (their own token): their run starts."""
    mine = RawClient(port, 1, client_timeout(), headers={"Authorization": f"Bearer {token}"})
    try:
        view = await call(mine, "GET", "/api/participant")
        done = await call(
            mine, "POST", "/api/participant/consent", {"consent_version": view["consent_version"]}
        )
    finally:
        await mine.aclose()
    return Seat(token, port, int(done["run_id"]))


def client_timeout() -> float:
    return 180.0


async def set_up(servers: list[Server], n: int, name: str) -> list[Seat]:
    """A study of `n` participants, each consented on the service hosting their run."""
    organiser = RawClient(servers[0].port, 1, client_timeout())
    try:
        await call(
            organiser,
            "POST",
            "/api/studies",
            {
                "name": name,
                "conditions": ["trainer"],
                "budget": {"seconds": 86_400},
                "consent_text": "A simulated trainer of the bench.",
                "consent_version": "1",
            },
        )
        invited = await call(organiser, "POST", f"/api/studies/{name}/participants", {"count": n})
    finally:
        await organiser.aclose()
    tokens = [p["token"] for p in invited["data"]]
    seats: list[Seat] = []
    for k in range(0, n, 16):  # a few at a time, as people arrive
        batch = tokens[k : k + 16]
        seats += await asyncio.gather(
            *(
                _consent(organiser, servers[(k + i) % len(servers)].port, token)
                for i, token in enumerate(batch)
            )
        )
    return seats


async def run_figures(port: int, run: int) -> dict[str, Any]:
    """A run's state (its live pacing figures) as the organiser reads it."""
    client = RawClient(port, 1, client_timeout())
    try:
        state: dict[str, Any] = await call(client, "GET", f"/api/runs/{run}")
        return state
    finally:
        await client.aclose()


async def reward_log(port: int, run: int) -> list[dict[str, Any]]:
    """A run's whole reward log."""
    client = RawClient(port, 1, client_timeout())
    rows: list[dict[str, Any]] = []
    try:
        while True:
            path = f"/api/runs/{run}/rewards?offset={len(rows)}&limit=1000"
            page = await call(client, "GET", path)
            rows += page["data"]
            if len(rows) >= page["count"] or not page["data"]:
                return rows
    finally:
        await client.aclose()


async def collect(
    seats: list[Seat], *, with_logs: bool = True
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Every run's state, then every run's reward log (`with_logs`), a few runs at a time."""
    states: list[dict[str, Any]] = []
    logs: list[dict[str, Any]] = []
    for k in range(0, len(seats), 16):
        batch = seats[k : k + 16]
        states += await asyncio.gather(*(run_figures(s.port, s.run) for s in batch))
    for k in range(0, len(seats) if with_logs else 0, 16):
        batch = seats[k : k + 16]
        for rows in await asyncio.gather(*(reward_log(s.port, s.run) for s in batch)):
            logs += rows
    return states, logs


def ticks_run(states: list[dict[str, Any]]) -> int:
    """The ticks the runs have run, all together (their states' live figures)."""
    return sum(int(s["live"]["ticks_run"]) for s in states if s.get("live"))


@dataclass
class Figures:
    """The bench's figures, beside the goals."""

    trainers: int
    acks_s: list[float]
    lateness_p99_ms: list[float]
    overruns: int
    sent: int
    acknowledged: int
    logged: int
    lost: int
    duplicated: int
    refused: int
    other: dict[int, int]
    errors: int
    foreign_tries: int
    foreign_read: int
    foreign_other: int
    ticks_seen: int

    @property
    def ok(self) -> bool:
        """Whether every goal is met."""
        return (
            percentile(self.acks_s, 95) <= ACK_P95_GOAL_S
            and max(self.lateness_p99_ms, default=math.inf) <= LATENESS_GOAL_SHARE * 1000 / HZ
            and self.lost == 0
            and self.duplicated == 0
            and self.foreign_read == 0
            and self.sent == self.acknowledged == self.logged
        )


def figures(
    tallies: list[dict[str, Any]], states: list[dict[str, Any]], log: list[dict[str, Any]]
) -> Figures:
    """The trainers' tallies, the runs' states and their reward logs, counted."""
    sent = [m for t in tallies for m in t["markers"]]
    acked: dict[str, str] = {m: u for t in tallies for m, u in t["acked"].items()}
    marks: Counter[str] = Counter()
    uids: Counter[str] = Counter()
    for row in log:
        note = str(row.get("note", ""))
        if note.startswith(MARKER):
            marks[note.removeprefix(MARKER).strip()] += 1
            uids[str(row["uid"])] += 1
    lost = sum(1 for m in acked if marks[m] == 0)
    duplicated = sum(c - 1 for c in marks.values() if c > 1) + sum(
        c - 1 for c in uids.values() if c > 1
    )
    lateness = [
        float(s["live"]["lateness_p99_ms"])
        for s in states
        if s.get("live") and s["live"].get("lateness_p99_ms") is not None
    ]
    other: Counter[int] = Counter()
    for t in tallies:
        other.update({int(k): v for k, v in t["other"].items()})
    return Figures(
        trainers=len(tallies),
        acks_s=[a for t in tallies for a in t["acks_s"]],
        lateness_p99_ms=lateness,
        overruns=sum(int(s["live"]["overruns"]) for s in states if s.get("live")),
        sent=len(sent),
        acknowledged=len(acked),
        logged=sum(marks.values()),
        lost=lost,
        duplicated=duplicated,
        refused=sum(t["refused"] for t in tallies),
        other=dict(other),
        errors=sum(t["errors"] for t in tallies),
        foreign_tries=sum(t["foreign_tries"] for t in tallies),
        foreign_read=sum(t["foreign_read"] for t in tallies),
        foreign_other=sum(t["foreign_other"] for t in tallies),
        ticks_seen=sum(t["ticks"] for t in tallies),
    )


def print_figures(f: Figures, states: list[dict[str, Any]]) -> None:
    """The figures beside the goals."""

    def ms(q: float) -> str:
        v = percentile(f.acks_s, q)
        return "-" if math.isnan(v) else f"{v * 1000:.1f} ms"

    worst = max(f.lateness_p99_ms, default=math.nan)
    engine_acks = [
        float(s["live"]["reward_ack_p99_ms"])
        for s in states
        if s.get("live") and s["live"].get("reward_ack_p99_ms") is not None
    ]
    running = sum(1 for s in states if s.get("status") == "running")
    goal_late = LATENESS_GOAL_SHARE * 1000 / HZ
    rows = [
        ("trainers (runs running at the end)", f"{f.trainers} ({running})", ""),
        ("reward ack p50 / p95 / p99", f"{ms(50)} / {ms(95)} / {ms(99)}",
         f"p95 <= {ACK_P95_GOAL_S * 1000:g} ms"),
        ("  of which in the engine: p99, worst run", f"{max(engine_acks, default=math.nan):.1f} ms",
         ""),
        ("tick lateness p99, worst run", f"{worst:.1f} ms",
         f"<= {goal_late:g} ms ({LATENESS_GOAL_SHARE:.0%} of the period)"),
        ("overruns, all runs", f"{f.overruns:,}", ""),
        ("rewards sent / acknowledged / logged", f"{f.sent:,} / {f.acknowledged:,} / {f.logged:,}",
         "all equal"),
        ("lost / duplicated (marker, uid)", f"{f.lost} / {f.duplicated}", "0 / 0"),
        ("429s / other statuses", f"{f.refused} / {f.other or 0}", ""),
        ("connection errors and timeouts", f"{f.errors}", ""),
        ("foreign reads answered 2xx (of tries)", f"{f.foreign_read} ({f.foreign_tries})", "0"),
        ("foreign reads neither 2xx nor 403", f"{f.foreign_other}", "0"),
        ("tick events the trainers saw", f"{f.ticks_seen:,}", ""),
    ]  # fmt: skip
    print(f"  {'figure':<44}{'measured':<36}goal")
    for name, value, goal in rows:
        print(f"  {name:<44}{value:<36}{goal}")
    print(f"  goal met: {'yes' if f.ok else 'NO'}")


def pg_url(given: str | None) -> str:
    """The PostgreSQL URL: given, else what `scripts/pg-test-server.sh start` left."""
    if given:
        return given
    saved = ROOT / ".pg" / "url"
    if saved.exists():
        return saved.read_text().strip()
    raise SystemExit(
        "bench.studies: --store postgres needs --database-url, or "
        "`bash scripts/pg-test-server.sh start` first"
    )


def settings(n: int) -> dict[str, str]:
    """The servers' settings: room for n runs and streams, production reward limits."""
    return {
        "SRLAB_MAX_RUNS": str(n + 8),
        "SRLAB_MAX_STREAMS": str(n + 64),
        "SRLAB_REWARD_RATE_PER_S": "20",
        "SRLAB_REWARD_BURST": "40",
    }


def measure(args: argparse.Namespace, folder: Path) -> Figures:
    """Start the services, set the study up, run the trainers, read the logs, print."""
    database = pg_url(args.database_url) if args.store == "postgres" else ""
    servers: list[Server] = []
    for k in range(args.services):
        where = folder / f"service{k}"
        where.mkdir()
        made = StudyServer(where, database=database or f"sqlite:///{folder / 'bench.db'}")
        made.env.update(settings(args.trainers))
        made.env.update(dict(item.split("=", 1) for item in args.env))
        servers.append(made)
    try:
        for server in servers:  # one at a time: each migrates the database first
            server.start()
            asyncio.run(_healthy(server))
        load0 = os.getloadavg()
        name = f"bench-{os.getpid()}-{int(time.time())}"
        started = time.perf_counter()
        seats = asyncio.run(set_up(servers, args.trainers, name))
        print(
            f"study {name}: {len(seats)} participants consented, their runs started in "
            f"{time.perf_counter() - started:.1f} s on {len(servers)} service(s) "
            f"({args.store}); trainers for {args.seconds:g} s",
            flush=True,
        )
        rng = random.Random(args.seed)
        people = []
        for k, seat in enumerate(seats):
            other = seats[(k + 1 + rng.randrange(max(1, len(seats) - 1))) % len(seats)]
            people.append(asdict(Trainer(k, seat.port, seat.token, seat.run, other.run)))
        spec = {"trainers": people, "seconds": args.seconds, "seed": args.seed, "poll": args.poll}
        (folder / "spec.json").write_text(json.dumps(spec))
        meter = CpuMeter(servers[0].pid)
        ticks0 = ticks_run(asyncio.run(collect(seats, with_logs=False))[0])
        split = ProcessSplit(servers[0].pid)
        others = [(s.pid, tree_cpu_seconds(s.pid)) for s in servers[1:]]
        wall0 = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "bench.studies", "--worker", str(folder)],
            cwd=ROOT,
            check=True,
        )
        # The ticks read at once, and the CPU up to then: the same span, whatever comes after.
        ticks = ticks_run(asyncio.run(collect(seats, with_logs=False))[0]) - ticks0
        split.stop()
        cpu = meter.report("trainers")
        for k, (pid, before) in enumerate(others, 1):
            after = tree_cpu_seconds(pid)
            if before is not None and after is not None:
                share = (after - before) / (time.perf_counter() - wall0)
                cpu += f"; service {k} {share:.0%}"
        load1 = os.getloadavg()
        tallies = json.loads((folder / "tallies.json").read_text())
        states, log = asyncio.run(collect(seats))
        result = figures(tallies, states, log)
        print(f"CPU while the trainers ran: {cpu}")
        print(f"  of which: {split.report(ticks)}")
        print(f"load average (1 min) before / after: {load0[0]:.2f} / {load1[0]:.2f}")
        print_figures(result, states)
        return result
    finally:
        for k, server in enumerate(servers):
            code = server.stop()
            print(f"service {k}: stopped (SIGINT), exit code {code}")
            print_log(server.log)


class ProcessSplit:
    """The service's own process and its engines' process apart, from `start` to `stop`."""

    def __init__(self, service_pid: int) -> None:
        self._service = service_pid
        self._engines = sorted(descendants(service_pid))
        self._wall = time.perf_counter()
        self._spent = self._seconds()

    def _seconds(self) -> tuple[float, float]:
        own = cpu_seconds(self._service) or 0.0
        return own, sum(cpu_seconds(p) or 0.0 for p in self._engines)

    def stop(self) -> None:
        """The CPU each spent since it was made."""
        wall = time.perf_counter() - self._wall
        own, engines = self._seconds()
        self._wall, self._spent = wall, (own - self._spent[0], engines - self._spent[1])

    def report(self, ticks: int) -> str:
        """Each one's share of one core; the engines' CPU a tick of the `ticks` run."""
        (own, engines), wall = self._spent, self._wall
        per_tick = f"{engines * 1000 / ticks:.3f} ms" if ticks > 0 else "-"
        return (
            f"the service's process {own / wall:.0%}, the engines' {engines / wall:.0%} of one "
            f"core ({per_tick} a tick, {ticks / wall:,.0f} ticks a second)"
        )


async def _healthy(server: Server) -> None:
    client = RawClient(server.port, 1, 10.0)
    try:
        await wait_healthy(client, server, 240.0)
    finally:
        await client.aclose()


def main() -> None:
    parser = argparse.ArgumentParser(
        prog="python -m bench.studies", description=(__doc__ or "").splitlines()[0]
    )
    parser.add_argument("--trainers", type=int, default=64, help="participants (64)")
    parser.add_argument("--seconds", type=float, default=40.0, help="of training (40)")
    parser.add_argument("--store", choices=["sqlite", "postgres"], default="sqlite")
    parser.add_argument("--database-url", help="PostgreSQL's (else .pg/url)")
    parser.add_argument("--services", type=int, default=1, help="sharing one PostgreSQL (1)")
    parser.add_argument("--poll", type=float, default=0.0, help="the console's poll, s (0: off)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="4 trainers for 5 s")
    parser.add_argument(
        "--env", action="append", default=[], metavar="SRLAB_NAME=VALUE",
        help="a setting for every service (repeatable)",
    )  # fmt: skip
    parser.add_argument("--json", type=Path, help="also write the figures here, as JSON")
    parser.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker is not None:
        worker(args.worker / "spec.json", args.worker / "tallies.json")
        return
    if args.quick:
        args.trainers, args.seconds = 4, 5.0
    if args.trainers < 2 or args.seconds <= 0 or args.poll < 0:
        parser.error("--trainers must be at least 2, --seconds positive, --poll not negative")
    if args.services not in (1, 2) or (args.services == 2 and args.store != "postgres"):
        parser.error("--services 2 needs --store postgres (two services share its database)")
    if bad := [item for item in args.env if not item.startswith("SRLAB_") or "=" not in item]:
        parser.error(f"--env takes SRLAB_NAME=VALUE, not {bad[0]!r}")
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    with tempfile.TemporaryDirectory(prefix="srlab-studies-") as tmp:
        result = measure(args, Path(tmp))  # a missed goal is a figure, not a failure
    if args.json is not None:
        args.json.write_text(json.dumps({**asdict(result), "ok": result.ok}))


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        sys.exit("bench.studies: interrupted")
