"""GET /api/runs/{id}/kp on the real app: a KP run's RSTM and each association's provenance."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import httpx
import pytest
from apphelpers import client_for, create, settings_for

from core.brain.propagation import KpConfig

pytestmark = [pytest.mark.anyio, pytest.mark.usefixtures("each_link")]  # over both links
HANG_GUARD_S = 300
"""Not a timing: how long a busy machine may take before the test is called hung."""


async def until_propagated(client: httpx.AsyncClient, run_id: int) -> dict[str, Any]:
    """Poll the inspector until an association has provenance and one is in the network."""
    async with asyncio.timeout(HANG_GUARD_S):
        while True:
            body: dict[str, Any] = (await client.get(f"/api/runs/{run_id}/kp")).json()
            made = [a for a in body.get("associations", []) if a["provenance"]]
            if any(a["in_network"] for a in made):
                return body
            await asyncio.sleep(0.05)


async def test_get_run_kp_shows_provenance_of_a_live_kp_run(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        # Far more episodes than it needs: it is stopped once KP has made an association.
        run = await create(client, condition="kp", seed=3, episodes=100_000)
        assert (await client.post(f"/api/runs/{run['id']}/start")).status_code == 200
        body = await until_propagated(client, run["id"])
        await client.post(f"/api/runs/{run['id']}/pause")
        body = (await client.get(f"/api/runs/{run['id']}/kp")).json()

        assert (body["kp"], body["live"], body["condition"]) == (True, True, "kp")
        assert body["insert_threshold"] == KpConfig().insert_threshold
        assert body["tick"] >= 0 and body["window_ticks"] > 0
        assert {r["sensor"] for r in body["rstm"]} <= {"camera_obstacle"}
        for rstm in body["rstm"]:
            for rec in rstm["records"]:
                assert rec["camera_stimulus"].startswith("Obstacle_")
                assert rec["sonar_stimulus"].startswith("Sonar")
        assoc = next(a for a in body["associations"] if a["in_network"] and a["provenance"])
        assert assoc["stimulus"].startswith("Obstacle_")
        p = assoc["provenance"][-1]
        assert p["sources"], "a propagation has at least one source behaviour"
        assert all(s["sonar_stimulus"].startswith("Sonar") for s in p["sources"])
        assert p["resolution"] == "snapped" and p["behaviour"] == p["nearest"]
        assert p["behaviour"] == assoc["behaviour"]
        assert abs(p["sum_x"]) + abs(p["sum_y"]) > 0
        assert len(assoc["history"]) == assoc["reasoned"] >= 1
        assert assoc["history"][-1]["after"] == pytest.approx(assoc["reliability"])
        rltm = (await client.get(f"/api/runs/{run['id']}/rltm")).json()["data"]
        assert any(
            (r["stimulus"], r["behaviour"]) == (assoc["stimulus"], assoc["behaviour"]) for r in rltm
        )

        await client.post(f"/api/runs/{run['id']}/stop")
        stored = (await client.get(f"/api/runs/{run['id']}/kp")).json()
        assert (stored["kp"], stored["live"]) == (True, False)
        assert stored["insert_threshold"] == KpConfig().insert_threshold
        assert "not running here" in stored["reason"]
        assert any(
            (a["stimulus"], a["behaviour"]) == (assoc["stimulus"], assoc["behaviour"])
            for a in stored["associations"]
        )
        # Where each ran, read back from the stored traces: the spans the engine saw.
        live_spans = {
            (a["stimulus"], a["behaviour"], r["first_tick"], r["last_tick"])
            for a in body["associations"]
            for r in a["runs"]
        }
        stored_spans = {
            (a["stimulus"], a["behaviour"], r["first_tick"], r["last_tick"])
            for a in stored["associations"]
            for r in a["runs"]
        }
        assert stored_spans <= live_spans
        # And they are the trace rows a kp association released, by GET .../episodes/{n}.
        count = (await client.get(f"/api/runs/{run['id']}/episodes?limit=1")).json()["count"]
        from_traces: set[tuple[str, str, int]] = set()
        for n in range(max(0, count - 20), count):
            trace = (await client.get(f"/api/runs/{run['id']}/episodes/{n}")).json()["trace"]
            from_traces |= {
                (r["released_by"], r["behaviour"], r["tick"]) for r in trace if r["origin"] == "kp"
            }
        assert from_traces == {
            (st, be, t) for st, be, a, z in stored_spans for t in range(a, z + 1)
        }


async def test_get_run_kp_of_an_unknown_run_is_404(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.get("/api/runs/999/kp")
        assert r.status_code == 404


async def test_get_run_kp_of_a_run_without_kp_says_why(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="rp", seed=1, episodes=2)
        r = await client.get(f"/api/runs/{run['id']}/kp")
        assert r.status_code == 200
        body = r.json()
        assert (body["kp"], body["associations"], body["rstm"]) == (False, [], [])
        assert "'rp' does not run knowledge propagation" in body["reason"]
        assert "kp" in body["reason"]


async def test_get_run_kp_is_in_the_openapi_document(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        doc = (await client.get("/openapi.json")).json()
        op = doc["paths"]["/api/runs/{run_id}/kp"]["get"]
        assert op["operationId"] == "getRunKp"
        assert "404" in op["responses"]
