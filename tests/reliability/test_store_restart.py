"""kill -9 of `srlab serve`'s store processes: each is started again, and health says so.

`srlab serve` runs four processes: the service, its store process, the engines' process
and the engines' store process. Each store process is found by the process tree and
killed while clients post rewards to a realtime run. `/api/health` answers 503 naming the
store process that is down, then 200 once a new one serves, with the service never
restarted; the run that failed resumes, a new run starts and takes a reward, and the log
holds every acknowledged reward exactly once. A store process that cannot start (its
database moved away) is tried again with waits that double, not in a tight loop, and
health says why meanwhile.

No timing is asserted: every wait is a generous deadline for a hang.
"""

from __future__ import annotations

import itertools
import os
import re
import signal
import time
from collections.abc import Callable
from pathlib import Path

import httpx
from harness import RewardTraffic, check_log

from bench.liveserver import LiveServer, children, server_log, stop_server, wait_status
from core.ports import StoredReward
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker

ENV = {
    "SRLAB_VISER": "false",
    "SRLAB_REWARD_RATE_PER_S": "100000",
    "SRLAB_REWARD_BURST": "100000",
    "SRLAB_REWARD_RUN_RATE_PER_S": "100000",
    "SRLAB_REWARD_RUN_BURST": "100000",
}
RUN = {"condition": "rp", "seed": 11, "mode": "realtime", "hz": 50}
DEADLINE_S = 120.0
"""How long a store process may take to be noticed, or to serve again: a hang guard."""


def store_processes(service: int) -> dict[str, int]:
    """The store processes of a `srlab serve` by whose they are (none while one is down)."""
    found = children(service)
    (engines,) = [pid for pid, cmd in found.items() if "server.runtime.process" in cmd]
    stores = {}
    for whose, parent in (("service's", found), ("engines'", children(engines))):
        pids = [pid for pid, cmd in parent.items() if "spawn_main" in cmd]
        assert len(pids) <= 1, f"two store processes of the {whose}: {parent}"
        if pids:
            stores[whose] = pids[0]
    return stores


def until(what: Callable[[], object], deadline_s: float = DEADLINE_S) -> object:
    """Poll `what` until it gives something true, within the deadline; that."""
    deadline = time.monotonic() + deadline_s
    while not (found := what()):
        assert time.monotonic() < deadline, f"not within {deadline_s:g} s: {what}"
        time.sleep(0.005)
    return found


def health(server: LiveServer) -> httpx.Response:
    return server.client.get("/api/health")


def answers(server: LiveServer, code: int) -> Callable[[], str | None]:
    """Whether health answers `code`: its detail (or 'ok') when it does."""

    def check() -> str | None:
        r = health(server)
        return (r.json().get("detail") or "ok") if r.status_code == code else None

    return check


def start_run(server: LiveServer) -> int:
    created = server.client.post("/api/runs", json=RUN)
    assert created.status_code == 201, created.text
    run_id = int(created.json()["id"])
    started = server.client.post(f"/api/runs/{run_id}/start")
    assert started.status_code == 200, started.text
    return run_id


def reward(server: LiveServer, run_id: int) -> int:
    r = server.client.post(f"/api/runs/{run_id}/rewards", json={"value": 1.0, "note": "after"})
    assert r.status_code == 202, r.text
    return int(r.json()["id"])


def stored_rewards(database: Path, run_id: int) -> list[StoredReward]:
    engine = make_engine(f"sqlite:///{database}")
    try:
        return SqlAlchemyRunStore(make_sessionmaker(engine)).rewards(run_id)
    finally:
        engine.dispose()


def test_each_killed_store_process_is_started_again_while_health_says_runs_cannot_store(
    tmp_path: Path, start_server: Callable[..., LiveServer]
) -> None:
    database, log = tmp_path / "serve.db", tmp_path / "serve.log"
    server = start_server(database, env=ENV, log=log)
    service = server.process.pid
    run_id = start_run(server)
    wait_status(server.client, run_id, "running")
    traffic = RewardTraffic(server.url, run_id, "t").start()
    killed = {}
    try:
        for whose in ("engines'", "service's"):
            before = store_processes(service)
            killed[whose] = before[whose]
            os.kill(before[whose], signal.SIGKILL)
            down = until(answers(server, 503))
            assert f"the {whose} store process is down, restarting" in str(down), down
            until(answers(server, 200))
            after = store_processes(service)
            assert after[whose] != before[whose] and server.process.poll() is None
            other = next(w for w in after if w != whose)
            assert after[other] == before[other]  # only the dead one was started again
            # The run failed if its storage died under it; it resumes from its checkpoint.
            run = server.client.get(f"/api/runs/{run_id}").json()
            if run["status"] == "failed":
                assert "store process" in run["error"], run
                resumed = server.client.post(f"/api/runs/{run_id}/start")
                assert resumed.status_code == 200, resumed.text
            wait_status(server.client, run_id, "running")
    finally:
        traffic.stop()
    assert server.process.poll() is None  # the same service all along
    acked = dict(traffic.acked)
    acked[reward(server, run_id)] = "after"
    new = start_run(server)
    reward(server, new)
    for r in (run_id, new):
        assert server.client.post(f"/api/runs/{r}/stop").status_code == 200
    said = stop_server(server)
    for whose, pid in killed.items():
        assert said.count(f"the {whose} store process ({pid}) died (killed by SIGKILL)") == 1
        assert f"the {whose} store process was started again" in said
    check = check_log(stored_rewards(database, run_id), acked)
    assert check.acknowledged >= 1
    assert not check.lost, f"acknowledged rewards lost: {check.lost[:20]}"
    assert not check.twice, f"stored twice: {check.twice[:20]}"


def test_a_store_process_that_cannot_start_is_tried_again_with_growing_waits(
    tmp_path: Path, start_server: Callable[..., LiveServer]
) -> None:
    database, log = tmp_path / "serve.db", tmp_path / "serve.log"
    server = start_server(database, env=ENV, log=log)
    created = server.client.post("/api/runs", json=RUN)
    assert created.status_code == 201, created.text
    waiting = int(created.json()["id"])
    before = store_processes(server.process.pid)
    away = database.with_name("away.db")
    database.rename(away)  # the store process started again cannot open it
    os.kill(before["engines'"], signal.SIGKILL)
    failed = re.compile(r"the engines' store process did not start: (.*); trying again in (\S+) s")
    tries = until(lambda: len(found := failed.findall(server_log(server))) >= 4 and found)
    assert isinstance(tries, list)
    assert all("was deleted" in why for why, _ in tries), tries
    waits = [float(wait) for _, wait in tries]
    # Each wait twice the one before, until they reach the cap (a few seconds).
    assert waits[1] == 2 * waits[0] > 0, waits
    assert all(b == 2 * a or a == b == max(waits) for a, b in itertools.pairwise(waits)), waits
    r = health(server)
    assert r.status_code == 503, r.text
    detail = r.json()["detail"]
    assert "the engines' store process is down, restarting (its last start failed" in detail
    assert "was deleted" in detail
    assert server.client.post(f"/api/runs/{waiting}/start").status_code == 503
    away.rename(database)
    until(answers(server, 200))
    assert "the engines' store process was started again" in server_log(server)
    assert server.client.post(f"/api/runs/{waiting}/start").status_code == 200
    reward(server, waiting)
    assert server.client.post(f"/api/runs/{waiting}/stop").status_code == 200
    stop_server(server)
