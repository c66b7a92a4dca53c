"""Storage failing under a running service: the run ends with a clear error, nothing else.

A realtime `rp` run takes rewards from two clients when the database fails under it. On
SQLite another process holds the write lock longer than the busy timeout. On PostgreSQL
another session locks the reward log, then the database turns read-only, then the
service's connections are killed with pg_terminate_backend, one fault after the other on
the same live service. Each time:

- the run ends, failed, with an error that names the storage failure; a run that rides
  the fault out (the pool reconnects) must keep going instead;
- no request hangs: every one is answered (202, or 409/503 with a reason) within 15 s;
- the service stays up: /api/health answers during the fault (200, or 503 while the
  database does not answer) and 200 after it;
- once the fault is lifted the run resumes, and in the end every acknowledged reward is
  stored once and applied once (the stored LTM equals a replay of the log).
"""

from __future__ import annotations

import sqlite3
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import httpx
from harness import RewardTraffic, check_log, replay_ltm
from liveharness import wait_status
from reliability_report import count, record
from sqlalchemy import create_engine, text
from sqlalchemy.engine import Connection, make_url

from bench.liveserver import LiveServer, live_server
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker

CONDITION, SEED = "rp", 11
RUN = {"condition": CONDITION, "seed": SEED, "mode": "realtime", "hz": 100}
ENV = {"SRLAB_REWARD_RATE_PER_S": "100000", "SRLAB_REWARD_BURST": "100000"}
FAIL_WITHIN_S = 30.0


@dataclass
class Outcome:
    """What one fault did to the run and the service."""

    fault: str
    run_id: int
    status: str
    error: str | None
    requests: int
    answers: dict[str, int]
    health_during: list[int]
    acked: dict[int, str]


def _run_status(api: httpx.Client, run_id: int) -> dict[str, Any]:
    """The run as the API answers it.

    A run that has ended is read from storage, and while the fault lasts that read may get
    503 (the documented answer to a storage failure): it is asked again, for up to 10 s,
    and a run still unreadable then says so in its status.
    """
    for _ in range(100):
        r = api.get(f"/api/runs/{run_id}")
        if r.status_code != 503:
            run: dict[str, Any] = r.json()
            return run
        time.sleep(0.1)
    return {"status": f"unreadable (503: {r.json().get('detail')})"}


def _under_fault(
    server: LiveServer,
    fault: str,
    inject: Callable[[], AbstractContextManager[None]],
    expect_failure: bool,
    seed: int,
) -> Outcome:
    """Run a rewarded realtime run, inject the fault, then resume the run after it."""
    api = server.client
    created = api.post("/api/runs", json=RUN)
    assert created.status_code == 201, created.text
    run_id = int(created.json()["id"])
    assert api.post(f"/api/runs/{run_id}/start").status_code == 200
    traffic = RewardTraffic(server.url, run_id, f"f{seed}", seed=seed).start()
    time.sleep(0.5)
    health: list[int] = []
    with inject():
        deadline = time.monotonic() + FAIL_WITHIN_S
        run = _run_status(api, run_id)
        while run["status"] == "running" and time.monotonic() < deadline:
            health.append(api.get("/api/health").status_code)
            time.sleep(0.2)
            run = _run_status(api, run_id)
            if not expect_failure and len(health) >= 10:
                break
        health.append(api.get("/api/health").status_code)
    traffic.stop()
    outcome = Outcome(
        fault,
        run_id,
        str(run["status"]),
        run["error"],
        traffic.sent,
        dict(traffic.outcomes),
        health,
        dict(traffic.acked),
    )
    assert api.get("/api/health").status_code == 200, "the service is up after the fault"
    # Lifted: the run goes on from where it was, and stops cleanly.
    if run["status"] != "running":
        resumed = api.post(f"/api/runs/{run_id}/start")
        assert resumed.status_code == 200, resumed.text
    after = RewardTraffic(server.url, run_id, f"a{seed}", seed=seed + 100).start()
    time.sleep(0.5)
    after.stop()
    outcome.acked |= after.acked
    assert api.post(f"/api/runs/{run_id}/stop").status_code == 200
    wait_status(api, run_id, "stopped")
    return outcome


def _check_stored(database: str, run_id: int, acked: dict[int, str]) -> tuple[bool, str]:
    engine = make_engine(database)
    try:
        store = SqlAlchemyRunStore(make_sessionmaker(engine))
        rewards = store.rewards(run_id)
        stored_ltm = store.ltm(run_id)
    finally:
        engine.dispose()
    check = check_log(rewards, acked)
    same = replay_ltm(rewards, CONDITION, SEED) == stored_ltm
    held = check.held and check.unapplied == 0 and same
    return held, (
        f"{count(check.acknowledged)} acknowledged, {len(check.lost)} lost, "
        f"{len(check.twice)} stored twice, {check.unapplied} unapplied, "
        f"LTM {'=' if same else '!='} replay"
    )


def _verdict(o: Outcome, expect_failure: bool) -> list[str]:
    """What went wrong, if anything."""
    problems = []
    if expect_failure and o.status != "failed":
        problems.append(f"the run did not fail: {o.status}")
    if o.status == "failed" and "storage failed" not in (o.error or ""):
        problems.append(f"unclear error: {o.error!r}")
    if o.status not in ("failed", "running"):
        problems.append(f"the run ended {o.status}")
    bad = {k: n for k, n in o.answers.items() if k not in ("202", "409", "503", "429")}
    if bad:
        problems.append(f"answers other than 202/409/503: {bad}")
    if any(code not in (200, 503) for code in o.health_during):
        problems.append(f"health during the fault: {o.health_during}")
    return problems


def _describe(o: Outcome) -> str:
    answers = ", ".join(f"{n} x {k}" for k, n in sorted(o.answers.items()))
    if o.status == "failed":
        first = (o.error or "").split("\n")[0]
        what = f"run failed: {first[:110]}"
    else:
        what = f"run went on ({o.status})"
    health = ", ".join(f"{n} x {k}" for k, n in sorted(Counter(o.health_during).items()))
    return f"{o.fault}: {what}; {o.requests} reward requests ({answers}); health {health}"


def test_a_locked_sqlite_database_fails_the_run_cleanly(tmp_path: Path) -> None:
    path = tmp_path / "locked.db"

    @contextmanager
    def lock() -> Iterator[None]:
        # Another process's write transaction, held past the 5 s busy timeout.
        other = sqlite3.connect(path, isolation_level=None, check_same_thread=False)
        other.execute("BEGIN IMMEDIATE")
        try:
            yield
        finally:
            other.execute("ROLLBACK")
            other.close()

    with live_server(path, env=ENV) as server:
        outcome = _under_fault(server, "write lock held past the busy timeout", lock, True, 1)
    held, stored = _check_stored(f"sqlite:///{path}", outcome.run_id, outcome.acked)
    problems = _verdict(outcome, True)
    record(
        "storage error: SQLite locked",
        "another process holds SQLite's write lock (BEGIN IMMEDIATE) longer than the 5 s "
        "busy timeout while a realtime run takes rewards from 2 clients",
        f"{_describe(outcome)}; resumed after; {stored}",
    )
    assert not problems, problems
    assert held, stored


@dataclass
class Postgres:
    """An admin connection to the service's PostgreSQL database."""

    url: str
    name: str

    @contextmanager
    def connect(self, autocommit: bool = True) -> Iterator[Connection]:
        """A connection; without autocommit, inside one transaction."""
        engine = create_engine(self.url, isolation_level="AUTOCOMMIT" if autocommit else None)
        try:
            with engine.connect() if autocommit else engine.begin() as c:
                yield c
        finally:
            engine.dispose()

    def terminate_others(self, c: Connection, idle_only: bool = False) -> int:
        """Kill the other sessions on the database (only those between transactions)."""
        idle = " AND state = 'idle'" if idle_only else ""
        killed = c.execute(
            text(
                "SELECT count(pg_terminate_backend(pid)) FROM pg_stat_activity "
                f"WHERE datname = :db AND pid <> pg_backend_pid(){idle}"
            ),
            {"db": self.name},
        ).scalar_one()
        return int(killed)


def test_postgres_faults_fail_the_run_cleanly_and_the_service_stays_up(
    postgres_database: str,
) -> None:
    pg = Postgres(postgres_database, str(make_url(postgres_database).database))
    terminated = 0

    @contextmanager
    def table_lock() -> Iterator[None]:
        with pg.connect(autocommit=False) as c:
            c.execute(text("LOCK TABLE rewards IN ACCESS EXCLUSIVE MODE"))
            yield

    @contextmanager
    def read_only() -> Iterator[None]:
        with pg.connect() as c:
            c.execute(text(f'ALTER DATABASE "{pg.name}" SET default_transaction_read_only = on'))
            # The pool reconnects into read-only sessions; idle ones only, so that it is
            # the read-only database that fails the run, not a killed transaction.
            pg.terminate_others(c, idle_only=True)
            try:
                yield
            finally:
                c.execute(text(f'ALTER DATABASE "{pg.name}" RESET default_transaction_read_only'))
                pg.terminate_others(c, idle_only=True)

    @contextmanager
    def terminations() -> Iterator[None]:
        nonlocal terminated
        stop = threading.Event()

        def kill() -> None:
            nonlocal terminated
            with pg.connect() as c:
                while not stop.is_set():
                    terminated += pg.terminate_others(c)
                    stop.wait(0.02)

        killer = threading.Thread(target=kill)
        killer.start()
        try:
            yield
        finally:
            stop.set()
            killer.join()

    faults: list[tuple[str, Callable[[], AbstractContextManager[None]], bool]] = [
        ("reward log locked (LOCK TABLE) by another session", table_lock, True),
        ("database made read-only, idle sessions reset", read_only, True),
        ("service's connections killed every 20 ms", terminations, False),
    ]
    outcomes: list[Outcome] = []
    with live_server(postgres_database, env=ENV) as server:
        for seed, (name, inject, expect_failure) in enumerate(faults, start=10):
            outcomes.append(_under_fault(server, name, inject, expect_failure, seed))
    rows = []
    problems = []
    for o, (_, _, expect_failure) in zip(outcomes, faults, strict=True):
        held, stored = _check_stored(postgres_database, o.run_id, o.acked)
        rows.append(f"{_describe(o)}; {stored}")
        problems += [f"{o.fault}: {p}" for p in _verdict(o, expect_failure)]
        if not held:
            problems.append(f"{o.fault}: {stored}")
    record(
        "storage errors: PostgreSQL",
        "on one live service, while a realtime run takes rewards from 2 clients: "
        + "; ".join(name for name, _, _ in faults)
        + f" ({terminated} connections killed)",
        " | ".join(rows),
    )
    assert not problems, problems
