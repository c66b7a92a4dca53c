"""Runs, rewards and events over HTTP, happy and error paths side by side."""

from __future__ import annotations

import asyncio
import json
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import pytest
from apphelpers import client_for, create, settings_for, until

from core.engine import RunEngine
from core.engine.messages import state_of
from core.ports import RunStatus
from server.runtime.reads import run_of_state
from server.schemas import EpisodeDetail

pytestmark = [pytest.mark.anyio, pytest.mark.usefixtures("each_link")]  # over both links


async def test_create_run_and_run_it_in_fast_mode(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="kp", seed=3, episodes=4)
        assert (run["status"], run["episodes"], run["mode"]) == ("created", 4, "fast")
        r = await client.post(f"/api/runs/{run['id']}/start")
        assert r.status_code == 200
        done = await until(client, run["id"], "finished")
        assert done["episodes_done"] == 4 and done["ticks"] > 0
        episodes = (await client.get(f"/api/runs/{run['id']}/episodes")).json()
        assert episodes["count"] == 4
        answer = await client.get(f"/api/runs/{run['id']}/episodes/0")
        assert answer.headers["content-type"] == "application/json"
        # Written as JSON directly (no response model on the way out): it must still be
        # exactly what the documented schema says.
        EpisodeDetail.model_validate_json(answer.content, strict=True)
        detail = answer.json()
        assert len(detail["trace"]) == detail["ticks"]
        assert detail["trace"][0]["behaviour"] == "goforward3"
        ltm = (await client.get(f"/api/runs/{run['id']}/ltm")).json()
        assert ltm["count"] > 0
        network = (await client.get(f"/api/runs/{run['id']}/network")).json()
        assert any(
            (a["stimulus"], a["behaviour"], a["source"]) == ("Corner", "leftturn90", "innate")
            for a in network["data"]
        )
        rltm = (await client.get(f"/api/runs/{run['id']}/rltm")).json()
        assert rltm["count"] >= 0
        listed = (await client.get("/api/runs")).json()
        assert listed["count"] == 1 and listed["data"][0]["id"] == run["id"]


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"condition": "telepathy"}, "condition"),
        ({"condition": "qlambda"}, "condition"),
        ({"condition": "kp", "seed": -1}, "seed"),
        ({"condition": "kp", "episodes": 0}, "episodes"),
        ({"condition": "kp", "mode": "warp"}, "mode"),
        ({"condition": "kp", "hz": 0}, "hz"),
        ({"condition": "kp", "hz": 1e-300}, "hz"),
        ({"condition": "kp", "hz": 0.05}, "hz"),
        ({"condition": "kp", "hz": 1000.5}, "hz"),
        ({"condition": "kp", "params": {"eta": 2}}, "eta"),
        ({"condition": "kp", "colour": "red"}, "colour"),
        ({}, "condition"),
    ],
)
async def test_create_run_with_a_bad_body_is_422_naming_the_field(
    tmp_path: Path, body: dict[str, Any], field: str
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post("/api/runs", json=body)
    assert r.status_code == 422
    assert field in json.dumps(r.json()["detail"])


async def test_create_run_from_an_unknown_network_is_404(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post("/api/runs", json={"condition": "kp", "network": "nope"})
    assert r.status_code == 404 and "nope" in r.json()["detail"]


@pytest.mark.parametrize("path", ["/api/runs/99", "/api/runs/99/ltm", "/api/runs/99/rltm",
                                  "/api/runs/99/network", "/api/runs/99/episodes",
                                  "/api/runs/99/rewards", "/api/runs/99/episodes/0",
                                  "/api/runs/99/events"])  # fmt: skip
async def test_an_unknown_run_is_404(tmp_path: Path, path: str) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.get(path)
    assert r.status_code == 404


@pytest.mark.parametrize("action", ["start", "pause", "resume", "stop"])
async def test_control_of_an_unknown_run_is_404(tmp_path: Path, action: str) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post(f"/api/runs/99/{action}")
    assert r.status_code == 404


async def test_a_realtime_run_takes_rewards_whose_ltm_shows_them(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="kp", mode="realtime", hz=100)
        run_id = run["id"]
        early = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1})
        assert early.status_code == 409 and "not running" in early.json()["detail"]
        await client.post(f"/api/runs/{run_id}/start")
        await until(client, run_id, "running")
        await asyncio.sleep(0.3)
        r = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1, "note": "good"})
        assert r.status_code == 202, r.text
        ack = r.json()
        assert ack["tick"] >= 1 and ack["value"] == 1.0
        bad = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1.5})
        assert bad.status_code == 422 and "value" in json.dumps(bad.json())
        async with asyncio.timeout(10):
            while True:
                log = (await client.get(f"/api/runs/{run_id}/rewards")).json()["data"]
                if log and log[0]["applied"]:
                    break
                await asyncio.sleep(0.02)
        assert log[0]["id"] == ack["id"] and log[0]["note"] == "good" and log[0]["credited"] > 0
        ltm = (await client.get(f"/api/runs/{run_id}/ltm")).json()["data"]
        assert any(p["stimulus"] == "Middle" and p["reliability"] > 0 for p in ltm)
        # pause, resume, stop
        assert (await client.post(f"/api/runs/{run_id}/pause")).json()["status"] == "paused"
        paused = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1})
        assert paused.status_code == 202, paused.text  # credited at the paused boundary
        assert (await client.post(f"/api/runs/{run_id}/pause")).status_code == 409
        assert (await client.post(f"/api/runs/{run_id}/resume")).json()["status"] == "running"
        assert (await client.post(f"/api/runs/{run_id}/stop")).status_code == 200
        await until(client, run_id, "stopped")
        assert (await client.post(f"/api/runs/{run_id}/stop")).status_code == 409


async def test_rewards_are_rate_limited_per_client(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, reward_rate_per_s=1.0, reward_burst=3)
    async with client_for(settings) as (client, _):
        run = await create(client, condition="delayed", mode="realtime", hz=200)
        await client.post(f"/api/runs/{run['id']}/start")
        await until(client, run["id"], "running")
        codes = [
            (await client.post(f"/api/runs/{run['id']}/rewards", json={"value": 0.5})).status_code
            for _ in range(5)
        ]
        assert codes[:3] == [202, 202, 202]
        assert 429 in codes[3:]
        await client.post(f"/api/runs/{run['id']}/stop")


async def test_too_many_runs_is_429(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path, max_runs=1)) as (client, _):
        a = await create(client, condition="delayed", mode="realtime", hz=20)
        b = await create(client, condition="delayed", mode="realtime", hz=20)
        assert (await client.post(f"/api/runs/{a['id']}/start")).status_code == 200
        r = await client.post(f"/api/runs/{b['id']}/start")
        assert r.status_code == 429 and "SRLAB_MAX_RUNS" in r.json()["detail"]
        again = await client.post(f"/api/runs/{a['id']}/start")
        assert again.status_code == 409
        await client.post(f"/api/runs/{a['id']}/stop")


async def test_a_start_refused_with_429_leaves_a_stopped_run_as_it_was(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path, max_runs=1)) as (client, app):
        a = await create(client, condition="delayed", mode="realtime", hz=50)
        b = await create(client, condition="delayed", mode="realtime", hz=50)
        assert (await client.post(f"/api/runs/{b['id']}/start")).status_code == 200
        assert (await client.post(f"/api/runs/{b['id']}/stop")).status_code == 200
        await until(client, b["id"], "stopped")
        assert (await client.post(f"/api/runs/{a['id']}/start")).status_code == 200
        refused = await client.post(f"/api/runs/{b['id']}/start")
        assert refused.status_code == 429
        assert app.state.srlab.engines.get(b["id"]) is None  # nothing rebuilt and left behind
        assert (await client.get(f"/api/runs/{b['id']}")).json()["status"] == "stopped"
        assert (await client.post(f"/api/runs/{b['id']}/stop")).status_code == 409
        reward = await client.post(f"/api/runs/{b['id']}/rewards", json={"value": 1})
        assert reward.status_code == 409  # answered at once, never held for a later start
        await client.post(f"/api/runs/{a['id']}/stop")
        await until(client, a["id"], "stopped")
        assert (await client.post(f"/api/runs/{b['id']}/start")).status_code == 200
        await client.post(f"/api/runs/{b['id']}/stop")
        await until(client, b["id"], "stopped")
        log = (await client.get(f"/api/runs/{b['id']}/rewards")).json()
        assert [r for r in log["data"] if r["source"] == "trainer"] == []


async def test_only_ticking_runs_keep_an_engine_in_memory(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        engines = app.state.srlab.engines
        created = [await create(client, condition="innate", episodes=1) for _ in range(5)]
        assert list(engines.engines()) == []
        run = created[0]["id"]
        assert (await client.post(f"/api/runs/{run}/start")).status_code == 200
        done = await until(client, run, "finished")
        assert done["episodes_done"] == 1 and done["live"] is None
        # Its status is stored before its task ends; the engine goes when the task has.
        assert await engines.ended(run, timeout_s=30)
        assert list(engines.engines()) == []  # its state is in storage: the engine is gone
        episodes = (await client.get(f"/api/runs/{run}/episodes")).json()
        assert episodes["count"] == 1


async def test_a_run_that_has_ended_has_no_live_figures_while_its_engine_is_still_held(
    tmp_path: Path,
) -> None:
    # The engine is let go only after its task ends: a read in between meets a finished run
    # still in memory, and must answer what the read of the stored run answers.
    async with client_for(settings_for(tmp_path)) as (client, app):
        run = await create(client, condition="innate", episodes=1)
        engine = RunEngine.restore(run["id"], app.state.srlab.store)
        public = run_of_state(engine.spec, state_of(engine.view(), 1))
        assert public.live is not None  # created: starting
        assert await engine.run() == RunStatus.FINISHED
        held = run_of_state(engine.spec, state_of(engine.view(), 1))
        stored = (await client.get(f"/api/runs/{run['id']}")).json()
    assert (held.status, held.live) == ("finished", None)
    assert held.model_dump(mode="json") == stored


async def test_a_stopped_run_starts_again_from_its_checkpoint(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="kp", episodes=40, seed=2)
        await client.post(f"/api/runs/{run['id']}/start")
        await asyncio.sleep(0.05)
        await client.post(f"/api/runs/{run['id']}/stop")
        stopped = await until(client, run["id"], "stopped")
        assert stopped["episodes_done"] < 40
        await client.post(f"/api/runs/{run['id']}/start")
        done = await until(client, run["id"], "finished")
        assert done["episodes_done"] == 40


async def test_the_event_stream_delivers_an_episode_end(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="expert", episodes=2, seed=1)
        events: list[tuple[str, dict[str, Any]]] = []

        async def follow() -> None:
            async with client.stream("GET", f"/api/runs/{run['id']}/events?tick_hz=0") as r:
                assert r.status_code == 200
                assert r.headers["content-type"].startswith("text/event-stream")
                name = ""
                async for line in r.aiter_lines():
                    if line.startswith("event: "):
                        name = line[7:]
                    elif line.startswith("data: "):
                        events.append((name, json.loads(line[6:])))

        async with asyncio.timeout(30):
            follower = asyncio.create_task(follow())
            await asyncio.sleep(0.1)
            await client.post(f"/api/runs/{run['id']}/start")
            await follower
    names = [n for n, _ in events]
    assert "episode" in names and names[-1] == "status"
    episode = next(d for n, d in events if n == "episode")
    assert episode["outcome"] in ("success", "failure")
    assert events[-1][1]["status"] == "finished"
    assert "tick" not in names  # tick_hz=0


async def test_writes_need_the_token_when_one_is_set(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, token="s3cret")
    async with client_for(settings) as (client, _):
        r = await client.post("/api/runs", json={"condition": "kp"})
        assert r.status_code == 401 and "Bearer" in r.json()["detail"]
        wrong = await client.post(
            "/api/runs", json={"condition": "kp"}, headers={"authorization": "Bearer nope"}
        )
        assert wrong.status_code == 401
        ok = await client.post(
            "/api/runs", json={"condition": "kp"}, headers={"authorization": "Bearer s3cret"}
        )
        assert ok.status_code == 201
        assert (await client.get("/api/runs")).status_code == 200  # reads stay open


async def test_beyond_loopback_every_write_needs_the_token(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, host="0.0.0.0", token="t0k3n")
    async with client_for(settings) as (client, _):
        for path in ("/api/runs", "/api/runs/1/start", "/api/runs/1/rewards", "/api/runs/1/stop"):
            r = await client.post(path, json={"condition": "kp", "value": 1})
            assert r.status_code == 401, path


async def test_a_run_from_an_edited_network_starts_again_after_a_stop(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        assert (
            await client.post("/api/networks", json={"name": "mine", "base": "kp"})
        ).status_code == 201
        run = await create(client, condition="kp", mode="realtime", hz=100, network="mine")
        await client.post(f"/api/runs/{run['id']}/start")
        await until(client, run["id"], "running")
        await client.post(f"/api/runs/{run['id']}/stop")
        await until(client, run["id"], "stopped")
        # The network changes meanwhile; the run goes on with the one it started from.
        await client.put("/api/networks/mine/associations/Red/stop", json={"strength": 1.0})
        again = await client.post(f"/api/runs/{run['id']}/start")
        assert again.status_code == 200, again.text
        await until(client, run["id"], "running")
        network = (await client.get(f"/api/runs/{run['id']}/network")).json()["data"]
        assert not any(a["stimulus"] == "Red" for a in network)
        await client.post(f"/api/runs/{run['id']}/stop")


async def test_the_reward_log_is_paged(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, reward_rate_per_s=1000.0, reward_burst=1000)
    async with client_for(settings) as (client, _):
        run = await create(client, condition="delayed", mode="realtime", hz=200)
        await client.post(f"/api/runs/{run['id']}/start")
        for i in range(7):
            r = await client.post(
                f"/api/runs/{run['id']}/rewards", json={"value": 0.1, "note": str(i)}
            )
            assert r.status_code == 202
        page = (await client.get(f"/api/runs/{run['id']}/rewards?offset=2&limit=3")).json()
        assert page["count"] == 7
        assert [x["note"] for x in page["data"]] == ["2", "3", "4"]
        # each with the time the log took it, in UTC
        assert all(
            datetime.fromisoformat(x["at"]).utcoffset() == timedelta(0) for x in page["data"]
        )
        bad = await client.get(f"/api/runs/{run['id']}/rewards?limit=0")
        assert bad.status_code == 422
        await client.post(f"/api/runs/{run['id']}/stop")
