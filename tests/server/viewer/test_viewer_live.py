"""The 3D view inside the service: its lifecycle, live following, panel commands, replay.

The app runs with its lifespan (viser on a free port, the renderer thread, the controller
task). Panel commands are handed to the controller with `Controller.post`, the call
viser's callbacks make; the browser test (test_viewer_browser.py) clicks the real panel.
"""

from __future__ import annotations

import asyncio
import socket
import time
from collections.abc import Callable
from pathlib import Path

import pytest
from apphelpers import client_for, settings_for
from gatehelpers import start_run, viewer_of

from bench.liveserver import free_port
from core.brain.selection import ORIGINS
from core.ports import RunStatus
from core.sim.worlds import default_world, load_world, world_names
from server.main import create_app
from server.viewer.render import REWARD_NOTE
from server.viewer.scene import static_scene, why
from server.viewer.state import (
    ChangeRate,
    ClientsChanged,
    GiveReward,
    Seek,
    SelectRun,
    SetMode,
    TogglePlay,
)

pytestmark = pytest.mark.anyio


async def until(check: Callable[[], object], timeout: float = 20.0, what: str = "") -> None:
    deadline = time.monotonic() + timeout
    while not check():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what or check}")
        await asyncio.sleep(0.01)


async def test_health_names_the_views_port_and_null_without_it(tmp_path: Path) -> None:
    port = free_port()
    async with client_for(settings_for(tmp_path, viser=True, viser_port=port)) as (client, app):
        assert (await client.get("/api/health")).json()["viser_port"] == port
        assert viewer_of(app).port == port
    async with client_for(settings_for(tmp_path)) as (client, app):
        assert (await client.get("/api/health")).json()["viser_port"] is None
        assert app.state.srlab.viewer is None


async def test_a_taken_port_is_a_clear_error_not_another_port(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        settings = settings_for(tmp_path, viser=True, viser_port=port)
        with pytest.raises(OSError, match=f"port {port} .* taken.*SRLAB_VISER_PORT"):
            async with client_for(settings):
                pass


def test_the_view_and_the_api_cannot_share_a_port(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="SRLAB_VISER_PORT and SRLAB_PORT are both 8123"):
        create_app(settings_for(tmp_path, viser=True, viser_port=8123, port=8123))
    create_app(settings_for(tmp_path, viser=False, viser_port=8123, port=8123))


async def test_a_watched_live_run_is_drawn_and_an_unwatched_one_costs_nothing(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        run_id = await start_run(client, condition="kp", mode="realtime", hz=50, seed=3)
        engine = app.state.srlab.engines.link.engine(run_id)  # the local host's
        await asyncio.sleep(0.2)
        assert engine.view().tick_watchers == 0  # nobody watches yet
        viewer.controller.post(ClientsChanged(1))
        r = viewer.renderer
        await until(lambda: r.drawn is not None and r.drawn.tick > 5, what="live ticks drawn")
        assert engine.view().tick_watchers == 1
        assert viewer.controller.state.run_id == run_id  # the live run was picked
        drawn = r.drawn
        assert drawn is not None and drawn.run_id == run_id and drawn.behaviour
        frame = r.last_frame
        assert frame is not None
        assert tuple(r._robot.position) == pytest.approx(frame.robot_position)
        assert frame.robot_position[:2] == (drawn.x, drawn.y)
        assert drawn.successes is not None and drawn.episodes_done is not None
        first = r.frames
        await asyncio.sleep(0.5)
        # At most 30 frames a second (the throttle), and some were drawn.
        assert 0 < r.frames - first <= 0.5 * 30 + 2
        viewer.controller.post(ClientsChanged(0))
        await until(lambda: engine.view().tick_watchers == 0, what="the subscription")
        await client.post(f"/api/runs/{run_id}/stop")


@pytest.mark.slow
async def test_the_view_link_chooses_the_run_and_it_stays_chosen(tmp_path: Path) -> None:
    port = free_port()
    settings = settings_for(tmp_path, viser=True, viser_port=port)
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        chosen = await start_run(client, condition="expert", episodes=1)
        newest = await start_run(client, condition="delayed", mode="realtime", hz=50)
        viewer.controller.post(ClientsChanged(1))
        await until(lambda: viewer.controller.state.run_id == newest, what="the newest followed")
        viewer.controller.post(SetMode("replay"))

        # A GET (an <img> on any page) chooses nothing.
        assert (await client.get(f"/api/runs/{chosen}/view")).status_code == 405
        r = await client.post(f"/api/runs/{chosen}/view")
        assert r.status_code == 200, r.text
        assert r.json()["run"] == chosen
        assert r.json()["url"].startswith(f"http://127.0.0.1:{port}/run/{chosen}?ticket=")
        # The next viewer to connect starts on it, live; the one open keeps its own.
        fresh = await asyncio.to_thread(viewer.open, viewer.server)
        try:
            c = fresh.controller
            await until(lambda: c.state.run_id == chosen, what="the chosen run")
            assert c.state.mode == "live"
            await asyncio.sleep(2.5)  # the view looks for runs every second: it stays put
            assert c.state.run_id == chosen
            assert viewer.controller.state.run_id == newest
            assert viewer.controller.state.mode == "replay"
        finally:
            await asyncio.to_thread(viewer.close, fresh)
        # A choice is for one viewer: the one after starts on the newest live run.
        later = await asyncio.to_thread(viewer.open, viewer.server)
        try:
            await until(lambda: later.controller.state.run_id == newest, what="the newest")
        finally:
            await asyncio.to_thread(viewer.close, later)

        missing = await client.post("/api/runs/999/view")
        assert missing.status_code == 404 and "999" in missing.json()["detail"]
        await client.post(f"/api/runs/{newest}/stop")
    async with client_for(settings_for(tmp_path)) as (client, _):
        off = await client.post(f"/api/runs/{chosen}/view")
        assert off.status_code == 409 and "SRLAB_VISER" in off.json()["detail"]


async def test_panel_rewards_are_stored_and_credited_like_rewards_over_http(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        run_id = await start_run(client, condition="kp", mode="realtime", hz=50, seed=1)
        viewer.controller.post(ClientsChanged(1))
        viewer.controller.post(SelectRun(run_id))
        await until(lambda: viewer.controller.state.live is not None, what="the run selected")
        await asyncio.sleep(0.3)
        viewer.controller.post(GiveReward(1.0))

        async def log() -> list[dict[str, object]]:
            data: list[dict[str, object]] = (
                await client.get(f"/api/runs/{run_id}/rewards")
            ).json()["data"]
            return data

        deadline = time.monotonic() + 20
        rewards = await log()
        while not (rewards and rewards[0]["applied"]) and time.monotonic() < deadline:
            await asyncio.sleep(0.05)
            rewards = await log()
        assert len(rewards) == 1
        reward = rewards[0]
        assert reward["source"] == "trainer" and reward["note"] == REWARD_NOTE
        assert reward["value"] == 1.0 and reward["applied"] and reward["credited"] > 0  # type: ignore[operator]
        assert f"stored as #{reward['id']}" in viewer.controller.state.notice
        ltm = (await client.get(f"/api/runs/{run_id}/ltm")).json()["data"]
        assert any(p["reliability"] > 0 for p in ltm)

        viewer.controller.post(ChangeRate(25.0))
        engine = app.state.srlab.engines.get(run_id)
        await until(lambda: engine.hz == 25.0, what="the new rate")
        assert (await client.get(f"/api/runs/{run_id}")).json()["live"]["hz"] == 25.0
        await client.post(f"/api/runs/{run_id}/stop")
        await until(lambda: engine.status is RunStatus.STOPPED, what="the stop")
        viewer.controller.post(GiveReward(-1.0))
        await until(lambda: "not given" in viewer.controller.state.notice, what="a refusal")
        assert len(await log()) == 1


async def test_the_panel_cannot_write_when_the_service_needs_a_token(tmp_path: Path) -> None:
    settings = settings_for(
        tmp_path, viser=True, viser_port=free_port(), host="127.0.0.1", token="s3cret"
    )
    headers = {"Authorization": "Bearer s3cret"}
    async with client_for(settings, headers) as (client, app):
        viewer = viewer_of(app)
        run_id = await start_run(client, condition="delayed", mode="realtime", hz=50, seed=1)
        viewer.controller.post(ClientsChanged(1))
        viewer.controller.post(GiveReward(1.0))
        await until(lambda: "loopback only" in viewer.controller.state.notice, what="a refusal")
        viewer.controller.post(ChangeRate(5.0))
        await asyncio.sleep(0.1)
        assert app.state.srlab.engines.get(run_id).hz == 50.0
        assert (await client.get(f"/api/runs/{run_id}/rewards")).json()["count"] == 0
        await client.post(f"/api/runs/{run_id}/stop")


async def test_a_fast_run_has_no_rate_to_change(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        run_id = await start_run(client, condition="innate", mode="fast", seed=1)
        viewer.controller.post(ClientsChanged(1))
        viewer.controller.post(SelectRun(run_id))
        viewer.controller.post(ChangeRate(5.0))
        await until(lambda: "Not done" in viewer.controller.state.notice, what="a refusal")
        await client.post(f"/api/runs/{run_id}/stop")


async def test_replay_from_the_panel_draws_the_stored_poses(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        c, r = viewer.controller, viewer.renderer
        run_id = await start_run(client, condition="kp", mode="fast", seed=5, episodes=3)
        engine = app.state.srlab.engines.get(run_id)
        await until(lambda: engine.status is RunStatus.FINISHED, what="the run to finish")
        await asyncio.sleep(0.2)  # its episodes are committed a moment later
        c.post(ClientsChanged(1))
        c.post(SelectRun(run_id))
        c.post(SetMode("replay"))
        await until(lambda: c.state.replay is not None, what="a replay")
        replay = c.state.replay
        assert replay is not None and replay.episode == 2  # the last stored episode
        assert [n for n, _ in c.state.episodes] == [0, 1, 2]
        detail = (await client.get(f"/api/runs/{run_id}/episodes/2")).json()
        assert len(detail["trace"]) == replay.ticks
        c.post(TogglePlay())  # it plays when loaded: pause it
        await until(lambda: c.state.clock is not None and not c.state.clock.playing)
        for index in (10, replay.ticks - 1, 0):
            c.post(Seek(index))
            row = detail["trace"][index]
            await until(
                lambda row=row: r.drawn is not None and r.drawn.tick == row["tick"],  # type: ignore[misc]
                what=f"tick {row['tick']} drawn",
            )
            assert r.drawn is not None
            assert (r.drawn.x, r.drawn.y) == pytest.approx((row["x"], row["y"]))
            assert r.drawn.behaviour == row["behaviour"]
            assert list(r.drawn.stimuli) == row["stimuli"]
            assert tuple(r._robot.position)[:2] == pytest.approx((row["x"], row["y"]))
            # The slider and the panel count the same ticks, both from 1 (defect 10).
            await until(lambda: r._scrub.value == r.drawn.episode_tick, what="the slider")  # type: ignore[union-attr]
            assert f"(tick {r.drawn.episode_tick} of it)" in r._decision.content
            assert r._scrub.value == index + 1 and r._scrub.min == 1
        assert r._scrub.max == replay.ticks


async def test_each_run_is_drawn_in_its_own_world_live_and_replayed(tmp_path: Path) -> None:
    other = next(n for n in world_names() if n != default_world())
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        c, r = viewer.controller, viewer.renderer
        stored = await start_run(client, condition="kp", episodes=1, seed=2, world=other)
        ended = app.state.srlab.engines.get(stored)
        await until(
            lambda: ended.status is RunStatus.FINISHED,
            what="the run in the other world to finish",
        )
        await asyncio.sleep(0.2)  # its episode is committed a moment later
        live = await start_run(client, condition="kp", mode="realtime", hz=50, seed=3)
        c.post(ClientsChanged(1))
        await until(lambda: r.drawn is not None and r.drawn.run_id == live, what="live ticks")
        assert r.world == load_world(default_world()).config
        assert r.drawn is not None and r.drawn.origin in ORIGINS
        assert f"({why(r.drawn)})" in r._decision.content

        c.post(SelectRun(stored))
        c.post(SetMode("replay"))
        await until(lambda: c.state.replay is not None, what="a replay")
        preset = load_world(other).config
        assert c.state.replay is not None and c.state.replay.world == preset
        await until(lambda: r.world == preset, what="the other world drawn")
        assert r.static == static_scene(preset)
        await until(lambda: f"world {other}" in r._header.content, what="the run's world named")
        await until(lambda: r.drawn is not None and r.drawn.run_id == stored, what="a replay")
        assert r.drawn is not None and r.drawn.origin in ORIGINS
        await client.post(f"/api/runs/{live}/stop")


async def test_the_panel_rewards_a_paused_run_as_the_api_does(tmp_path: Path) -> None:
    settings = settings_for(tmp_path, viser=True, viser_port=free_port())
    async with client_for(settings) as (client, app):
        viewer = viewer_of(app)
        run_id = await start_run(client, condition="kp", mode="realtime", hz=50, seed=1)
        viewer.controller.post(ClientsChanged(1))
        viewer.controller.post(SelectRun(run_id))
        await until(lambda: viewer.controller.state.live is not None, what="the run selected")
        assert (await client.post(f"/api/runs/{run_id}/pause")).status_code == 200
        viewer.controller.post(GiveReward(1.0))
        await until(lambda: "stored as #" in viewer.controller.state.notice, what="stored")
        log = (await client.get(f"/api/runs/{run_id}/rewards")).json()["data"]
        assert [(r["source"], r["value"]) for r in log] == [("trainer", 1.0)]
        await client.post(f"/api/runs/{run_id}/stop")
