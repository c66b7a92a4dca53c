"""Strict request bodies: no coercion, no NaN, no duplicate keys, and every 422 names its field."""

from __future__ import annotations

import re
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from apphelpers import client_for, settings_for, started_realtime

from core.commands import RewardSource
from core.text import unstorable
from server.api.strictjson import MAX_DEPTH
from server.config import Settings
from server.main import create_app
from server.schemas import TEXT_PATTERN

pytestmark = pytest.mark.anyio
JSON = {"content-type": "application/json"}


async def post_raw(client: httpx.AsyncClient, path: str, body: bytes) -> httpx.Response:
    return await client.post(path, content=body, headers=JSON)


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
        # Numbers past what the fields' types hold:
        (b'{"condition": "kp", "hz": 1e400}', ["body", "hz"]),
        (b'{"condition": "kp", "params": {"eta": -1e400}}', ["body", "params", "eta"]),
        (b'{"condition": "kp", "seed": 1%s}' % (b"0" * 5000), ["body", "seed"]),
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


@pytest.fixture(params=["sqlite", "postgresql"])
def database(request: pytest.FixtureRequest, tmp_path: Path) -> Settings:
    """The service's settings on each supported database (PostgreSQL's: the module's)."""
    if request.param == "sqlite":
        return settings_for(tmp_path)
    request.getfixturevalue("postgres_engine")  # migrated and seeded
    url: str = request.getfixturevalue("postgres_database")
    return Settings(database_url=url, viser=False)


def unique(prefix: str) -> str:
    """A network name no earlier test on the module's database took."""
    return f"{prefix}-{uuid.uuid4().hex[:12]}"


async def test_a_note_no_database_stores_is_a_422_and_the_run_goes_on(database: Settings) -> None:
    async with client_for(database) as (client, app):
        run_id = await started_realtime(client)
        for note in ("a\x00b", "\x00"):
            r = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1, "note": note})
            assert ["body", "note"] in locs(r)
            assert "NUL (U+0000)" in r.text
        # The engine refuses such a note itself before queueing it, whoever sends it.
        live = app.state.srlab.engines.get(run_id)
        with pytest.raises(ValueError, match="cannot be stored"):
            await live.reward(1.0, note="a\x00b", source=RewardSource.TRAINER)
        ok = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1, "note": "é 😀"})
        assert ok.status_code == 202, ok.text
        assert (await client.get(f"/api/runs/{run_id}")).json()["status"] == "running"
        rewards = (await client.get(f"/api/runs/{run_id}/rewards")).json()
        assert [r["note"] for r in rewards["data"] if r["source"] == "trainer"] == ["é 😀"]
        assert (await client.post(f"/api/runs/{run_id}/stop")).status_code == 200


def text_fields(name: str) -> list[tuple[str, str, dict[str, Any], list[str | int]]]:
    """Each text a request takes, with NUL in it: method, path, request and the 422's loc."""
    document = {"format": "srlab-network/1", "name": name, "associations": []}
    return [
        ("POST", "/api/networks", {"json": {"name": name, "description": "a\x00"}},
         ["body", "description"]),
        ("POST", "/api/networks", {"json": {"name": name, "base": "dp\x00"}}, ["body", "base"]),
        ("POST", "/api/networks", {"json": {"name": name}, "params": {"note": "\x00"}},
         ["query", "note"]),
        ("POST", "/api/networks/import", {"json": {**document, "description": "\x00"}},
         ["body", "description"]),
        ("POST", "/api/networks/import", {"json": document, "params": {"note": "a\x00"}},
         ["query", "note"]),
        ("POST", "/api/runs", {"json": {"condition": "dp", "network": "dp\x00"}},
         ["body", "network"]),
        ("GET", f"/api/networks/{name}%00", {}, ["path", "name"]),
        ("GET", f"/api/networks/{name}%00/versions", {}, ["path", "name"]),
        ("PUT", "/api/networks/dp/associations/Red%00/stop", {"json": {"strength": 1}},
         ["path", "stimulus"]),
        ("DELETE", "/api/networks/dp/associations/Red/stop%00", {}, ["path", "behaviour"]),
    ]  # fmt: skip


async def test_nul_in_any_text_a_request_takes_is_a_422_naming_it(database: Settings) -> None:
    name = unique("nul")
    async with client_for(database) as (client, _):
        runs = (await client.get("/api/runs")).json()["count"]
        for method, path, request, loc in text_fields(name):
            r = await client.request(method, path, **request)
            assert loc in locs(r), (method, path, r.text)
        # A lone surrogate (escaped in JSON) is no text either.
        raw = b'{"name": "%s", "description": "\\udfff"}' % name.encode()
        assert ["body", "description"] in locs(await post_raw(client, "/api/networks", raw))
        assert (await client.get(f"/api/networks/{name}")).status_code == 404
        assert (await client.get("/api/runs")).json()["count"] == runs


def string_schemas(
    schema: Any, where: str, components: dict[str, Any], seen: set[str]
) -> Iterator[tuple[str, dict[str, Any]]]:
    """Every string schema under `schema`, references followed, but those an enum closes."""
    if isinstance(schema, dict):
        ref = schema.get("$ref", "").rsplit("/", 1)[-1]
        if ref and ref not in seen:
            seen.add(ref)
            yield from string_schemas(components[ref], ref, components, seen)
        if {"enum", "const"} & schema.keys():
            return
        if schema.get("type") == "string":
            yield where, schema
        for key, value in schema.items():
            yield from string_schemas(value, f"{where}.{key}", components, seen)
    elif isinstance(schema, list):
        for i, value in enumerate(schema):
            yield from string_schemas(value, f"{where}[{i}]", components, seen)


async def test_every_string_a_request_takes_declares_what_it_may_hold(tmp_path: Path) -> None:
    """A string parameter or body field without the rule fails here (`Text`, `Strict`)."""
    doc = create_app(settings_for(tmp_path)).openapi()
    components = doc["components"]["schemas"]
    seen: set[str] = set()
    strings: list[tuple[str, dict[str, Any]]] = []
    for path, item in doc["paths"].items():
        for method, op in item.items():
            for p in op.get("parameters", ()):
                at = f"{method} {path} {p['in']} {p['name']}"
                strings += string_schemas(p["schema"], at, components, seen)
            body = op.get("requestBody", {}).get("content", {}).get("application/json")
            if body:
                strings += string_schemas(body["schema"], f"{method} {path}", components, seen)
    assert len(strings) >= 15
    nul = [where for where, s in strings if re.search(s.get("pattern", ""), "a\x00b")]
    assert nul == [], "strings that would take NUL"
    assert re.search(TEXT_PATTERN, "é 😀\x01\uffff") and not re.search(TEXT_PATTERN, "a\x00")
    assert unstorable("é 😀\x01\uffff") is None and unstorable("a\x00") is not None


def nested(depth: int) -> bytes:
    return b"[" * depth + b"]" * depth


async def test_json_nested_a_thousand_deep_is_a_422_on_every_json_route(tmp_path: Path) -> None:
    values = {"run_id": "1", "name": "dp", "stimulus": "Red", "behaviour": "stop", "version": "1"}
    async with client_for(settings_for(tmp_path)) as (client, app):
        routes = [
            (method.upper(), path.format(**values))
            for path, item in app.openapi()["paths"].items()
            for method, op in item.items()
            if "requestBody" in op
        ]
        assert len(routes) >= 8
        for method, path in routes:
            for depth in (1000, 100_000 // 2):  # 2 KB and 100 KB: over the body limit
                body = nested(depth)
                r = await client.request(method, path, content=body, headers=JSON)
                if len(body) > 64 * 1024:
                    assert r.status_code == 413, (method, path, r.text)
                    continue
                assert r.status_code == 422, (method, path, r.text)
                assert "levels deep" in r.text, r.text
        # MAX_DEPTH levels are read (and refused by the schema: a body is an object).
        r = await post_raw(client, "/api/runs", nested(MAX_DEPTH))
        assert r.status_code == 422 and "levels deep" not in r.text
        r = await post_raw(client, "/api/runs", nested(MAX_DEPTH + 1))
        assert r.status_code == 422 and "levels deep" in r.text
