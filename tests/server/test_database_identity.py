"""A database file deleted or replaced under the service: the run fails, health says so."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from apphelpers import client_for, create, settings_for, until

pytestmark = pytest.mark.anyio


@pytest.mark.parametrize("engines", ["local", pytest.param("process", marks=pytest.mark.slow)])
@pytest.mark.parametrize("fault", ["deleted", "replaced"])
async def test_a_lost_database_file_fails_the_run_and_health_and_no_reward_is_acked(
    tmp_path: Path, fault: str, engines: str
) -> None:
    settings = settings_for(tmp_path, reward_rate_per_s=1000.0, reward_burst=1000, engines=engines)
    database = tmp_path / "api.db"
    async with client_for(settings) as (client, _):
        run = await create(client, condition="rp", mode="realtime", hz=100)
        await client.post(f"/api/runs/{run['id']}/start")
        ok = await client.post(f"/api/runs/{run['id']}/rewards", json={"value": 1})
        assert ok.status_code == 202
        if fault == "deleted":
            database.unlink()
        else:
            other = tmp_path / "other.db"
            other.write_bytes(b"")
            os.replace(other, database)
        answers = [
            (await client.post(f"/api/runs/{run['id']}/rewards", json={"value": 1})).status_code
            for _ in range(3)
        ]
        assert 202 not in answers and set(answers) <= {409, 503}
        failed = await until(client, run["id"], "failed")
        assert failed["error"] and str(database) in failed["error"]
        assert ("deleted" if fault == "deleted" else "replaced") in failed["error"]
        health = await client.get("/api/health")
        assert health.status_code == 503 and str(database) in health.json()["detail"]
        late = await client.post(f"/api/runs/{run['id']}/rewards", json={"value": 1})
        assert late.status_code == 409
    if fault == "deleted":
        assert not database.exists()  # no pooled connection made an empty file in its place
