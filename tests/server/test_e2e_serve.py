"""End to end against a live `srlab serve` on loopback, as a user with curl would."""

from __future__ import annotations

import json
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest
from liveharness import wait_status

from bench.liveserver import live_server


@pytest.fixture(scope="module")
def api(tmp_path_factory: pytest.TempPathFactory) -> Iterator[httpx.Client]:
    with live_server(tmp_path_factory.mktemp("e2e") / "e2e.db") as server:
        yield server.client


def test_edit_a_network_run_it_fast_to_completion_and_read_the_results(
    api: httpx.Client,
) -> None:
    assert api.post("/api/networks", json={"name": "mine", "base": "kp"}).status_code == 201
    edit = api.put(
        "/api/networks/mine/associations/Red/stop",
        json={"strength": 1.0, "source": "dp", "locked": True},
    )
    assert edit.status_code in (200, 201), edit.text
    r = api.post("/api/runs", json={"condition": "kp", "seed": 4, "episodes": 6, "network": "mine"})
    assert r.status_code == 201, r.text
    run_id = r.json()["id"]
    assert api.post(f"/api/runs/{run_id}/start").status_code == 200
    done = wait_status(api, run_id, "finished")
    assert done["episodes_done"] == 6
    network = api.get(f"/api/runs/{run_id}/network").json()["data"]
    assert {"stimulus": "Red", "behaviour": "stop", "locked": True}.items() <= next(
        a for a in network if a["stimulus"] == "Red"
    ).items()
    episodes = api.get(f"/api/runs/{run_id}/episodes").json()
    assert episodes["count"] == 6
    assert api.get(f"/api/runs/{run_id}/episodes/5").json()["trace"]
    assert api.get(f"/api/runs/{run_id}/ltm").json()["count"] > 0


def test_a_realtime_run_rewarded_over_http_shows_it_in_ltm(api: httpx.Client) -> None:
    r = api.post("/api/runs", json={"condition": "kp", "mode": "realtime", "hz": 50})
    run_id = r.json()["id"]
    api.post(f"/api/runs/{run_id}/start")
    wait_status(api, run_id, "running")
    time.sleep(0.5)
    ack = api.post(f"/api/runs/{run_id}/rewards", json={"value": 1.0, "note": "well done"})
    assert ack.status_code == 202, ack.text
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        log = api.get(f"/api/runs/{run_id}/rewards").json()["data"]
        if log and log[0]["applied"]:
            break
        time.sleep(0.05)
    assert log[0]["id"] == ack.json()["id"] and log[0]["credited"] > 0
    ltm = api.get(f"/api/runs/{run_id}/ltm").json()["data"]
    assert any(p["reliability"] > 0 for p in ltm)
    assert api.post(f"/api/runs/{run_id}/stop").status_code == 200
    wait_status(api, run_id, "stopped")


def test_the_event_stream_delivers_an_episode_end(api: httpx.Client) -> None:
    r = api.post("/api/runs", json={"condition": "expert", "seed": 2, "episodes": 1})
    run_id = r.json()["id"]
    events: list[tuple[str, dict[str, Any]]] = []
    with api.stream("GET", f"/api/runs/{run_id}/events", params={"tick_hz": 5}) as stream:
        assert stream.status_code == 200
        api.post(f"/api/runs/{run_id}/start")
        name = ""
        for line in stream.iter_lines():
            if line.startswith("event: "):
                name = line[7:]
            elif line.startswith("data: "):
                events.append((name, json.loads(line[6:])))
    names = [n for n, _ in events]
    assert "episode" in names and "tick" in names
    assert events[-1] == ("status", {"status": "finished", "error": None})
