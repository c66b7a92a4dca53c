"""A long day of training on a live `srlab serve`: what stays bounded, and what is noticed.

Each check runs the real service (uvicorn on loopback, a SQLite file):

- paged reads: a run with ``SRLAB_DAY_EPISODES`` stored episodes (300 in CI, 10,000 in
  `make reliability`) answers a page of 50 and one episode, and a 404 for a missing one;
  the latencies are reported, not asserted;
- the database file deleted, or replaced by another, under a realtime run taking rewards:
  the run fails with an error naming the file, /api/health answers 503 saying so, no
  reward sent after the fault is acknowledged, and no empty file appears in its place;
- the WAL index (-shm) truncated under the service: /api/health answers 503 naming it
  instead of the process dying of SIGBUS; what the process does when it is stopped is
  reported (closing SQLite's connections touches the mapping SQLite cannot report on);
- event streams past ``SRLAB_MAX_STREAMS`` and the per-run cap get 503 with Retry-After,
  exactly as many accepted as the caps allow, and the slots come back when they close;
- ``SRLAB_DAY_RUNS`` finished runs (40 in CI, 400 in full) keep no engine: the server's
  memory growth per run is reported, a stopped run resumes from storage;
- a start refused with 429 leaves the run as stored (stop 409, a reward 409 at once, a
  later start without the refused run's reward);
- stop answers once the run has stopped (200, status stopped), paused or not.
"""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path

import httpx
from harness import RewardTraffic, rss_kib
from liveharness import wait_status
from reliability_report import count, record

from bench.figures import percentile
from bench.liveserver import live_server, start_server
from bench.service import store_episodes

EPISODES = int(os.environ.get("SRLAB_DAY_EPISODES", "300"))
RUNS = int(os.environ.get("SRLAB_DAY_RUNS", "40"))
FAST = {
    "SRLAB_REWARD_RATE_PER_S": "100000",
    "SRLAB_REWARD_BURST": "100000",
    "SRLAB_REWARD_RUN_RATE_PER_S": "100000",
    "SRLAB_REWARD_RUN_BURST": "100000",
}
"""The rate limits out of the way (per trainer and per run): how many rewards the traffic
gets through in a second depends on the machine, and a drained bucket answers 429 first."""


def _gets(api: httpx.Client, paths: list[str]) -> tuple[list[float], set[int]]:
    latencies, statuses = [], set()
    for path in paths:
        sent = time.perf_counter()
        r = api.get(path)
        latencies.append(time.perf_counter() - sent)
        statuses.add(r.status_code)
    return latencies, statuses


def _ms(values: list[float]) -> str:
    return f"p50 {percentile(values, 50) * 1000:.1f} ms, p99 {percentile(values, 99) * 1000:.1f} ms"


def test_a_run_with_many_episodes_reads_a_page_and_one_episode(tmp_path: Path) -> None:
    database = tmp_path / "day.db"
    run_id = store_episodes(f"sqlite:///{database}", EPISODES)
    with live_server(database) as server:
        api = server.client
        base = f"/api/runs/{run_id}/episodes"
        page = api.get(base, params={"limit": 50, "offset": EPISODES - 60}).json()
        assert page["count"] == EPISODES and len(page["data"]) == 50
        assert page["data"][0]["episode"] == EPISODES - 60
        assert api.get(base, params={"limit": 1001}).status_code == 422
        pages, page_codes = _gets(api, [f"{base}?limit=50&offset={i * 7 % (EPISODES - 50)}"
                                        for i in range(200)])  # fmt: skip
        ones, one_codes = _gets(api, [f"{base}/{i * 13 % EPISODES}" for i in range(200)])
        missing, missing_codes = _gets(api, [f"{base}/{EPISODES + 1}"] * 50)
        record(
            "paged reads of a run's episodes",
            f"{count(EPISODES)} stored episodes; 200 GETs of ?limit=50 and of /episodes/{{n}}, "
            "50 of a missing one, one at a time",
            f"page {_ms(pages)}; one episode {_ms(ones)}; 404 {_ms(missing)}",
        )
        assert page_codes == one_codes == {200} and missing_codes == {404}


def _lose(database: Path, fault: str) -> None:
    if fault == "deleted":
        database.unlink()
    else:
        other = database.with_name("other.db")
        other.write_bytes(b"")
        os.replace(other, database)


def _fail_database(tmp_path: Path, fault: str) -> None:
    database = tmp_path / f"{fault}.db"
    with live_server(database, env=FAST) as server:
        api = server.client
        run = api.post("/api/runs", json={"condition": "rp", "mode": "realtime", "hz": 50})
        run_id = run.json()["id"]
        api.post(f"/api/runs/{run_id}/start")
        before = RewardTraffic(server.url, run_id, "before").start()
        time.sleep(1.0)
        before.stop()
        _lose(database, fault)
        after = RewardTraffic(server.url, run_id, "after").start()
        failed = wait_status(api, run_id, "failed", timeout=30)
        time.sleep(0.5)
        after.stop()
        health = api.get("/api/health")
        late = api.post(f"/api/runs/{run_id}/rewards", json={"value": 1})
        record(
            f"the database file {fault} under a running run",
            f"a 50 Hz rp run taking rewards from 2 clients; the SQLite file {fault}",
            f"{count(len(before.acked))} rewards acked before, {count(len(after.acked))} "
            f"after (answers after: {dict(after.outcomes)}); run failed: "
            f"{failed['error']}; health {health.status_code}",
        )
        assert after.acked == {}, after.details
        assert failed["error"] and str(database) in failed["error"]
        assert health.status_code == 503 and str(database) in health.json()["detail"]
        assert late.status_code == 409
        if fault == "deleted":
            assert not database.exists()  # nothing made an empty file in its place


def test_a_deleted_database_file_fails_the_run_and_health(tmp_path: Path) -> None:
    _fail_database(tmp_path, "deleted")


def test_a_replaced_database_file_fails_the_run_and_health(tmp_path: Path) -> None:
    _fail_database(tmp_path, "replaced")


def test_a_truncated_wal_index_is_reported_not_a_silent_sigbus(tmp_path: Path) -> None:
    database = tmp_path / "shm.db"
    server = start_server(database, log=tmp_path / "server.log")
    api = server.client
    try:
        assert api.get("/api/health").status_code == 200
        os.truncate(database.with_name("shm.db-shm"), 0)
        health = api.get("/api/health")
        again = api.get("/api/health")
        alive = server.process.poll() is None
    finally:
        api.close()
        server.process.terminate()
        server.process.wait(timeout=30)
    log = (tmp_path / "server.log").read_text(errors="replace")
    at_exit = server.process.returncode
    record(
        "the WAL index (-shm) truncated under the service",
        "the -shm file of a serving SQLite database truncated to 0 bytes, then /api/health",
        f"health {health.status_code}: {health.json()['detail']}; still serving: {alive}; "
        f"exit code on SIGTERM {at_exit}"
        + (" (SIGBUS closing SQLite, traceback in the log)" if "Bus error" in log else ""),
    )
    assert health.status_code == again.status_code == 503
    assert "WAL index" in health.json()["detail"] and alive


def _stream(port: int, run_id: int) -> tuple[int, str, socket.socket]:
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    s.sendall(
        f"GET /api/runs/{run_id}/events?tick_hz=0 HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n".encode()
    )
    head = b""
    while b"\r\n\r\n" not in head:
        chunk = s.recv(4096)
        if not chunk:
            break
        head += chunk
    lines = head.decode(errors="replace").split("\r\n")
    retry = next(
        (x.split(":", 1)[1].strip() for x in lines if x.lower().startswith("retry-after")), ""
    )
    return int(lines[0].split()[1]), retry, s


def test_event_streams_past_the_caps_are_refused(tmp_path: Path) -> None:
    env = {"SRLAB_MAX_STREAMS": "20", "SRLAB_MAX_STREAMS_PER_RUN": "8"}
    with live_server(tmp_path / "streams.db", env=env) as server:
        api = server.client
        body = {"condition": "rp", "mode": "realtime", "hz": 20}
        runs = [api.post("/api/runs", json=body).json()["id"] for _ in range(3)]
        for r in runs:
            api.post(f"/api/runs/{r}/start")
        before = api.get(f"/api/runs/{runs[0]}").json()["live"]
        opened = [_stream(server.port, runs[i % 3]) for i in range(12 * 3)]
        accepted = [s for code, _, s in opened if code == 200]
        refused = [(code, retry) for code, retry, _ in opened if code != 200]
        by_run = [sum(1 for i, (c, _, _) in enumerate(opened) if c == 200 and i % 3 == k)
                  for k in range(3)]  # fmt: skip
        after = api.get(f"/api/runs/{runs[0]}").json()["live"]
        for _, _, s in opened:
            s.close()
        time.sleep(0.5)
        reopened = [_stream(server.port, runs[0]) for _ in range(8)]
        for _, _, s in reopened:
            s.close()
        for r in runs:
            api.post(f"/api/runs/{r}/stop")
        record(
            "event streams past the caps",
            "36 stream clients over 3 runs, SRLAB_MAX_STREAMS=20, SRLAB_MAX_STREAMS_PER_RUN=8",
            f"{len(accepted)} accepted ({by_run} by run), {len(refused)} refused "
            f"({sorted(set(refused))}); a 20 Hz run's overruns meanwhile "
            f"{after['overruns'] - before['overruns']}; 8 reopened after closing: "
            f"{sorted({c for c, _, _ in reopened})}",
        )
        assert len(accepted) == 20 and all(n <= 8 for n in by_run)
        assert set(refused) == {(503, "5")}
        assert {c for c, _, _ in reopened} == {200}


def test_finished_runs_keep_no_engine_and_resume_from_storage(tmp_path: Path) -> None:
    env = {**FAST, "SRLAB_VISER": "false"}
    with live_server(tmp_path / "runs.db", env=env) as server:
        api = server.client
        pid = server.process.pid
        first = _finish_runs(api, 5)
        start_kib, _ = rss_kib(pid)
        ids = _finish_runs(api, RUNS)
        end_kib, _ = rss_kib(pid)
        listed = api.get("/api/runs", params={"limit": 1000}).json()
        health = api.get("/api/health").json()
        # Rebuilt on demand: a realtime run stopped, then started again from storage.
        run = api.post("/api/runs", json={"condition": "rp", "mode": "realtime", "hz": 20}).json()
        api.post(f"/api/runs/{run['id']}/start")
        stopped = api.post(f"/api/runs/{run['id']}/stop").json()
        resumed = api.post(f"/api/runs/{run['id']}/start")
        reward = api.post(f"/api/runs/{run['id']}/rewards", json={"value": 1})
        api.post(f"/api/runs/{run['id']}/stop")
        per_run = (end_kib - start_kib) / RUNS
        record(
            "finished runs' engines evicted",
            f"{count(RUNS)} one-episode runs created, started and finished (after 5 to warm up)",
            f"server RSS {start_kib / 1024:.0f} -> {end_kib / 1024:.0f} MiB, "
            f"{per_run:.1f} KiB per run (was about 240 KiB with every engine kept); "
            "a stopped run resumed and took a reward",
        )
        assert listed["count"] == RUNS + 5 and health["runs_active"] == 0
        assert all(r["status"] == "finished" for r in listed["data"] if r["id"] in ids + first)
        assert stopped["status"] == "stopped"
        assert resumed.status_code == 200 and reward.status_code == 202


def _finish_runs(api: httpx.Client, n: int) -> list[int]:
    ids = []
    for _ in range(n):
        run = api.post("/api/runs", json={"condition": "innate", "episodes": 1}).json()
        api.post(f"/api/runs/{run['id']}/start")
        ids.append(run["id"])
    for run_id in ids:
        wait_status(api, run_id, "finished")
    return ids


def test_a_start_refused_with_429_leaves_the_run_as_stored(tmp_path: Path) -> None:
    with live_server(tmp_path / "slots.db", env={"SRLAB_MAX_RUNS": "1"}) as server:
        api = server.client
        body = {"condition": "rp", "mode": "realtime", "hz": 20}
        a, b = (api.post("/api/runs", json=body).json()["id"] for _ in range(2))
        api.post(f"/api/runs/{b}/start")
        api.post(f"/api/runs/{b}/stop")
        api.post(f"/api/runs/{a}/start")
        refused = api.post(f"/api/runs/{b}/start")
        state = api.get(f"/api/runs/{b}").json()["status"]
        stop = api.post(f"/api/runs/{b}/stop").status_code
        reward = api.post(f"/api/runs/{b}/rewards", json={"value": 1, "note": "refused"})
        api.post(f"/api/runs/{a}/stop")
        later = api.post(f"/api/runs/{b}/start")
        api.post(f"/api/runs/{b}/stop")
        notes = [r["note"] for r in api.get(f"/api/runs/{b}/rewards").json()["data"]]
        record(
            "a start refused with 429",
            "SRLAB_MAX_RUNS=1, one run running, a stopped one started",
            f"start {refused.status_code}; then status {state}, stop {stop}, reward "
            f"{reward.status_code}; after the slot was freed start {later.status_code}, the "
            f"refused run's reward in its log: {'refused' in notes}",
        )
        assert (refused.status_code, state, stop, reward.status_code) == (429, "stopped", 409, 409)
        assert later.status_code == 200 and "refused" not in notes


def test_stop_answers_once_the_run_has_stopped(tmp_path: Path) -> None:
    with live_server(tmp_path / "stop.db") as server:
        api = server.client
        answers: list[tuple[int, str]] = []
        for hz, pause in ((0.5, False), (20, False), (20, True)):
            run = api.post("/api/runs", json={"condition": "rp", "mode": "realtime", "hz": hz})
            run_id = run.json()["id"]
            api.post(f"/api/runs/{run_id}/start")
            if pause:
                api.post(f"/api/runs/{run_id}/pause")
            r = api.post(f"/api/runs/{run_id}/stop")
            answers.append((r.status_code, r.json()["status"]))
        record(
            "stop answers when the run has stopped",
            "POST /stop of realtime runs at 0.5 Hz and 20 Hz, and of a paused one",
            f"answers {answers}",
        )
        assert answers == [(200, "stopped")] * 3
