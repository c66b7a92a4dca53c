"""A participant's token reaches their own run and nothing else, on every route of the app.

The routes are walked from the app itself, so a route added later is checked too.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

import httpx
import pytest
from apphelpers import client_for, settings_for
from routewalk import api_routes, consented_participants, fill, study_body

from server.api.access import PARTICIPANT_TAGS

pytestmark = pytest.mark.anyio

STUDY = study_body("walk")


ROUTES = api_routes()
RUN_ROUTES = [(m, p) for m, p, _ in ROUTES if "{run_id}" in p]
OTHER_ROUTES = [
    (m, p)
    for m, p, tags in ROUTES
    if "{run_id}" not in p and not tags & PARTICIPANT_TAGS and (m, p) != ("GET", "/api/runs")
]


@pytest.fixture(scope="module")
def anyio_backend() -> str:
    return "asyncio"


@pytest.fixture(scope="module")
async def service(
    tmp_path_factory: pytest.TempPathFactory,
) -> AsyncIterator[tuple[httpx.AsyncClient, dict[str, Any]]]:
    """Two consented participants with a live run each, and the organiser's client."""
    settings = settings_for(tmp_path_factory.mktemp("walk"))
    async with client_for(settings) as (client, _):
        yield client, await consented_participants(client, STUDY, 2)


async def _stored(client: httpx.AsyncClient, run_id: int) -> tuple[Any, ...]:
    """What a foreign participant could change: the run, its log, the runs, the networks."""
    run = (await client.get(f"/api/runs/{run_id}")).json()
    return (
        run["status"],
        run["hz"],
        (await client.get(f"/api/runs/{run_id}/rewards")).json()["count"],
        (await client.get(f"/api/runs/{run_id}/network")).json(),
        (await client.get("/api/runs")).json()["count"],
        (await client.get("/api/networks")).json(),
        (await client.get("/api/studies/walk")).json()["progress"],
    )


def test_the_walk_finds_the_run_routes() -> None:
    paths = {p for _, p in RUN_ROUTES}
    assert {
        "/api/runs/{run_id}",
        "/api/runs/{run_id}/rewards",
        "/api/runs/{run_id}/events",
        "/api/runs/{run_id}/kp",
        "/api/runs/{run_id}/view",
        "/api/runs/{run_id}/stop",
        "/api/runs/{run_id}/episodes/{episode}",
    } <= paths
    assert ("POST", "/api/runs") in OTHER_ROUTES and ("GET", "/api/comparisons") in OTHER_ROUTES
    assert ("GET", "/api/runs/{run_id}/export") in RUN_ROUTES
    assert ("GET", "/api/studies/{name}/export") in OTHER_ROUTES


@pytest.mark.parametrize(("method", "path"), RUN_ROUTES)
async def test_a_run_route_refuses_a_foreign_participant_and_changes_nothing(
    service: tuple[httpx.AsyncClient, dict[str, Any]], method: str, path: str
) -> None:
    client, ctx = service
    foreign_run = ctx["runs"][1]
    before = await _stored(client, foreign_run)

    r = await client.request(
        method,
        fill(path, foreign_run),
        json={} if method in ("POST", "PUT", "PATCH") else None,
        headers={"Authorization": f"Bearer {ctx['tokens'][0]}"},
    )

    assert r.status_code == 403, r.text
    assert "own run" in r.json()["detail"] and f"run {foreign_run}" in r.json()["detail"]
    assert await _stored(client, foreign_run) == before


@pytest.mark.parametrize(("method", "path"), OTHER_ROUTES)
async def test_a_route_not_a_participants_refuses_their_token(
    service: tuple[httpx.AsyncClient, dict[str, Any]], method: str, path: str
) -> None:
    client, ctx = service
    before = await _stored(client, ctx["runs"][1])

    r = await client.request(
        method,
        fill(path, ctx["runs"][0]),
        json={} if method in ("POST", "PUT", "PATCH") else None,
        headers={"Authorization": f"Bearer {ctx['tokens'][0]}"},
    )

    assert r.status_code == 403, r.text
    assert await _stored(client, ctx["runs"][1]) == before


@pytest.mark.parametrize(
    "path", ["", "/world", "/ltm", "/rltm", "/network", "/episodes", "/rewards", "/kp"]
)
async def test_a_participant_reads_their_own_run(
    service: tuple[httpx.AsyncClient, dict[str, Any]], path: str
) -> None:
    client, ctx = service
    r = await client.get(
        f"/api/runs/{ctx['runs'][0]}{path}",
        headers={"Authorization": f"Bearer {ctx['tokens'][0]}"},
    )
    assert r.status_code == 200, r.text


@pytest.mark.parametrize("action", ["pause", "resume", "step", "stop", "view", "start"])
async def test_a_participant_may_not_control_their_own_run(
    service: tuple[httpx.AsyncClient, dict[str, Any]], action: str
) -> None:
    client, ctx = service
    run_id = ctx["runs"][0]

    r = await client.post(
        f"/api/runs/{run_id}/{action}", headers={"Authorization": f"Bearer {ctx['tokens'][0]}"}
    )

    assert r.status_code == 403 and "the organiser's" in r.json()["detail"]
    assert (await client.get(f"/api/runs/{run_id}")).json()["status"] == "running"


async def test_a_participant_may_not_export_their_own_run(
    service: tuple[httpx.AsyncClient, dict[str, Any]],
) -> None:
    client, ctx = service
    run_id = ctx["runs"][0]

    r = await client.get(
        f"/api/runs/{run_id}/export", headers={"Authorization": f"Bearer {ctx['tokens'][0]}"}
    )

    assert r.status_code == 403 and "the organiser's" in r.json()["detail"]
    assert (await client.get(f"/api/runs/{run_id}/export")).status_code == 200
