"""The store process `srlab serve` runs: its errors, its death, and the service's death."""

from __future__ import annotations

import asyncio
import logging
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from apphelpers import client_for, create, settings_for

from core.errors import StorageError, UnknownRunError
from core.networks import ExpectedVersion, ReadOnlyNetworkError, StaleVersionError
from server.persistence import process as process_module
from server.persistence.process import StoreProcess, StoreProcessError

pytestmark = pytest.mark.anyio


def gone(pid: int) -> bool:
    """Whether no process `pid` runs (a zombie of ours counts as gone)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return True
    return state == "Z"


def wait_until_gone(pid: int, timeout: float = 30.0) -> None:
    """A hang guard, not a timing: the process must be gone within `timeout`."""
    deadline = time.monotonic() + timeout
    while not gone(pid):
        assert time.monotonic() < deadline, f"process {pid} is still running"
        time.sleep(0.05)


def test_errors_cross_the_process_boundary_with_their_type_and_fields(
    clean_store_process: StoreProcess,
) -> None:
    runs, networks = clean_store_process.runs, clean_store_process.networks
    with pytest.raises(UnknownRunError, match="12345"):
        runs.load_run(12345)
    with pytest.raises(ReadOnlyNetworkError) as read_only:
        networks.delete("innate")
    assert read_only.value.network == "innate" and "built in" in str(read_only.value)
    networks.create("mine", description="a copy")
    with pytest.raises(StaleVersionError) as stale:
        networks.delete("mine", expected=ExpectedVersion(version=99))
    assert stale.value.current == 1 and stale.value.fingerprint


def test_sigint_leaves_the_store_process_serving(clean_store_process: StoreProcess) -> None:
    """Ctrl-C reaches the whole process group: the service stops the store after its writes."""
    pid = clean_store_process.pid
    assert pid is not None
    os.kill(pid, signal.SIGINT)
    time.sleep(0.2)
    assert clean_store_process.alive()
    assert clean_store_process.database.check() == "sqlite"


def wait_for(what: Callable[[], bool], timeout: float = 60.0) -> None:
    """A hang guard, not a timing: `what()` must come true within `timeout`."""
    deadline = time.monotonic() + timeout
    while not what():
        assert time.monotonic() < deadline, f"still not {what}"
        time.sleep(0.02)


@pytest.fixture
def database(migrated_sqlite: Path, tmp_path: Path) -> Path:
    """A copy of the migrated SQLite database for one test."""
    path = tmp_path / "srlab.db"
    path.write_bytes(migrated_sqlite.read_bytes())
    return path


def error_of(call: Callable[[], object]) -> str:
    """What `call` fails with ('' if it does not)."""
    try:
        call()
    except StoreProcessError as e:
        return str(e)
    return ""


def test_a_dead_store_process_is_a_storage_error_that_says_so(
    database: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Down for the test: no new one is started meanwhile.
    monkeypatch.setattr(process_module, "RESTART_FIRST_S", 3600.0)
    process = StoreProcess(f"sqlite:///{database}")
    try:
        assert process.runs.list_runs() == []
        pid = process.pid
        assert pid is not None
        os.kill(pid, signal.SIGKILL)
        wait_until_gone(pid)
        # A call that reaches it first says only that it stopped answering.
        wait_for(lambda: "died" in error_of(process.runs.list_runs))
        said = re.escape(f"the store process is down, restarting ({pid} died: killed by SIGKILL)")
        for call in (process.runs.list_runs, process.networks.summaries, process.database.check):
            with pytest.raises(StoreProcessError, match=said):
                call()
        assert issubclass(StoreProcessError, StorageError)
    finally:
        process.stop()  # while it waits to start another: it starts none


def test_a_dead_store_process_is_started_again_and_serves_what_was_stored(
    database: Path, caplog: pytest.LogCaptureFixture
) -> None:
    process = StoreProcess(f"sqlite:///{database}")
    try:
        process.networks.create("mine", description="before the kill")
        dead = process.pid
        assert dead is not None
        with caplog.at_level(logging.WARNING, logger="srlab.storage"):
            os.kill(dead, signal.SIGKILL)
            wait_for(lambda: not error_of(process.database.check) and process.pid != dead)
        assert process.networks.get("mine").description == "before the kill"
        assert process.runs.list_runs() == []
        messages = [r.getMessage() for r in caplog.records]
        assert messages == [
            f"the store process ({dead}) died (killed by SIGKILL): starting it again in 0.1 s",
            f"the store process was started again (pid {process.pid})",
        ]
    finally:
        process.stop()
    assert not process.alive()


def test_a_store_process_that_cannot_start_is_tried_again_with_growing_waits(
    database: Path, monkeypatch: pytest.MonkeyPatch, caplog: pytest.LogCaptureFixture
) -> None:
    """Its database unopenable (moved away), each start fails; the waits double to a cap."""
    monkeypatch.setattr(process_module, "RESTART_MAX_S", 0.8)  # soon reached
    process = StoreProcess(f"sqlite:///{database}")
    away = database.with_name("moved.db")
    try:
        process.networks.create("mine", description="before the kill")
        dead = process.pid
        assert dead is not None
        with caplog.at_level(logging.ERROR, logger="srlab.storage"):
            database.rename(away)
            os.kill(dead, signal.SIGKILL)
            wait_for(lambda: sum("trying again" in r.getMessage() for r in caplog.records) >= 5)
        said = [r.getMessage() for r in caplog.records]
        assert said[0].endswith("starting it again in 0.1 s"), said
        assert all("did not start" in m and "was deleted" in m for m in said[1:6]), said
        waits = [float(m.rsplit(" in ", 1)[1].removesuffix(" s")) for m in said[1:6]]
        assert waits == [0.2, 0.4, 0.8, 0.8, 0.8]  # doubled from the first, to the cap
        why = error_of(lambda: process.networks.get("mine"))
        assert why.startswith("the store process is down, restarting (its last start failed")
        assert "was deleted" in why
        changes: list[StoreProcessError | None] = []
        process.watch(changes.append)  # told at once how things stand, then each change
        assert changes and changes[0] is not None and "its last start failed" in str(changes[0])
        away.rename(database)
        wait_for(lambda: changes[-1] is None)
        assert process.down() is None
        assert process.networks.get("mine").description == "before the kill"
    finally:
        process.stop()


CHILD = textwrap.dedent(
    """
    import sys, time
    from server.persistence.process import StoreProcess

    process = StoreProcess(sys.argv[1])
    print(process.pid, flush=True)
    time.sleep(600)
    """
)


def test_the_store_process_exits_when_the_service_is_killed(
    migrated_sqlite: Path, tmp_path: Path
) -> None:
    path = tmp_path / "srlab.db"
    path.write_bytes(migrated_sqlite.read_bytes())
    with subprocess.Popen(
        [sys.executable, "-c", CHILD, f"sqlite:///{path}"],
        stdout=subprocess.PIPE,
        text=True,
        cwd=Path(__file__).resolve().parents[2],
    ) as service:
        try:
            assert service.stdout is not None
            store_pid = int(service.stdout.readline())
            assert not gone(store_pid)
            service.kill()
            service.wait(timeout=30)
            wait_until_gone(store_pid)
        finally:
            service.kill()


async def test_the_service_answers_503_and_fails_its_runs_when_the_store_process_dies(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(process_module, "RESTART_FIRST_S", 3600.0)  # down for the test
    settings = settings_for(
        tmp_path, store_process=True, reward_rate_per_s=1000.0, reward_burst=1000
    )
    async with client_for(settings) as (client, app):
        storage = app.state.srlab
        run = await create(client, condition="rp", mode="realtime", hz=50)
        assert (await client.post(f"/api/runs/{run['id']}/start")).status_code == 200
        ok = await client.post(f"/api/runs/{run['id']}/rewards", json={"value": 1})
        assert ok.status_code == 202
        pid = storage.store._owner.pid
        os.kill(pid, signal.SIGKILL)
        await asyncio.to_thread(wait_until_gone, pid)
        health = await client.get("/api/health")
        assert health.status_code == 503 and "store process" in health.json()["detail"]
        answers = [
            (await client.post(f"/api/runs/{run['id']}/rewards", json={"value": 1})).status_code
            for _ in range(3)
        ]
        assert 202 not in answers and set(answers) <= {409, 503}
        listed = await client.get("/api/runs")
        assert listed.status_code == 503 and "store process" in listed.json()["detail"]
        engine = storage.engines.get(run["id"])
        async with asyncio.timeout(30):
            while engine.status.value != "failed":
                await asyncio.sleep(0.02)
        assert "store process" in (engine.error or "")
