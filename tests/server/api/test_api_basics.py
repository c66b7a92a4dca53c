"""Health, catalogue, body limit, host check and auth on the real app."""

from __future__ import annotations

from collections.abc import AsyncIterator
from pathlib import Path

import pytest
from apphelpers import client_for, settings_for

pytestmark = pytest.mark.anyio


async def test_health_reports_the_database(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.get("/api/health")
    assert r.status_code == 200
    assert r.json()["status"] == "ok" and r.json()["database"] == "sqlite"


async def test_catalogue_lists_stimuli_behaviours_and_sensors(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        stimuli = (await client.get("/api/stimuli")).json()
        behaviours = (await client.get("/api/behaviours")).json()
        sensors = (await client.get("/api/sensors")).json()
    assert len(stimuli) == 25 and {"name": "Corner"}.items() <= stimuli[3].items()
    assert len(behaviours) == 21
    turn90 = next(b for b in behaviours if b["name"] == "leftturn90")
    assert turn90["motion"][2] == pytest.approx(1.5708, abs=1e-3)
    assert {s["name"] for s in sensors} >= {"camera_obstacle", "sonar_obstacle"}


async def test_a_body_over_64_kib_gets_413(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post(
            "/api/runs",
            content=b"{" + b" " * 70_000 + b"}",
            headers={"content-type": "application/json"},
        )
    assert r.status_code == 413
    assert "larger than the limit" in r.json()["detail"]


async def test_a_chunked_body_over_64_kib_gets_413_not_a_parse_error(tmp_path: Path) -> None:
    # No Content-Length: the limit trips while FastAPI reads the body, which FastAPI would
    # turn into 400 "error parsing the body".
    async def chunks() -> AsyncIterator[bytes]:
        for chunk in (b"{", b" " * 40_000, b" " * 40_000, b"}"):
            yield chunk

    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post(
            "/api/runs", content=chunks(), headers={"content-type": "application/json"}
        )
    assert r.status_code == 413
    assert "larger than the limit" in r.json()["detail"]


async def test_an_unknown_host_header_is_refused(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.get("/api/health", headers={"host": "evil.example"})
    assert r.status_code == 400


def test_serving_beyond_loopback_needs_a_token(tmp_path: Path) -> None:
    from server.main import create_app

    with pytest.raises(ValueError, match="SRLAB_TOKEN"):
        create_app(settings_for(tmp_path, host="0.0.0.0"))


async def test_the_lifespan_interrupts_running_runs_and_startup_marks_dead_ones(
    tmp_path: Path,
) -> None:
    from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker

    settings = settings_for(tmp_path)
    async with client_for(settings) as (client, _):
        run = (await client.post("/api/runs", json={"condition": "delayed", "mode": "realtime",
                                                    "hz": 100})).json()  # fmt: skip
        await client.post(f"/api/runs/{run['id']}/start")
        await client.get(f"/api/runs/{run['id']}")
    store = SqlAlchemyRunStore(make_sessionmaker(make_engine(settings.database_url)))
    assert store.load_run(run["id"]).status.value == "interrupted"
    # A process that died left a run "running": the next start marks it interrupted.
    from core.ports import RunStatus

    store.set_status(run["id"], RunStatus.RUNNING)
    async with client_for(settings) as (client, _):
        r = await client.get(f"/api/runs/{run['id']}")
        assert r.json()["status"] == "interrupted"
        again = await client.post(f"/api/runs/{run['id']}/start")
        assert again.status_code == 200 and again.json()["status"] == "running"
