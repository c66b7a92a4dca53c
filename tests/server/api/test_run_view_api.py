"""What the console's 2D view needs over HTTP: one-tick steps, the rate, the track, ticks."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path
from typing import Any

import pytest
from apphelpers import client_for, create, settings_for, until

from core.errors import RunStateError
from server.api.routes.events import encode
from server.api.routes.runs import world_public
from server.runtime import Runs
from server.runtime.local import LocalLink
from server.schemas import TickEvent

pytestmark = [pytest.mark.anyio, pytest.mark.usefixtures("each_link")]  # over both links


async def _paused_realtime_run(client: Any, hz: float = 5.0) -> int:
    run = await create(client, condition="kp", mode="realtime", hz=hz)
    run_id = int(run["id"])
    await client.post(f"/api/runs/{run_id}/start")
    await until(client, run_id, "running")
    paused = await client.post(f"/api/runs/{run_id}/pause")
    assert paused.json()["status"] == "paused"
    return run_id


async def streamed_ticks(client: Any, app: Any, run_id: int, n: int) -> list[dict[str, Any]]:
    """Start run `run_id`, read `n` tick events of its stream as JSON, then stop it."""
    await client.post(f"/api/runs/{run_id}/start")
    await until(client, run_id, "running")
    live = app.state.srlab.engines.get(run_id)
    assert live is not None
    sub = live.subscribe(256, tick_hz=100)
    ticks: list[dict[str, Any]] = []
    async with asyncio.timeout(30):
        while len(ticks) < n:
            encoded = encode(await sub.get(), live.catalog)
            if encoded is not None and encoded[0] == "tick":
                ticks.append(json.loads(json.dumps(encoded[1])))
    live.unsubscribe(sub)
    await client.post(f"/api/runs/{run_id}/stop")
    await until(client, run_id, "stopped")
    return ticks


async def test_step_runs_exactly_one_tick_of_a_paused_run(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run_id = await _paused_realtime_run(client)
        before = (await client.get(f"/api/runs/{run_id}")).json()["ticks"]
        for k in range(1, 4):
            r = await client.post(f"/api/runs/{run_id}/step")
            assert r.status_code == 200, r.text
            stepped = r.json()
            assert stepped["status"] == "paused"
            assert stepped["ticks"] == before + k
            assert stepped["live"]["tick"] == before + k
        # Still paused: nothing ticks on its own.
        await asyncio.sleep(0.5)
        assert (await client.get(f"/api/runs/{run_id}")).json()["ticks"] == before + 3
        assert (await client.post(f"/api/runs/{run_id}/resume")).json()["status"] == "running"
        await client.post(f"/api/runs/{run_id}/stop")


async def test_step_of_a_running_or_fast_run_is_409(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="kp", mode="realtime", hz=20)
        await client.post(f"/api/runs/{run['id']}/start")
        await until(client, run["id"], "running")
        r = await client.post(f"/api/runs/{run['id']}/step")
        assert r.status_code == 409 and "not paused" in r.json()["detail"]
        await client.post(f"/api/runs/{run['id']}/stop")
        created = await create(client, condition="kp")
        assert (await client.post(f"/api/runs/{created['id']}/step")).status_code == 409
        assert (await client.post("/api/runs/99/step")).status_code == 404


async def test_steps_asked_together_each_run_one_tick(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run_id = await _paused_realtime_run(client)
        before = (await client.get(f"/api/runs/{run_id}")).json()["ticks"]
        answers = await asyncio.gather(*(client.post(f"/api/runs/{run_id}/step") for _ in range(3)))
        assert all(a.status_code == 200 for a in answers)
        assert (await client.get(f"/api/runs/{run_id}")).json()["ticks"] == before + 3
        await client.post(f"/api/runs/{run_id}/stop")


@pytest.mark.parametrize("each_link", ["local"], indirect=True)  # reaches into the engine
async def test_a_pending_step_is_answered_when_the_run_stops(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        run_id = await _paused_realtime_run(client)
        runs: Runs = app.state.srlab.engines
        assert isinstance(runs.link, LocalLink)
        engine = runs.link.engine(run_id)
        assert engine is not None

        async def step_then_stop() -> int:  # on the engines' loop, where the run ticks
            step = asyncio.ensure_future(engine.step())
            await asyncio.sleep(0)  # the step is asked; the tick task has not woken yet
            engine.stop()
            return await step

        step = asyncio.create_task(step_then_stop())
        with pytest.raises(RunStateError, match="ended before the step"):
            await step
        await until(client, run_id, "stopped")


async def test_rate_changes_a_live_realtime_run(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run_id = await _paused_realtime_run(client)
        r = await client.post(f"/api/runs/{run_id}/rate", json={"hz": 20})
        assert r.status_code == 200 and r.json()["live"]["hz"] == 20.0
        bad = await client.post(f"/api/runs/{run_id}/rate", json={"hz": 0})
        assert bad.status_code == 422 and "hz" in json.dumps(bad.json())
        await client.post(f"/api/runs/{run_id}/stop")
        await until(client, run_id, "stopped")
        assert (await client.post(f"/api/runs/{run_id}/rate", json={"hz": 5})).status_code == 409


async def test_world_describes_the_runs_track(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="kp")
        r = await client.get(f"/api/runs/{run['id']}/world")
        assert r.status_code == 200
        w = r.json()
        x0, y0, x1, y1 = w["outer_box"]
        ix0, iy0, ix1, iy1 = w["inner_box"]
        assert x0 < ix0 < ix1 < x1 and y0 < iy0 < iy1 < y1
        assert len(w["sonars"]) == 8 and w["sonar_range_m"] > 0
        assert len(w["stopline"]) == 2 and len(w["lamp"]) == 2
        # the walls as segments: the ring's are the two boxes' sides
        assert [x0, y0, x1, y0] in w["walls"]
        assert len(w["walls"]) == 8 and len(w["centre_line"]) == 4
        assert w["corridor_widths_m"] == [w["corridor_width_m"]] * 4
        assert (await client.get("/api/runs/99/world")).status_code == 404


def test_a_corridor_worlds_view_has_its_walls_and_centre_line() -> None:
    w = world_public("figure-8")
    assert w.centre_line == [
        [0.6, 3.1], [6.6, 3.1], [6.6, 7.1], [3.6, 7.1], [3.6, 0.6], [0.6, 0.6]
    ]  # fmt: skip
    assert w.corridor_widths_m == [1.2] * 6
    assert len(w.walls) == 16  # 12 mitred sides, 2 of them cut open at the crossing
    x0, y0, x1, y1 = w.outer_box
    assert all(x0 <= x <= x1 and y0 <= y <= y1 for s in w.walls for x, y in (s[:2], s[2:]))


async def test_tick_events_carry_sonar_readings_and_the_obstacle(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        run = await create(client, condition="kp", mode="realtime", hz=50)
        ticks = await streamed_ticks(client, app, run["id"], 3)
        world = (await client.get(f"/api/runs/{run['id']}/world")).json()
    for t in ticks:
        TickEvent.model_validate(t)  # the stream's contract
        assert len(t["sonar_m"]) == len(world["sonars"]) == 8
        assert all(0 <= r <= world["sonar_range_m"] + 0.5 for r in t["sonar_m"])
        assert t["obstacle"] is None or len(t["obstacle"]) == 2


def test_a_views_floor_is_a_quadrilateral_a_segment_and_says_which_kind_of_track() -> None:
    ring, corridor = world_public(""), world_public("l-shape")
    assert ring.ring and not corridor.ring
    assert len(ring.floor) == 4 and len(corridor.floor) == len(corridor.centre_line) == 6
    # The l-shape's first segment, (0.6, 0.6) to (7.4, 0.6), 1.2 m wide, mitred at both
    # corners: left side (0.6 m in) from x 1.2 to 6.8, right side from x 0 to 8.
    assert [v for p in corridor.floor[0] for v in p] == pytest.approx(
        [1.2, 1.2, 6.8, 1.2, 8, 0, 0, 0]
    )
    x0, y0, x1, y1 = corridor.outer_box
    assert all(x0 <= x <= x1 and y0 <= y <= y1 for q in corridor.floor for x, y in q)


async def test_a_corridor_runs_ticks_and_trace_carry_every_obstacle_where_it_is(
    tmp_path: Path,
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, app):
        run = await create(client, condition="kp", world="l-shape", mode="realtime", hz=100)
        ticks = await streamed_ticks(client, app, run["id"], 12)
    for t in ticks:
        TickEvent.model_validate(t)
        assert len(t["obstacles"]) == 2 and t["obstacle"] == t["obstacles"][0]
    # The seeded obstacle stands, the trolley on segment 0 (y = 0.6 + 0.3) moves.
    same = [t for t in ticks if t["episode"] == ticks[0]["episode"]]
    first, last = same[0], same[-1]
    assert last["tick"] > first["tick"]
    assert first["obstacles"][0] == last["obstacles"][0]
    assert first["obstacles"][1] != last["obstacles"][1]
    assert first["obstacles"][1][1] == pytest.approx(0.9)


async def test_a_stored_corridor_episodes_trace_rows_place_every_obstacle(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run = await create(client, condition="rp", world="l-shape", seed=4, episodes=1)
        await client.post(f"/api/runs/{run['id']}/start")
        await until(client, run["id"], "finished")
        trace = (await client.get(f"/api/runs/{run['id']}/episodes/0")).json()["trace"]
        ring = await create(client, condition="rp", seed=4, episodes=1)
        await client.post(f"/api/runs/{ring['id']}/start")
        await until(client, ring["id"], "finished")
        ring_trace = (await client.get(f"/api/runs/{ring['id']}/episodes/0")).json()["trace"]
    assert len(trace) > 10 and all(len(r["obstacles"]) == 2 for r in trace)
    trolley = {tuple(r["obstacles"][1]) for r in trace}
    assert len(trolley) > 5  # it moves through the episode
    assert len({tuple(r["obstacles"][0]) for r in trace}) == 1  # the seeded one stands
    # The ring's one obstacle, or none, the same on every row.
    assert len({json.dumps(r["obstacles"]) for r in ring_trace}) == 1
    assert all(len(r["obstacles"]) <= 1 for r in ring_trace)
