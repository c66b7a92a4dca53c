"""The editor's "run this network": runs of a past version, rates over seeds, paired diffs."""

from __future__ import annotations

from pathlib import Path

import pytest
from apphelpers import client_for, create, settings_for, until

pytestmark = [pytest.mark.anyio, pytest.mark.usefixtures("each_link")]  # over both links


async def test_compare_runs_of_two_versions_on_the_same_seeds(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post("/api/networks", json={"name": "mine", "base": "dp"})
        assert r.status_code == 201
        r = await client.delete("/api/networks/mine/associations/Red/stop", params={"force": True})
        assert r.status_code == 204  # version 2 has no Red -> stop
        a, b = [], []
        for seed in (0, 1):
            a.append(await create(client, condition="dp", network="mine", seed=seed, episodes=2))
            b.append(
                await create(
                    client,
                    condition="dp",
                    network="mine",
                    network_version=1,
                    seed=seed,
                    episodes=2,
                )
            )
        for run in a + b:
            assert (await client.post(f"/api/runs/{run['id']}/start")).status_code == 200
        for run in a + b:
            await until(client, run["id"], "finished")
        r = await client.get(
            "/api/comparisons",
            params={"a": [x["id"] for x in a], "b": [x["id"] for x in b]},
        )
        assert r.status_code == 200, r.text
        body = r.json()
        assert body["episodes"] == 2 and body["seeds"] == [0, 1] and body["complete"]
        assert body["a"]["n"] == 2 and 0 <= body["a"]["mean"] <= 1
        assert body["diff"]["mean"] == pytest.approx(body["a"]["mean"] - body["b"]["mean"])
        assert body["p"] is not None
        # Version 1's run started with Red -> stop, today's did not.
        first = (await client.get(f"/api/runs/{b[0]['id']}/network")).json()["data"]
        now = (await client.get(f"/api/runs/{a[0]['id']}/network")).json()["data"]
        assert any((p["stimulus"], p["behaviour"]) == ("Red", "stop") for p in first)
        assert not any(
            (p["stimulus"], p["behaviour"], p["source"]) == ("Red", "stop", "dp") for p in now
        )


async def test_compare_runs_errors_name_the_problem(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        x = await create(client, condition="dp", seed=0, episodes=1)
        y = await create(client, condition="dp", seed=5, episodes=1)
        r = await client.get("/api/comparisons", params={"a": [x["id"]], "b": [y["id"]]})
        assert r.status_code == 409 and "same seed" in r.json()["detail"]
        r = await client.get("/api/comparisons", params={"a": [x["id"]], "b": [x["id"], y["id"]]})
        assert r.status_code == 422
        r = await client.get("/api/comparisons", params={"a": [999]})
        assert r.status_code == 404
        # Each run once per side: a repeat would count one seed many times.
        r = await client.get("/api/comparisons", params={"a": [x["id"], y["id"], x["id"]]})
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "a", 2]
        r = await client.get("/api/comparisons", params={"a": [x["id"]] * 33})
        assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["query", "a"]
        r = await client.get("/api/comparisons", params={"a": [], "b": [x["id"]]})
        assert r.status_code == 422
        r = await client.get("/api/comparisons", params={"a": [x["id"]]})
        assert r.status_code == 200, r.text
        assert r.json()["episodes"] == 0 and r.json()["a"]["mean"] is None
        r = await client.post("/api/runs", json={"condition": "dp", "network_version": 1})
        assert r.status_code == 404 and "give `network` too" in r.text
        r = await client.post(
            "/api/runs", json={"condition": "dp", "network": "dp", "network_version": 99}
        )
        assert r.status_code == 404


async def test_stimuli_say_what_they_mean_and_conditions_are_listed(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        stimuli = {s["name"]: s for s in (await client.get("/api/stimuli")).json()}
        assert stimuli["Obstacle_L_R"]["description"].startswith("robot in the left lane")
        assert "obstacle right" in stimuli["Obstacle_L_R"]["description"]
        assert "lateral_offset_m > 0.2" in stimuli["Obstacle_L_R"]["rule"]
        assert all(s["description"] for s in stimuli.values())
        conditions = {c["name"]: c for c in (await client.get("/api/conditions")).json()}
        assert (
            conditions["dp"]["learning"] and "Direct programming" in conditions["dp"]["description"]
        )
        assert "qlambda" not in conditions
        # the signal's KP pairing and its ablation (docs/results/signal-kp/)
        assert conditions["kp-signal"]["kp"] and conditions["kp-signal"]["network"] == "beacon"
        assert not conditions["beacon"]["kp"] and conditions["beacon"]["network"] == "beacon"
        assert "beacon_phase == 1" in stimuli["BeaconRed"]["rule"]
