"""Runs over HTTP in a world preset and a sensor definition, and what made each behaviour run."""

from __future__ import annotations

import asyncio
import importlib.util
import json
from pathlib import Path
from typing import Any

import pytest
from apphelpers import client_for, create, settings_for, until

from core.brain.catalog import load_catalog, sensor_definitions
from core.brain.selection import ORIGINS
from core.run.setup import default_sensors
from core.sim.worlds import default_world, load_world, world_names

pytestmark = pytest.mark.anyio

OTHER_WORLD = next(n for n in world_names() if n != default_world())
OTHER_SENSORS = next(d for d in sensor_definitions() if d != default_sensors())
STIMULI = {s.name for s in load_catalog().stimuli}


async def test_create_run_with_a_world_and_sensors_keeps_their_names(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        run = await create(
            client, condition="dp", world=OTHER_WORLD, sensors=OTHER_SENSORS, mode="realtime"
        )
        assert (run["world"], run["sensors"]) == (OTHER_WORLD, OTHER_SENSORS)
        assert app.state.srlab.engines.get(run["id"]) is None  # created: in storage only
        assert (await client.post(f"/api/runs/{run['id']}/start")).status_code == 200
        engine = app.state.srlab.engines.link.engine(run["id"])  # the local host's
        view = engine.view()
        definition, config = view.catalog.definition, view.world_config
        assert definition == OTHER_SENSORS
        assert config == load_world(OTHER_WORLD).config
        await client.post(f"/api/runs/{run['id']}/stop")
        listed = (await client.get("/api/runs")).json()["data"]
        assert (listed[0]["world"], listed[0]["sensors"]) == (OTHER_WORLD, OTHER_SENSORS)
        stored = app.state.srlab.store.load_run(run["id"]).spec
        assert (stored.world, stored.sensors) == (OTHER_WORLD, OTHER_SENSORS)


async def test_create_run_without_them_stores_the_defaults_by_name(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        run = await create(client, condition="kp")
        empty = await create(client, condition="kp", world="", sensors=None)
        stored = app.state.srlab.store.load_run(run["id"]).spec
    assert (run["world"], run["sensors"]) == (default_world(), default_sensors())
    assert (empty["world"], empty["sensors"]) == (default_world(), default_sensors())
    assert (stored.world, stored.sensors) == (default_world(), default_sensors())


@pytest.mark.parametrize(
    ("body", "field", "known"),
    [
        ({"world": "atlantis"}, "world", world_names()),
        ({"sensors": "sixth"}, "sensors", tuple(sensor_definitions())),
        ({"world": 3}, "world", ()),
        ({"sensors": "x" * 101}, "sensors", ()),
    ],
)
async def test_create_run_with_an_unknown_world_or_sensors_is_422_naming_them(
    tmp_path: Path, body: dict[str, Any], field: str, known: tuple[str, ...]
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post("/api/runs", json={"condition": "kp", **body})
        listed = (await client.get("/api/runs")).json()
    assert r.status_code == 422
    [error] = r.json()["detail"]
    assert error["loc"] == ["body", field]
    for name in known:
        assert name in error["msg"]
    assert listed["count"] == 0


async def test_a_run_resumed_by_another_service_keeps_its_world_and_sensors(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path)
    async with client_for(settings) as (client, _):
        setup = {"world": OTHER_WORLD, "sensors": OTHER_SENSORS}
        run = await create(client, condition="kp", mode="realtime", hz=100, **setup)
        await client.post(f"/api/runs/{run['id']}/start")
        await until(client, run["id"], "running")
    # The service stopped (the run is interrupted); a new one resumes it from storage.
    async with client_for(settings) as (client, app):
        assert (await client.get(f"/api/runs/{run['id']}")).json()["status"] == "interrupted"
        r = await client.post(f"/api/runs/{run['id']}/start")
        assert r.status_code == 200, r.text
        assert (r.json()["world"], r.json()["sensors"]) == (OTHER_WORLD, OTHER_SENSORS)
        engine = app.state.srlab.engines.link.engine(run["id"])  # the local host's
        preset = load_world(OTHER_WORLD).config
        view = engine.view()
        definition, config = view.catalog.definition, view.world_config
        assert definition == OTHER_SENSORS
        assert config == preset
        assert config.track.obstacle == preset.track.obstacle
        await client.post(f"/api/runs/{run['id']}/stop")
        await until(client, run["id"], "stopped")


async def test_list_worlds_names_each_preset_its_reasons_and_the_default(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        worlds = (await client.get("/api/worlds")).json()
    assert [w["name"] for w in worlds] == list(world_names())
    assert [w["name"] for w in worlds if w["default"]] == [default_world()]
    for w in worlds:
        preset = load_world(w["name"])
        assert (w["description"], w["reasons"]) == (preset.description, preset.reasons)
        assert w["overrides"] == json.loads(json.dumps(dict(preset.overrides)))
    assert any(w["overrides"] for w in worlds), "some preset changes the defaults"


async def test_list_sensor_definitions_and_the_sensors_say_theirs(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        definitions = (await client.get("/api/sensor-definitions")).json()
        sensors = (await client.get("/api/sensors")).json()
    assert [d["name"] for d in definitions] == list(sensor_definitions())
    assert [d["name"] for d in definitions if d["default"]] == [default_sensors()]
    assert all(d["description"] for d in definitions)
    camera = next(s for s in sensors if s["name"] == "camera_obstacle")
    assert camera["definition"] == default_sensors()


async def test_a_run_counts_its_ticks_by_origin_and_its_trace_says_each_ones(
    tmp_path: Path,
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        # Realtime, so that it is still running (with its live figures) after an episode.
        run = await create(client, condition="kp", seed=2, mode="realtime", hz=1000)
        await client.post(f"/api/runs/{run['id']}/start")
        async with asyncio.timeout(60):
            while (done := (await client.get(f"/api/runs/{run['id']}")).json())[
                "episodes_done"
            ] < 1:
                await asyncio.sleep(0.05)
        await client.post(f"/api/runs/{run['id']}/stop")
        await until(client, run["id"], "stopped")  # its episodes are committed by then
        detail = (await client.get(f"/api/runs/{run['id']}/episodes/0")).json()
    counts = done["live"]["ticks_by_origin"]
    assert sum(counts.values()) == done["ticks"] > 0
    assert set(counts) <= set(ORIGINS)
    rows = detail["trace"]
    assert rows and {r["origin"] for r in rows} <= set(ORIGINS)
    released = [r for r in rows if r["how"] == "released"]
    assert released, "a kp robot's design releases behaviours on the track"
    for r in released:
        assert r["released_by"] in r["stimuli"] and r["origin"] in counts
    assert all(r["released_by"] is None or r["released_by"] in STIMULI for r in rows)


async def test_the_event_stream_says_what_made_each_ticks_behaviour_run(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="kp", seed=1, episodes=1, mode="realtime", hz=200)
        ticks: list[dict[str, Any]] = []

        async def follow() -> None:
            # ASGITransport hands the body over once the stream ends, with the run.
            async with client.stream("GET", f"/api/runs/{run['id']}/events?tick_hz=50") as r:
                name = ""
                async for line in r.aiter_lines():
                    if line.startswith("event: "):
                        name = line[7:]
                    elif line.startswith("data: ") and name == "tick":
                        ticks.append(json.loads(line[6:]))

        async with asyncio.timeout(60):
            follower = asyncio.create_task(follow())
            await asyncio.sleep(0.1)
            await client.post(f"/api/runs/{run['id']}/start")
            await follower
    assert ticks and all(t["origin"] in ORIGINS for t in ticks)
    released = [t for t in ticks if t["how"] == "released"]
    assert released, "a kp robot's design releases behaviours on the track"
    for t in released:
        assert t["released_by"] in t["stimuli"]
        assert t["origin"] not in ("default", "explored", "commanded")


async def test_a_run_on_an_unknown_robot_is_refused_naming_the_known_ones(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post("/api/runs", json={"condition": "kp", "world": "ros2:nosuch"})
        assert r.status_code == 422, r.text
        assert "unknown robot 'ros2:nosuch'" in r.text and "ros2:amigobot" in r.text


async def test_a_run_on_a_robot_is_realtime_at_its_rate_with_the_ros2_extra(
    tmp_path: Path,
) -> None:
    body = {"condition": "kp", "world": "ros2:amigobot", "mode": "fast"}
    async with client_for(settings_for(tmp_path)) as (client, _):
        r = await client.post("/api/runs", json=body)
        assert r.status_code == 409, r.text
        if importlib.util.find_spec("rclpy") is None:  # `make test`'s environment
            assert r.json()["detail"].startswith("world: a run on a robot needs the srlab[ros2]")
        else:  # `make test-ros2`'s (tests/ros2 run such runs on a fake robot)
            assert r.json()["detail"].startswith("mode: a run on a robot ticks in realtime")
            made = await client.post("/api/runs", json={**body, "mode": "realtime"})
            assert made.status_code == 201, made.text
            assert made.json()["hz"] == 20.0  # the robot file's
        assert (await client.get("/api/runs")).json()["count"] == (
            0 if importlib.util.find_spec("rclpy") is None else 1
        )
