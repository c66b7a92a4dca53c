"""A long day bounded: paged reads that read only their page, capped streams, a stop that
answers once the run has stopped, and a database file that went away noticed."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest
from apphelpers import client_for, create, settings_for, until
from fastapi import FastAPI
from sqlalchemy import event

pytestmark = pytest.mark.anyio


@contextmanager
def statements(app: FastAPI) -> Iterator[list[str]]:
    """The SQL the app's database engine runs inside the block."""
    seen: list[str] = []
    bind = app.state.srlab.database.engine

    def record(_conn: Any, _cursor: Any, sql: str, *_: Any) -> None:
        seen.append(" ".join(sql.split()).lower())

    event.listen(bind, "before_cursor_execute", record)
    try:
        yield seen
    finally:
        event.remove(bind, "before_cursor_execute", record)


async def test_episodes_are_paged_and_read_without_traces(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        run = await create(client, condition="innate", episodes=5, seed=4)
        await client.post(f"/api/runs/{run['id']}/start")
        await until(client, run["id"], "finished")
        with statements(app) as sql:
            page = (await client.get(f"/api/runs/{run['id']}/episodes?offset=1&limit=2")).json()
        assert page["count"] == 5
        assert [e["episode"] for e in page["data"]] == [1, 2]
        assert not any("trace" in s for s in sql)  # a list never reads a trace
        with statements(app) as sql:
            missing = await client.get(f"/api/runs/{run['id']}/episodes/99")
        assert missing.status_code == 404 and "no episode 99" in missing.json()["detail"]
        traces = [s for s in sql if "trace" in s]
        assert traces and all("episodes.episode =" in s for s in traces)  # one row by key
        one = (await client.get(f"/api/runs/{run['id']}/episodes/3")).json()
        assert one["episode"] == 3 and one["trace"]
        for bad in ("limit=0", "limit=1001", "offset=-1", "limit=ten"):
            r = await client.get(f"/api/runs/{run['id']}/episodes?{bad}")
            assert r.status_code == 422, bad
            assert r.json()["detail"][0]["loc"][-1] in ("limit", "offset")


async def test_runs_are_listed_a_page_at_a_time(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        ids = [(await create(client, condition="innate", seed=s))["id"] for s in range(5)]
        first = (await client.get("/api/runs?limit=2")).json()
        rest = (await client.get("/api/runs?offset=2&limit=1000")).json()
        assert first["count"] == rest["count"] == 5
        assert [r["id"] for r in first["data"] + rest["data"]] == ids
        with statements(app) as sql:
            await client.get(f"/api/runs/{ids[0]}")
        # A stored run's state comes from its row: no checkpoint blob, no log read.
        assert not any("rewards" in s or "run_commands" in s for s in sql)
        assert (await client.get("/api/runs?limit=1001")).status_code == 422


async def test_stop_answers_once_the_run_has_stopped(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        run = await create(client, condition="delayed", mode="realtime", hz=0.5)
        await client.post(f"/api/runs/{run['id']}/start")
        r = await client.post(f"/api/runs/{run['id']}/stop")
        assert r.status_code == 200, r.text
        assert r.json()["status"] == "stopped" and r.json()["live"] is None
        assert app.state.srlab.engines.get(run["id"]) is None  # its state is stored
        again = await client.post(f"/api/runs/{run['id']}/stop")
        assert again.status_code == 409 and "not running" in again.json()["detail"]
        # A paused run stops as well, and answers the same way.
        await client.post(f"/api/runs/{run['id']}/start")
        await client.post(f"/api/runs/{run['id']}/pause")
        paused = await client.post(f"/api/runs/{run['id']}/stop")
        assert (paused.status_code, paused.json()["status"]) == (200, "stopped")
