"""Optimistic concurrency for networks: ETag on reads, If-Match or expected_version on writes.

Two editors that both read version 1 cannot both write as if the other had not: the
second gets 412 with the current version, and nothing of the first is lost.
"""

from __future__ import annotations

from pathlib import Path

import httpx
import pytest
from apphelpers import client_for, settings_for
from reliability_report import record

pytestmark = pytest.mark.anyio
CELL = "/api/networks/mine/associations/Red/goforward1"


async def fresh(client: httpx.AsyncClient, name: str = "mine", base: str = "dp") -> str:
    r = await client.post("/api/networks", json={"name": name, "base": base})
    assert r.status_code == 201, r.text
    etag = (await client.get(f"/api/networks/{name}")).headers["etag"]
    return etag


async def test_every_read_gives_the_version_as_an_etag(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        etag = await fresh(client)
        assert etag.startswith('"v1-') and etag.endswith('"')
        for path in ("", "/associations", "/export"):
            assert (await client.get(f"/api/networks/mine{path}")).headers["etag"] == etag
        written = await client.put(CELL, json={"strength": 0.5}, headers={"If-Match": etag})
        assert written.status_code == 200, written.text
        assert written.json()["version"] == 2 and written.headers["etag"].startswith('"v2-')


async def test_a_write_based_on_a_stale_version_gets_412_and_changes_nothing(
    tmp_path: Path,
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        v1 = await fresh(client)
        # Editor A writes first; editor B still holds version 1.
        a = await client.put(CELL, json={"strength": 0.3}, headers={"If-Match": v1})
        assert a.status_code == 200
        for attempt in (
            client.put(CELL, json={"strength": 0.9}, headers={"If-Match": v1}),
            client.put(CELL, json={"strength": 0.9}, params={"expected_version": 1}),
            client.delete(CELL, headers={"If-Match": v1}),
            client.post(
                "/api/networks/mine/associations",
                json={"stimulus": "Green", "behaviour": "stop"},
                params={"expected_version": 1},
            ),
            client.post(
                "/api/networks/mine/revert", json={"version": 1}, params={"expected_version": 1}
            ),
            client.delete("/api/networks/mine", headers={"If-Match": v1}),
        ):
            r = await attempt
            assert r.status_code == 412, r.text
            body = r.json()
            assert body["version"] == 2 and body["etag"] == a.headers["etag"]
            assert "version 2" in body["detail"] and r.headers["etag"] == a.headers["etag"]
        stored = (await client.get("/api/networks/mine")).json()
        assert stored["version"] == 2
        red_go = next(
            x
            for x in stored["associations"]
            if (x["stimulus"], x["behaviour"]) == ("Red", "goforward1")
        )
        assert red_go["strength"] == 0.3
        record(
            "lost updates between editors",
            "6 writes (put, delete, add, revert, delete network) based on version 1 after "
            "another editor made version 2",
            "all 412 with the current version; version 2 kept as it was",
        )
        # Without a precondition a write goes through as before; "*" matches any version.
        assert (
            await client.put(CELL, json={"strength": 0.4}, headers={"If-Match": "*"})
        ).status_code == 200


async def test_an_import_replacing_a_newer_version_is_refused(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        await fresh(client)
        doc = (await client.get("/api/networks/mine/export")).json()
        assert (await client.put(CELL, json={"strength": 0.2})).status_code == 200  # v2
        r = await client.post(
            "/api/networks/import", json=doc, params={"replace": True, "expected_version": 1}
        )
        assert r.status_code == 412 and r.json()["version"] == 2
        assert (await client.get("/api/networks/mine")).json()["version"] == 2


async def test_a_network_made_again_under_its_name_has_other_etags(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        old = await fresh(client)
        assert (await client.delete("/api/networks/mine")).status_code == 204
        # SQLite may give it the deleted one's id, in the same second: its content differs.
        # (Were it the same too, the representation would be the same: nothing is lost.)
        new = await fresh(client, base="innate")
        assert old != new  # both are version 1
        r = await client.put(CELL, json={"strength": 0.5}, headers={"If-Match": old})
        assert r.status_code == 412


async def started_run(client: httpx.AsyncClient, network: str) -> int:
    """A realtime dp run started from `network`."""
    run = await client.post(
        "/api/runs", json={"condition": "dp", "network": network, "mode": "realtime", "hz": 20}
    )
    run_id: int = run.json()["id"]
    assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
    return run_id


async def test_live_edits_reach_runs_of_that_network_not_of_an_older_namesake(
    tmp_path: Path,
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        await fresh(client, "same")
        run_id = await started_run(client, "same")
        cell = "/api/networks/same/associations/Red/goforward1"
        reached = await client.put(cell, json={"strength": 0.5}, params={"live": True})
        assert reached.json()["live_runs"] == [run_id]
        assert (await client.delete("/api/networks/same")).status_code == 204
        await fresh(client, "same")  # unrelated, same name
        other = await client.put(cell, json={"strength": 0.1}, params={"live": True})
        assert other.status_code == 200 and other.json()["live_runs"] == []
        await client.post(f"/api/runs/{run_id}/stop")


async def test_a_resumed_run_is_reached_by_its_network_id_after_a_restart(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path)
    cell = "/api/networks/same/associations/Red/goforward1"
    async with client_for(settings) as (client, _):
        await fresh(client, "same")
        run_id = await started_run(client, "same")
    # A new process: the run was interrupted; it knows its network only from the store.
    async with client_for(settings) as (client, _):
        assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
        reached = await client.put(cell, json={"strength": 0.5}, params={"live": True})
        assert reached.json()["live_runs"] == [run_id]
        await client.post(f"/api/runs/{run_id}/stop")
    async with client_for(settings) as (client, _):
        assert (await client.delete("/api/networks/same")).status_code == 204
        await fresh(client, "same")  # unrelated, same name, perhaps the same id
    # Made before this process started, like the run: only the stored id tells them apart.
    async with client_for(settings) as (client, _):
        assert (await client.post(f"/api/runs/{run_id}/start")).status_code == 200
        other = await client.put(cell, json={"strength": 0.1}, params={"live": True})
        assert other.status_code == 200 and other.json()["live_runs"] == []
        await client.post(f"/api/runs/{run_id}/stop")


@pytest.mark.parametrize(
    ("if_match", "status"),
    [
        ("{etag}", 200),
        ("{bare}", 200),  # a client that dropped the quotes means the same tag
        ('W/{etag}, "v9-0"', 200),
        ("*", 200),
        ('"v9-0"', 412),
        ('"a\\"b"', 422),  # not an entity tag: refused naming the header
        ("\x7f", 422),
    ],
)
async def test_if_match_takes_entity_tags_as_http_writes_them(
    tmp_path: Path, if_match: str, status: int
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        etag = await fresh(client)
        header = if_match.format(etag=etag, bare=etag.strip('"'))
        r = await client.put(CELL, json={"strength": 0.5}, headers={"If-Match": header})
        assert r.status_code == status, r.text
        if status == 422:
            assert r.json()["detail"][0]["loc"] == ["header", "if-match"]
