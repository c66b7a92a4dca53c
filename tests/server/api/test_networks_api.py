"""The DP S-R editor's API: networks, associations, locks, history, export/import, live edits."""

from __future__ import annotations

import asyncio
from typing import Any

import httpx
import networkapihelpers
import pytest
from networkapihelpers import A, make, pairs

from core.brain.catalog import load_catalog
from server.api.routes import networks as networks_routes

pytestmark = pytest.mark.anyio

client = networkapihelpers.client
"""A client on a fresh service (a fixture)."""


async def test_list_networks_shows_the_builtin_ones(client: httpx.AsyncClient) -> None:
    r = await client.get(A)
    assert r.status_code == 200
    body = r.json()
    shipped = load_catalog().knowledge  # innate, position, kp, signal, dp, expert, variants
    assert body["count"] == len(shipped) == len(body["data"])
    assert {n["name"] for n in body["data"]} == set(shipped)
    innate = next(n for n in body["data"] if n["name"] == "innate")
    assert innate["builtin"] is True and innate["version"] == 1
    assert innate["association_count"] == 4
    assert innate["updated_at"].endswith(("Z", "+00:00"))


async def test_create_network_copies_innate_by_default(client: httpx.AsyncClient) -> None:
    created = await make(client, "my-net_1", description="mine")
    innate = (await client.get(f"{A}/innate")).json()

    assert created["name"] == "my-net_1" and created["builtin"] is False
    assert created["version"] == 1 and created["description"] == "mine"
    assert pairs(created) == pairs(innate)
    listed = {n["name"] for n in (await client.get(A)).json()["data"]}
    assert "my-net_1" in listed


async def test_create_network_from_a_base_with_associations_over_it(
    client: httpx.AsyncClient,
) -> None:
    created = await make(
        client,
        base="dp",
        associations=[{"stimulus": "Corner", "behaviour": "leftturn90", "strength": 0.5}],
    )
    dp = (await client.get(f"{A}/dp")).json()

    assert len(created["associations"]) == len(dp["associations"])
    assert pairs(created)["Corner", "leftturn90"]["strength"] == 0.5
    assert pairs(created)["Corner", "leftturn90"]["source"] == "dp"


async def test_create_network_empty_with_a_null_base(client: httpx.AsyncClient) -> None:
    created = await make(client, base=None)
    assert created["associations"] == [] and created["association_count"] == 0


async def test_create_network_refuses_a_taken_name(client: httpx.AsyncClient) -> None:
    await make(client)
    for name in ("mine", "innate"):
        r = await client.post(A, json={"name": name})
        assert r.status_code == 409
        assert "exists already" in r.json()["detail"]


@pytest.mark.parametrize("name", ["", "has space", "a/b", "ü", "x" * 65, "semi;colon"])
async def test_create_network_refuses_a_bad_name(client: httpx.AsyncClient, name: str) -> None:
    r = await client.post(A, json={"name": name})
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "name"]


async def test_create_network_unknown_base_is_404(client: httpx.AsyncClient) -> None:
    r = await client.post(A, json={"name": "mine", "base": "nope"})
    assert r.status_code == 404
    assert "nope" in r.json()["detail"]


async def test_create_network_names_the_bad_field_in_its_associations(
    client: httpx.AsyncClient,
) -> None:
    good = {"stimulus": "Red", "behaviour": "stop"}
    bad = [good, {"stimulus": "Purple", "behaviour": "stop"}, {"stimulus": "Red", "behaviour": "x"}]
    r = await client.post(A, json={"name": "mine", "associations": bad})
    assert r.status_code == 422
    errors = r.json()["detail"]
    assert [e["loc"] for e in errors] == [
        ["body", "associations", 1, "stimulus"],
        ["body", "associations", 2, "behaviour"],
    ]
    assert errors[0]["msg"] == "unknown stimulus 'Purple'"
    assert (await client.get(f"{A}/mine")).status_code == 404


async def test_create_network_a_later_association_of_a_pair_wins(
    client: httpx.AsyncClient,
) -> None:
    twice = [
        {"stimulus": "Red", "behaviour": "stop", "strength": 0.2},
        {"stimulus": "Red", "behaviour": "stop", "strength": 0.9},
    ]
    created = await make(client, base=None, associations=twice)
    assert [a["strength"] for a in created["associations"]] == [0.9]


async def test_the_schema_lists_the_known_names(client: httpx.AsyncClient) -> None:
    schema = (await client.get("/openapi.json")).json()["components"]["schemas"]
    props = schema["AssociationCreate"]["properties"]
    stimuli = [s["name"] for s in (await client.get("/api/stimuli")).json()]
    behaviours = [b["name"] for b in (await client.get("/api/behaviours")).json()]
    assert props["stimulus"]["enum"] == stimuli and props["behaviour"]["enum"] == behaviours


@pytest.mark.parametrize(
    "extra",
    [{"strength": 1.5}, {"strength": -0.1}, {"source": "magic"}, {"colour": "red"}],
)
async def test_create_network_refuses_invalid_association_values(
    client: httpx.AsyncClient, extra: dict[str, Any]
) -> None:
    a = {"stimulus": "Red", "behaviour": "stop", **extra}
    r = await client.post(A, json={"name": "mine", "associations": [a]})
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"][:3] == ["body", "associations", 0]


async def test_get_network_has_its_associations(client: httpx.AsyncClient) -> None:
    r = await client.get(f"{A}/innate")
    assert r.status_code == 200
    body = r.json()
    assert body["version"] == 1 and body["association_count"] == 4
    assert {
        "stimulus": "Corner",
        "behaviour": "leftturn90",
        "strength": 1.0,
        "source": "innate",
        "locked": False,
    } in body["associations"]
    order = [s["name"] for s in (await client.get("/api/stimuli")).json()]
    positions = [order.index(a["stimulus"]) for a in body["associations"]]
    assert positions == sorted(positions)  # catalogue order, as the editor's matrix


async def test_get_network_unknown_is_404(client: httpx.AsyncClient) -> None:
    r = await client.get(f"{A}/nope")
    assert r.status_code == 404
    assert r.json() == {"detail": "unknown network 'nope'"}


async def test_delete_network_removes_it(client: httpx.AsyncClient) -> None:
    await make(client)
    r = await client.delete(f"{A}/mine")
    assert r.status_code == 204 and r.content == b""
    assert (await client.get(f"{A}/mine")).status_code == 404
    assert (await client.delete(f"{A}/mine")).status_code == 404


@pytest.mark.parametrize("name", ["innate", "dp", "kp", "expert"])
async def test_delete_network_refuses_a_builtin_one(client: httpx.AsyncClient, name: str) -> None:
    r = await client.delete(f"{A}/{name}")
    assert r.status_code == 409
    assert "built in" in r.json()["detail"] and '"base": ' in r.json()["detail"]
    assert (await client.get(f"{A}/{name}")).status_code == 200


async def test_builtin_networks_are_read_only(client: httpx.AsyncClient) -> None:
    writes = [
        client.post(f"{A}/dp/associations", json={"stimulus": "Red", "behaviour": "back"}),
        client.put(f"{A}/dp/associations/Red/stop", json={"strength": 0.2}),
        client.delete(f"{A}/dp/associations/Red/stop"),
        client.post(f"{A}/dp/revert", json={"version": 1}),
    ]
    for response in await asyncio.gather(*writes):
        assert response.status_code == 409, response.text
        assert "copy it first" in response.json()["detail"]
    assert (await client.get(f"{A}/dp")).json()["version"] == 1


# --- associations ----------------------------------------------------------------------


async def test_list_associations(client: httpx.AsyncClient) -> None:
    r = await client.get(f"{A}/innate/associations")
    assert r.status_code == 200
    body = r.json()
    assert body["count"] == 4 == len(body["data"]) and body["version"] == 1
    assert (await client.get(f"{A}/nope/associations")).status_code == 404


async def test_add_association(client: httpx.AsyncClient) -> None:
    await make(client)
    r = await client.post(f"{A}/mine/associations", json={"stimulus": "Red", "behaviour": "stop"})
    assert r.status_code == 201
    assert r.json() == {
        "stimulus": "Red",
        "behaviour": "stop",
        "strength": 1.0,
        "source": "dp",
        "locked": False,
        "network": "mine",
        "version": 2,
        "live_runs": [],
    }
    assert ("Red", "stop") in pairs((await client.get(f"{A}/mine")).json())


async def test_add_association_refuses_an_existing_pair(client: httpx.AsyncClient) -> None:
    await make(client)
    body = {"stimulus": "Corner", "behaviour": "leftturn90", "strength": 0.1}
    r = await client.post(f"{A}/mine/associations", json=body)
    assert r.status_code == 409 and "PUT" in r.json()["detail"]
    assert (await client.get(f"{A}/mine")).json()["version"] == 1


async def test_add_association_names_unknown_names_as_422(client: httpx.AsyncClient) -> None:
    await make(client)
    r = await client.post(f"{A}/mine/associations", json={"stimulus": "Purple", "behaviour": "fly"})
    assert r.status_code == 422
    locs = [e["loc"] for e in r.json()["detail"]]
    assert locs == [["body", "stimulus"], ["body", "behaviour"]]
    r = await client.post(f"{A}/nope/associations", json={"stimulus": "Red", "behaviour": "stop"})
    assert r.status_code == 404


async def test_put_association_adds_then_changes(client: httpx.AsyncClient) -> None:
    await make(client)
    r = await client.put(f"{A}/mine/associations/Red/stop", json={"strength": 0.7})
    assert r.status_code == 200
    assert r.json()["strength"] == 0.7 and r.json()["source"] == "dp"
    assert r.json()["version"] == 2
    r = await client.put(f"{A}/mine/associations/Red/stop", json={"source": "expert"})
    assert r.json()["strength"] == 0.7 and r.json()["source"] == "expert"
    assert r.json()["version"] == 3


async def test_put_association_that_changes_nothing_makes_no_version(
    client: httpx.AsyncClient,
) -> None:
    await make(client)
    r = await client.put(f"{A}/mine/associations/Corner/leftturn90", json={"strength": 1.0})
    assert r.status_code == 200 and r.json()["version"] == 1
    assert (await client.get(f"{A}/mine/versions")).json()["count"] == 1


async def test_put_association_unknown_path_names_are_404(client: httpx.AsyncClient) -> None:
    await make(client)
    for path in (
        "mine/associations/Purple/stop",
        "mine/associations/Red/fly",
        "nope/associations/Red/stop",
    ):
        r = await client.put(f"{A}/{path}", json={"strength": 0.5})
        assert r.status_code == 404, path
        assert "unknown" in r.json()["detail"]


@pytest.mark.parametrize(
    "body", [{"strength": 2}, {"strength": "high"}, {"source": "x"}, {"locked": "maybe"}, {"s": 1}]
)
async def test_put_association_refuses_invalid_values(
    client: httpx.AsyncClient, body: dict[str, Any]
) -> None:
    await make(client)
    r = await client.put(f"{A}/mine/associations/Red/stop", json=body)
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"][0] == "body"


async def test_a_locked_association_changes_only_with_force(client: httpx.AsyncClient) -> None:
    await make(client)
    url = f"{A}/mine/associations/Corner/leftturn90"
    r = await client.put(url, json={"locked": True})
    assert r.status_code == 200 and r.json()["locked"] is True

    refused = await client.put(url, json={"strength": 0.3})
    assert refused.status_code == 409
    assert "locked" in refused.json()["detail"] and "force=true" in refused.json()["detail"]
    assert (await client.delete(url)).status_code == 409
    assert (await client.put(url, json={"locked": False})).status_code == 409

    forced = await client.put(url, params={"force": "true"}, json={"strength": 0.3})
    assert forced.status_code == 200
    assert forced.json()["strength"] == 0.3 and forced.json()["locked"] is True
    unlocked = await client.put(url, params={"force": "true"}, json={"locked": False})
    assert unlocked.json()["locked"] is False
    assert (await client.put(url, json={"strength": 0.4})).status_code == 200


async def test_remove_association(client: httpx.AsyncClient) -> None:
    await make(client)
    url = f"{A}/mine/associations/Corner/leftturn90"
    r = await client.delete(url, params={"note": "corner is learned now"})
    assert r.status_code == 204 and r.content == b""
    assert r.headers["srlab-network-version"] == "2" and r.headers["srlab-live-runs"] == ""
    assert ("Corner", "leftturn90") not in pairs((await client.get(f"{A}/mine")).json())
    assert (await client.delete(url)).status_code == 404
    history = (await client.get(f"{A}/mine/versions")).json()["data"]
    assert history[-1]["note"] == "corner is learned now"


async def test_remove_a_locked_association_needs_force(client: httpx.AsyncClient) -> None:
    await make(client, associations=[{"stimulus": "Red", "behaviour": "stop", "locked": True}])
    url = f"{A}/mine/associations/Red/stop"
    refused = await client.delete(url)
    assert refused.status_code == 409 and "force=true" in refused.json()["detail"]
    assert (await client.delete(url, params={"force": True})).status_code == 204


# --- history: versions, diff, revert ---------------------------------------------------


async def test_malformed_json_is_422_not_500(client: httpx.AsyncClient) -> None:
    for url in (A, f"{A}/import", f"{A}/innate/associations"):
        r = await client.post(url, content=b"{nope", headers={"content-type": "application/json"})
        assert r.status_code == 422, url


# --- live edits -------------------------------------------------------------------------


async def test_a_live_edit_reaches_a_running_run(client: httpx.AsyncClient) -> None:
    await make(client, "live-net", base="kp")
    r = await client.post(
        "/api/runs", json={"condition": "kp", "mode": "realtime", "hz": 50, "network": "live-net"}
    )
    assert r.status_code == 201, r.text
    run_id = r.json()["id"]
    plain = {"condition": "kp", "mode": "realtime", "hz": 50}
    other = (await client.post("/api/runs", json=plain)).json()["id"]
    assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
    assert (await client.post(f"/api/runs/{other}/start")).status_code == 200
    try:
        quiet = await client.put(f"{A}/live-net/associations/Red/back", json={"strength": 0.3})
        assert quiet.json()["live_runs"] == []

        r = await client.put(
            f"{A}/live-net/associations/Red/stop",
            params={"live": True, "note": "stop at red"},
            json={"strength": 0.95, "locked": True},
        )
        assert r.status_code == 200
        assert r.json()["live_runs"] == [run_id]
        corner = f"{A}/live-net/associations/Corner/leftturn90"
        gone = await client.delete(corner, params={"live": 1})
        assert gone.status_code == 204 and gone.headers["srlab-live-runs"] == str(run_id)

        network: dict[tuple[str, str], dict[str, Any]] = {}
        for _ in range(100):
            got = (await client.get(f"/api/runs/{run_id}/network")).json()["data"]
            network = {(a["stimulus"], a["behaviour"]): a for a in got}
            if ("Red", "stop") in network and ("Corner", "leftturn90") not in network:
                break
            await asyncio.sleep(0.02)
        assert network["Red", "stop"]["strength"] == 0.95
        assert network["Red", "stop"]["locked"] is True
        assert ("Corner", "leftturn90") not in network
        assert ("Red", "back") not in network  # written without live=true
        others = (await client.get(f"/api/runs/{other}/network")).json()["data"]
        assert all(a["strength"] != 0.95 for a in others if a["stimulus"] == "Red")
    finally:
        for rid in (run_id, other):
            assert (await client.post(f"/api/runs/{rid}/stop")).status_code == 200


async def test_a_live_edit_with_no_running_run_reaches_none(client: httpx.AsyncClient) -> None:
    await make(client)
    r = await client.post(
        "/api/runs", json={"condition": "kp", "mode": "realtime", "hz": 50, "network": "mine"}
    )
    assert r.status_code == 201  # created, never started
    put = await client.put(
        f"{A}/mine/associations/Red/stop", params={"live": True}, json={"strength": 0.5}
    )
    assert put.status_code == 200 and put.json()["live_runs"] == []


async def test_one_network_past_the_cap_is_a_409_and_a_replaced_one_is_not(
    client: httpx.AsyncClient, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(networks_routes, "MAX_NETWORKS", 2)
    await make(client, "one")
    await make(client, "two")
    r = await client.post(A, json={"name": "three"})
    assert r.status_code == 409 and "delete one" in r.json()["detail"]
    document = (await client.get(f"{A}/one/export")).json()
    r = await client.post(f"{A}/import", params={"name": "three"}, json=document)
    assert r.status_code == 409
    r = await client.post(f"{A}/import", params={"replace": True}, json=document)
    assert r.status_code in (200, 201), r.text  # replacing one adds none
    assert (await client.delete(f"{A}/two")).status_code == 204
    assert (await client.post(A, json={"name": "three"})).status_code == 201
    names = {n["name"] for n in (await client.get(A)).json()["data"]}
    assert {"one", "three"} <= names and "two" not in names
