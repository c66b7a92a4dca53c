"""The composition root: the service built over other storage, here the in-memory fakes."""

from __future__ import annotations

import pytest
from apphelpers import client_for, create, until
from fakes import InMemoryNetworkRepository, InMemoryRunStore

from core.ports import RunStatus
from core.run.setup import Setup
from server.config import Settings
from server.persistence.storage import Storage

pytestmark = pytest.mark.anyio


class MemoryProbe:
    """Health's question to storage, answered by memory."""

    def check(self) -> str:
        return "memory"


async def test_the_api_and_its_runs_work_over_the_in_memory_fakes() -> None:
    catalog = Setup().catalog()
    runs, networks = InMemoryRunStore(catalog), InMemoryNetworkRepository(catalog)
    closed: list[bool] = []

    def storage(_: Settings) -> Storage:
        return Storage(runs, networks, MemoryProbe(), lambda: closed.append(True))

    # No database at all: the URL names a file that is never opened.
    settings = Settings(database_url="sqlite:////nonexistent/never-opened.db", viser=False)
    async with client_for(settings, storage=storage) as (client, _):
        health = await client.get("/api/health")
        assert health.status_code == 200 and health.json()["database"] == "memory"
        run = await create(client, condition="rp", mode="fast", episodes=3, seed=4)
        assert (await client.post(f"/api/runs/{run['id']}/start")).status_code == 200
        done = await until(client, run["id"], "finished")
        assert done["episodes_done"] == 3
        page = (await client.get(f"/api/runs/{run['id']}/episodes?limit=2")).json()
        assert page["count"] == 3 and [e["episode"] for e in page["data"]] == [0, 1]
        one = await client.get(f"/api/runs/{run['id']}/episodes/2")
        assert one.status_code == 200 and one.json()["ticks"] > 0
        rewards = (await client.get(f"/api/runs/{run['id']}/rewards")).json()
        assert rewards["count"] == len(runs.rewards(run["id"])) > 0
        names = {n["name"] for n in (await client.get("/api/networks")).json()["data"]}
        assert set(catalog.knowledge) <= names
        copy = await client.post("/api/networks", json={"name": "mine", "base": "dp"})
        assert copy.status_code == 201
        assert networks.get("mine").version == 1
        assert not closed
    assert closed == [True]
    assert runs.run_summary(run["id"]).status is RunStatus.FINISHED
