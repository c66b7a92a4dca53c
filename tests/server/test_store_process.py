"""The store process `srlab serve` runs: its errors, its death, and the service's death."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from apphelpers import client_for, create, settings_for

from core.errors import StorageError, UnknownRunError
from core.networks import Precondition, ReadOnlyNetworkError, StaleVersionError
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
        networks.delete("mine", expected=Precondition(version=99))
    assert stale.value.current == 1 and stale.value.etag


def test_sigint_leaves_the_store_process_serving(clean_store_process: StoreProcess) -> None:
    """Ctrl-C reaches the whole process group: the service stops the store after its writes."""
    os.kill(clean_store_process.pid, signal.SIGINT)
    time.sleep(0.2)
    assert clean_store_process.alive()
    assert clean_store_process.database.check() == "sqlite"


def test_a_dead_store_process_is_a_storage_error_that_says_so(
    migrated_sqlite: Path, tmp_path: Path
) -> None:
    path = tmp_path / "srlab.db"
    path.write_bytes(migrated_sqlite.read_bytes())
    process = StoreProcess(f"sqlite:///{path}")
    try:
        assert process.runs.list_runs() == []
        os.kill(process.pid, signal.SIGKILL)
        wait_until_gone(process.pid)
        with pytest.raises(StoreProcessError, match=f"store process \\({process.pid}\\) is gone"):
            process.runs.list_runs()
        assert issubclass(StoreProcessError, StorageError)
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
    tmp_path: Path,
) -> None:
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
