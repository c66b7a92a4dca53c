"""A trainer's reward with the tick they saw, over HTTP: the window, the log, bad input."""

from __future__ import annotations

import asyncio
from pathlib import Path
from typing import Any

import pytest
from apphelpers import client_for, create, settings_for, until

from server.config import Settings

pytestmark = [pytest.mark.anyio, pytest.mark.usefixtures("each_link")]  # over both links


async def test_a_reward_with_a_seen_tick_is_answered_logged_and_credited_in_its_window(
    tmp_path: Path,
) -> None:
    settings = settings_for(tmp_path, reaction_window="0.02-0.05")  # 1..5 ticks at 100 Hz
    async with client_for(settings) as (client, _):
        run = await create(client, condition="kp", mode="realtime", hz=100)
        assert run["reaction_window_s"] == [0.02, 0.05]
        run_id = run["id"]
        await client.post(f"/api/runs/{run_id}/start")
        await until(client, run_id, "running")
        assert (await client.post(f"/api/runs/{run_id}/pause")).status_code == 200
        for _ in range(12):
            assert (await client.post(f"/api/runs/{run_id}/step")).status_code == 200
        ticks = (await client.get(f"/api/runs/{run_id}")).json()["live"]["tick"]
        seen = ticks - 1
        r = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1, "tick_seen": seen})
        assert r.status_code == 202, r.text
        ack = r.json()
        assert (ack["tick_seen"], ack["seen_episode"]) == (seen, 0)
        assert ack["window"] == [seen - 5, seen]  # paused: up to the seen tick itself
        log = await applied(client, run_id)
        assert (log["tick_seen"], log["window"], log["seen_episode"]) == (seen, ack["window"], 0)
        assert 1 <= log["credited"] <= 6
        plain = await client.post(f"/api/runs/{run_id}/rewards", json={"value": 1})
        assert plain.json()["tick_seen"] is None and plain.json()["window"] is None
        await client.post(f"/api/runs/{run_id}/stop")


@pytest.mark.parametrize(
    ("body", "field", "says"),
    [
        ({"value": 1, "tick_seen": 10_000}, "tick_seen", "in the future"),
        ({"value": 1, "tick_seen": 0, "episode": 4}, "episode", "episode 4"),
        ({"value": 1, "episode": 0}, "episode", "send both"),
        ({"value": 1, "tick_seen": -1}, "tick_seen", "greater than or equal"),
    ],
)
async def test_a_bad_seen_tick_is_a_422_naming_the_field_and_stores_nothing(
    tmp_path: Path, body: dict[str, Any], field: str, says: str
) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        run_id = (await create(client, condition="kp", mode="realtime", hz=100))["id"]
        await client.post(f"/api/runs/{run_id}/start")
        await until(client, run_id, "running")
        await client.post(f"/api/runs/{run_id}/pause")
        r = await client.post(f"/api/runs/{run_id}/rewards", json=body)
        assert r.status_code == 422, r.text
        (problem,) = r.json()["detail"]
        assert problem["loc"] == ["body", field] and says in problem["msg"]
        assert (await client.get(f"/api/runs/{run_id}/rewards")).json()["count"] == 0
        await client.post(f"/api/runs/{run_id}/stop")


async def test_a_run_keeps_the_window_it_was_created_with(tmp_path: Path) -> None:
    async with client_for(settings_for(tmp_path)) as (client, _):
        default = await create(client, condition="kp")
        own = await create(client, condition="kp", params={"reaction_window_s": [2, 0.5]})
        bad = await client.post(
            "/api/runs", json={"condition": "kp", "params": {"reaction_window_s": [2, 61]}}
        )
    assert default["reaction_window_s"] == [0.2, 4.0]
    assert own["reaction_window_s"] == [0.5, 2.0]  # the bounds in either order
    assert bad.status_code == 422 and "reaction_window_s" in bad.text
    async with client_for(settings_for(tmp_path, reaction_window="1-3")) as (client, _):
        again = (await client.get(f"/api/runs/{default['id']}")).json()
        new = await create(client, condition="kp")
    assert again["reaction_window_s"] == [0.2, 4.0]  # a setting changed later: the run's own
    assert new["reaction_window_s"] == [1.0, 3.0]


@pytest.mark.parametrize("text", ["4", "4-1", "a-b", "0.2-100", "-1-2"])
def test_a_bad_reaction_window_setting_says_what_it_needs(text: str) -> None:
    with pytest.raises(ValueError, match="LO-HI"):
        Settings(reaction_window=text)


async def applied(client: Any, run_id: int, reward_id: int | None = None) -> dict[str, Any]:
    """The reward (the first logged, or `reward_id`) once applied."""
    async with asyncio.timeout(30):  # a bound for a hang, not a speed test
        while True:
            log = (await client.get(f"/api/runs/{run_id}/rewards")).json()["data"]
            mine = [r for r in log if reward_id is None or r["id"] == reward_id][:1]
            if mine and mine[0]["applied"]:
                return dict(mine[0])
            await asyncio.sleep(0.02)


async def paused_after_two_episodes(client: Any) -> tuple[int, int]:
    """A 1 kHz kp run paused once it has ended two episodes: its id and its episodes done."""
    run_id = (await create(client, condition="kp", mode="realtime", hz=1000))["id"]
    await client.post(f"/api/runs/{run_id}/start")
    async with asyncio.timeout(60):  # a bound for a hang, not a speed test
        while (await client.get(f"/api/runs/{run_id}")).json()["episodes_done"] < 2:
            await asyncio.sleep(0.05)
    paused = await client.post(f"/api/runs/{run_id}/pause")
    assert paused.status_code == 200, paused.text
    return run_id, int(paused.json()["episodes_done"])


async def test_a_reward_on_a_stored_episode_s_tick_credits_its_stored_records(
    tmp_path: Path,
) -> None:
    """Feedback on replay: the trainer scrubs episode 0, ended and stored, and presses +
    at one of its ticks: the records of its trace in the window up to that tick."""
    settings = settings_for(tmp_path, reaction_window="0.02-0.05")  # up to 50 ticks at 1 kHz
    async with client_for(settings) as (client, _):
        run_id, _ = await paused_after_two_episodes(client)
        trace = (await client.get(f"/api/runs/{run_id}/episodes/0")).json()["trace"]
        answered = [row["tick"] for row in trace if row["released_by"] is not None]
        seen = answered[len(answered) // 2]
        expected = [t for t in answered if seen - 50 <= t <= seen]
        body = {"value": 1, "tick_seen": seen, "episode": 0}
        r = await client.post(f"/api/runs/{run_id}/rewards", json=body)
        assert r.status_code == 202, r.text
        assert (r.json()["seen_episode"], r.json()["window"]) == (0, [seen - 50, seen])
        log = await applied(client, run_id, r.json()["id"])
        assert log["credited"] == len(expected) > 0
        outside = {"value": 1, "tick_seen": trace[-1]["tick"] + 1, "episode": 0}
        bad = await client.post(f"/api/runs/{run_id}/rewards", json=outside)
        assert bad.status_code == 422 and bad.json()["detail"][0]["loc"] == ["body", "tick_seen"]
        unknown = await client.post(
            f"/api/runs/{run_id}/rewards", json={"value": 1, "tick_seen": 0, "episode": 99}
        )
        assert unknown.status_code == 422, unknown.text
        await client.post(f"/api/runs/{run_id}/stop")


async def test_every_tick_of_the_episode_that_ended_last_credits_its_stored_records(
    tmp_path: Path,
) -> None:
    """Feedback on replay of the episode that ended last (the run still keeps its last
    records aside): each tick credits the records of its trace in the window up to it, its
    first as its last, and a tick outside it is a 422 naming `tick_seen`."""
    settings = settings_for(tmp_path, reaction_window="0.02-0.05")  # up to 50 ticks at 1 kHz
    async with client_for(settings) as (client, _):
        run_id, episodes_done = await paused_after_two_episodes(client)
        last = episodes_done - 1
        async with asyncio.timeout(60):
            while (
                got := await client.get(f"/api/runs/{run_id}/episodes/{last}")
            ).status_code != 200:
                await asyncio.sleep(0.05)
        trace = got.json()["trace"]
        answered = [row["tick"] for row in trace if row["released_by"] is not None]
        for seen in (answered[0], answered[len(answered) // 2], trace[-1]["tick"]):
            expected = [t for t in answered if seen - 50 <= t <= seen]
            body = {"value": 1, "tick_seen": seen, "episode": last}
            r = await client.post(f"/api/runs/{run_id}/rewards", json=body)
            assert r.status_code == 202, r.text
            assert (r.json()["seen_episode"], r.json()["window"]) == (last, [seen - 50, seen])
            assert (await applied(client, run_id, r.json()["id"]))["credited"] == len(expected)
        outside = {"value": 1, "tick_seen": trace[0]["tick"] - 1, "episode": last}
        bad = await client.post(f"/api/runs/{run_id}/rewards", json=outside)
        assert bad.status_code == 422 and bad.json()["detail"][0]["loc"] == ["body", "tick_seen"]
        await client.post(f"/api/runs/{run_id}/stop")
