"""The DP S-R editor's API, a network's history: versions, diffs, reverts, export and import."""

from __future__ import annotations

from typing import Any

import httpx
import networkapihelpers
import pytest
from networkapihelpers import A, make, pairs

pytestmark = pytest.mark.anyio

client = networkapihelpers.client
"""A client on a fresh service (a fixture)."""


async def test_versions_record_every_change(client: httpx.AsyncClient) -> None:
    await make(client)
    await client.put(f"{A}/mine/associations/Red/stop", json={"strength": 0.6})
    await client.put(
        f"{A}/mine/associations/Red/stop", params={"note": "softer"}, json={"strength": 0.4}
    )
    await client.delete(f"{A}/mine/associations/Corner/leftturn90")

    r = await client.get(f"{A}/mine/versions")
    assert r.status_code == 200
    history = r.json()
    assert history["count"] == 4
    assert [(v["version"], v["association_count"]) for v in history["data"]] == [
        (1, 4),
        (2, 5),
        (3, 5),
        (4, 4),
    ]
    assert history["data"][0]["note"] == "created from innate"
    assert history["data"][1]["note"] == "added Red -> stop"
    assert history["data"][2]["note"] == "softer"


async def test_versions_of_a_builtin_network_start_at_the_seed(client: httpx.AsyncClient) -> None:
    r = await client.get(f"{A}/kp/versions")
    assert r.status_code == 200
    assert [v["version"] for v in r.json()["data"]] == [1]
    assert (await client.get(f"{A}/nope/versions")).status_code == 404


async def test_get_version_gives_the_snapshot(client: httpx.AsyncClient) -> None:
    await make(client)
    await client.put(f"{A}/mine/associations/Red/stop", json={"strength": 0.6})

    v1 = (await client.get(f"{A}/mine/versions/1")).json()
    v2 = (await client.get(f"{A}/mine/versions/2")).json()
    assert v1["version"] == 1 and v1["association_count"] == 4
    assert ("Red", "stop") not in pairs(v1) and pairs(v2)["Red", "stop"]["strength"] == 0.6
    for bad in ("3", "0", "x"):
        r = await client.get(f"{A}/mine/versions/{bad}")
        assert r.status_code == (404 if bad == "3" else 422)
    assert "no version 3" in (await client.get(f"{A}/mine/versions/3")).json()["detail"]


async def test_diff_between_versions(client: httpx.AsyncClient) -> None:
    await make(client)
    await client.put(f"{A}/mine/associations/Red/stop", json={"strength": 0.6})
    await client.put(f"{A}/mine/associations/Corner/leftturn90", json={"strength": 0.2})
    await client.delete(f"{A}/mine/associations/Collision/back")

    r = await client.get(f"{A}/mine/diff", params={"from": 1, "to": 4})
    assert r.status_code == 200
    d = r.json()
    assert (d["from_version"], d["to_version"]) == (1, 4)
    assert [(a["stimulus"], a["behaviour"]) for a in d["added"]] == [("Red", "stop")]
    assert [(a["stimulus"], a["behaviour"]) for a in d["removed"]] == [("Collision", "back")]
    assert len(d["changed"]) == 1
    change = d["changed"][0]
    assert change["before"]["strength"] == 1.0 and change["after"]["strength"] == 0.2

    last = (await client.get(f"{A}/mine/diff")).json()
    assert (last["from_version"], last["to_version"]) == (3, 4)
    assert len(last["removed"]) == 1 and not last["added"] and not last["changed"]
    back = (await client.get(f"{A}/mine/diff", params={"from": 4, "to": 1})).json()
    assert len(back["removed"]) == 1 and len(back["added"]) == 1


async def test_diff_unknown_version_or_network(client: httpx.AsyncClient) -> None:
    await make(client)
    assert (await client.get(f"{A}/mine/diff", params={"from": 1, "to": 9})).status_code == 404
    assert (await client.get(f"{A}/mine/diff", params={"from": 0})).status_code == 422
    assert (await client.get(f"{A}/nope/diff")).status_code == 404


async def test_revert_makes_an_old_version_current_as_a_new_one(
    client: httpx.AsyncClient,
) -> None:
    first = await make(client)
    await client.put(f"{A}/mine/associations/Red/stop", json={"strength": 0.6})
    await client.delete(f"{A}/mine/associations/Corner/leftturn90")

    r = await client.post(f"{A}/mine/revert", json={"version": 1})
    assert r.status_code == 200
    body = r.json()
    assert body["version"] == 4 and body["live_runs"] == []
    assert pairs(body) == pairs(first)
    history = (await client.get(f"{A}/mine/versions")).json()["data"]
    assert history[-1]["note"] == "reverted to version 1"


async def test_revert_refusals(client: httpx.AsyncClient) -> None:
    await make(client)
    assert (await client.post(f"{A}/mine/revert", json={"version": 7})).status_code == 404
    assert (await client.post(f"{A}/mine/revert", json={"version": 0})).status_code == 422
    assert (await client.post(f"{A}/mine/revert", json={})).status_code == 422
    assert (await client.post(f"{A}/nope/revert", json={"version": 1})).status_code == 404

    await client.put(f"{A}/mine/associations/Corner/leftturn90", json={"locked": True})
    refused = await client.post(f"{A}/mine/revert", json={"version": 1})
    assert refused.status_code == 409 and "locked" in refused.json()["detail"]
    forced = await client.post(f"{A}/mine/revert", params={"force": True}, json={"version": 1})
    assert forced.status_code == 200
    assert pairs(forced.json())["Corner", "leftturn90"]["locked"] is False


# --- export / import ----------------------------------------------------------------------


async def test_export_then_import_under_another_name(client: httpx.AsyncClient) -> None:
    await make(
        client,
        base="dp",
        description="tuned",
        associations=[
            {"stimulus": "Red", "behaviour": "stop", "strength": 0.9, "locked": True},
        ],
    )
    r = await client.get(f"{A}/mine/export")
    assert r.status_code == 200
    assert r.headers["content-disposition"] == 'attachment; filename="mine.json"'
    doc = r.json()
    assert doc["format"] == "srlab-network/1" and doc["name"] == "mine"
    assert doc["description"] == "tuned"

    imported = await client.post(f"{A}/import", params={"name": "copy"}, json=doc)
    assert imported.status_code == 201
    original = (await client.get(f"{A}/mine")).json()
    copy = (await client.get(f"{A}/copy")).json()
    assert copy["associations"] == original["associations"]
    assert copy["description"] == "tuned" and copy["builtin"] is False and copy["version"] == 1
    assert (await client.get(f"{A}/copy/versions")).json()["data"][0]["note"] == "imported"


async def test_export_a_builtin_network_and_import_it_as_a_new_one(
    client: httpx.AsyncClient,
) -> None:
    doc = (await client.get(f"{A}/expert/export")).json()
    doc["name"] = "expert-2"
    r = await client.post(f"{A}/import", json=doc)
    assert r.status_code == 201 and r.json()["name"] == "expert-2"
    assert len(r.json()["associations"]) == len(doc["associations"])
    assert (await client.get(f"{A}/nope/export")).status_code == 404


async def test_import_refuses_a_taken_name_unless_replacing(client: httpx.AsyncClient) -> None:
    await make(client)
    doc = (await client.get(f"{A}/mine/export")).json()
    doc["associations"] = [{"stimulus": "Red", "behaviour": "stop"}]
    doc["description"] = "replaced"

    taken = await client.post(f"{A}/import", json=doc)
    assert taken.status_code == 409 and "replace=true" in taken.json()["detail"]
    replaced = await client.post(f"{A}/import", params={"replace": True}, json=doc)
    assert replaced.status_code == 200
    assert replaced.json()["version"] == 2 and replaced.json()["description"] == "replaced"
    assert list(pairs(replaced.json())) == [("Red", "stop")]

    doc["name"] = "dp"
    builtin = await client.post(f"{A}/import", params={"replace": True}, json=doc)
    assert builtin.status_code == 409 and "built in" in builtin.json()["detail"]


@pytest.mark.parametrize(
    ("change", "loc"),
    [
        ({"format": "srlab-network/2"}, ["body", "format"]),
        ({"format": None}, ["body", "format"]),
        ({"name": "has space"}, ["body", "name"]),
        ({"associations": [{"stimulus": "Red"}]}, ["body", "associations", 0, "behaviour"]),
        (
            {"associations": [{"stimulus": "X", "behaviour": "stop"}]},
            ["body", "associations", 0, "stimulus"],
        ),
        ({"extra": 1}, ["body", "extra"]),
    ],
)
async def test_import_names_what_is_wrong_with_the_document(
    client: httpx.AsyncClient, change: dict[str, Any], loc: list[Any]
) -> None:
    doc = (await client.get(f"{A}/innate/export")).json() | {"name": "fresh"} | change
    r = await client.post(f"{A}/import", json=doc)
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == loc
    assert (await client.get(f"{A}/fresh")).status_code == 404


async def test_import_under_a_bad_query_name_is_422(client: httpx.AsyncClient) -> None:
    doc = (await client.get(f"{A}/innate/export")).json()
    r = await client.post(f"{A}/import", params={"name": "no way"}, json=doc)
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "name"]


async def test_versions_are_read_a_page_at_a_time(client: httpx.AsyncClient) -> None:
    await make(client)
    for strength in (0.1, 0.2, 0.3):
        r = await client.put(f"{A}/mine/associations/Red/stop", json={"strength": strength})
        assert r.status_code == 200, r.text
    page = (await client.get(f"{A}/mine/versions", params={"offset": 1, "limit": 2})).json()
    assert page["count"] == 4 and [v["version"] for v in page["data"]] == [2, 3]
    r = await client.get(f"{A}/mine/versions", params={"limit": 1001})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "limit"]
