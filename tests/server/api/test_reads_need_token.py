"""`SRLAB_READS=token`: every API route but the health check needs the organiser's token or
a participant's (401 without), each participant their own run only (403), event streams
included.

The routes are walked from the app itself, so a route added later is checked too.
"""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

import httpx
import pytest
from apphelpers import client_for, settings_for
from routewalk import api_routes, consented_participants, fill, study_body

from server.api.access import OPEN_TAGS
from server.config import Settings

pytestmark = pytest.mark.anyio
TOKEN = "organiser-s3cret"
STUDY = study_body("closed")


ROUTES = api_routes()
CLOSED = [(m, p) for m, p, tags in ROUTES if not tags & OPEN_TAGS]
READS = [(m, p) for m, p in CLOSED if m == "GET"]
RUN_READS = [(m, p) for m, p in READS if "{run_id}" in p]


@pytest.fixture(scope="module")
def anyio_backend() -> str:
    return "asyncio"


@pytest.fixture(scope="module")
async def service(
    tmp_path_factory: pytest.TempPathFactory,
) -> AsyncIterator[tuple[httpx.AsyncClient, dict[str, Any]]]:
    """Two consented participants with a live run each, and the organiser's client."""
    settings = settings_for(tmp_path_factory.mktemp("closed"), token=TOKEN, reads="token")
    async with client_for(settings, {"Authorization": f"Bearer {TOKEN}"}) as (client, _):
        yield client, await consented_participants(client, STUDY, 2)


def test_the_walk_finds_the_reads() -> None:
    paths = {p for _, p in READS}
    assert {
        "/api/runs",
        "/api/runs/{run_id}",
        "/api/runs/{run_id}/events",
        "/api/runs/{run_id}/rewards",
        "/api/studies",
        "/api/participant",
        "/api/networks",
    } <= paths
    assert ("GET", "/api/health") not in CLOSED


@pytest.mark.parametrize(("method", "path"), CLOSED)
async def test_without_a_token_every_route_but_health_is_401(
    service: tuple[httpx.AsyncClient, dict[str, Any]], method: str, path: str
) -> None:
    client, ctx = service
    r = await client.request(
        method,
        fill(path, ctx["runs"][0]),
        json={} if method in ("POST", "PUT", "PATCH") else None,
        headers={"Authorization": ""},
    )
    assert r.status_code == 401, r.text
    assert r.headers["www-authenticate"] == "Bearer"


@pytest.mark.parametrize("token", ["", "Bearer not-the-token"])
async def test_the_health_check_stays_open(
    service: tuple[httpx.AsyncClient, dict[str, Any]], token: str
) -> None:
    client, _ = service
    r = await client.get("/api/health", headers={"Authorization": token})
    assert r.status_code == 200 and r.json()["status"] == "ok"


@pytest.mark.parametrize(("method", "path"), [r for r in READS if not r[1].endswith("/events")])
async def test_the_organisers_token_reads_everything(
    service: tuple[httpx.AsyncClient, dict[str, Any]], method: str, path: str
) -> None:
    client, ctx = service
    r = await client.request(method, fill(path, ctx["runs"][0]))
    # The organiser is never refused; a placeholder may name nothing (404), and the
    # participant's own route asks for a participant (401 naming it).
    assert r.status_code not in (403,), r.text
    if r.status_code == 401:
        assert path == "/api/participant" and "participant's token" in r.json()["detail"]


@pytest.mark.parametrize(("method", "path"), RUN_READS)
async def test_a_participant_reads_no_other_run_events_included(
    service: tuple[httpx.AsyncClient, dict[str, Any]], method: str, path: str
) -> None:
    client, ctx = service
    foreign = ctx["runs"][1]
    r = await client.request(
        method,
        fill(path, foreign),
        headers={"Authorization": f"Bearer {ctx['tokens'][0]}"},
    )
    assert r.status_code == 403, r.text
    assert f"run {foreign}" in r.json()["detail"]


@pytest.mark.parametrize(
    "path",
    [
        "/api/runs/{run}",
        "/api/runs/{run}/world",
        "/api/runs/{run}/rewards",
        "/api/runs/{run}/kp",
        "/api/runs",
        "/api/participant",
        "/api/conditions",
    ],
)
async def test_a_participant_reads_their_own_run_and_study(
    service: tuple[httpx.AsyncClient, dict[str, Any]], path: str
) -> None:
    client, ctx = service
    r = await client.get(
        path.format(run=ctx["runs"][0]),
        headers={"Authorization": f"Bearer {ctx['tokens'][0]}"},
    )
    assert r.status_code == 200, r.text


def test_reads_default_to_open() -> None:
    assert Settings().reads == "open"
    assert Settings(reads="token").reads == "token"
