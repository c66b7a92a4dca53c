"""Strict request bodies: no coercion, no NaN, no duplicate keys, and every 422 names its field."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import pytest
from apphelpers import client_for, settings_for

pytestmark = pytest.mark.anyio


async def post_raw(client: httpx.AsyncClient, path: str, body: bytes) -> httpx.Response:
    return await client.post(path, content=body, headers={"content-type": "application/json"})


def locs(r: httpx.Response) -> list[list[Any]]:
    assert r.status_code == 422, r.text
    detail = r.json()["detail"]
    assert isinstance(detail, list) and detail
    return [e["loc"] for e in detail]


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"condition": "kp", "hz": "10"}, "hz"),  # a string is not a number
        ({"condition": "kp", "seed": True}, "seed"),  # a boolean is not an integer
        ({"condition": "kp", "episodes": True}, "episodes"),
        ({"condition": "kp", "hz": True}, "hz"),  # nor a number
        ({"condition": "kp", "seed": 1.5}, "seed"),
        ({"condition": "kp", "params": {"eta": "0.1"}}, "eta"),
    ],
)
async def test_values_are_not_coerced(tmp_path: Path, body: dict[str, Any], field: str) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post("/api/runs", json=body)
        assert any(loc[-1] == field for loc in locs(r)), r.text
        assert (await client.get("/api/runs")).json()["count"] == 0


@pytest.mark.parametrize(
    ("raw", "loc"),
    [
        (b'{"condition": "kp", "hz": NaN}', ["body", "hz"]),
        (b'{"condition": "kp", "hz": Infinity}', ["body", "hz"]),
        (b'{"condition": "kp", "params": {"eta": -Infinity}}', ["body", "params", "eta"]),
        (b'{"condition": "kp", "seed": 1, "seed": 2}', ["body", "seed"]),
        (b'{"condition": "kp", "network": "\\ud800"}', ["body", "network"]),
    ],
)
async def test_what_json_does_not_allow_is_a_422_naming_the_field(
    tmp_path: Path, raw: bytes, loc: list[str]
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await post_raw(client, "/api/runs", raw)
        assert loc in locs(r), r.text
        assert (await client.get("/api/runs")).json()["count"] == 0


async def test_a_strength_of_true_is_refused_and_an_integer_is_a_number(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        await client.post("/api/networks", json={"name": "mine"})
        cell = "/api/networks/mine/associations/Red/goforward1"
        r = await client.put(cell, json={"strength": True})
        assert ["body", "strength"] in locs(r)
        ok = await client.put(cell, json={"strength": 1})
        assert ok.status_code == 200 and ok.json()["strength"] == 1.0
        run = await client.post("/api/runs", json={"condition": "kp", "hz": 10})
        assert run.status_code == 201 and run.json()["hz"] == 10.0
