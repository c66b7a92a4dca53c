"""The runs in a process of their own (`server.runtime.process`), through the service's API.

What the placement guarantees, without timing anything: a run ticks, reads and takes its
rewards in the engines' process, not the service's; every control and read of the API
works as with the engines on the service's loop; the event stream carries the run's
events across and ends with it; the service's loop blocked solid does not stop a run from
ticking; if the engines' process dies, its runs read as failed with an error that says so,
calls on them answer 503 and the service stays up, then starts a new one where runs tick
and the failed ones resume; and the service stops with the engines' process gone and its
runs resumable.
"""

from __future__ import annotations

import asyncio
import logging
import os
import signal
import time
from pathlib import Path

import pytest
from apphelpers import client_for, create, settings_for, started_realtime, until
from fakes import InMemoryRunStore
from liveharness import children, wait_status

from bench.liveserver import family, live_server
from core.engine import StatusChanged
from core.engine.messages import Latest, LatestTick
from server.config import Settings
from server.persistence.storage import Storage, open_storage
from server.runtime import LiveRun, RunLetGo, Runs
from server.runtime import process as engine_process
from server.runtime.process import EngineProcessError, ProcessLink
from server.runtime.tuning import SHORT_SLICE_NS, slice_ns, threads

pytestmark = pytest.mark.anyio

BLOCK_S = 0.5
"""How long a test holds the service's loop: many 50 Hz periods on any machine."""


def _engines(app: object) -> Runs:
    engines = app.state.srlab.engines  # type: ignore[attr-defined]
    assert isinstance(engines, Runs) and isinstance(engines.link, ProcessLink)
    return engines


def _pid(engines: Runs) -> int | None:
    assert isinstance(engines.link, ProcessLink)
    return engines.link.pid


async def _tick(live: LiveRun) -> int:
    """The run's latest tick, read where it ticks."""
    now: LatestTick | None = await live.ask(Latest())
    assert now is not None
    return now.snapshot.tick


async def test_a_run_ticks_reads_and_takes_rewards_in_the_engines_process(
    tmp_path: Path,
) -> None:
    async with client_for(settings_for(tmp_path, engines="process")) as (client, app):
        engines = _engines(app)
        run_id = await started_realtime(client)
        live = engines.get(run_id)
        assert live is not None
        assert _pid(engines) not in (None, os.getpid())
        assert await _tick(live) >= 0  # a query answered there
        await until(client, run_id, "running")
        r = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1.0})
        assert r.status_code == 202, r.text
        reward_id = r.json()["id"]
        assert (await client.post(f"/api/runs/{run_id}/pause")).json()["status"] == "paused"
        assert (await client.post(f"/api/runs/{run_id}/pause")).status_code == 409
        step = await client.post(f"/api/runs/{run_id}/step")
        assert step.status_code == 200, step.text
        assert (await client.post(f"/api/runs/{run_id}/resume")).json()["status"] == "running"
        rate = await client.post(f"/api/runs/{run_id}/rate", json={"hz": 20})
        assert rate.status_code == 200, rate.text
        assert rate.json()["live"]["hz"] == 20
        stopped = await client.post(f"/api/runs/{run_id}/stop")
        assert stopped.status_code == 200, stopped.text
        assert stopped.json()["status"] == "stopped"
        assert engines.get(run_id) is None  # its end is stored: let go there and here
        log = (await client.get(f"/api/runs/{run_id}/rewards")).json()
        assert any(r["id"] == reward_id and r["applied"] for r in log["data"]), log
        # Started again from its checkpoint, in the engines' process again.
        again = await client.post(f"/api/runs/{run_id}/start")
        assert again.status_code == 200, again.text
        assert (await client.post(f"/api/runs/{run_id}/stop")).json()["status"] == "stopped"


async def test_a_read_reaching_the_engines_process_after_the_run_was_let_go_reads_storage(
    tmp_path: Path,
) -> None:
    async with client_for(settings_for(tmp_path, engines="process")) as (client, app):
        engines = _engines(app)
        run_id = await started_realtime(client)
        late = engines.get(run_id)  # what the service held when a read left for it
        assert late is not None
        assert (await client.post(f"/api/runs/{run_id}/stop")).json()["status"] == "stopped"
        with pytest.raises(RunLetGo):  # the child let it go: its end is stored
            await _tick(late)
        assert await engines.ask(run_id, Latest()) is None  # callers read storage
        run = await client.get(f"/api/runs/{run_id}")
        assert run.status_code == 200 and run.json()["status"] == "stopped"


@pytest.mark.parametrize("in_process", [True, False], ids=["process", "loop"])
async def test_a_stream_opened_before_the_start_keeps_the_runs_names_after_it_was_let_go(
    tmp_path: Path, in_process: bool
) -> None:
    # A stream follows a run from its next start; the run may end and be let go (its end
    # stored) before the stream reads its last events, which name things by its catalogue.
    async with client_for(settings_for(tmp_path, engines="process" if in_process else "local")) as (
        client,
        app,
    ):
        engines = app.state.srlab.engines
        run_id = int((await create(client, condition="expert", seed=2, episodes=1))["id"])
        sub = engines.subscribe(run_id, maxsize=512, tick_hz=0.0)
        assert engines.followed(run_id) is None  # not started yet
        assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
        await until(client, run_id, "finished")
        async with asyncio.timeout(30):  # a hang guard: let go once its end is stored
            while engines.get(run_id) is not None:
                await asyncio.sleep(0.01)
        followed = engines.followed(run_id)
        assert followed is not None and followed.run_id == run_id
        assert followed.catalog.behaviours  # the names its events use
        engines.unsubscribe(run_id, sub)
        assert engines.followed(run_id) is None  # nobody follows it any more


async def test_the_event_stream_carries_the_runs_events_across_and_ends_with_it(
    tmp_path: Path,
) -> None:
    async with client_for(settings_for(tmp_path, engines="process")) as (client, app):
        engines = _engines(app)
        run_id = await started_realtime(client)
        sub = engines.subscribe(run_id, maxsize=256, tick_hz=50.0)
        assert engines.streams(run_id) == 1
        await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1.0})
        kinds: set[str] = set()
        async with asyncio.timeout(30):  # a hang guard: both come within a few ticks
            while not {"TickPublished", "RewardApplied"} <= kinds:
                kinds.add(type(await sub.get()).__name__)
        await client.post(f"/api/runs/{run_id}/stop")
        seen: list[object] = []
        async with asyncio.timeout(30):  # a hang guard: the run's end closes it
            async for e in sub:
                seen.append(e)
        last = seen[-1]
        assert isinstance(last, StatusChanged) and last.status.value == "stopped"
        engines.unsubscribe(run_id, sub)
        assert engines.streams() == 0


async def test_a_blocked_service_loop_does_not_stop_the_ticks(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path, engines="process")) as (client, app):
        run_id = await started_realtime(client)
        live = _engines(app).get(run_id)
        assert live is not None
        await until(client, run_id, "running")
        before = await _tick(live)
        time.sleep(BLOCK_S)  # the service's loop (this test's) does nothing else meanwhile
        # What ticked meanwhile is read after: the process ticked on its own.
        assert await _tick(live) > before
        await client.post(f"/api/runs/{run_id}/stop")


async def test_runs_fail_clearly_and_the_service_stays_up_when_the_engines_process_dies(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(engine_process, "RESPAWN_FIRST_S", 3600.0)  # gone for the test
    async with client_for(settings_for(tmp_path, engines="process")) as (client, app):
        engines = _engines(app)
        run_id = await started_realtime(client)
        sub = engines.subscribe(run_id, maxsize=64, tick_hz=0.0)
        pid = _pid(engines)
        assert pid is not None
        os.kill(pid, signal.SIGKILL)
        async with asyncio.timeout(30):  # a hang guard: its stream ends
            async for _ in sub:
                pass
        async with asyncio.timeout(30):  # a hang guard: stored as failed
            while (run := (await client.get(f"/api/runs/{run_id}")).json()).get("status") != (
                "failed"
            ):
                await asyncio.sleep(0.05)
        assert "engines' process is gone" in run["error"]
        r = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1.0})
        assert r.status_code in (409, 503), r.text
        other = await create(client, condition="rp", mode="realtime", hz=50)
        started = await client.post(f"/api/runs/{other['id']}/start")
        assert started.status_code == 503, started.text
        assert "engines' process is gone" in started.json()["detail"]
        health = await client.get("/api/health")
        assert health.status_code == 503, health.text  # no run can start
        assert "engines' process is gone" in health.json()["detail"]


async def test_a_new_engines_process_is_started_and_a_failed_run_resumes_there(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(engine_process, "RESPAWN_FIRST_S", 0.0)
    async with client_for(settings_for(tmp_path, engines="process")) as (client, app):
        engines = _engines(app)
        run_id = await started_realtime(client)
        await until(client, run_id, "running")
        dead = _pid(engines)
        assert dead is not None
        os.kill(dead, signal.SIGKILL)
        async with asyncio.timeout(60):  # a hang guard: stored as failed, then resumed
            while (await client.get(f"/api/runs/{run_id}")).json().get("status") != "failed":
                await asyncio.sleep(0.05)
            # 503 until the new process is up; then the run resumes from its checkpoint.
            while (started := await client.post(f"/api/runs/{run_id}/start")).status_code == 503:
                await asyncio.sleep(0.05)
        assert started.status_code == 200, started.text
        assert _pid(engines) not in (None, dead)
        assert (await client.get("/api/health")).status_code == 200
        live = engines.get(run_id)
        assert live is not None
        assert await _tick(live) >= 0  # a query answered by the new process
        await until(client, run_id, "running")
        other = await started_realtime(client)
        assert (await client.post(f"/api/runs/{other}/stop")).json()["status"] == "stopped"
        assert (await client.post(f"/api/runs/{run_id}/stop")).json()["status"] == "stopped"


async def test_a_child_that_fails_to_start_is_started_again_until_one_does(
    monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    monkeypatch.setattr(engine_process, "RESPAWN_FIRST_S", 0.0)
    monkeypatch.setattr(engine_process, "RESPAWN_MAX_S", 0.0)  # no waiting in a test
    engines = ProcessLink(Runs(InMemoryRunStore()))
    starts: list[int] = []

    async def start_child() -> None:
        starts.append(len(starts))
        if len(starts) < 3:
            raise EngineProcessError(f"the engines' process did not start: try {len(starts)}")

    monkeypatch.setattr(engines, "_start_child", start_child)
    with caplog.at_level(logging.ERROR, logger="srlab.engines"):
        await engines._respawn()
    assert len(starts) == 3
    assert [r.getMessage() for r in caplog.records if r.levelno == logging.ERROR] == [
        "the engines' process did not start: try 1; trying again in 0 s",
        "the engines' process did not start: try 2; trying again in 0 s",
    ]


async def test_the_service_stops_with_the_engines_process_gone_and_its_run_resumable(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path, engines="process")
    async with client_for(settings) as (client, app):
        run_id = await started_realtime(client)
        await until(client, run_id, "running")
        pid = _pid(_engines(app))
    assert pid is not None
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # reaped: gone
    async with client_for(settings) as (client, _):
        assert (await client.get(f"/api/runs/{run_id}")).json()["status"] == "interrupted"
        assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
        assert (await client.post(f"/api/runs/{run_id}/stop")).json()["status"] == "stopped"


def test_the_engines_are_local_or_in_a_process_and_nothing_else(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="engines"):
        settings_for(tmp_path, engines="thread")


async def test_the_engines_process_refuses_storage_it_could_not_open_itself(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path, engines="process")

    def storage(s: Settings) -> Storage:  # any factory but the default
        return open_storage(s)

    with pytest.raises(ValueError, match="by SRLAB_DATABASE_URL only"):
        async with client_for(settings, storage=storage):
            pass


def _nices(pid: int) -> set[int]:
    """The nice values of process `pid`'s threads (Linux gives each thread its own)."""
    return {os.getpriority(os.PRIO_PROCESS, tid) for tid in threads(pid)}


def _slices(pid: int) -> set[int | None]:
    """The scheduler slices of process `pid`'s threads, in ns."""
    return {slice_ns(tid) for tid in threads(pid)}


def _loads_numba(pid: int) -> bool:
    """Whether process `pid` has numba's machine code mapped (Linux)."""
    return "/numba/" in Path(f"/proc/{pid}/maps").read_text()


def _interpreters(pid: int) -> dict[int, str]:
    """Process `pid` and its descendants that run Python, with their command lines."""
    found = {}
    for p in family(pid):
        try:
            exe = os.readlink(f"/proc/{p}/exe")
            command = Path(f"/proc/{p}/cmdline").read_bytes().replace(b"\0", b" ")
        except OSError:  # gone meanwhile
            continue
        if "python" in Path(exe).name:
            found[p] = command.decode(errors="replace")
    return found


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux's /proc")
def test_srlab_serve_runs_in_two_interpreters(tmp_path: Path) -> None:
    """The service and the engines' process: no store process, no resource tracker."""
    with live_server(tmp_path / "count.db", env={"SRLAB_VISER": "false"}) as server:
        run = server.client.post("/api/runs", json={"condition": "rp", "episodes": 1}).json()
        assert server.client.post(f"/api/runs/{run['id']}/start").status_code == 200
        assert wait_status(server.client, run["id"], "finished")["episodes_done"] == 1
        found = _interpreters(server.process.pid)
        assert len(found) == 2, found
        assert sum("server.runtime.process" in cmd for cmd in found.values()) == 1, found


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux's /proc")
def test_srlab_serve_steps_back_for_the_engines_process(tmp_path: Path) -> None:
    """The service's threads yield to the ticks; the engines' process does not.

    `srlab serve` with the engines in their own process lowers its own priority by
    SRLAB_SERVICE_NICE (10 unless set) once that process runs, so on a busy machine the
    ticks get a core before requests do (docs/benchmarks.md measures the effect).
    """
    base = os.getpriority(os.PRIO_PROCESS, 0)
    env = {"SRLAB_ENGINES": "process", "SRLAB_VISER": "false"}
    with live_server(tmp_path / "nice.db", env=env) as server:
        service = server.process.pid
        found = children(service)
        (engines,) = [pid for pid, cmd in found.items() if "server.runtime.process" in cmd]
        assert _nices(service) == {min(19, base + 10)}
        assert _nices(engines) == {base}


@pytest.mark.skipif(not slice_ns(), reason="the kernel reports no slices (Linux 6.12+ does)")
def test_every_process_of_srlab_serve_runs_its_threads_in_short_slices(tmp_path: Path) -> None:
    """Each thread of the service and of the engines' process.

    So that beside busy processes a tick's or a storage thread's wake-up is let in at once
    rather than at the end of another process's slice (`server.runtime.tuning.ask_short_slices`).
    """
    env = {"SRLAB_ENGINES": "process", "SRLAB_VISER": "false"}
    with live_server(tmp_path / "slices.db", env=env) as server:
        service = server.process.pid
        found = children(service)
        (engines,) = [pid for pid, cmd in found.items() if "server.runtime.process" in cmd]
        for pid in (service, engines):
            assert _slices(pid) == {SHORT_SLICE_NS}, f"process {pid}"


@pytest.mark.parametrize(
    ("env", "in_process"),
    [({}, True), ({"SRLAB_ENGINES": "local"}, False)],
    ids=["default", "engines-local"],
)
def test_srlab_serve_ticks_runs_in_the_engines_process_unless_told_otherwise(
    tmp_path: Path, env: dict[str, str], in_process: bool
) -> None:
    with live_server(tmp_path / "placement.db", env={"SRLAB_VISER": "false", **env}) as server:
        found = children(server.process.pid).values()
        assert any("server.runtime.process" in cmd for cmd in found) is in_process, found
        run = server.client.post("/api/runs", json={"condition": "rp", "episodes": 1}).json()
        assert server.client.post(f"/api/runs/{run['id']}/start").status_code == 200
        assert wait_status(server.client, run["id"], "finished")["episodes_done"] == 1
        # Numba (the sensing kernel) is loaded where runs tick, and only there.
        assert _loads_numba(server.process.pid) is not in_process
        engines = [p for p, cmd in children(server.process.pid).items() if "runtime.process" in cmd]
        assert [_loads_numba(p) for p in engines] == ([True] if in_process else [])


def test_on_sqlite_the_engines_storage_calls_share_one_thread() -> None:
    """SQLite takes one writer at a time: every run's writes queue on one thread there.

    PostgreSQL keeps asyncio's pool, whose threads' writes go in one transaction together.
    """
    assert engine_process.storage_threads("sqlite:///runs.db") == 1
    assert engine_process.storage_threads("postgresql+psycopg://srlab@localhost/srlab") is None
