"""kill -9 of `srlab serve` itself at random moments, while clients post rewards over HTTP.

The service runs a realtime `rp` run; two client threads post trainer rewards and keep
every acknowledgement (202 with the reward's id). The server is killed with SIGKILL at a
random moment after it answers: during the resumed run's replay, while rewards are
acknowledged, or while learning is committed. Then it is started again, and POST .../start
resumes the run, which the restart marked interrupted. In the end the run is stopped
cleanly, and the stored log must hold every acknowledged reward exactly once, with every
logged reward applied once (the stored LTM equals a headless replay of the log).

``SRLAB_SERVE_KILLS`` (SQLite, 4 by default) and ``SRLAB_SERVE_KILLS_PG`` (PostgreSQL,
2) set the numbers; ``make reliability`` runs 200 and 25.
"""

from __future__ import annotations

import os
import random
import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import pytest
from harness import RewardTraffic, check_log, integrity, replay_ltm
from liveharness import wait_status
from reliability_report import count, record

from bench.liveserver import LiveServer, stop_server
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker

KILLS = {
    "sqlite": int(os.environ.get("SRLAB_SERVE_KILLS", "4")),
    "postgresql": int(os.environ.get("SRLAB_SERVE_KILLS_PG", "2")),
}
ENV = {"SRLAB_REWARD_RATE_PER_S": "100000", "SRLAB_REWARD_BURST": "100000"}
CONDITION, SEED = "rp", 11
RUN = {"condition": CONDITION, "seed": SEED, "mode": "realtime", "hz": 200}
KILL_WITHIN_S = 1.0
"""Kills fall uniformly within this long after the restarted server answers."""
LAST_LIFE_S = 120.0
"""How long the last life may take to acknowledge a reward: a bound for a hang, not a speed
test."""


def _resume(server: LiveServer, run_id: int, traffic: list[RewardTraffic], n: int) -> None:
    """Resume the run and post rewards to it until the server dies."""
    try:
        server.client.post(f"/api/runs/{run_id}/start")
    except httpx.HTTPError:
        return  # killed during the replay
    traffic.append(RewardTraffic(server.url, run_id, f"k{n}", seed=n).start())


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_kill_9_of_the_service_loses_no_acknowledged_reward(
    backend: str,
    request: pytest.FixtureRequest,
    tmp_path: Path,
    start_server: Callable[..., LiveServer],
) -> None:
    kills = KILLS[backend]
    if kills == 0:
        pytest.skip(f"no kills asked for on {backend}")
    path = tmp_path / "serve.db"
    database = (
        f"sqlite:///{path}"
        if backend == "sqlite"
        else str(request.getfixturevalue("postgres_database"))
    )
    log = tmp_path / "serve.log"
    rng = random.Random(2027)
    acked: dict[int, str] = {}
    sent = 0
    started = time.monotonic()

    server = start_server(database, env=ENV, log=log)
    created = server.client.post("/api/runs", json=RUN)
    assert created.status_code == 201, created.text
    run_id = int(created.json()["id"])
    assert server.client.post(f"/api/runs/{run_id}/start").status_code == 200
    traffic = [RewardTraffic(server.url, run_id, "k0").start()]
    resumer: threading.Thread | None = None
    for n in range(1, kills + 1):
        time.sleep(rng.uniform(0.0, KILL_WITHIN_S))
        server.process.kill()
        server.process.wait()
        server.client.close()
        if resumer is not None:
            resumer.join()
        for t in traffic:
            t.stop()
            acked |= t.acked
            sent += t.sent
        traffic = []
        if backend == "sqlite":
            assert integrity(path) == "ok", f"after kill {n}"
        server = start_server(database, env=ENV, log=log)
        resumer = threading.Thread(target=_resume, args=(server, run_id, traffic, n))
        resumer.start()
    assert resumer is not None
    resumer.join()

    # The last life: the run goes on until a client has been acknowledged a reward in it,
    # then stops cleanly and everything must add up. How many rewards the earlier lives
    # got acknowledged before their kill depends on the machine's speed (a slow one may
    # get none); this wait makes the check below cover acknowledged rewards on any machine.
    if not traffic:  # the resume's request timed out: post to the run anyway
        traffic.append(RewardTraffic(server.url, run_id, f"k{kills + 1}", seed=kills + 1).start())
    deadline = time.monotonic() + LAST_LIFE_S
    while not any(t.acked for t in traffic) and time.monotonic() < deadline:
        time.sleep(0.1)
    for t in traffic:
        t.stop()
        acked |= t.acked
        sent += t.sent
    assert server.client.post(f"/api/runs/{run_id}/stop").status_code == 200
    wait_status(server.client, run_id, "stopped")
    text = stop_server(server)
    assert "Traceback" not in text

    engine = make_engine(database)
    try:
        store = SqlAlchemyRunStore(make_sessionmaker(engine))
        rewards = store.rewards(run_id)
        stored_ltm = store.ltm(run_id)
    finally:
        engine.dispose()
    check = check_log(rewards, acked)
    replayed_ltm = replay_ltm(rewards, CONDITION, SEED)
    where = "SQLite file" if backend == "sqlite" else "PostgreSQL"
    record(
        f"kill -9 of srlab serve ({where})",
        f"{count(kills)} SIGKILLs of `srlab serve` at random moments (0-{KILL_WITHIN_S:g} s "
        f"after it answered; the run resumed over HTTP after each) while 2 clients posted "
        f"rewards to a realtime run ({count(sent)} requests, {time.monotonic() - started:.0f} s)",
        f"{count(check.acknowledged)} rewards acknowledged: {len(check.lost)} lost, "
        f"{len(check.twice)} stored twice; {count(check.stored)} logged, "
        f"{check.unapplied} never applied; LTM "
        f"{'=' if replayed_ltm == stored_ltm else '!='} a replay of the log"
        + ("; integrity_check ok after every kill" if backend == "sqlite" else ""),
    )
    assert check.acknowledged >= 1, f"no reward acknowledged in {LAST_LIFE_S:g} s: {check}"
    assert not check.lost, f"acknowledged rewards lost: {check.lost[:20]}"
    assert not check.twice, f"stored twice: {check.twice[:20]}"
    assert check.unapplied == 0, "a logged reward was never applied"
    assert replayed_ltm == stored_ltm
