"""A wrong method on an API path is a 405 with the API's `Allow`; no path is a JSON 404.

The methods come from the routes the OpenAPI document is made of, read without building
the document (server/api/methods.py).
"""

from __future__ import annotations

from pathlib import Path

import pytest
from apphelpers import client_for, settings_for
from fastapi.routing import APIRoute

from server.api import ROUTERS
from server.api.methods import operations, route_operations
from server.main import create_app

pytestmark = pytest.mark.anyio


def test_the_routes_give_the_openapi_documents_paths_and_methods(tmp_path: Path) -> None:
    app = create_app(settings_for(tmp_path))
    from_routes = {(p.pattern, m) for p, m in route_operations(app.routes)}
    from_document = {(p.pattern, m) for p, m in operations(app.openapi())}
    assert from_routes == from_document
    assert (r"/api/runs/[^/]+/rewards$", frozenset({"GET", "POST"})) in from_routes


async def test_a_wrong_method_names_the_paths_methods(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.delete("/api/runs")
        assert r.status_code == 405
        assert r.headers["allow"] == "GET, POST"
        assert r.json()["detail"] == "DELETE is not an operation of /api/runs: use GET, POST"
        r = await client.put("/api/runs/7/rewards")
        assert (r.status_code, r.headers["allow"]) == (405, "GET, POST")


async def test_no_api_path_is_a_json_404(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.get("/api/nothing")
        assert r.status_code == 404
        assert r.json()["detail"] == "no API path /api/nothing (see /openapi.json)"


async def test_api_requests_do_not_build_the_openapi_document(tmp_path: Path) -> None:
    """It costs about 1.5 s of CPU; a service builds it when someone asks for it."""
    async with client_for(settings_for(tmp_path)) as (client, app):
        assert (await client.get("/api/health")).status_code == 200
        assert (await client.delete("/api/runs")).status_code == 405
        assert app.openapi_schema is None
        assert (await client.get("/openapi.json")).status_code == 200
        assert app.openapi_schema is not None


def test_an_app_serves_the_resource_routers_routes_as_they_are(tmp_path: Path) -> None:
    """Each app holds the routers' own route objects, complete (prefix, errors, operation
    ids), so no app builds its routes again on its first request (server/api/routing.py)."""
    first, second = create_app(settings_for(tmp_path)), create_app(settings_for(tmp_path))
    api = [route for router in ROUTERS for route in router.routes]
    assert len(api) > 40
    for app in (first, second):
        held = [route for route in app.routes if isinstance(route, APIRoute)]
        assert [id(r) for r in held] == [id(r) for r in api]
    assert all(route.path.startswith("/api/") for route in api if isinstance(route, APIRoute))
    ids = {r.unique_id for r in api if isinstance(r, APIRoute)}
    assert {"injectReward", "createRun", "getRun"} <= ids
