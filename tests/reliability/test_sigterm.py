"""SIGTERM of `srlab serve` with runs going: it exits within 5 s and the runs resume.

This is what `docker compose stop` does. The service holds three runs on PostgreSQL: a
realtime `rp` run that two clients post rewards to and a third follows over the event
stream, a fast run with no episode limit, and a paused realtime run. It gets SIGTERM at a
random moment. It must exit within 5 s, cleanly, with every run stored as interrupted
and every acknowledged reward stored. Started again, POST .../start resumes each run. In
the end the rewarded run's log must show every reward applied exactly once.

``SRLAB_SIGTERMS`` sets the number (2 by default; ``make reliability`` runs 20).
"""

from __future__ import annotations

import os
import random
import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx
from harness import RewardTraffic, check_log, replay_ltm
from liveharness import wait_status
from reliability_report import count, record

from bench.liveserver import LiveServer
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker

SIGTERMS = int(os.environ.get("SRLAB_SIGTERMS", "2"))
EXIT_WITHIN_S = 5.0
ENV = {"SRLAB_REWARD_RATE_PER_S": "100000", "SRLAB_REWARD_BURST": "100000"}
CONDITION, SEED = "rp", 11
RUNS = [
    {"condition": CONDITION, "seed": SEED, "mode": "realtime", "hz": 100},
    {"condition": "delayed", "seed": 5, "mode": "fast"},
    {"condition": "kp", "seed": 6, "mode": "realtime", "hz": 20},
]


class Follower:
    """A client following a run's event stream until the server ends it."""

    def __init__(self, url: str, run_id: int) -> None:
        self.events = 0
        self.error: str | None = None
        self.thread = threading.Thread(target=self._follow, args=(url, run_id), daemon=True)
        self.thread.start()

    def _follow(self, url: str, run_id: int) -> None:
        try:
            with (
                httpx.Client(base_url=url, timeout=httpx.Timeout(10, read=30)) as c,
                c.stream("GET", f"/api/runs/{run_id}/events", params={"tick_hz": 10}) as s,
            ):
                for line in s.iter_lines():
                    self.events += line.startswith("event:")
        except httpx.HTTPError as e:
            self.error = f"{type(e).__name__}: {e}"


def _stored_statuses(database: str, run_ids: list[int]) -> dict[int, str]:
    engine = make_engine(database)
    try:
        store = SqlAlchemyRunStore(make_sessionmaker(engine))
        return {i: store.load_run(i).status.value for i in run_ids}
    finally:
        engine.dispose()


def _start_all(server: LiveServer, run_ids: list[int]) -> None:
    for run_id in run_ids:
        r = server.client.post(f"/api/runs/{run_id}/start")
        assert r.status_code == 200, r.text
    r = server.client.post(f"/api/runs/{run_ids[2]}/pause")
    assert r.status_code == 200, r.text


def test_sigterm_with_runs_going_exits_within_5_s_and_the_runs_resume(
    postgres_database: str, tmp_path: Path, start_server: Callable[..., LiveServer]
) -> None:
    database = postgres_database
    log = tmp_path / "serve.log"
    rng = random.Random(2028)
    acked: dict[int, str] = {}
    sent = 0
    exits: list[float] = []
    ticks: dict[int, int] = {}

    server = start_server(database, env=ENV, log=log)
    run_ids = []
    for spec in RUNS:
        created = server.client.post("/api/runs", json=spec)
        assert created.status_code == 201, created.text
        run_ids.append(int(created.json()["id"]))
    for n in range(SIGTERMS):
        if n > 0:
            server = start_server(database, env=ENV, log=log)
        _start_all(server, run_ids)
        for run_id in run_ids:
            ticks[run_id] = server.client.get(f"/api/runs/{run_id}").json()["ticks"]
        traffic = RewardTraffic(server.url, run_ids[0], f"t{n}", seed=n).start()
        follower = Follower(server.url, run_ids[0])
        time.sleep(rng.uniform(0.5, 1.5))
        before = server.client.get(f"/api/runs/{run_ids[1]}").json()["ticks"]
        assert before > ticks[run_ids[1]], "the fast run resumed and went on"

        server.client.close()
        sent_at = time.monotonic()
        server.process.terminate()
        server.process.wait(timeout=30)
        exits.append(time.monotonic() - sent_at)
        traffic.stop()
        follower.thread.join(10)
        assert not follower.thread.is_alive(), "the event stream did not end"
        acked |= traffic.acked
        sent += traffic.sent
        text = log.read_text(errors="replace")
        assert "Traceback" not in text, text[-3000:]
        assert server.process.returncode in (0, -15), text[-3000:]
        assert text.count("Application shutdown complete") == n + 1, text[-3000:]
        statuses = _stored_statuses(database, run_ids)
        assert set(statuses.values()) == {"interrupted"}, statuses

    # Once more: resume them all, stop them cleanly, check the rewarded run's log.
    server = start_server(database, env=ENV, log=log)
    _start_all(server, run_ids)
    time.sleep(0.3)
    for run_id in run_ids:
        assert server.client.post(f"/api/runs/{run_id}/stop").status_code == 200
        wait_status(server.client, run_id, "stopped")
    server.client.close()
    server.process.terminate()
    server.process.wait(timeout=30)

    engine = make_engine(database)
    try:
        store = SqlAlchemyRunStore(make_sessionmaker(engine))
        rewards = store.rewards(run_ids[0])
        stored_ltm = store.ltm(run_ids[0])
    finally:
        engine.dispose()
    check = check_log(rewards, acked)
    replayed = replay_ltm(rewards, CONDITION, SEED) == stored_ltm
    record(
        "SIGTERM of srlab serve (PostgreSQL)",
        f"{count(SIGTERMS)} SIGTERMs of `srlab serve` 0.5-1.5 s after it resumed 3 runs "
        "(realtime with 2 clients posting rewards and an open event stream, fast with no "
        f"episode limit, paused), {count(sent)} reward requests",
        f"exit after {max(exits):.2f} s at most (mean {sum(exits) / len(exits):.2f} s); "
        f"every run stored as interrupted and resumed each time; "
        f"{count(check.acknowledged)} rewards acknowledged, {len(check.lost)} lost, "
        f"{len(check.twice)} stored twice; LTM {'=' if replayed else '!='} a replay of the log",
    )
    assert max(exits) <= EXIT_WITHIN_S, exits
    assert check.held, check
    assert check.unapplied == 0
    assert replayed
