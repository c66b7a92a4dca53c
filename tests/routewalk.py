"""Helpers for tests that walk every API route: the routes, their paths filled, and a
study's participants each with a live run to walk them with."""

from __future__ import annotations

import re
from typing import Any

import httpx
from fastapi.routing import APIRoute

from server.config import Settings
from server.main import create_app


def study_body(name: str, **changes: Any) -> dict[str, Any]:
    """A study's creation body: one trainer condition, an hour each, a consent text."""
    return {
        "name": name,
        "conditions": ["trainer"],
        "budget": {"seconds": 3600},
        "consent_text": "You will train a simulated robot.",
    } | changes


def api_routes() -> list[tuple[str, str, frozenset[str]]]:
    """Every (method, path, tags) of the app's API, from the app itself."""
    app = create_app(Settings(viser=False))
    return [
        (method, route.path, frozenset(str(t) for t in route.tags))
        for route in app.routes
        if isinstance(route, APIRoute)
        for method in sorted(route.methods or set())
    ]


def fill(path: str, run_id: int) -> str:
    """`path` with `run_id` for its run, and a plausible value for any other parameter."""
    path = path.replace("{run_id}", str(run_id))
    return re.sub(r"\{[a-z_]+\}", "0", path)


async def consented_participants(
    client: httpx.AsyncClient, study: dict[str, Any], count: int
) -> dict[str, Any]:
    """Create `study`, invite `count` participants and consent each: their tokens and runs."""
    assert (await client.post("/api/studies", json=study)).status_code == 201
    r = await client.post(f"/api/studies/{study['name']}/participants", json={"count": count})
    tokens = [p["token"] for p in r.json()["data"]]
    runs = []
    for token in tokens:
        r = await client.post(
            "/api/participant/consent",
            json={"consent_version": study.get("consent_version", "1")},
            headers={"Authorization": f"Bearer {token}"},
        )
        assert r.status_code == 200, r.text
        runs.append(r.json()["run_id"])
    return {"tokens": tokens, "runs": runs}
